"""Batched vector environments equal single environments; the SB3 adapter trains."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from sim_factories import quiet_simulator

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.envs import BatchedVectorEnv, SB3VecEnvAdapter, make_sb3_vec_env
from fignet_gym.simulator.model import LearnedSimulator

ENV_IDS = ["fignet_gym/Push-v2", "fignet_gym/Push-v1", "fignet_gym/PushT-v0", "fignet_gym/Toss-v0"]
FAST = {"fignet_gym/Push-v2": {}, "fignet_gym/Push-v1": {}, "fignet_gym/PushT-v0": {},
        "fignet_gym/Toss-v0": {"settle_steps": 3}}

def make_kwargs(env_id: str, dynamics: str, sim: LearnedSimulator | None = None) -> dict[str, Any]:
    if dynamics == "mujoco":
        return {"dynamics": "mujoco"}
    return {"dynamics": "fignet", "checkpoint": sim or quiet_simulator(), **FAST[env_id]}


@pytest.mark.parametrize("dynamics", ["mujoco", "fignet"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_vector_env_equals_single_envs(env_id: str, dynamics: str) -> None:
    """N batched sub-environments reproduce N single environments, autoresets included."""
    N, T, limit = 3, 7, 4
    sim = quiet_simulator()
    venv = gym.make_vec(
        env_id,
        num_envs=N,
        vectorization_mode="vector_entry_point",
        max_episode_steps=limit,
        **make_kwargs(env_id, dynamics, sim),
    )
    assert isinstance(venv.unwrapped, BatchedVectorEnv)
    assert venv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    singles = [
        gym.make(env_id, max_episode_steps=limit, **make_kwargs(env_id, dynamics, sim))
        for _ in range(N)
    ]
    rng = np.random.default_rng(0)
    obs, _ = venv.reset(seed=10)
    ref = np.stack([e.reset(seed=10 + i)[0] for i, e in enumerate(singles)])
    np.testing.assert_array_equal(obs, ref)
    needs_reset = np.zeros(N, dtype=bool)
    tol = 0 if dynamics == "mujoco" else 1e-4
    for _ in range(T):
        actions = rng.uniform(-1, 1, (N, *venv.single_action_space.shape))
        obs, rew, term, trunc, _ = venv.step(actions)
        for i, e in enumerate(singles):
            if needs_reset[i]:
                o, r, te, tr = e.reset()[0], 0.0, False, False
            else:
                o, r, te, tr, _ = e.step(actions[i])
            np.testing.assert_allclose(obs[i], o, atol=tol)
            assert rew[i] == pytest.approx(r, abs=max(tol, 1e-12) * 10)
            assert (term[i], trunc[i]) == (te, tr)
        needs_reset = term | trunc
    venv.close()


def test_same_step_autoreset_reports_final_obs() -> None:
    venv = gym.make_vec(
        "fignet_gym/Toss-v0",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.SAME_STEP,
    )
    venv.reset(seed=0)
    for _ in range(3):
        obs, _, term, _, info = venv.step(np.zeros((2, 2)))
    assert term.all() and info["_final_obs"].all()
    lay = venv.unwrapped.envs[0].observation_layout
    assert info["final_obs"][0][lay["released"]].sum() == 3  # the last state before the reset
    assert obs[0][lay["released"]].sum() == 0  # already reset
    assert info["final_info"]["num_in_target"].shape == (2,)


def test_render_frames_for_each_sub_env() -> None:
    venv = gym.make_vec(
        "fignet_gym/Push-v2",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        render_mode="rgb_array",
        width=32,
        height=32,
    )
    venv.reset(seed=0)
    frames = venv.render()
    assert len(frames) == 2 and frames[0].shape == (32, 32, 3)
    venv.close()


@pytest.mark.parametrize("dynamics", ["mujoco", "fignet"])
def test_sb3_adapter_and_ppo_smoke(dynamics: str) -> None:
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecEnv

    vec = make_sb3_vec_env(
        "fignet_gym/Push-v2", 2, max_episode_steps=5, **make_kwargs("fignet_gym/Push-v2", dynamics)
    )
    assert isinstance(vec, VecEnv) and isinstance(vec, SB3VecEnvAdapter)
    vec.seed(3)
    obs = vec.reset()
    assert obs.shape == (2, 19)
    dones_seen = False
    for _ in range(5):
        obs, rewards, dones, infos = vec.step(np.zeros((2, 2), dtype=np.float32))
        assert rewards.shape == (2,) and len(infos) == 2
        if dones.any():
            dones_seen = True
            for i in np.flatnonzero(dones):
                assert infos[i]["terminal_observation"].shape == (19,)
                assert infos[i]["TimeLimit.truncated"] is True
                assert "reward_position" in infos[i]
    assert dones_seen
    assert vec.get_attr("shape") == ["rect1", "rect1"]
    model = PPO(
        "MlpPolicy",
        vec,
        n_steps=8,
        batch_size=8,
        n_epochs=1,
        seed=0,
        device="cpu",
        policy_kwargs={"net_arch": [16]},
    )
    model.learn(total_timesteps=16)
    vec.close()
