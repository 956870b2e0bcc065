"""A goal-conditioned view of the push envs, for off-policy learning with hindsight relabelling.

Hindsight Experience Replay (Andrychowicz et al., 2017; SB3's ``HerReplayBuffer``) replays each
transition with goals the episode reached later, so it needs the observation split into what the
agent sees of the world, the goal it reached and the goal it was given, and a reward that is a
function of the two goals alone. :class:`PushGoalVecEnv` gives the push envs (``Push-v0``,
``Push-v1``) that view without changing them: a dictionary observation

| key | values | from the env's observation |
|---|---|---|
| ``observation`` | 11 | :data:`OBSERVATION_PARTS` (object pose, tip, tip in the object frame, velocities) |
| ``achieved_goal`` | 4 | ``object_xy``, ``object_yaw`` (x, y, cos, sin) |
| ``desired_goal`` | 4 | ``goal_xy``, ``goal_yaw`` (x, y, cos, sin) |

(``observation`` holds nothing that names the goal: HER swaps ``desired_goal`` alone)
and the reward :class:`GoalReward` computes from those goals: ``"sparse"`` (0 on a success, -1
otherwise, as in the Fetch tasks) or ``"dense"`` (the env's own reward without its action term).
Success is the env's own rule (position and heading errors below the task's tolerances).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from fignet_gym.envs.push import PushEnv

#: The goal rewards :class:`GoalReward` computes.
GOAL_REWARDS = ("sparse", "dense")
_LAYOUT = PushEnv.observation_layout
#: Slices of the env's observation that make each key of the goal view (in this order).
OBSERVATION_PARTS = ("object_xy", "object_yaw", "tip_xy", "tip_rel_xy", "object_velocity_xy",
                     "object_yaw_rate")
ACHIEVED_PARTS = ("object_xy", "object_yaw")
DESIRED_PARTS = ("goal_xy", "goal_yaw")
#: A goal: x, y (m), cos and sin of the heading.
GOAL_SIZE = 4


def _take(obs: np.ndarray, parts: tuple[str, ...]) -> np.ndarray:
    """``float[..., 19] -> float32[..., n]``: the named slices of push observations, concatenated."""
    return np.concatenate([obs[..., _LAYOUT[p]] for p in parts], axis=-1).astype(np.float32)


def goal_observation(obs: np.ndarray) -> dict[str, np.ndarray]:
    """The goal view of push observations ``float[..., 19]``: ``{"observation": float32[..., 11],
    "achieved_goal": float32[..., 4], "desired_goal": float32[..., 4]}``."""
    obs = np.asarray(obs)
    return {"observation": _take(obs, OBSERVATION_PARTS),
            "achieved_goal": _take(obs, ACHIEVED_PARTS),
            "desired_goal": _take(obs, DESIRED_PARTS)}


def goal_errors(achieved: np.ndarray, desired: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (m) and absolute heading (rad, in [0, pi]) errors between goals ``float[..., 4]``
    (x, y, cos, sin): two ``float[...]``."""
    a = np.asarray(achieved, dtype=np.float64)
    d = np.asarray(desired, dtype=np.float64)
    pos = np.linalg.norm(d[..., :2] - a[..., :2], axis=-1)
    # The heading difference from the two unit vectors: atan2 of their cross and dot products.
    cross = a[..., 2] * d[..., 3] - a[..., 3] * d[..., 2]
    dot = a[..., 2] * d[..., 2] + a[..., 3] * d[..., 3]
    return pos, np.abs(np.arctan2(cross, dot))


