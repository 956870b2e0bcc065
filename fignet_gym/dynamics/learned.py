"""The learned dynamics: a FIGNet :class:`~fignet_gym.simulator.LearnedSimulator` behind the
:class:`~fignet_gym.dynamics.Dynamics` interface (``mj_step``-like ``step``, batched ``rollout``)."""

from __future__ import annotations

import math
import os
import warnings
import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
import torch
from torch import Tensor

from fignet_gym.dynamics import history
from fignet_gym.dynamics.base import (
    STATE_SPEC,
    DivergenceError,
    DynamicsBase,
    normalize_mocap_quat,
    set_mocap,
)
from fignet_gym.dynamics.learned_ops import (  # noqa: F401  (CHUNK_NODES: re-exported)
    CHUNK_NODES,
    batched_step,
    blend_targets,
    describe_divergence,
    integrate_back,
    kinematic_targets,
)
from fignet_gym.pretrained import load_pretrained
from fignet_gym.simulator.geometry import (
    ShapeMatchError,
    quat_conj,
    quat_mul,
    quat_normalize,
    quat_to_axis_angle,
)
from fignet_gym.simulator.model import LearnedSimulator
from fignet_gym.simulator.scene import ObjectKind, Scene


@dataclass(frozen=True)
class _SceneInfo:
    """A model's scene (on the simulator's device) with the index arrays the step needs."""

    scene: Scene
    dyn: np.ndarray  # int[D] dynamic object indices
    qadr: np.ndarray  # int[D] their qpos addresses
    dadr: np.ndarray  # int[D] their qvel addresses
    kin: np.ndarray  # int[K] kinematic object indices
    kin_mocap: np.ndarray  # int[K] their mocap ids
    kin_body: np.ndarray  # int[K] their body ids
    floor_z: float  # lowest static node (m), -inf without static objects
    dyn_track: np.ndarray  # int[D] their rows in the userdata history (history.py)
    kin_track: np.ndarray  # int[K]


#: Network precisions of :class:`FIGNetDynamics`.
PRECISIONS = {"float32": torch.float32, "bfloat16": torch.bfloat16}


