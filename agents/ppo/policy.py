"""A trained PPO policy with its observation transform and normaliser, acting on the env's raw
observations."""

from __future__ import annotations

import os
import pickle
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecNormalize

from fignet_gym.agents.ppo.config import RunConfig
from fignet_gym.agents.ppo.features import ObservationTransform
from fignet_gym.agents.ppo.rundir import NORMALIZER, POLICY, RunError, saved_config


class NormalizedPolicy:
    """A PPO policy, the observation transform and normaliser it was trained with, acting on raw
    observations.

    SB3's ``predict`` interface, so :func:`~fignet_gym.agents.evaluate_policy_on` and
    ``stable_baselines3.common.evaluation.evaluate_policy`` take it as is.

    Args:
        model: the trained PPO model.
        normalizer: its ``VecNormalize`` (statistics only; ``None``: observations as they are).
        transform: what the policy sees of the env's observation (``None``: the observation).
        config: the run that trained it (``None``: unknown); :attr:`env_id` and
            :attr:`env_kwargs` say which env it acts in.
    """

    def __init__(self, model: PPO, normalizer: VecNormalize | None,
                 transform: ObservationTransform | None = None, *,
                 config: RunConfig | None = None) -> None:
        self.model = model
        self.normalizer = normalizer
        self.transform = transform
        self.config = config

    @property
    def env_id(self) -> str | None:
        """The environment id the policy was trained in (``None``: unknown)."""
        return None if self.config is None else self.config.env_id

    @property
    def env_kwargs(self) -> dict[str, Any]:
        """The task arguments it was trained with, without the dynamics: ``gym.make(policy.env_id,
        **policy.env_kwargs, dynamics="mujoco")`` is its task on MuJoCo."""
        return {} if self.config is None else dict(self.config.env_kwargs)

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, Any]:
        """Actions ``float32[N, A]`` for raw observations ``float32[N, D]``."""
        obs = observation if self.transform is None else self.transform(observation)
        obs = obs if self.normalizer is None else self.normalizer.normalize_obs(obs)
        return self.model.predict(obs, state, episode_start, deterministic)


def load_normalizer(path: Path) -> VecNormalize | None:
    """A saved ``VecNormalize`` in evaluation mode, detached from any environment (or ``None``)."""
    if not path.exists():
        return None
    with path.open("rb") as f:
        norm = pickle.load(f)  # VecNormalize.load would also attach a venv; only its stats are used
    norm.training = False
    norm.norm_reward = False
    return norm


def load_run_policy(run: str | os.PathLike) -> NormalizedPolicy:
    """The final policy of a run folder (``policy.zip``, ``vecnormalize.pkl`` and the observation
    transform its ``config.json`` names)."""
    root = Path(run)
    if not (root / POLICY).exists():
        raise RunError(f"{root}: no {POLICY} (the run has not finished)")
    model = PPO.load(root / POLICY, device="cpu")
    cfg = saved_config(root)
    transform = run_transform(cfg.env_id, cfg.env_kwargs, cfg.observation) if cfg else None
    return NormalizedPolicy(model, load_normalizer(root / NORMALIZER), transform, config=cfg)


def run_transform(env_id: str, env_kwargs: dict[str, Any], kind: str) -> ObservationTransform | None:
    """The observation transform ``kind`` for ``env_id`` (``None`` for ``"env"``): the geometry is
    read from a MuJoCo instance of the env (its task's outline and tip)."""
    if kind == "env":
        return None
    env = gym.make(env_id, **{**env_kwargs, "dynamics": "mujoco"})
    try:
        return ObservationTransform.of_env(kind, env.unwrapped)
    finally:
        env.close()
