"""A goal curriculum for PPO on a push env, as MuJoCo Playground's pushing tasks train: goals
resampled within an episode on success, and a goal range that widens from easy to the env's own as
the agent succeeds. Training-time only: evaluation envs are built from the run's arguments and
always have the task's own goals."""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn

from fignet_gym.agents.ppo.rng import adapter

#: Episodes over which the success rate is taken.
WINDOW = 256
#: Success rate over the window at which the level rises by :data:`LEVEL_STEP`.
THRESHOLD = 0.6
LEVEL_STEP = 0.1


class GoalCurriculum(VecEnvWrapper):
    """Sets ``resample_goal`` and ``goal_level`` (:class:`~fignet_gym.envs.push.PushEnv`) on every
    sub-environment of ``venv`` and raises the level by :data:`LEVEL_STEP` each time the share of
    episodes that reached their first goal, over the last :data:`WINDOW`, reaches
    :data:`THRESHOLD`.

    The success rate is over episodes: an episode succeeds when it reaches its first goal (the one
    its reset drew, the task's own measure), fails when it ends (time limit, workspace,
    divergence) before; the goals drawn after a success are practice and not counted, since the
    one in progress at the time limit would otherwise count as a miss and cap the rate at
    ``k / (k + 1)`` for ``k`` goals an episode. Sit it right above the batched env's SB3
    adapter, so ``VecMonitor`` above still logs the env's own reward.
    """

    def __init__(self, venv: VecEnv, level: float = 0.0) -> None:
        super().__init__(venv)
        envs = adapter(venv).venv.envs
        if not all(hasattr(e, "goal_level") and hasattr(e, "resample_goal") for e in envs):
            raise ValueError(f"a goal curriculum needs a push env, not {type(envs[0]).__name__}")
        self.outcomes: deque[bool] = deque(maxlen=WINDOW)
        self._first = np.ones(venv.num_envs, dtype=bool)  # still on the episode's first goal
        self.goals_reached = 0
        self._set(level)
        adapter(venv).venv.set_attr("resample_goal", True)

    def _set(self, level: float) -> None:
        self.level = round(float(np.clip(level, 0.0, 1.0)), 9)  # 0.8, not 0.7999999999999999
        adapter(self.venv).venv.set_attr("goal_level", self.level)

    def reset(self) -> Any:
        """The wrapped env's reset (the level stays)."""
        self._first[:] = True
        return self.venv.reset()

    def step_wait(self) -> VecEnvStepReturn:
        """The wrapped step; counts goals and raises the level when they are reached often."""
        obs, rewards, dones, infos = self.venv.step_wait()
        ends = dones.copy()
        for i, (done, info) in enumerate(zip(dones, infos, strict=True)):
            reached = bool(info.get("goal_reached"))
            self.goals_reached += reached
            if self._first[i] and (reached or done):
                self.outcomes.append(reached)
                self._first[i] = False
            if done:
                self._first[i] = True
            elif reached:
                # For PPO a reached goal ends an episode (no bootstrapping into the next goal's
                # costs, which would make reaching a goal worth less than hovering near it);
                # the world goes on, so the observation returned is the next one's first.
                ends[i] = True
                info["terminal_observation"] = obs[i].copy()
                info["TimeLimit.truncated"] = False
        if (self.level < 1.0 and len(self.outcomes) == WINDOW
                and np.mean(self.outcomes) >= THRESHOLD):
            self._set(self.level + LEVEL_STEP)
            self.outcomes.clear()
        return obs, rewards, ends, infos

    def success_rate(self) -> float:
        """Share of the window's episodes that reached their first goal (NaN before any)."""
        return float(np.mean(self.outcomes)) if self.outcomes else float("nan")

    def state(self) -> dict[str, Any]:
        """What a checkpoint keeps: the level and the window."""
        return {"level": self.level, "outcomes": [bool(o) for o in self.outcomes],
                "goals_reached": self.goals_reached}

    def load_state(self, state: dict[str, Any]) -> None:
        """Inverse of :meth:`state`."""
        self._set(float(state["level"]))
        self.outcomes = deque((bool(o) for o in state["outcomes"]), maxlen=WINDOW)
        self.goals_reached = int(state.get("goals_reached", 0))


def find_curriculum(vec: VecEnv) -> GoalCurriculum | None:
    """The :class:`GoalCurriculum` under ``vec``'s SB3 wrappers, if any."""
    inner: Any = vec
    while isinstance(inner, VecEnvWrapper):
        if isinstance(inner, GoalCurriculum):
            return inner
        inner = inner.venv
    return None
