"""MuJoCo itself behind the :class:`~fignet_gym.dynamics.base.Dynamics` interface."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from fignet_gym.dynamics.base import (
    CONTROL_SPEC,
    DivergenceError,
    DynamicsBase,
    join_state,
    split_state,
    userdata_slice,
)
from fignet_gym.dynamics.history import (
    current_poses,
    has_history,
    normalized_qpos,
    num_tracked,
    record,
    record_step,
    tracked_poses,
)

_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
)


class MujocoDynamics(DynamicsBase):
    """MuJoCo itself: ``mujoco.mj_step`` and threaded ``mujoco.rollout``.

    ``step`` is ``mujoco.mj_step(model, data, nstep)``, then raises :class:`DivergenceError` if
    MuJoCo reported an instability (bad ``qacc``/``qpos``/``qvel`` warnings; MuJoCo has then
    already reset ``data``). Mocap targets move linearly over the ``nstep`` timesteps, from the
    mocap bodies' current poses (``xpos``/``xquat``) to ``mocap_pos``/``mocap_quat``, as the
    training data's pusher does: holding a target for all substeps would make the pusher jump and
    kick the object (a 0.1 m/s push launched it at 0.7 m/s). With targets at the current poses,
    ``step`` is exactly ``mj_step``. On a model with room for it (:mod:`.history`), each call
    also records the poses before and after it in ``data.userdata`` (frames ``nstep`` timesteps
    apart), so that a learned model planning from this state sees the trajectory that led to it.

    Args:
        nthread: threads of :meth:`rollout` (default: the CPU count).
    """

    def __init__(self, nthread: int | None = None) -> None:
        self.nthread = int(nthread or os.cpu_count() or 1)
        self._pool: mujoco.rollout.Rollout | None = None
        # Scratch MjData of the last model rolled out. Not a WeakKeyDictionary: its MjData values
        # hold their model, so no key was ever freed (a fit over 500 models grew to 16 GB).
        self._scratch: tuple[mujoco.MjModel, list[mujoco.MjData]] | None = None

    def step(self, model: mujoco.MjModel, data: mujoco.MjData, nstep: int = 1) -> None:
        """``mujoco.mj_step(model, data, nstep)``; :class:`DivergenceError` if MuJoCo blew up."""
        before_warn = [data.warning[w].number for w in _WARNINGS]
        bodies = mocap_bodies(model)
        start = np.concatenate((data.xpos[bodies].ravel(), data.xquat[bodies].ravel()))
        target = np.concatenate((data.mocap_pos.ravel(), data.mocap_quat.ravel()))
        if nstep < 1:
            raise ValueError(f"nstep must be >= 1, got {nstep}")
        t0, before = data.time, None
        if has_history(model):
            before = current_poses(model, data.qpos, data.xpos[bodies], data.xquat[bodies])
            vel0 = data.qvel.copy()
        if nstep == 1 or np.array_equal(start, target):
            mujoco.mj_step(model, data, nstep)
        else:
            path = interpolate_mocap(start[None], target[None, None], nstep, model.nmocap)[0]
            for row in path:
                data.mocap_pos[:] = row[: 3 * model.nmocap].reshape(-1, 3)
                data.mocap_quat[:] = row[3 * model.nmocap :].reshape(-1, 4)
                mujoco.mj_step(model, data, 1)
        after = [data.warning[w].number for w in _WARNINGS]
        if after != before_warn:
            names = [w.name for w, a, b in zip(_WARNINGS, after, before_warn, strict=True) if a != b]
            raise DivergenceError(
                f"MuJoCo reported {', '.join(names)} at t={data.time:.3f}s "
                "(it reset the simulation)"
            )
        if before is not None:
            # mj_step normalised qpos already
            now = current_poses(model, data.qpos, data.mocap_pos, data.mocap_quat, normalize=False)
            record_step(model, data.userdata, before, now, t0, data.time,
                        nstep * float(model.opt.timestep), vel0, data.qvel)

    def _rollout(
        self, model: mujoco.MjModel, state: np.ndarray, control: np.ndarray, nstep: int,
        frame_skip: int,
    ) -> np.ndarray:
        """``mujoco.rollout`` on a persistent thread pool, one state per ``frame_skip`` timesteps.

        Shapes as :meth:`DynamicsBase._rollout`. Control row ``t`` is reached linearly over the
        ``frame_skip`` timesteps of step ``t``, from row ``t - 1`` (from the initial state's mocap
        pose for ``t = 0``), exactly as :meth:`step` moves them; ``frame_skip = 1`` is exactly
        ``mujoco.rollout``. Each returned state's mocap poses are the control rows.
        """
        if frame_skip < 1:
            raise ValueError(f"frame_skip must be >= 1, got {frame_skip}")
        B, T = control.shape[:2]
        if B == 0 or T == 0:  # mujoco.rollout crashes on an empty batch
            return np.zeros((B, T, state.shape[1]))
        if self._pool is None:
            self._pool = mj_rollout.Rollout(nthread=self.nthread if self.nthread > 1 else 0)
        if self._scratch is None or self._scratch[0] is not model:
            self._scratch = (model, [mujoco.MjData(model) for _ in range(max(self.nthread, 1))])
        datas = self._scratch[1]
        phys, start = split_state(model, state)
        fine = control
        if frame_skip > 1 and model.nmocap:
            fine = interpolate_mocap(start, control, frame_skip, model.nmocap)
        elif frame_skip > 1:
            fine = np.repeat(control, frame_skip, axis=1)
        out, _ = self._pool.rollout(
            model, datas, phys, fine, control_spec=CONTROL_SPEC, nstep=nstep * frame_skip
        )
        out = out[:, frame_skip - 1 :: frame_skip]
        user = np.repeat(state[:, None, userdata_slice(model)], T, axis=1)
        if has_history(model):
            n = num_tracked(model)
            before = tracked_poses(model, normalized_qpos(model, phys[:, 1 : 1 + model.nq]),
                                   start).reshape(B, n, 7)
            after = tracked_poses(model, out[..., 1:], control).reshape(B, T, n, 7)
            hist = record(model, state[:, userdata_slice(model)], before, after, phys[:, 0],
                          out[..., 0], frame_skip * float(model.opt.timestep),
                          phys[:, 1 + model.nq : 1 + model.nq + model.nv],
                          out[..., 1 + model.nq : 1 + model.nq + model.nv])
            user[..., : hist.shape[-1]] = hist
        return join_state(model, out, control, user)

    def close(self) -> None:
        """Stop the rollout thread pool."""
        if self._pool is not None:
            self._pool.close()
            self._pool = None


@contextlib.contextmanager
def collect_warnings() -> Iterator[list[str]]:
    """Collect MuJoCo's warnings (``Nan, Inf or huge value in QACC ...``) in the yielded list
    instead of letting MuJoCo print each and append it to ``MUJOCO_LOG.TXT`` in the working
    directory; the previous handler is restored on exit. Callers count and summarise them."""
    got: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(got.append)
    try:
        yield got
    finally:
        mujoco.set_mju_user_warning(previous)


def unstable_summary(what: str, unstable: int, total: int) -> str:
    """One line saying how many of ``total`` replays (or candidates) ``what`` made MuJoCo warn."""
    return (f"{what}: MuJoCo went unstable in {unstable} of {total} (its 'Nan, Inf or huge value' "
            "warning; each such replay holds its last finite poses and is scored as it is)")


def mocap_bodies(model: mujoco.MjModel) -> np.ndarray:
    """Body id of each mocap id, ``int[nmocap]``."""
    ids = np.nonzero(model.body_mocapid >= 0)[0]
    return ids[np.argsort(model.body_mocapid[ids])]


def interpolate_mocap(start: np.ndarray, targets: np.ndarray, substeps: int, nmocap: int) -> np.ndarray:
    """Per-timestep mocap controls moving linearly through a sequence of targets.

    ``start float[B, C]`` and ``targets float[B, T, C]`` (``C = nmocap * 7``: positions then
    quaternions) -> ``float[B, T * substeps, C]``; quaternions are normalised linear blends.
    """
    prev = np.concatenate((start[:, None], targets[:, :-1]), axis=1)  # [B, T, C]
    frac = (np.arange(1, substeps + 1) / substeps)[None, None, :, None]
    path = prev[:, :, None] + (targets - prev)[:, :, None] * frac  # [B, T, S, C]
    q = path[..., 3 * nmocap :].reshape(*path.shape[:-1], nmocap, 4)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    # A zero blend (a zero target quaternion) is the identity, as mju_normalize4 makes it.
    q[:] = np.where(norm > 0, q / np.where(norm > 0, norm, 1.0), np.array([1.0, 0.0, 0.0, 0.0]))
    path[..., 3 * nmocap :] = q.reshape(*path.shape[:-1], nmocap * 4)
    return path.reshape(path.shape[0], -1, path.shape[-1])
