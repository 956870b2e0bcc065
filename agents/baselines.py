"""Reference agents for the planning benchmark: do nothing, act at random.

They (and :class:`~fignet_gym.agents.policy_agent.PolicyAgent`) share the planners' interface
(``reset``, ``bind``, ``plan``, ``last``, SB3's ``predict``) so that
:func:`~fignet_gym.agents.planners.run_episode` and the ``fignet-gym plan`` table treat
them like any planner.
"""

from __future__ import annotations

import time
from typing import Any

import gymnasium as gym
import numpy as np

from fignet_gym.agents.planners import PlanInfo


class ReactiveAgent:
    """An agent that acts without a model; subclasses give the action (``_act``). Shared
    plumbing: binding, timing (``last``), SB3 ``predict``."""

    prediction = None

    def __init__(self, seed: int = 0) -> None:
        self.seed = int(seed)
        self.env: gym.Env | None = None
        self.last: PlanInfo | None = None
        self._episode = -1
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        """New episode: a new generator (``seed``, else the constructor's seed and the number of
        episodes so far: every episode of a run differs, every run repeats)."""
        self._episode += 1
        self.rng = np.random.default_rng(seed if seed is not None else [self.seed, self._episode])

    def bind(self, env: gym.Env) -> None:
        """Act in ``env`` from now on."""
        self.env = getattr(env, "unwrapped", env)

    def plan(self, env: gym.Env) -> np.ndarray:
        """``float32[A]`` action for ``env``'s current state."""
        self.bind(env)
        start, cpu = time.perf_counter(), time.process_time()
        action = self._act(self.env)
        self.last = PlanInfo(np.nan, 0, 0, time.perf_counter() - start, time.process_time() - cpu)
        return action

    def _act(self, env: gym.Env) -> np.ndarray:
        """``float32[A]`` action in the bound (unwrapped) ``env``'s current state."""
        raise NotImplementedError

    def predict(
        self, observation: np.ndarray, state: Any = None, episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """SB3's policy interface: ``float[N, D]`` observations -> ``float32[N, A]`` actions."""
        if self.env is None:
            raise RuntimeError("bind(env) first")
        obs = np.asarray(observation)
        n = obs.shape[0] if obs.ndim == 2 else None
        acts = np.stack([self._act(self.env) for _ in range(n or 1)])
        return (acts if n is not None else acts[0]), state


class IdleAgent(ReactiveAgent):
    """Always the zero action (Push: the tip stays put; Toss: the middle release velocity)."""

    def _act(self, env: gym.Env) -> np.ndarray:
        return np.zeros(env.action_space.shape, dtype=np.float32)


class RandomAgent(ReactiveAgent):
    """Uniform random actions in the action box, seeded (``reset`` restarts the sequence)."""

    def _act(self, env: gym.Env) -> np.ndarray:
        space = env.action_space
        return self.rng.uniform(space.low, space.high).astype(np.float32)
