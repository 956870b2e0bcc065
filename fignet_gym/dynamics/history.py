"""The pose history a learned step needs, kept in ``MjData.userdata`` so that it is part of the state.

A learned simulator steps from the last few poses of every object, not from ``qpos``/``qvel``
alone. Those past poses live in ``data.userdata`` (``mjSTATE_USERDATA`` is in
:data:`~fignet_gym.dynamics.STATE_SPEC`), so ``mj_getState``/``mj_setState``, ``MjData`` copies,
``env.get_state()`` and ``Dynamics.rollout`` carry them with the rest of the state; a reset
(``mj_resetData``) zeroes them. Both backends record them: what a planner predicts from a state
taken mid-episode starts from the same history the environment's next step uses, whichever
dynamics produced that state.

Layout of the first :func:`history_size` entries of ``userdata`` (``P = 7 * (nfree + nmocap)``
tracked poses: every free joint's ``qpos`` in joint order, then every mocap body's position and
quaternion in mocap order)::

    [time, interval, count[nfree + nmocap], qvel[nfree, 6], frames[FRAMES, P]]

``frames[0]`` holds the poses at ``time``, ``frames[k]`` those ``k * interval`` seconds earlier;
``count[j]`` says how many frames of tracked body ``j`` are valid (0: none, after a reset or
before the first step); ``qvel`` is each free joint's velocity at ``time``, so that an edited
velocity (a released object) is told from the recorded one. A model compiled without room
for it (``model.nuserdata < history_size(model)``) still steps: the learned dynamics then
re-seeds its history from ``qpos``/``qvel`` at every call. :func:`compile_with_history`
compiles MJCF with the room; :func:`with_history` gives an already compiled model (one loaded
with ``MjModel.from_xml_path``) the room.
"""

from __future__ import annotations

import functools
import os
import tempfile
import weakref

import mujoco
import numpy as np

#: Frames of history kept per tracked body (the current poses and ``FRAMES - 1`` earlier ones):
#: a learned simulator with ``history + 1 <= FRAMES`` poses per step reads its whole input here.
FRAMES = 5
#: Entries before the per-body counts: the time of ``frames[0]`` and the spacing of the frames.
HEADER = 2
#: Two frames at most this far apart in position (m) or quaternion components count as the same
#: pose: a learned history stored in float32 and re-read in float64 differs by rounding only,
#: while a teleported object moves by far more.
SAME_POSE = 1e-6


#: Per model: free joints' qpos and qvel addresses (read-only ``int[nfree]``), computed once
#: (a MuJoCo env step records the history: it must stay cheap next to ``mj_step``).
_ADDRESSES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _addresses(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    out = _ADDRESSES.get(model)
    if out is None:
        free = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)
        out = (model.jnt_qposadr[free].astype(np.int64), model.jnt_dofadr[free].astype(np.int64))
        for a in out:
            a.flags.writeable = False
        _ADDRESSES[model] = out
    return out


def free_qpos_addresses(model: mujoco.MjModel) -> np.ndarray:
    """``int[nfree]``: ``qpos`` address of every free joint, in joint order."""
    return _addresses(model)[0]


def num_tracked(model: mujoco.MjModel) -> int:
    """Tracked bodies: free joints, then mocap bodies."""
    return len(_addresses(model)[0]) + model.nmocap


def history_size(model: mujoco.MjModel) -> int:
    """``userdata`` entries the history of ``model`` needs."""
    n = num_tracked(model)
    return HEADER + n + 6 * len(_addresses(model)[0]) + FRAMES * 7 * n


def has_history(model: mujoco.MjModel) -> bool:
    """Whether ``model`` has room for the pose history in ``userdata``."""
    return model.nuserdata >= history_size(model)


def compile_with_history(xml: str) -> mujoco.MjModel:
    """Compile MJCF ``xml`` with ``nuserdata`` large enough for the pose history (kept if larger)."""
    spec = mujoco.MjSpec.from_string(xml)
    model = spec.compile()
    need = history_size(model)
    if model.nuserdata >= need:
        return model
    spec.nuserdata = need
    return spec.compile()


def _binary(model: mujoco.MjModel) -> bytearray:
    """``model`` in MuJoCo's binary (MJB) format."""
    buf = np.zeros(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buf)
    return bytearray(buf.tobytes())


@functools.lru_cache(maxsize=1)
def _nuserdata_offset() -> int:
    """Byte offset of ``nuserdata`` in an MJB file of this MuJoCo build: the one place where two
    models differing only in ``nuserdata`` differ (measured, so no version's layout is assumed)."""
    spec = mujoco.MjSpec.from_string("<mujoco><worldbody/></mujoco>")
    probes = []
    for n in (0, 0x1234567):
        spec.nuserdata = n
        probes.append(np.frombuffer(bytes(_binary(spec.compile())), np.uint8))
    diff = np.flatnonzero(probes[0] != probes[1])
    offset = int(diff[0]) - int(diff[0]) % 4
    if diff.max() >= offset + 4:
        raise RuntimeError("this MuJoCo build's model files differ in more than nuserdata")
    return offset


