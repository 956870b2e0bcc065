"""Every random stream a PPO run draws from, captured and restored (a resumed run continues them).

The streams: torch's, NumPy's global, Python's ``random``, and each training sub-environment's
``np_random`` (the episodes it samples), reached through the SB3 wrappers.
"""

from __future__ import annotations

import random
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.vec_env import VecEnv

from fignet_gym.envs.sb3 import SB3VecEnvAdapter


def adapter(vec: VecEnv) -> SB3VecEnvAdapter:
    """The batched env's SB3 adapter under SB3 wrappers (``VecNormalize``, ``VecMonitor``)."""
    inner: Any = vec
    while not isinstance(inner, SB3VecEnvAdapter):
        inner = inner.venv
    return inner


def rng_state(vec: VecEnv) -> dict[str, Any]:
    """The random states of the process and of ``vec``'s sub-environments."""
    return {
        "torch": torch.get_rng_state(),
        "numpy": np.random.get_state(),
        "random": random.getstate(),
        "envs": [env.np_random.bit_generator.state for env in adapter(vec).venv.envs],
    }


def set_rng_state(vec: VecEnv, state: Mapping[str, Any]) -> None:
    """Restore :func:`rng_state`'s ``state`` (``vec`` must have as many sub-environments)."""
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["random"])
    for env, s in zip(adapter(vec).venv.envs, state["envs"], strict=True):
        env.np_random.bit_generator.state = s
