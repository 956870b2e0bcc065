"""Natively batched vector environments: N ``MjData`` of one model, one ``step_many`` per step.

:class:`BatchedVectorEnv` holds N copies of a single environment that share its ``MjModel`` and its
:class:`~fignet_gym.dynamics.Dynamics`. A vector step applies each sub-environment's action to its
own ``MjData``, advances all of them with **one** ``dynamics.step_many`` call (for the learned
dynamics: one batched graph of N scenes per learned step), then computes each observation and
reward. Seeds follow Gymnasium's vector convention (``reset(seed=s)`` seeds sub-environment ``i``
with ``s + i``), so the vector environment reproduces N single environments.

Autoreset follows Gymnasium 1.x (``metadata["autoreset_mode"]``): ``NEXT_STEP`` (default; the step
after an episode ended resets that sub-environment, returning its first observation with reward 0),
``SAME_STEP`` (reset at once; the last observation and info are in ``info["final_obs"]`` /
``info["final_info"]``, what :class:`~fignet_gym.envs.sb3.SB3VecEnvAdapter` uses) or ``DISABLED``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from fignet_gym.dynamics import DivergenceError
from fignet_gym.envs.base import MjDynamicsEnv, check_action


def _is_seed(value: Any) -> bool:
    """Whether ``value`` is a seed NumPy accepts: a non-negative integer (not a bool)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= 0


