"""A reactive policy (SB3's ``predict``) behind the planners' interface, timed like a planner.

:func:`~fignet_gym.agents.run_episode`, the ``fignet-gym plan`` table and the demo time every
agent by ``agent.last`` (wall and CPU seconds per action); :class:`PolicyAgent` lets a trained
policy (e.g. :func:`~fignet_gym.agents.load_policy`'s) stand beside the planners there.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from fignet_gym.agents.baselines import ReactiveAgent


class PolicyAgent(ReactiveAgent):
    """Acts with ``policy.predict`` on the env's current observation.

    Args:
        policy: anything with SB3's ``predict(obs float32[N, D], deterministic=...)`` returning
            ``(float32[N, A], state)``.
        deterministic: the policy's mean action (as the evaluations use).
    """

    def __init__(self, policy: Any, deterministic: bool = True) -> None:
        self.policy = policy
        self.deterministic = deterministic
        super().__init__()

    def _act(self, env: gym.Env) -> np.ndarray:
        obs = np.asarray(env.observe(), dtype=np.float32)[None]
        action, _ = self.policy.predict(obs, deterministic=self.deterministic)
        return np.asarray(action, dtype=np.float32)[0]

    def predict(
        self, observation: np.ndarray, state: Any = None, episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """SB3's policy interface: the wrapped policy's own ``predict`` (``float[N, D]`` ->
        ``float32[N, A]``)."""
        return self.policy.predict(observation, state, episode_start, deterministic)