def with_history(model: mujoco.MjModel) -> mujoco.MjModel:
    """``model`` itself if it has room for the pose history, else a copy that has it.

    For a model already compiled (``MjModel.from_xml_path``, a binary file): MuJoCo fixes a
    model's sizes when it compiles, so the copy goes through its binary format with only
    ``nuserdata`` changed; the physics are the same. Make ``MjData`` from the returned model.
    """
    need = history_size(model)
    if model.nuserdata >= need:
        return model
    buf, at = _binary(model), _nuserdata_offset()
    if int.from_bytes(buf[at:at + 4], "little") != model.nuserdata:
        raise RuntimeError("cannot locate nuserdata in this model's binary form: compile its MJCF "
                           "with fignet_gym.dynamics.compile_with_history instead")
    buf[at:at + 4] = int(need).to_bytes(4, "little")
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "model.mjb")
        with open(path, "wb") as f:
            f.write(buf)
        return mujoco.MjModel.from_binary_path(path)


def tracked_poses(model: mujoco.MjModel, qpos: np.ndarray, mocap: np.ndarray) -> np.ndarray:
    """``float64[..., P]`` tracked poses from ``qpos float[..., nq]`` and mocap poses ``float[...,
    nmocap * 7]`` (positions, then quaternions: the control layout)."""
    qa = free_qpos_addresses(model)
    free = np.asarray(qpos)[..., qa[:, None] + np.arange(7)]  # [..., nfree, 7]
    nm = model.nmocap
    mocap = np.asarray(mocap)
    pos = mocap[..., : 3 * nm].reshape(*mocap.shape[:-1], nm, 3)
    quat = mocap[..., 3 * nm :].reshape(*mocap.shape[:-1], nm, 4)
    poses = np.concatenate((free, np.concatenate((pos, quat), -1)), axis=-2)
    return poses.reshape(*poses.shape[:-2], -1)


def free_qvel(model: mujoco.MjModel, qvel: np.ndarray) -> np.ndarray:
    """``float[..., nv] -> float[..., nfree, 6]`` the free joints' velocities."""
    da = _addresses(model)[1]
    return np.asarray(qvel)[..., da[:, None] + np.arange(6)]


