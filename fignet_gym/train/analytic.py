"""Analytic baselines on any trajectory file: MuJoCo (or any :class:`Dynamics`) replaying the data.

A trajectory with an MJCF is re-simulated from its recorded start: dynamic objects start at a
recorded pose with velocities from finite differences of the first poses (the same poses a learned
rollout is given), kinematic objects (the MIT pusher) follow their recorded poses, static ones
stay. :class:`~fignet_gym.dynamics.contact_params.ContactParams` overrides MuJoCo's contact
parameters (the family system identification searches), so nominal and fitted MuJoCo are the
same code.

Velocities from ``n`` given poses (``history + 1``; frame indices from 0): with ``n >= 3`` the
simulation starts at frame ``n - 2`` with central differences over frames ``n - 3`` and ``n - 1``
(exact for free flight: uniform acceleration and constant spin); with ``n = 2`` at frame 1 with
the backward difference. Frames up to the start are the recorded ones.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence

import mujoco
import numpy as np

from fignet_gym.data.format import Trajectory
from fignet_gym.dynamics.base import STATE_SPEC, Dynamics
from fignet_gym.dynamics.contact_params import ContactParams
from fignet_gym.dynamics.mujoco import MujocoDynamics
from fignet_gym.simulator.scene import ObjectKind, Scene

#: Poses a replay is given by default (a learned model's ``history + 1``).
GIVEN_POSES = 3
#: Below this norm of a quaternion's vector part the rotation is the small-angle limit.
SMALL_ANGLE = 1e-12


def _axis_angle(q: np.ndarray) -> np.ndarray:
    """Rotation vector ``float[3]`` of a unit quaternion ``float[4]`` (w x y z), angle in [0, pi]."""
    q = q if q[0] >= 0 else -q
    s = np.linalg.norm(q[1:])
    if s < SMALL_ANGLE:
        return 2.0 * q[1:]
    return 2.0 * np.arctan2(s, q[0]) * q[1:] / s


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.empty(4)
    mujoco.mju_mulQuat(out, a, b)
    return out


def _conj(q: np.ndarray) -> np.ndarray:
    return np.array([q[0], -q[1], -q[2], -q[3]])


def finite_difference_state(poses: np.ndarray, dt: float) -> tuple[int, np.ndarray]:
    """Start frame and free-joint velocities from the given poses (see the module docstring).

    ``poses float[n, O, 7]`` (``n >= 2``) -> ``(k, qvel float[O, 6])``: linear velocity (world)
    and angular velocity (body frame, as MuJoCo's free-joint ``qvel``) of every object at frame
    ``k``.
    """
    n = poses.shape[0]
    if n < 2:
        raise ValueError(f"finite differences need at least 2 poses, got {n}")
    k, a, b = (n - 2, n - 3, n - 1) if n >= 3 else (1, 0, 1)
    span = (b - a) * dt
    qvel = np.zeros((poses.shape[1], 6))
    for o in range(poses.shape[1]):
        qvel[o, :3] = (poses[b, o, :3] - poses[a, o, :3]) / span
        w_world = _axis_angle(_quat_mul(poses[b, o, 3:], _conj(poses[a, o, 3:]))) / span
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, poses[k, o, 3:])
        qvel[o, 3:] = rot.reshape(3, 3).T @ w_world
    return k, qvel


class Replay:
    """One trajectory's MJCF, compiled once, with :class:`ContactParams` applied on demand.

    Args:
        traj: a trajectory with an MJCF (imported real data or generated).
    """

    def __init__(self, traj: Trajectory) -> None:
        if traj.mjcf is None:
            raise ValueError(f"trajectory {traj.name!r} has no MJCF (mesh-only records, such as "
                             "imported MOVi scenes, cannot be re-simulated in MuJoCo)")
        self.traj = traj
        self.base = mujoco.MjModel.from_xml_string(traj.mjcf)
        self.scene = Scene.from_mjmodel(self.base)
        if self.scene.object_names != tuple(traj.names):
            raise ValueError(f"trajectory {traj.name!r}: its MJCF's objects "
                             f"{self.scene.object_names} are not its stored {tuple(traj.names)}")
        self._model: mujoco.MjModel | None = None
        self._data: mujoco.MjData | None = None
        self._params: ContactParams | None = None
        self.substeps = 1

    def model(self, params: ContactParams) -> mujoco.MjModel:
        """The MJCF's model with ``params`` applied: one copy per replay, reset to the MJCF's
        values and updated in place (a new model per candidate would cost memory and time)."""
        if self._model is None:
            self._model = _copy_model(self.base)
            self._data = mujoco.MjData(self._model)
        if params != self._params:
            m, b = self._model, self.base
            m.geom_friction[:] = b.geom_friction
            m.geom_solref[:] = b.geom_solref
            m.opt.gravity[:] = b.opt.gravity
            for key in ("cone", "impratio", "noslip_iterations", "integrator", "timestep"):
                setattr(m.opt, key, getattr(b.opt, key))
            self.substeps = params.substeps_for(b, self.traj.dt)
            params.apply(m, self.traj.dt)
            self._params = params
        return self._model

    def rollout(self, params: ContactParams, dynamics: Dynamics, given: int = GIVEN_POSES,
                steps: int | None = None) -> np.ndarray:
        """Poses ``float[T', O, 7]`` (``T' = min(T, steps)``): recorded up to the start frame,
        simulated after it by ``dynamics.rollout`` (one state per data step of ``substeps``
        timesteps; the recorded kinematic poses as mocap targets).

        A simulation that diverges holds its last finite poses (scored as it is, not dropped).
        """
        traj, scene = self.traj, self.scene
        model = self.model(params)
        data = self._data
        T = traj.num_steps if steps is None else min(steps, traj.num_steps)
        poses = np.asarray(traj.poses, np.float64)
        given = max(2, min(given, T))
        k, qvel = finite_difference_state(poses[:given], traj.dt)
        out = poses[:T].copy()
        if k + 1 >= T:
            return out
        mujoco.mj_resetData(model, data)
        kinds = scene.object_kind.tolist()
        qadr, dadr, mocap = (x.tolist() for x in (scene.object_qpos_adr, scene.object_dof_adr,
                                                   scene.object_mocap))
        dyn = [o for o, kind in enumerate(kinds) if kind == ObjectKind.DYNAMIC]
        kin = [o for o, kind in enumerate(kinds) if kind == ObjectKind.KINEMATIC]
        for o in dyn:
            data.qpos[qadr[o]:qadr[o] + 7] = poses[k, o]
            data.qvel[dadr[o]:dadr[o] + 6] = qvel[o]
        for o in kin:
            data.mocap_pos[mocap[o]] = poses[k, o, :3]
            data.mocap_quat[mocap[o]] = poses[k, o, 3:]
        state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
        mujoco.mj_getState(model, data, state, STATE_SPEC)
        nm = model.nmocap
        control = np.zeros((T - 1 - k, 7 * nm))
        control[:, 3 * nm:] = np.tile([1.0, 0, 0, 0], nm)
        for o in kin:  # each row is reached at the end of its step (linearly over the substeps)
            m = mocap[o]
            control[:, 3 * m:3 * m + 3] = poses[k + 1:T, o, :3]
            control[:, 3 * nm + 4 * m:3 * nm + 4 * m + 4] = poses[k + 1:T, o, 3:]
        states = dynamics.rollout(model, state[None], control[None],  # float[1, T, 0] without mocap
                                  (T - 1 - k) * self.substeps, frame_skip=self.substeps)[0]
        for o in dyn:
            out[k + 1:, o] = states[:, 1 + qadr[o]:1 + qadr[o] + 7]
        for o in kin:
            out[k + 1:, o] = poses[k + 1:T, o]
        bad = ~np.isfinite(out).all(axis=(1, 2))
        if bad.any():  # diverged: hold the last finite poses
            first = int(np.argmax(bad))
            out[first:] = out[first - 1]
        return out


def _copy_model(model: mujoco.MjModel) -> mujoco.MjModel:
    return copy.copy(model)


def replay_all(trajs: Sequence[Trajectory], params: ContactParams, dynamics: Dynamics | None = None,
               given: int = GIVEN_POSES, steps: int | None = None,
               replays: Sequence[Replay] | None = None) -> list[np.ndarray]:
    """:meth:`Replay.rollout` of every trajectory (``MujocoDynamics`` by default)."""
    dynamics = dynamics or MujocoDynamics(nthread=1)
    replays = replays or [Replay(t) for t in trajs]
    return [r.rollout(params, dynamics, given, steps) for r in replays]
