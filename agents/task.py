"""Push-v0 as a planning problem: the env's own action semantics and reward on predicted states.

A planner proposes ``B`` tip-velocity sequences ``float[B, T, 2]``, a :class:`Dynamics` predicts the
states they lead to, and the planner ranks them by the environment's reward. :class:`PushTask`
connects the three without re-implementing the environment:

* actions become mocap controls through ``PushEnv._pre_step`` (the env's clipping, speed and tip
  bounds), applied step by step on a scratch copy of the environment;
* predicted states are scored through ``PushEnv._evaluate`` (the reward terms whose sum
  ``env.step`` returns), again on the scratch copy.

The environment has no public, vectorised function ``(state, action) -> reward terms``: its reward
reads ``self.data``. This adapter is the minimal bridge: it writes each predicted state into the
scratch environment's ``MjData`` and calls the environment's code, one state at a time (a Python
loop over ``B * T`` states, some 30 us each: as long as MuJoCo's own rollout of them).
"""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np

from fignet_gym.dynamics import STATE_SPEC
from fignet_gym.envs.base import yaw_of
from fignet_gym.envs.push import PushEnv
from fignet_gym.mjcf import push_object

#: State layout accepted by planners in place of an environment: everything ``mj_step`` needs plus
#: the mocap poses (where the tip is), ``mujoco.mj_getState(model, data, s, PLAN_STATE_SPEC)``.
PLAN_STATE_SPEC = int(mujoco.mjtState.mjSTATE_INTEGRATION)


def push_env_of(env: gym.Env) -> PushEnv:
    """The :class:`PushEnv` under Gymnasium wrappers (``TypeError`` for another environment)."""
    inner = getattr(env, "unwrapped", env)
    if not isinstance(inner, PushEnv):
        raise TypeError(f"planners need a fignet_gym/Push-v0 environment, got {type(inner).__name__}")
    return inner


def plan_state(env: gym.Env) -> np.ndarray:
    """``float64[nstate]`` :data:`PLAN_STATE_SPEC` state of ``env`` (physics and mocap poses)."""
    push = push_env_of(env)
    out = np.zeros(mujoco.mj_stateSize(push.model, PLAN_STATE_SPEC))
    mujoco.mj_getState(push.model, push.data, out, PLAN_STATE_SPEC)
    return out


