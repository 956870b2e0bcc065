"""The stable-baselines3 adapter drives a batched vector env without changing how it was made."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.envs.sb3 import SB3VecEnvAdapter, make_sb3_vec_env

PUSH = "fignet_gym/Push-v1"
LIMIT = 75  # Push-v1's registered episode length


def test_adapter_leaves_the_given_env_in_its_autoreset_mode() -> None:
    venv = gym.make_vec(PUSH, num_envs=2, vectorization_mode="vector_entry_point")
    assert venv.autoreset_mode == AutoresetMode.NEXT_STEP
    sb = SB3VecEnvAdapter(venv)
    sb.seed(3)
    sb.reset()
    idle = np.zeros((2, 2), dtype=np.float32)
    for _ in range(LIMIT):
        obs, _, dones, infos = sb.step(idle)
        assert venv.autoreset_mode == AutoresetMode.NEXT_STEP  # between calls: as it was made
        assert venv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    # SB3's semantics through the adapter: the episode ends at the limit and is reset at once.
    assert dones.all() and all("terminal_observation" in i for i in infos)
    assert all(i["TimeLimit.truncated"] for i in infos)
    assert not np.array_equal(obs, np.stack([i["terminal_observation"] for i in infos]))
    # The same env used directly still follows its own (next-step) rule.
    obs, _ = venv.reset(seed=0)
    for _ in range(LIMIT):
        obs, rew, term, trunc, _ = venv.step(idle)
    assert trunc.all()
    after, rew, term, trunc, _ = venv.step(idle)  # the reset step of NEXT_STEP: reward 0
    assert not trunc.any() and np.array_equal(rew, np.zeros(2))


def test_make_sb3_vec_env_makes_a_same_step_env() -> None:
    sb = make_sb3_vec_env(PUSH, 2)
    assert sb.venv.autoreset_mode == AutoresetMode.SAME_STEP
    sb.seed(0)
    assert sb.reset().shape == (2, 19)
