"""A reactive policy (SB3's ``predict``) behind the planners' interface, timed like a planner.

:func:`~fignet_gym.agents.run_episode`, the ``fignet-gym plan`` table and the demo time every
agent by ``agent.last`` (wall and CPU seconds per action); :class:`PolicyAgent` lets a trained
policy (e.g. :func:`~fignet_gym.agents.load_policy`'s) stand beside the planners there.
"""

from __future__ import annotations

import time
from typing import Any

import gymnasium as gym
import numpy as np

from fignet_gym.agents.planners import PlanInfo


class PolicyAgent:
    """Acts with ``policy.predict`` on the env's current observation.

    Args:
        policy: anything with SB3's ``predict(obs float32[N, D], deterministic=...)`` returning
            ``(float32[N, A], state)``.
        deterministic: the policy's mean action (as the evaluations use).
    """

    def __init__(self, policy: Any, deterministic: bool = True) -> None:
        self.policy = policy
        self.deterministic = deterministic
        self.env: gym.Env | None = None
        self.last: PlanInfo | None = None

    def reset(self, seed: int | None = None) -> None:
        """New episode (a feed-forward policy keeps no state)."""
        self.last = None

    def bind(self, env: gym.Env) -> None:
        """Act in ``env`` from now on."""
        self.env = getattr(env, "unwrapped", env)

    def plan(self, env: gym.Env) -> np.ndarray:
        """``float32[A]`` action for ``env``'s current observation (``env.unwrapped.observe()``)."""
        self.bind(env)
        start, cpu = time.perf_counter(), time.process_time()
        obs = np.asarray(self.env.observe(), dtype=np.float32)[None]
        action, _ = self.policy.predict(obs, deterministic=self.deterministic)
        self.last = PlanInfo(np.nan, 0, 0, time.perf_counter() - start, time.process_time() - cpu)
        return np.asarray(action, dtype=np.float32)[0]