class FIGNetDynamics(DynamicsBase):
    """A learned FIGNet simulator behind MuJoCo's step interface.

    A learned step of ``sim.config.dt`` needs the last ``H = history + 1`` poses. They are part of
    the state: ``data.userdata`` (:mod:`fignet_gym.dynamics.history`), written after each call and
    read on the next, so ``mj_getState``/``mj_setState`` and ``rollout`` carry them. A body whose
    stored history does not fit ``data`` (another ``time``: a reset; frames not ``dt`` apart; its
    pose edited since: a teleported or released object; fewer than ``H`` frames: a state fresh
    from a reset or from MuJoCo stepping in other intervals) is reseeded, assuming constant
    velocity (``qvel``: linear in the world frame, angular in the body frame) over the past
    ``H - 1`` steps, so initial velocities are honoured from the first step; mocap bodies are
    reseeded at rest at their current pose (``xpos``/``xquat`` as of the last ``mj_forward``).
    A model without room in ``userdata`` (``history.compile_with_history``) is reseeded at every
    call, with a warning. Quaternions are normalised as MuJoCo does (a zero one is the identity).

    After the step, ``qpos`` holds the predicted poses (unit quaternions), ``qvel`` the finite
    difference of the last two (linear world / ``dt``; angular in the body frame, the axis-angle of
    ``q_prev^-1 q_next`` / ``dt``), ``time`` advances by ``nstep * timestep``, then ``mj_forward``.
    When ``nstep`` spans several learned steps the mocap bodies move linearly from their current
    poses to their targets over them (quaternions: normalised linear blends), as
    :class:`~fignet_gym.dynamics.mujoco.MujocoDynamics` moves them over its timesteps.

    Divergence (:class:`DivergenceError`): non-finite poses, a dynamic object farther than
    ``max_distance`` from the world origin, lower than ``fall_depth`` below the lowest static node,
    or faster than ``max_speed``; a failed shape match counts as divergence of its batch.

    Args:
        checkpoint: a checkpoint path, a pretrained name (``"push"``) or a
            :class:`~fignet_gym.simulator.LearnedSimulator`.
        max_distance: m. fall_depth: m. max_speed: m/s.
        device: where to run (default: the simulator's device).
        precision: ``"float32"``, or ``"bfloat16"`` for the network in bfloat16 (opt-in:
            on CPUs with AVX-512 BF16 or AMX 1.3-1.7x more batched scene-steps per second,
            at about 0.1 mm median divergence over a 0.5 s push and the toss model's error
            unchanged within 2%; experiments/README.md, Speed). ``None``: the simulator's own
            ``inference_dtype`` (float32 unless set).
    """

    def __init__(
        self,
        checkpoint: str | os.PathLike | LearnedSimulator,
        *,
        max_distance: float = 100.0,
        fall_depth: float = 1.0,
        max_speed: float = 100.0,
        device: str | torch.device | None = None,
        precision: str | None = None,
    ) -> None:
        if precision is not None and precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {sorted(PRECISIONS)}, got {precision!r}")
        sim = load_pretrained(checkpoint, map_location=device)
        self.simulator = sim.eval()
        if precision is not None:
            self.simulator.inference_dtype = PRECISIONS[precision]
        self.max_distance = float(max_distance)
        self.fall_depth = float(fall_depth)
        self.max_speed = float(max_speed)
        self._scenes: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
        self._warned: weakref.WeakSet = weakref.WeakSet()  # models without history room

    # ----------------------------------------------------------------- configuration
    @property
    def dt(self) -> float:
        """Learned step length (s)."""
        return float(self.simulator.config.dt)

    def learned_steps(self, model: mujoco.MjModel, nstep: int) -> int:
        """Learned steps in ``nstep`` MuJoCo timesteps (``ValueError`` unless a whole number)."""
        ratio = nstep * float(model.opt.timestep) / self.dt
        k = round(ratio)
        # Relative: a dt stored to 9 digits is off by ~1e-8 per learned step.
        if k < 1 or abs(ratio - k) > 1e-6 * k:
            raise ValueError(
                f"FIGNetDynamics: {nstep} x timestep {model.opt.timestep:g} s = "
                f"{nstep * model.opt.timestep:g} s "
                f"is not a whole number of learned steps of {self.dt:g} s; use nstep = "
                f"{self.dt / model.opt.timestep:g} (one learned step) or a multiple"
            )
        return k

    def validate(self, model: mujoco.MjModel, nstep: int, scene_type: str = "") -> None:
        """Check the checkpoint's scene type, the step length and that the model can be meshed."""
        trained = self.simulator.config.scene_type
        if scene_type and trained and trained != scene_type:
            raise ValueError(
                f"the checkpoint was trained on '{trained}' scenes, not '{scene_type}': "
                f"pass a '{scene_type}' checkpoint"
            )
        self.learned_steps(model, nstep)
        self._scene_info(model)

    def _scene_info(self, model: mujoco.MjModel) -> _SceneInfo:
        info = self._scenes.get(model)
        if info is None:
            scene = Scene.from_mjmodel(model, self.simulator.config.mesh_options).to(
                self.simulator.device
            )
            kind = scene.object_kind.cpu().numpy()
            dyn = np.flatnonzero(kind == ObjectKind.DYNAMIC)
            kin = np.flatnonzero(kind == ObjectKind.KINEMATIC)
            static = scene.object_kind[scene.node_object] == ObjectKind.STATIC
            floor_z = -math.inf
            if bool(static.any()):
                nodes = scene.node_positions(scene.static_poses)
                floor_z = float(nodes[static, 2].min())
            qadr = scene.object_qpos_adr.cpu().numpy()[dyn]
            kin_mocap = scene.object_mocap.cpu().numpy()[kin]
            free = list(history.free_qpos_addresses(model))
            info = _SceneInfo(
                scene, dyn, qadr, scene.object_dof_adr.cpu().numpy()[dyn], kin, kin_mocap,
                scene.object_body.cpu().numpy()[kin], floor_z,
                np.array([free.index(a) for a in qadr], dtype=np.int64),
                len(free) + kin_mocap.astype(np.int64),
            )
            self._scenes[model] = info
        return info

    # ----------------------------------------------------------------- history
    def _current(self, info: _SceneInfo, datas: Sequence[mujoco.MjData]
                 ) -> tuple[Tensor, Tensor, Tensor, np.ndarray]:
        """Current poses ``float[B, O, 7]``, dynamic linear (world) and angular (body) velocities
        ``float[B, D, 3]`` of ``B`` datas, and the dynamic objects' ``qpos float64[B, D, 7]``."""
        qa = info.qadr[:, None] + np.arange(7)
        poses = np.repeat(info.scene.static_poses.double().cpu().numpy()[None], len(datas), 0)
        qpos = np.stack([d.qpos[qa] for d in datas])
        poses[:, info.dyn] = qpos
        if len(info.kin):
            quat = np.stack([d.xquat[info.kin_body] for d in datas])
            use_x = (np.linalg.norm(quat, axis=-1) > 0.5)[..., None]  # zero until mj_forward
            pos = np.stack([d.xpos[info.kin_body] for d in datas])
            poses[:, info.kin, :3] = np.where(
                use_x, pos, np.stack([d.mocap_pos[info.kin_mocap] for d in datas]))
            poses[:, info.kin, 3:] = np.where(
                use_x, quat, np.stack([d.mocap_quat[info.kin_mocap] for d in datas]))
        vel = np.stack([d.qvel[info.dadr[:, None] + np.arange(6)] for d in datas])
        f = lambda x: torch.as_tensor(x, dtype=torch.float32, device=self.simulator.device)  # noqa: E731
        p = f(poses)
        p[..., 3:] = quat_normalize(p[..., 3:])
        return p, f(vel[..., :3]), f(vel[..., 3:]), qpos

    def _history(self, model: mujoco.MjModel, info: _SceneInfo, datas: Sequence[mujoco.MjData],
                 warn: bool = True) -> Tensor:
        """History ``float[H, B*O, 7]`` of ``B`` datas: their ``userdata`` frames where they fit,
        a constant-velocity reseed (see the class doc) for every other object (``warn``: once per
        model without room for the history, which loses it between calls)."""
        H = self.simulator.config.history + 1
        for d in datas:
            mujoco.mj_normalizeQuat(model, d.qpos)  # as mj_step does: a zero quaternion -> identity
        cur, lin, ang, qpos = self._current(info, datas)
        B, n_obj = cur.shape[:2]
        hist = cur[None].repeat(H, 1, 1, 1)
        dyn_cur = cur[:, info.dyn].reshape(-1, 7)
        lin, ang = lin.reshape(-1, 3), ang.reshape(-1, 3)
        for k in range(H):
            hist[H - 1 - k, :, info.dyn] = integrate_back(dyn_cur, lin, ang, k, self.dt).view(
                B, len(info.dyn), 7)
        hist = hist.view(H, B * n_obj, 7)
        if not history.has_history(model):
            if warn and model not in self._warned:
                self._warned.add(model)
                warnings.warn("FIGNetDynamics: the model has no room for the pose history in "
                              "userdata, so every call restarts it from qpos/qvel; use model = "
                              "fignet_gym.dynamics.with_history(model) and MjData(model)",
                              stacklevel=4)
            return hist
        objects = np.concatenate((info.dyn, info.kin))
        track = np.concatenate((info.dyn_track, info.kin_track))
        now = np.zeros((B, history.num_tracked(model), 7))
        now[:, track] = cur[:, objects].double().cpu().numpy()
        now[:, info.dyn_track] = qpos
        userdata = np.stack([d.userdata for d in datas])
        counts = history.valid_counts(model, userdata, np.array([d.time for d in datas]), self.dt,
                                      now, np.stack([d.qvel for d in datas]))
        ok = counts[:, track] >= H  # [B, len(objects)]
        if H <= history.FRAMES and ok.any():
            frames = history.unpack(model, userdata)[4]  # [B, FRAMES, n, 7], newest first
            b, j = np.nonzero(ok)
            stored = frames[b, :H][:, ::-1][np.arange(len(b)), :, track[j]]  # [M, H, 7]
            rows = torch.as_tensor(b * n_obj + objects[j], device=hist.device)
            hist[:, rows] = torch.as_tensor(
                np.ascontiguousarray(stored.transpose(1, 0, 2)), dtype=hist.dtype, device=hist.device)
        return hist

    def _userdata(self, model: mujoco.MjModel, info: _SceneInfo, hist: Tensor, times: np.ndarray,
                  vel: np.ndarray) -> np.ndarray:
        """``userdata`` history entries ``float64[..., B, history_size]`` of histories ``hist
        float[..., H, B*O, 7]`` at ``times float[..., B]`` with dynamic objects' velocities ``vel
        float[..., B, D, 6]`` (what ``qvel`` gets)."""
        H = hist.shape[-3]
        B = times.shape[-1]
        n_obj = info.scene.num_objects
        lead = hist.shape[:-3]
        h = hist.reshape(*lead, H, B, n_obj, 7).double().cpu().numpy()
        objects = np.concatenate((info.dyn, info.kin))
        track = np.concatenate((info.dyn_track, info.kin_track))
        n, keep = history.num_tracked(model), min(H, history.FRAMES)
        frames = np.zeros((*lead, B, history.FRAMES, n, 7))
        newest_first = np.moveaxis(h[..., ::-1, :, :, :][..., :keep, :, :, :], -4, -3)
        frames[..., :keep, track, :] = newest_first[..., objects, :]
        counts = np.zeros(n, dtype=np.int64)
        counts[track] = keep
        free = np.zeros((*lead, B, n - model.nmocap, 6))
        free[..., info.dyn_track, :] = vel
        return history.pack(model, times, self.dt, counts, free, frames)

    def _targets(self, info: _SceneInfo, last: Tensor, pos: np.ndarray, quat: np.ndarray) -> Tensor:
        """Next poses ``float[B*O, 7]`` of ``B`` scenes: ``last`` with kinematic rows replaced by
        their mocap targets ``pos float[B, K, 3]``, ``quat float[B, K, 4]``."""
        nxt = last.clone()
        if len(info.kin):
            B, n_obj = pos.shape[0], info.scene.num_objects
            tgt = torch.as_tensor(
                np.concatenate((pos, quat), -1).reshape(-1, 7),
                dtype=torch.float32,
                device=nxt.device,
            )
            tgt[:, 3:] = quat_normalize(tgt[:, 3:])
            rows = (np.arange(B)[:, None] * n_obj + info.kin[None]).ravel()
            nxt[torch.as_tensor(rows, device=nxt.device)] = tgt
        return nxt

    # ----------------------------------------------------------------- stepping
    def _advance(
        self,
        info: _SceneInfo,
        hist: Tensor,
        target: Tensor,
        B: int,
        nlearn: int,
        t0: Sequence[float],
        dead: Sequence[int] = (),
    ) -> tuple[Tensor, dict[int, str]]:
        """``nlearn`` batched learned steps of ``B`` copies of ``info.scene``.

        ``hist float[H, B*O, 7]``, ``target float[B*O, 7]`` -> final history ``float[H, B*O, 7]``
        and the reasons of the scenes that diverged, which are frozen at their last good poses from
        on (so that nothing non-finite ever enters the graph). Scenes in ``dead`` stay frozen.
        """
        n_obj = info.scene.num_objects
        dyn = info.scene.dynamic_mask.repeat(B)
        static_poses = info.scene.static_poses.repeat(B, 1)
        bad: dict[int, str] = {}
        finite = (
            (torch.isfinite(hist).all(0).all(-1) & torch.isfinite(target).all(-1))
            .view(B, n_obj)
            .all(1)
        )
        # Index lists come to the host only when something is wrong: a healthy step syncs a few
        # scalars for control flow and moves no tensor (tests/test_batching.py).
        if not bool(finite.all()):
            for b in torch.nonzero(~finite).flatten().tolist():
                bad[b] = f"non-finite state (qpos, qvel or mocap) at t={t0[b]:.3f}s"
        frozen = torch.zeros(B, dtype=torch.bool, device=hist.device)
        if bad or dead:
            frozen[torch.as_tensor(list(bad) + list(dead), device=hist.device)] = True
        if bool(frozen.any()):  # stand-in poses for frozen scenes: their reference configuration
            per_obj = frozen.repeat_interleave(n_obj)
            hist = torch.where(
                per_obj[None, :, None] & ~torch.isfinite(hist), static_poses[None], hist
            )
            target = torch.where(
                per_obj[:, None] & ~torch.isfinite(target), static_poses, target
            )
        kin = (info.scene.object_kind == ObjectKind.KINEMATIC).repeat(B)
        start = hist[-1]
        for k in range(nlearn):
            step_target = target if k == nlearn - 1 else blend_targets(start, target, kin, (k + 1) / nlearn)
            try:
                nxt = batched_step(self.simulator, info.scene, B, hist, step_target)
            except (ShapeMatchError, torch.linalg.LinAlgError) as err:
                reason = f"learned step failed at t={t0[0] + (k + 1) * self.dt:.3f}s: {err}"
                return hist, {b: bad.get(b, reason) for b in range(B) if b not in dead}
            sick = self._sick(nxt, hist[-1], dyn, info.floor_z)
            if bool(sick.any()):
                for b in torch.nonzero(sick.view(B, n_obj).any(1)).flatten().tolist():
                    if b not in bad and not bool(frozen[b]):
                        bad[b] = describe_divergence(
                            nxt[b * n_obj : (b + 1) * n_obj], hist[-1][b * n_obj : (b + 1) * n_obj],
                            info.dyn, info.scene.object_names, info.floor_z,
                            t0[b] + (k + 1) * self.dt, self)
                        frozen[b] = True
            if bool(frozen.any()):
                nxt = torch.where(frozen.repeat_interleave(n_obj)[:, None], hist[-1], nxt)
            hist = torch.cat((hist[1:], nxt[None]), dim=0)
        return hist, bad

    def _sick(self, nxt: Tensor, cur: Tensor, dyn: Tensor, floor_z: float) -> Tensor:
        """``bool[B*O]``: dynamic objects whose next pose is non-finite or runaway."""
        p = nxt[:, :3]
        bad = ~torch.isfinite(nxt).all(-1)
        bad |= p.norm(dim=-1) > self.max_distance
        bad |= p[:, 2] < floor_z - self.fall_depth
        bad |= (p - cur[:, :3]).norm(dim=-1) > self.max_speed * self.dt
        return bad & dyn

    def _pose_velocity(
        self, info: _SceneInfo, hist: Tensor, B: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """Dynamic objects' last poses ``float64[B, D, 7]`` (unit quaternions) and finite-difference
        velocities ``float64[B, D, 6]`` (linear world, angular body: axis-angle of
        ``q_prev^-1 q_next``, both / ``dt``) from ``hist float[H, B*O, 7]``."""
        n_obj = info.scene.num_objects
        cur = hist[-1].view(B, n_obj, 7)[:, info.dyn]
        prev = hist[-2].view(B, n_obj, 7)[:, info.dyn]
        q = quat_normalize(cur[..., 3:])
        lin = (cur[..., :3] - prev[..., :3]) / self.dt
        ang = quat_to_axis_angle(quat_mul(quat_conj(quat_normalize(prev[..., 3:])), q)) / self.dt
        pose = torch.cat((cur[..., :3], q), -1).double().cpu().numpy()
        return pose, torch.cat((lin, ang), -1).double().cpu().numpy()

    def step(self, model: mujoco.MjModel, data: mujoco.MjData, nstep: int = 1) -> None:
        """Advance ``data`` by ``nstep`` timesteps (whole learned steps); see the class doc."""
        try:
            self.step_many(model, [data], nstep)
        except DivergenceError as err:
            raise DivergenceError(err.reasons[0]) from None

    def step_many(
        self, model: mujoco.MjModel, datas: Sequence[mujoco.MjData], nstep: int = 1
    ) -> None:
        """All ``datas`` in one batched graph per learned step; see :meth:`Dynamics.step_many`."""
        nlearn = self.learned_steps(model, nstep)
        info = self._scene_info(model)
        B = len(datas)
        if B == 0:
            return
        hist = self._history(model, info, datas)
        m = info.kin_mocap
        pos = np.stack([d.mocap_pos[m] for d in datas])
        quat = normalize_mocap_quat(np.stack([d.mocap_quat[m] for d in datas]))
        target = self._targets(info, hist[-1], pos, quat)
        hist, bad = self._advance(info, hist, target, B, nlearn, [d.time for d in datas])
        pose, vel = self._pose_velocity(info, hist, B)
        qa = info.qadr[:, None] + np.arange(7)
        da = info.dadr[:, None] + np.arange(6)
        times = np.array([d.time + nstep * float(model.opt.timestep) for d in datas])
        user = (self._userdata(model, info, hist, times, vel)
                if history.has_history(model) else None)
        for b, d in enumerate(datas):
            if b in bad:
                continue
            d.qpos[qa] = pose[b]
            d.qvel[da] = vel[b]
            d.time = times[b]
            if user is not None:
                d.userdata[: user.shape[-1]] = user[b]
            mujoco.mj_forward(model, d)
        if bad:
            order = sorted(bad)
            raise DivergenceError(
                "; ".join(f"[{b}] {bad[b]}" for b in order), order, [bad[b] for b in order]
            )

    def _rollout(
        self, model: mujoco.MjModel, state: np.ndarray, control: np.ndarray, nstep: int,
        frame_skip: int,
    ) -> np.ndarray:
        """All ``B`` rollouts in one batched graph per learned step.

        Shapes as :meth:`DynamicsBase._rollout`. Free-joint velocities seed the history
        (constant-velocity back-extrapolation), mocap bodies start at rest at the state's mocap
        poses (as :meth:`step` reseeds them); ``frame_skip * timestep`` must be a whole number of
        learned steps. A rollout that diverges is NaN from that step on.
        """
        nlearn = self.learned_steps(model, frame_skip)
        info = self._scene_info(model)
        B, nstate = state.shape
        if B == 0 or nstep == 0:
            return np.zeros((B, nstep, nstate))
        scratch = mujoco.MjData(model)
        # A planner's candidates share one start state: its history is built once.
        uniq, inverse = np.unique(state, axis=0, return_inverse=True)
        hists = []
        for row in uniq:
            mujoco.mj_setState(model, scratch, row, STATE_SPEC)
            scratch.xquat[:] = 0.0  # mocap bodies start at the state's mocap_pos / mocap_quat
            hists.append(self._history(model, info, [scratch], warn=False))
        hist = torch.cat([hists[i] for i in inverse.ravel()], dim=1)
        times = [float(t) for t in state[:, 0]]
        out = np.full((B, nstep, nstate), np.nan)
        dead: set[int] = set()
        qa = info.qadr[:, None] + np.arange(7)
        da = info.dadr[:, None] + np.arange(6)
        nm = model.nmocap
        mocap_pos = control[..., : 3 * nm].reshape(B, nstep, nm, 3)[:, :, info.kin_mocap]
        mocap_quat = normalize_mocap_quat(
            control[..., 3 * nm :].reshape(B, nstep, nm, 4)[:, :, info.kin_mocap])
        # The loop stays on the simulator's device: mocap targets go there once, poses come back
        # once after the last step (no numpy round trip per step; see tests/test_batching.py).
        targets = kinematic_targets(mocap_pos, mocap_quat, hist.device)  # [T, B*K, 7]
        kin_rows = torch.as_tensor(
            (np.arange(B)[:, None] * info.scene.num_objects + info.kin[None]).ravel(),
            device=hist.device)
        dead_from: dict[int, int] = {}
        last, before, every = [], [], []
        for t in range(nstep):
            target = hist[-1].clone()
            if len(info.kin):
                target[kin_rows] = targets[t]
            times_t = [x + t * nlearn * self.dt for x in times]
            hist, bad = self._advance(info, hist, target, B, nlearn, times_t, sorted(dead))
            for b in bad:
                dead_from.setdefault(b, t)
            dead |= set(bad)
            last.append(hist[-1])
            before.append(hist[-2])
            every.append(hist)
        pose, vel = self._pose_velocity(
            info, torch.stack((torch.cat(before), torch.cat(last))), nstep * B)
        pose, vel = pose.reshape(nstep, B, -1, 7), vel.reshape(nstep, B, -1, 6)
        step_time = frame_skip * float(model.opt.timestep)
        times_out = state[None, :, 0] + np.arange(1, nstep + 1)[:, None] * step_time  # [T, B]
        user = (self._userdata(model, info, torch.stack(every), times_out, vel)
                if history.has_history(model) else None)
        for b in range(B):
            mujoco.mj_setState(model, scratch, state[b], STATE_SPEC)
            for t in range(dead_from.get(b, nstep)):
                scratch.qpos[qa] = pose[t, b]
                scratch.qvel[da] = vel[t, b]
                scratch.time = times_out[t, b]
                if user is not None:
                    scratch.userdata[: user.shape[-1]] = user[t, b]
                set_mocap(model, scratch, control[b, t])
                mujoco.mj_getState(model, scratch, out[b, t], STATE_SPEC)
        return out

    def forget(self, data: mujoco.MjData) -> None:
        """Drop the pose history of ``data`` (its ``userdata`` frames): the next step reseeds it
        from ``qpos``/``qvel``. ``mj_resetData`` does the same."""
        if history.has_history(data.model):
            data.userdata[: history.history_size(data.model)] = 0.0
