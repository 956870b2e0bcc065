"""What a PPO policy sees and is rewarded by on the push task, on top of ``Push-v1``'s own.

The env stays the benchmark the planners are measured on; these are the policy's side of it:

* :func:`push_features`: the quantities a pusher steers by, in the frame the action acts in
  (world) and in the object's frame: the pushing point behind the object relative to the tip,
  the goal relative to the object and to the tip, the heading error. They are functions of the
  observation (and of the object's outline), so the transform is part of the policy
  (:class:`ObservationTransform`): a saved policy acts on the env's raw observations.
* :class:`ProgressShaping`: potential-based shaping ``gamma * phi(s') - phi(s)`` with ``phi`` minus
  the env's own position and heading cost, a training-time reward for progress towards the goal
  that keeps the optimal policy (Ng, Harada and Russell, 1999). Episode returns are still logged
  in the env's reward (``VecMonitor`` sits below it).
* :class:`SuccessBonus`: extra reward on the step that succeeds, during training only. The
  env's dense cost ranks "close" above "far" but barely "inside the tolerance" above "close",
  which is what success is measured by.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn

from fignet_gym.agents.ppo.config import OBSERVATIONS
from fignet_gym.envs.tasks import wrap_angle

#: Observation names this module reads (``PushEnv.observation_layout``): slices of the 19 values.
OBJECT_XY, OBJECT_YAW, TIP_XY = slice(0, 2), slice(2, 4), slice(4, 6)
GOAL_XY, GOAL_YAW = slice(6, 8), slice(8, 10)
#: Values :func:`push_features` appends to the observation.
N_FEATURES = 11


def _heading(cos_sin: np.ndarray) -> np.ndarray:
    return np.arctan2(cos_sin[..., 1], cos_sin[..., 0])


def _to_object(vec: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """World vectors ``float[N, 2]`` in the object frame of headings ``(c, s)`` ``float[N]``."""
    return np.stack([c * vec[:, 0] + s * vec[:, 1], -s * vec[:, 0] + c * vec[:, 1]], -1)


def pushing_point(obs: np.ndarray, outline: np.ndarray, tip_radius: float) -> np.ndarray:
    """Where the tip meets the outline coming from the side opposite the goal (world, m).

    ``float[N, 19]`` Push observations, ``outline float[K, 2]`` (object frame) -> ``float[N, 2]``;
    the same point as ``PushTask.pushing_point`` on the state.
    """
    obs = np.asarray(obs, dtype=np.float64)
    obj, goal = obs[:, OBJECT_XY], obs[:, GOAL_XY]
    yaw = _heading(obs[:, OBJECT_YAW])
    to_goal = goal - obj
    unit = to_goal / np.maximum(np.linalg.norm(to_goal, axis=-1, keepdims=True), 1e-9)
    back = _to_object(-unit, np.cos(yaw), np.sin(yaw))
    reach = (back @ np.asarray(outline, dtype=np.float64).T).max(-1) + tip_radius
    return obj - reach[:, None] * unit


def push_features(obs: np.ndarray, outline: np.ndarray, tip_radius: float) -> np.ndarray:
    """``float[N, 19]`` Push observations -> ``float32[N, 19 + 11]``: the observation, then

    | index | meaning |
    |---|---|
    | 19:21 | goal minus object (world) |
    | 21:23 | pushing point minus tip (world) |
    | 23:25 | pushing point minus tip (object frame) |
    | 25:27 | goal minus tip (world) |
    | 27:29 | goal minus tip (object frame) |
    | 29 | heading error ``wrap(goal_yaw - object_yaw)`` (rad) |
    """
    obs = np.asarray(obs, dtype=np.float64)
    obj, tip, goal = obs[:, OBJECT_XY], obs[:, TIP_XY], obs[:, GOAL_XY]
    yaw = _heading(obs[:, OBJECT_YAW])
    c, s = np.cos(yaw), np.sin(yaw)
    pp = pushing_point(obs, outline, tip_radius)
    extra = np.concatenate([
        goal - obj,
        pp - tip,
        _to_object(pp - tip, c, s),
        goal - tip,
        _to_object(goal - tip, c, s),
        wrap_angle(_heading(obs[:, GOAL_YAW]) - yaw)[:, None],
    ], axis=-1)
    return np.concatenate([obs, extra], axis=-1).astype(np.float32)


@dataclass(frozen=True)
class ObservationTransform:
    """The observation a policy acts on, from the env's: ``"env"`` (as it is) or
    ``"push-features"`` (:func:`push_features` with this object's ``outline float[K, 2]`` and
    the tip's radius)."""

    kind: str = "env"
    outline: tuple[tuple[float, float], ...] = ()
    tip_radius: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in OBSERVATIONS:
            raise ValueError(f"observation must be one of {OBSERVATIONS}, got {self.kind!r}")

    @classmethod
    def of_env(cls, kind: str, env: Any) -> ObservationTransform:
        """The transform ``kind`` for an env (single or sub-environment) with a ``PushTask``."""
        if kind == "env":
            return cls()
        task = getattr(env, "task", None)
        if task is None or not hasattr(task, "outline"):
            raise ValueError(f"observation {kind!r} needs a push env, got {type(env).__name__}")
        return cls(kind, tuple(map(tuple, np.asarray(task.outline).tolist())), float(task.tip_radius))

    def size(self, base: int) -> int:
        """Observation length the policy sees for an env observation of ``base`` values."""
        return base + (N_FEATURES if self.kind == "push-features" else 0)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """``float[N, D] -> float32[N, size(D)]``."""
        if self.kind == "env":
            return obs
        return push_features(obs, np.asarray(self.outline), self.tip_radius)


class TransformedObservations(VecEnvWrapper):
    """SB3 ``VecEnv`` whose observations (and terminal observations) pass through ``transform``."""

    def __init__(self, venv: VecEnv, transform: ObservationTransform) -> None:
        n = transform.size(venv.observation_space.shape[0])
        super().__init__(venv, observation_space=spaces.Box(-np.inf, np.inf, (n,), np.float32))
        self.transform = transform

    def reset(self) -> np.ndarray:
        """Reset every sub-environment; transformed first observations."""
        return self.transform(self.venv.reset())

    def step_wait(self) -> VecEnvStepReturn:
        """Step; transformed observations and ``info["terminal_observation"]``."""
        obs, rewards, dones, infos = self.venv.step_wait()
        for info in infos:
            if "terminal_observation" in info:
                info["terminal_observation"] = self.transform(info["terminal_observation"][None])[0]
        return self.transform(obs), rewards, dones, infos


def progress_potential(obs: np.ndarray, position_weight: float, orientation_weight: float) -> np.ndarray:
    """``phi = -(position_weight * |goal - object| + orientation_weight * |heading error|)``:
    ``float[N, 19] -> float[N]``, minus the env's own position and heading cost."""
    obs = np.asarray(obs, dtype=np.float64)
    pos = np.linalg.norm(obs[:, GOAL_XY] - obs[:, OBJECT_XY], axis=-1)
    yaw = np.abs(wrap_angle(_heading(obs[:, GOAL_YAW]) - _heading(obs[:, OBJECT_YAW])))
    return -(position_weight * pos + orientation_weight * yaw)


class ProgressShaping(VecEnvWrapper):
    """Adds ``weight * (gamma * phi(s') - phi(s))`` to the reward (:func:`progress_potential`).

    ``phi`` is 0 after a termination (success), as potential-based shaping needs for episodic
    tasks to keep the optimal policy; after a truncation it is the last observation's.

    Args:
        venv: the env's SB3 view, below any observation transform (it reads raw observations).
        gamma: PPO's discount. weight: scale of the shaping term.
        position_weight, orientation_weight: the env's reward weights (1/m, 1/rad).
    """

    def __init__(self, venv: VecEnv, gamma: float, weight: float, position_weight: float,
                 orientation_weight: float) -> None:
        super().__init__(venv)
        self.gamma, self.weight = float(gamma), float(weight)
        self.weights = (float(position_weight), float(orientation_weight))
        self.phi = np.zeros(venv.num_envs)

    def reset(self) -> np.ndarray:
        """Reset every sub-environment and their potentials."""
        obs = self.venv.reset()
        self.phi = progress_potential(obs, *self.weights)
        return obs

    def step_wait(self) -> VecEnvStepReturn:
        """Step; shaped rewards ``float32[N]``."""
        obs, rewards, dones, infos = self.venv.step_wait()
        after = progress_potential(obs, *self.weights)
        nxt = after.copy()
        for i in np.flatnonzero(dones):
            terminated = not infos[i].get("TimeLimit.truncated", False)
            nxt[i] = 0.0 if terminated else progress_potential(
                infos[i]["terminal_observation"][None], *self.weights)[0]
        shaped = rewards + self.weight * (self.gamma * nxt - self.phi)
        self.phi = after  # finished sub-environments were reset: their new episode's potential
        return obs, shaped.astype(np.float32), dones, infos


class SuccessBonus(VecEnvWrapper):
    """Adds ``bonus`` to the reward of every step whose ``info["is_success"]`` is true.

    Args:
        venv: the env's SB3 view (its infos carry ``is_success``). bonus: the extra reward.
    """

    def __init__(self, venv: VecEnv, bonus: float) -> None:
        super().__init__(venv)
        self.bonus = float(bonus)

    def reset(self) -> np.ndarray:
        """Reset every sub-environment."""
        return self.venv.reset()

    def step_wait(self) -> VecEnvStepReturn:
        """Step; rewards ``float32[N]`` with the bonus on successful steps."""
        obs, rewards, dones, infos = self.venv.step_wait()
        success = np.array([bool(i.get("is_success", False)) for i in infos])
        return obs, (rewards + self.bonus * success).astype(np.float32), dones, infos