class BatchedVectorEnv(VectorEnv):
    """N sub-environments of one single environment class, physics batched in one call.

    Args:
        env: the first sub-environment; the others are spawned from it (same model, dynamics and
            arguments, their own ``MjData``).
        num_envs: ``N``.
        max_episode_steps: truncate each sub-environment after this many steps (``None``: never;
            ``gym.make_vec`` passes the registered limit).
        autoreset_mode: ``AutoresetMode`` or its value (``"NextStep"``, ``"SameStep"``,
            ``"Disabled"``).
    """

    def __init__(
        self,
        env: MjDynamicsEnv,
        num_envs: int,
        max_episode_steps: int | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
    ) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        self.envs: list[MjDynamicsEnv] = [env] + [env._spawn() for _ in range(num_envs - 1)]
        self.num_envs = int(num_envs)
        self.model = env.model
        self.dynamics = env.dynamics
        self.frame_skip = env.frame_skip
        self.max_episode_steps = max_episode_steps
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.single_observation_space = env.observation_space
        self.single_action_space = env.action_space
        self.observation_space = batch_space(env.observation_space, self.num_envs)
        self.action_space = batch_space(env.action_space, self.num_envs)
        self.metadata = {**env.metadata, "autoreset_mode": self.autoreset_mode}
        self.render_mode = env.render_mode
        self._needs_reset = np.zeros(self.num_envs, dtype=bool)
        self._elapsed = np.zeros(self.num_envs, dtype=np.int64)

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}({type(self.envs[0]).__name__}, num_envs={self.num_envs}, "
            f"dynamics={type(self.dynamics).__name__})"
        )

    # ----------------------------------------------------------------- API
    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every sub-environment; ``float32[N, D]`` observations and batched infos.

        ``seed``: an int (sub-environment ``i`` gets ``seed + i``), ``N`` seeds, or ``None``.
        """
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif _is_seed(seed):
            super().reset(seed=int(seed))
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            if isinstance(seed, (str, bytes)) or not isinstance(seed, Sequence | np.ndarray):
                raise ValueError(f"{self}: seed must be a non-negative integer, a sequence of "
                                 f"{self.num_envs} of them or None, got {seed!r}")
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"{self}: expected {self.num_envs} seeds, got {len(seeds)}")
            bad = [s for s in seeds if s is not None and not _is_seed(s)]
            if bad:
                raise ValueError(f"{self}: seeds must be non-negative integers or None, got {bad[0]!r}")
        obs, infos = [], {}
        for i, (env, s) in enumerate(zip(self.envs, seeds, strict=True)):
            o, info = env.reset(seed=s, options=options)
            obs.append(o)
            infos = self._add_info(infos, info, i)
        self._needs_reset[:] = False
        self._elapsed[:] = 0
        return np.stack(obs), infos

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """``float[N, A]`` actions -> observations ``float32[N, D]``, rewards ``float64[N]``,
        terminations ``bool[N]``, truncations ``bool[N]``, batched infos.

        The whole batch is checked first (``ValueError`` for a wrong shape or a NaN/inf in any
        row, also in a row that is being reset and whose action is ignored): a refused batch
        changes no sub-environment."""
        try:
            acts = np.asarray(actions, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{self}: actions are not numeric ({exc})") from None
        expected = (self.num_envs, *self.single_action_space.shape)
        if acts.shape != expected:
            raise ValueError(f"{self}: actions must have shape {expected}, got {acts.shape}")
        resetting = (
            self._needs_reset
            if self.autoreset_mode == AutoresetMode.NEXT_STEP
            else np.zeros(self.num_envs, dtype=bool)
        )
        if self.autoreset_mode == AutoresetMode.DISABLED and self._needs_reset.any():
            raise RuntimeError(
                f"{self}: autoreset is disabled and sub-environments "
                f"{np.flatnonzero(self._needs_reset).tolist()} ended: reset them first"
            )
        stepping = np.flatnonzero(~resetting)
        # Every row is checked before any is applied: a rejected batch changes no sub-environment.
        for i in stepping:
            self.envs[i]._check_was_reset()
        applied = {i: self.envs[i]._check_step(acts[i]) for i in stepping}
        for i in np.flatnonzero(resetting):  # ignored (the row resets), but a NaN is still a bug
            check_action(str(self), acts[i], self.single_action_space)
        for i in stepping:
            self.envs[i]._apply_action(applied[i])
        reasons: dict[int, str] = {}
        try:
            self.dynamics.step_many(self.model, [self.envs[i].data for i in stepping], self.frame_skip)
        except DivergenceError as err:
            for j, r in zip(err.indices, err.reasons, strict=True):
                reasons[int(stepping[j])] = r

        obs = np.zeros((self.num_envs, *self.single_observation_space.shape), dtype=np.float32)
        rewards = np.zeros(self.num_envs)
        terminated = np.zeros(self.num_envs, dtype=bool)
        truncated = np.zeros(self.num_envs, dtype=bool)
        infos: dict[str, Any] = {}
        stepped = dict(zip(stepping.tolist(), self.envs[0]._post_step_many(
            [self.envs[i] for i in stepping], [applied[i] for i in stepping],
            [reasons.get(i) for i in stepping]) if len(stepping) else [], strict=True))
        for i, env in enumerate(self.envs):
            if resetting[i]:
                obs[i], info = env.reset()
                self._elapsed[i] = 0
            else:
                obs[i], rewards[i], terminated[i], truncated[i], info = stepped[i]
                self._elapsed[i] += 1
                if (
                    self.max_episode_steps is not None
                    and self._elapsed[i] >= self.max_episode_steps
                ):
                    truncated[i] = True
                if self.autoreset_mode == AutoresetMode.SAME_STEP and (
                    terminated[i] or truncated[i]
                ):
                    infos = self._add_info(
                        infos, {"final_obs": obs[i].copy(), "final_info": info}, i
                    )
                    obs[i], info = env.reset()
                    self._elapsed[i] = 0
            infos = self._add_info(infos, info, i)
        self._needs_reset = (
            (terminated | truncated)
            if self.autoreset_mode != AutoresetMode.SAME_STEP
            else np.zeros(self.num_envs, dtype=bool)
        )
        return obs, rewards, terminated, truncated, infos

    def render(self) -> tuple[np.ndarray | None, ...]:
        """One frame per sub-environment (each renders lazily with its own MuJoCo renderer)."""
        return tuple(env.render() for env in self.envs)

    def close_extras(self, **kwargs: Any) -> None:
        """Close every sub-environment (their renderers)."""
        for env in self.envs:
            env.close()

    # ----------------------------------------------------------------- sub-environment access
    def get_attr(self, name: str) -> tuple[Any, ...]:
        """Attribute ``name`` of every sub-environment."""
        return tuple(getattr(env, name) for env in self.envs)

    def set_attr(self, name: str, values: Any | Sequence[Any]) -> None:
        """Set attribute ``name`` on every sub-environment (a list: one value each)."""
        if not isinstance(values, (list, tuple)):
            values = [values] * self.num_envs
        if len(values) != self.num_envs:
            raise ValueError(f"{self}: expected {self.num_envs} values, got {len(values)}")
        for env, v in zip(self.envs, values, strict=True):
            setattr(env, name, v)

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """Call method ``name`` (or read attribute ``name``) on every sub-environment."""
        out = []
        for env in self.envs:
            f = getattr(env, name)
            out.append(f(*args, **kwargs) if callable(f) else f)
        return tuple(out)


class SingleEnvVectorEnv(BatchedVectorEnv):
    """A :class:`BatchedVectorEnv` of ``env_class(**kwargs)``: subclasses set ``env_class`` (the
    ``gym.make_vec(..., vectorization_mode="vector_entry_point")`` entry points).

    Args:
        num_envs: number of sub-environments.
        max_episode_steps: per-episode step limit (``gym.make_vec`` passes the registered one).
        autoreset_mode: Gymnasium ``AutoresetMode`` (default ``NEXT_STEP``).
        kwargs: ``env_class`` arguments, shared by every sub-environment.
    """

    env_class: ClassVar[type[MjDynamicsEnv]]

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        **kwargs: Any,
    ) -> None:
        super().__init__(self.env_class(**kwargs), num_envs, max_episode_steps, autoreset_mode)