class PushTask:
    """Push-v0's action semantics and reward evaluated on states predicted by any dynamics.

    Args:
        env: the environment being controlled. Its goal (and workspace origin) is read at every
            call, so one task follows the environment across resets.

    Attributes:
        env: the controlled :class:`PushEnv`.
        model: its ``MjModel`` (shared with the planning dynamics).
        nstep: MuJoCo timesteps per environment step (the rollouts' ``frame_skip``).
    """

    def __init__(self, env: gym.Env) -> None:
        self.env = push_env_of(env)
        self.model = self.env.model
        self.nstep = self.env.nstep
        # Same model and configuration, its own MjData: evaluating never touches the live env.
        self._scratch = self.env._spawn()
        self._tip = self.env._tip_mocap
        self._qadr = self.env._qadr
        self._nq = self.model.nq
        self._nv = self.model.nv
        self._nm = self.model.nmocap
        self._outline = push_object(self.env.shape).outline  # float[K, 2], object frame
        tip_geom = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, "tip")
        self._tip_radius = float(self.model.geom_size[tip_geom, 0])

    def _sync(self) -> None:
        """Copy the task (goal, workspace origin) of the live environment into the scratch copy."""
        self._scratch.goal = self.env.goal.copy()
        self._scratch._start_xy = self.env._start_xy.copy()

    def load(self, state: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Initial rollout state and current mocap poses.

        Args:
            state: ``float64[nstate]`` :data:`PLAN_STATE_SPEC` state, or ``None`` for the live
                environment's current state.

        Returns:
            ``float64[nphys]`` ``mjSTATE_FULLPHYSICS`` state (``Dynamics.rollout``'s layout) and
            ``float64[nmocap * 7]`` mocap positions then quaternions (controls' layout).
        """
        data = self._scratch.data
        source = self.env.data if state is None else data
        if state is not None:
            expected = mujoco.mj_stateSize(self.model, PLAN_STATE_SPEC)
            state = np.asarray(state, dtype=np.float64)
            if state.shape != (expected,):
                raise ValueError(
                    f"state must be float64[{expected}] (mjSTATE_INTEGRATION, see plan_state), "
                    f"got shape {state.shape}"
                )
            mujoco.mj_setState(self.model, data, state, PLAN_STATE_SPEC)
        phys = np.zeros(mujoco.mj_stateSize(self.model, STATE_SPEC))
        mujoco.mj_getState(self.model, source, phys, STATE_SPEC)
        mocap = np.concatenate([source.mocap_pos.ravel(), source.mocap_quat.ravel()])
        return phys, mocap

    def controls(self, mocap: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mocap controls of action sequences, through the environment's own ``_pre_step``.

        Args:
            mocap: ``float64[nmocap * 7]`` current mocap poses (from :meth:`load`).
            actions: ``float[B, T, 2]`` tip velocities in action units.

        Returns:
            ``float64[B, T, nmocap * 7]`` controls (mocap targets after each step, the layout of
            ``Dynamics.rollout``) and ``float64[B, T, 2]`` the actions as the env applies them
            (clipped).
        """
        B, T, _ = actions.shape
        nm = self._nm
        data = self._scratch.data
        control = np.empty((B, T, nm * 7))
        applied = np.empty((B, T, actions.shape[2]))
        start_pos, start_quat = mocap[: 3 * nm].reshape(nm, 3), mocap[3 * nm :].reshape(nm, 4)
        for b in range(B):
            data.mocap_pos[:] = start_pos
            data.mocap_quat[:] = start_quat
            for t in range(T):
                applied[b, t] = self._scratch._pre_step(actions[b, t])
                control[b, t, : 3 * nm] = data.mocap_pos.ravel()
                control[b, t, 3 * nm :] = data.mocap_quat.ravel()
        return control, applied

    def rewards(self, states: np.ndarray, control: np.ndarray, applied: np.ndarray) -> np.ndarray:
        """The environment's reward for each predicted step.

        Args:
            states: ``float64[B, T, nphys]`` predicted ``mjSTATE_FULLPHYSICS`` states.
            control: ``float64[B, T, nmocap * 7]`` the controls that produced them.
            applied: ``float64[B, T, 2]`` the (clipped) actions of each step.

        Returns:
            ``float64[B, T]`` rewards exactly as ``env.step`` would return them; NaN where the
            predicted state is not finite (a diverged rollout).
        """
        self._sync()
        B, T, _ = states.shape
        nm, nq, nv = self._nm, self._nq, self._nv
        out = np.full((B, T), np.nan)
        finite = np.isfinite(states).all(-1)
        data = self._scratch.data
        for b, t in zip(*np.nonzero(finite), strict=True):
            data.qpos[:] = states[b, t, 1 : 1 + nq]
            data.qvel[:] = states[b, t, 1 + nq : 1 + nq + nv]
            data.mocap_pos[:] = control[b, t, : 3 * nm].reshape(nm, 3)
            data.mocap_quat[:] = control[b, t, 3 * nm :].reshape(nm, 4)
            # The env's reward is the sum of its reward terms (``MjDynamicsEnv._post_step``);
            # calling ``_evaluate`` skips building the observation, half of the cost.
            terms = self._scratch._evaluate(applied[b, t])[0]
            out[b, t] = sum(terms.values())
        return out

    def approach_distance(self, states: np.ndarray, control: np.ndarray) -> np.ndarray:
        """Distance (m) of the final tip from the pushing point behind the object.

        A planner-side shaping term, *not* part of the environment's reward: with a short horizon
        most candidate plans never touch the object and the reward alone cannot rank them. The
        pushing point is where the tip touches the object's outline when it comes from the side
        opposite the goal, on the line through the object's origin (for the final predicted pose).

        Args:
            states: ``float64[B, T, nphys]``; control: ``float64[B, T, nmocap * 7]``.

        Returns:
            ``float64[B]`` (NaN for diverged rollouts).
        """
        final = states[:, -1, 1 + self._qadr : 1 + self._qadr + 7]
        obj, yaw = final[:, :2], yaw_of(final[:, 3:])
        to_goal = self.env.goal[:2] - obj
        unit = to_goal / np.maximum(np.linalg.norm(to_goal, axis=-1, keepdims=True), 1e-9)
        # Support of the outline in direction -unit, taken in the object frame.
        c, s = np.cos(yaw), np.sin(yaw)
        back = np.stack([-(c * unit[:, 0] + s * unit[:, 1]), s * unit[:, 0] - c * unit[:, 1]], -1)
        reach = (back @ self._outline.T).max(-1) + self._tip_radius
        behind = obj - reach[:, None] * unit
        tip = control[:, -1, 3 * self._tip : 3 * self._tip + 2]
        return np.linalg.norm(tip - behind, axis=-1)