def normalized_qpos(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """A copy of ``qpos float[..., nq]`` with its quaternions normalised as ``mj_step`` does (a
    zero one becomes the identity): the pose a step starts from."""
    out = np.array(qpos, dtype=np.float64)
    for row in out.reshape(-1, model.nq):
        mujoco.mj_normalizeQuat(model, row)
    return out


def unpack(model: mujoco.MjModel, userdata: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``float64[..., nuserdata]`` -> time ``float[...]``, interval ``float[...]``, counts
    ``int[..., n]``, free-joint velocities ``float[..., nfree, 6]`` and frames ``float[...,
    FRAMES, n, 7]`` (``n`` tracked bodies)."""
    n, nf = num_tracked(model), len(free_qpos_addresses(model))
    u = np.asarray(userdata, dtype=np.float64)
    lead = u.shape[:-1]
    counts = u[..., HEADER : HEADER + n].astype(np.int64)
    vel = u[..., HEADER + n : HEADER + n + 6 * nf].reshape(*lead, nf, 6)
    frames = u[..., HEADER + n + 6 * nf : history_size(model)].reshape(*lead, FRAMES, n, 7)
    return u[..., 0], u[..., 1], counts, vel, frames


def pack(model: mujoco.MjModel, time: np.ndarray, interval: float | np.ndarray,
         counts: np.ndarray, vel: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Inverse of :func:`unpack` (the history entries only): ``float64[..., history_size]``."""
    time = np.asarray(time, dtype=np.float64)
    lead = time.shape
    n = num_tracked(model)
    return np.concatenate(
        (
            time[..., None],
            np.broadcast_to(np.asarray(interval, dtype=np.float64), lead)[..., None],
            np.broadcast_to(counts, (*lead, n)).astype(np.float64),
            np.asarray(vel, dtype=np.float64).reshape(*lead, -1),
            np.asarray(frames, dtype=np.float64).reshape(*lead, FRAMES * n * 7),
        ),
        axis=-1,
    )


def valid_counts(model: mujoco.MjModel, userdata: np.ndarray, time: np.ndarray,
                 interval: float, current: np.ndarray, qvel: np.ndarray) -> np.ndarray:
    """``int[..., n]`` frames usable per tracked body: 0 unless the history was recorded at
    ``time float[...]`` with frames ``interval`` apart, its ``frames[0]`` is ``current
    float[..., n, 7]`` and (free joints) its velocity ``qvel float[..., nv]`` (a body whose pose
    or velocity was edited since, e.g. a released object, has none)."""
    t, dt, counts, vel, frames = unpack(model, userdata)
    ok = (t == np.asarray(time)) & (np.abs(dt - interval) <= 1e-9 * max(interval, 1e-12))
    same = (np.abs(frames[..., 0, :, :] - current) <= SAME_POSE).all(-1)
    nf = vel.shape[-2]
    same[..., :nf] &= (np.abs(vel - free_qvel(model, qvel)) <= SAME_POSE).all(-1)
    return np.where(ok[..., None] & same, np.minimum(counts, FRAMES), 0)


def record(model: mujoco.MjModel, userdata: np.ndarray, before: np.ndarray, after: np.ndarray,
           time_before: np.ndarray, time_after: np.ndarray, interval: float,
           qvel_before: np.ndarray, qvel_after: np.ndarray) -> np.ndarray:
    """The history after steps of ``interval`` seconds, as MuJoCo-stepped data records it.

    ``userdata float64[B, nuserdata]`` at ``time_before float[B]`` with tracked poses ``before
    float[B, n, 7]``, then the poses after each step ``after float[B, T, n, 7]`` at ``time_after
    float[B, T]`` (the data's own clock, so that the next call finds its history valid), with
    velocities ``qvel_before float[B, nv]`` and ``qvel_after float[B, T, nv]`` ->
    ``float64[B, T, history_size]``: frames shifted by one per step, counts up to
    :data:`FRAMES` (restarting at 1 for a body whose history does not match ``before``).
    """
    B, T = after.shape[:2]
    counts = valid_counts(model, userdata, time_before, interval, before, qvel_before)
    old = unpack(model, userdata)[4]
    frames = old.copy()
    frames[:, 0] = before
    counts = np.maximum(counts, 1)
    out = np.empty((B, T, history_size(model)))
    for t in range(T):
        frames = np.concatenate((after[:, t, None], frames[:, :-1]), axis=1)
        counts = np.minimum(counts + 1, FRAMES)
        vel = free_qvel(model, qvel_after[:, t])
        out[:, t] = pack(model, time_after[:, t], interval, counts, vel, frames)
    return out


def record_step(model: mujoco.MjModel, userdata: np.ndarray, before: np.ndarray,
                after: np.ndarray, time_before: float, time_after: float, interval: float,
                qvel_before: np.ndarray, qvel_after: np.ndarray) -> None:
    """:func:`record` of one step of one ``MjData``, in place in its ``userdata
    float64[nuserdata]`` (``before``, ``after``: ``float[n, 7]``; ``qvel_*``: ``float[nv]``): the
    path of every MuJoCo env step, kept to a few array operations."""
    qa, da = _addresses(model)
    nf, n = len(qa), len(qa) + model.nmocap
    v0 = HEADER + n
    f0 = v0 + 6 * nf
    frames = userdata[f0 : f0 + FRAMES * 7 * n].reshape(FRAMES, n, 7)
    dofs = da[:, None] + np.arange(6)
    counts = np.zeros(n)
    if userdata[0] == time_before and abs(userdata[1] - interval) <= 1e-9 * max(interval, 1e-12):
        same = (np.abs(frames[0] - before) <= SAME_POSE).all(-1)
        vel = userdata[v0:f0].reshape(nf, 6)
        same[:nf] &= (np.abs(vel - qvel_before[dofs]) <= SAME_POSE).all(-1)
        counts = np.where(same, np.minimum(userdata[HEADER:v0], FRAMES), 0.0)
    frames[2:] = frames[1:-1].copy()
    frames[1] = before
    frames[0] = after
    userdata[HEADER:v0] = np.minimum(np.maximum(counts, 1) + 1, FRAMES)
    userdata[v0:f0] = qvel_after[dofs].ravel()
    userdata[0], userdata[1] = time_after, interval


def current_poses(model: mujoco.MjModel, qpos: np.ndarray, mocap_pos: np.ndarray,
                  mocap_quat: np.ndarray, normalize: bool = True) -> np.ndarray:
    """``float64[n, 7]`` tracked poses of one data: free joints from ``qpos float[nq]`` (with
    ``normalize``, their quaternions normalised as ``mj_step`` normalises them: a zero one is the
    identity), mocap bodies from ``mocap_pos float[nmocap, 3]``, ``mocap_quat float[nmocap, 4]``."""
    qa = _addresses(model)[0]
    nf = len(qa)
    out = np.empty((nf + model.nmocap, 7))
    out[:nf] = qpos[qa[:, None] + np.arange(7)]
    if normalize:
        q = out[:nf, 3:]
        norm = np.sqrt((q * q).sum(-1, keepdims=True))
        unit = q / np.maximum(norm, 1e-300)
        out[:nf, 3:] = np.where(norm < mujoco.mjMINVAL, (1.0, 0.0, 0.0, 0.0), unit)
    out[nf:, :3] = mocap_pos
    out[nf:, 3:] = mocap_quat
    return out
