"""The push features and the progress shaping a PPO run can train with, against the env itself."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents.ppo.features import (
    N_FEATURES,
    ObservationTransform,
    ProgressShaping,
    TransformedObservations,
    progress_potential,
    push_features,
)
from fignet_gym.envs.sb3 import make_sb3_vec_env
from fignet_gym.envs.tasks import wrap_angle

PUSH = "fignet_gym/Push-v1"


def test_features_equal_the_task_on_the_state() -> None:
    """Pushing point, relative vectors and heading error from the observation alone equal the
    env's own task evaluated on its full state (its goal, its outline)."""
    env = gym.make(PUSH)
    u = env.unwrapped
    rng = np.random.default_rng(0)
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        for _ in range(int(rng.integers(0, 20))):
            obs, *_ = env.step(rng.uniform(-1, 1, 2))
        feats = push_features(obs[None], u.task.outline, u.task.tip_radius)[0]
        assert feats.shape == (19 + N_FEATURES,)
        np.testing.assert_array_equal(feats[:19], obs)
        state = u.get_state()
        obj = u.data.qpos[u._qadr : u._qadr + 2]
        tip = u.data.mocap_pos[u._tip_mocap, :2]
        pp = u.task.pushing_point(state, u.goal)
        yaw = float(np.arctan2(obs[3], obs[2]))
        c, s = np.cos(yaw), np.sin(yaw)
        to_obj = np.array([[c, s], [-s, c]])
        np.testing.assert_allclose(feats[19:21], u.goal[:2] - obj, atol=1e-6)
        np.testing.assert_allclose(feats[21:23], pp - tip, atol=1e-5)
        np.testing.assert_allclose(feats[23:25], to_obj @ (pp - tip), atol=1e-5)
        np.testing.assert_allclose(feats[25:27], u.goal[:2] - tip, atol=1e-6)
        np.testing.assert_allclose(feats[27:29], to_obj @ (u.goal[:2] - tip), atol=1e-5)
        assert feats[29] == pytest.approx(float(wrap_angle(u.goal[2] - yaw)), abs=1e-5)


def test_potential_is_the_envs_own_cost() -> None:
    env = gym.make(PUSH, action_weight=0.0, success_weight=0.0)
    obs, _ = env.reset(seed=1)
    obs, reward, *_ = env.step(np.array([0.3, -0.2]))
    u = env.unwrapped
    phi = progress_potential(obs[None], u.task.position_weight, u.task.orientation_weight)[0]
    assert phi == pytest.approx(reward, abs=1e-5)  # with no action or success term: the reward


@pytest.mark.parametrize("gamma", [1.0, 0.9])
def test_shaping_telescopes_over_an_episode(gamma: float) -> None:
    """sum_t gamma^t (gamma phi(s_t+1) - phi(s_t)) = gamma^T phi(s_T) - phi(s_0): the shaped
    return differs from the env's by a function of the start state only (the optimal policy
    is kept); the truncated episode's last potential is its final observation's."""
    vec = make_sb3_vec_env(PUSH, 1)
    shaped = ProgressShaping(vec, gamma=gamma, weight=1.0, position_weight=10.0, orientation_weight=1.0)
    shaped.seed(4)
    first = shaped.reset()
    total, t = 0.0, 0
    actions = np.full((1, 2), 0.05, dtype=np.float32)  # a slow drift: the episode runs to the limit
    while True:
        shaped.step_async(actions)
        obs, shaped_r, dones, infos = shaped.step_wait()
        # the env's reward of the same step, recomputed independently from its info terms
        env_r = sum(v for k, v in infos[0].items() if k.startswith("reward_"))
        total += gamma**t * (shaped_r[0] - env_r)
        t += 1
        if dones[0]:
            break
    assert infos[0]["TimeLimit.truncated"]
    last = infos[0]["terminal_observation"][None]
    phi0 = progress_potential(first, 10.0, 1.0)[0]
    phiT = progress_potential(last, 10.0, 1.0)[0]
    assert total == pytest.approx(gamma**t * phiT - phi0, rel=1e-4, abs=1e-4)


def test_transformed_env_and_policy_transform_agree() -> None:
    vec = make_sb3_vec_env(PUSH, 2)
    transform = ObservationTransform.of_env("push-features", vec.venv.envs[0])
    wrapped = TransformedObservations(vec, transform)
    assert wrapped.observation_space.shape == (19 + N_FEATURES,)
    wrapped.seed(0)
    obs = wrapped.reset()
    raw = np.stack([e.observe() for e in vec.venv.envs])
    np.testing.assert_array_equal(obs, transform(raw))
    with pytest.raises(ValueError, match="observation"):
        ObservationTransform("pixels")


def test_run_with_features_and_shaping_saves_a_policy_that_acts_on_raw_observations(tmp_path) -> None:
    from fignet_gym.agents.ppo import PPOConfig, RunConfig, evaluate_policy_on, load_run_policy, run_ppo
    from fignet_gym.agents.ppo.eval import EVAL_SEED

    cfg = RunConfig(env_id=PUSH, dynamics="mujoco", observation="push-features", shaping=1.0,
                    eval_every=0, final_episodes=2,
                    ppo=PPOConfig(total_timesteps=32, num_envs=2, n_steps=16, batch_size=16, n_epochs=1))
    result = run_ppo(tmp_path / "run", cfg, progress=False)
    policy = load_run_policy(tmp_path / "run")
    assert policy.transform is not None and policy.model.observation_space.shape == (19 + N_FEATURES,)
    again = evaluate_policy_on("mujoco", policy, n_episodes=2, seed=EVAL_SEED, env_id=PUSH)
    # Reported returns are the env's own reward (no shaping), the same episodes as the run's.
    assert again["episode_returns"] == result["eval"]["mujoco"]["episode_returns"]


def test_success_bonus_is_added_on_successful_steps_only() -> None:
    """A run of the env from a hand-made near-goal state: the bonus lands on the success step."""
    from fignet_gym.agents.ppo.features import SuccessBonus

    vec = make_sb3_vec_env(PUSH, 2)
    bonus = SuccessBonus(vec, 5.0)
    bonus.seed(0)
    bonus.reset()
    u = vec.venv.envs[0]
    u.goal = np.array([*u.data.qpos[u._qadr : u._qadr + 2], u.goal[2]])  # position reached
    u.goal[2] = float(np.arctan2(*u.observe()[2:4][::-1]))  # heading reached
    bonus.step_async(np.zeros((2, 2), dtype=np.float32))
    _, rewards, dones, infos = bonus.step_wait()
    env_r = [sum(v for k, v in i.items() if k.startswith("reward_")) for i in infos]
    assert infos[0]["is_success"] and dones[0] and not infos[1]["is_success"]
    assert rewards[0] == pytest.approx(env_r[0] + 5.0, abs=1e-5)
    assert rewards[1] == pytest.approx(env_r[1], abs=1e-5)
