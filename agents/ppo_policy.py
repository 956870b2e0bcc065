"""A trained PPO policy with its observation normaliser, acting on the env's raw observations."""

from __future__ import annotations

import os
import pickle
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecNormalize

from fignet_gym.agents.ppo_rundir import NORMALIZER, POLICY, RunError


class NormalizedPolicy:
    """A PPO policy and the observation normaliser it was trained with, acting on raw observations.

    SB3's ``predict`` interface, so :func:`~fignet_gym.agents.evaluate_policy_on` and
    ``stable_baselines3.common.evaluation.evaluate_policy`` take it as is.

    Args:
        model: the trained PPO model.
        normalizer: its ``VecNormalize`` (statistics only; ``None``: observations as they are).
    """

    def __init__(self, model: PPO, normalizer: VecNormalize | None) -> None:
        self.model = model
        self.normalizer = normalizer

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, Any]:
        """Actions ``float32[N, A]`` for raw observations ``float32[N, D]``."""
        obs = observation if self.normalizer is None else self.normalizer.normalize_obs(observation)
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
    """The final policy of a run folder (``policy.zip`` + ``vecnormalize.pkl``)."""
    root = Path(run)
    if not (root / POLICY).exists():
        raise RunError(f"{root}: no {POLICY} (the run has not finished)")
    model = PPO.load(root / POLICY, device="cpu")
    return NormalizedPolicy(model, load_normalizer(root / NORMALIZER))