@dataclass(frozen=True)
class GoalReward:
    """The reward of the goal view, a function of the reached and given goals only.

    Args:
        kind: ``"sparse"`` (0 on a success, -1 otherwise) or ``"dense"`` (``-position_weight *
            position error - orientation_weight * heading error + success_weight * success``: the
            env's reward without its action term, which no goal determines).
        success_position: position tolerance (m). success_yaw: heading tolerance (rad).
        position_weight, orientation_weight, success_weight: the env's reward weights (dense).
    """

    kind: str
    success_position: float
    success_yaw: float
    position_weight: float = 0.0
    orientation_weight: float = 0.0
    success_weight: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in GOAL_REWARDS:
            raise ValueError(f"goal reward must be one of {GOAL_REWARDS}, got {self.kind!r}")

    @classmethod
    def of_task(cls, kind: str, task: Any) -> GoalReward:
        """The goal reward ``kind`` with the tolerances and weights of a ``PushTask``."""
        return cls(kind, task.success_position, task.success_yaw, task.position_weight,
                   task.orientation_weight, task.success_weight)

    def is_success(self, achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
        """``bool[...]`` for goals ``float[..., 4]``: the env's success rule (both errors strictly
        below the tolerances)."""
        pos, yaw = goal_errors(achieved, desired)
        return (pos < self.success_position) & (yaw < self.success_yaw)

    def __call__(self, achieved: np.ndarray, desired: np.ndarray, info: Any = None) -> np.ndarray:
        """``float32[...]`` rewards of reaching ``achieved float[..., 4]`` when ``desired
        float[..., 4]`` was asked (``info`` is unused: SB3's ``compute_reward`` signature)."""
        success = self.is_success(achieved, desired).astype(np.float64)
        if self.kind == "sparse":
            return (success - 1.0).astype(np.float32)
        pos, yaw = goal_errors(achieved, desired)
        reward = (-self.position_weight * pos - self.orientation_weight * yaw
                  + self.success_weight * success)
        return reward.astype(np.float32)


def goal_space(flat: spaces.Box) -> spaces.Dict:
    """The ``Dict`` space of :func:`goal_observation` for a push env's observation space."""
    sizes = {"observation": goal_observation(np.zeros(flat.shape))["observation"].shape[0],
             "achieved_goal": GOAL_SIZE, "desired_goal": GOAL_SIZE}
    return spaces.Dict({k: spaces.Box(-np.inf, np.inf, (n,), np.float32) for k, n in sizes.items()})


class PushGoalVecEnv(VecEnvWrapper):
    """Goal view (:func:`goal_observation`, :class:`GoalReward`) of a push ``VecEnv``.

    Episodes, success and termination are the env's; only the observation and the reward change.
    ``compute_reward`` is answered here (``env_method("compute_reward", ...)``, as
    ``HerReplayBuffer`` calls it), every other method goes to the sub-environments.

    Args:
        venv: a ``VecEnv`` of a push env (flat observations ``float32[N, 19]``).
        reward: ``"sparse"`` or ``"dense"`` (:class:`GoalReward`), with the env task's tolerances
            and weights.
    """

    def __init__(self, venv: VecEnv, reward: str = "sparse") -> None:
        task = venv.get_attr("task", [0])[0]
        self.goal_reward = GoalReward.of_task(reward, task)
        super().__init__(venv, observation_space=goal_space(venv.observation_space))

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray,
                       info: Any = None) -> np.ndarray:
        """``float32[B]`` rewards of goals ``float[B, 4]`` (:class:`GoalReward`)."""
        return self.goal_reward(achieved_goal, desired_goal, info)

    def reset(self) -> dict[str, np.ndarray]:
        return goal_observation(self.venv.reset())

    def step_wait(self) -> VecEnvStepReturn:
        obs, _, dones, infos = self.venv.step_wait()
        # The reward of an ended episode's last step is that of its terminal observation (``obs``
        # already holds the next episode's first one).
        last = np.array(obs, copy=True)
        for i, info in enumerate(infos):
            if "terminal_observation" in info:
                last[i] = info["terminal_observation"]
                info["terminal_observation"] = goal_observation(last[i])
        ended = goal_observation(last)
        reward = self.compute_reward(ended["achieved_goal"], ended["desired_goal"])
        return goal_observation(obs), reward, dones, infos

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        """``compute_reward`` of this view (one result per index), else the sub-environments'."""
        if method_name == "compute_reward":
            return [self.compute_reward(*method_args, **method_kwargs)
                    for _ in self._get_indices(indices)]
        return self.venv.env_method(method_name, *method_args, indices=indices, **method_kwargs)


class GoalPolicy:
    """A policy trained on the goal view, acting on the push env's flat observations.

    SB3's ``predict`` interface (so :func:`~fignet_gym.agents.evaluate_policy_on` and SB3's
    ``evaluate_policy`` take it): flat ``float32[N, 19]`` -> goal view -> the normaliser (if
    any) -> the model.

    Args:
        model: an SB3 model with a ``MultiInputPolicy`` over :func:`goal_space`.
        normalizer: its ``VecNormalize`` (statistics only) or ``None``.
    """

    def __init__(self, model: Any, normalizer: Any = None) -> None:
        self.model = model
        self.normalizer = normalizer

    def predict(self, observation: np.ndarray, state: Any = None,
                episode_start: np.ndarray | None = None,
                deterministic: bool = False) -> tuple[np.ndarray, Any]:
        """Actions ``float32[N, 2]`` for flat observations ``float32[N, 19]``."""
        obs = goal_observation(observation)
        if self.normalizer is not None:
            obs = self.normalizer.normalize_obs(obs)
        return self.model.predict(obs, state, episode_start, deterministic)
