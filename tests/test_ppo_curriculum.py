"""The goal curriculum (``fignet-gym ppo --curriculum``): goals resampled on success, a level that
rises with success, kept across a resume, and evaluation envs that keep the task's own goals."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents.ppo import curriculum as cur
from fignet_gym.agents.ppo.config import RunConfig
from fignet_gym.agents.ppo.curriculum import GoalCurriculum
from fignet_gym.agents.ppo.run import run_ppo
from fignet_gym.cli import main
from fignet_gym.envs.push import EASY_GOAL
from fignet_gym.envs.sb3 import make_sb3_vec_env
from fignet_gym.envs.tasks import wrap_angle

PUSH = "fignet_gym/Push-v2"


def _goal_offsets(env: gym.Env, n: int) -> np.ndarray:
    """``float[n, 2]``: distance and |heading difference| of ``n`` reset goals from the object."""
    out = []
    for s in range(n):
        env.reset(seed=s)
        u = env.unwrapped
        xy, yaw, _ = u._object_pose()
        out.append((np.linalg.norm(u.goal[:2] - xy), abs(wrap_angle(u.goal[2] - yaw))))
    return np.array(out)


def test_goal_level_scales_the_goal_ranges_from_easy_to_the_envs_own() -> None:
    env = gym.make(PUSH)
    own = _goal_offsets(env, 200)
    assert own[:, 0].min() >= 0.02 and own[:, 0].max() <= 0.05 and own[:, 1].max() <= 0.3
    assert own[:, 0].max() > 0.045 and own[:, 1].max() > 0.25  # the default is the env's own range
    u = env.unwrapped
    # Exactly the env's own at level 1: a rounding there moved every seeded episode of Push-v1
    # (the shipped policy's evaluation) although no curriculum was on.
    assert u.goal_ranges() == (u.goal_distance_min, u.goal_distance, u.goal_yaw)
    env.unwrapped.goal_level = 0.0
    easy = _goal_offsets(env, 200)
    lo, hi, yaw = EASY_GOAL
    assert easy[:, 0].min() >= lo - 1e-12 and easy[:, 0].max() <= hi + 1e-12
    assert easy[:, 1].max() <= yaw and easy[:, 1].max() > 0.8 * yaw
    env.unwrapped.goal_level = 0.5
    assert env.unwrapped.goal_ranges() == pytest.approx(((lo + 0.02) / 2, (hi + 0.05) / 2, (yaw + 0.3) / 2))


def test_resampled_goal_keeps_the_episode_going_around_the_objects_new_pose() -> None:
    env = gym.make(PUSH)
    env.reset(seed=3)
    u = env.unwrapped
    xy, yaw, _ = u._object_pose()
    u.goal = np.array([xy[0], xy[1], yaw])  # already reached
    _, reward, terminated, _, info = env.step(np.zeros(2))
    assert terminated and info["is_success"] and "goal_reached" not in info  # the task's own rule
    env.reset(seed=3)
    u.resample_goal = True
    u.goal = np.array([xy[0], xy[1], yaw])
    obs, reward_r, terminated, truncated, info = env.step(np.zeros(2))
    assert info["goal_reached"] and info["is_success"] and not terminated and not truncated
    assert reward_r == pytest.approx(reward)  # the step that reached it is paid as before
    xy2, yaw2, _ = u._object_pose()
    d = np.linalg.norm(u.goal[:2] - xy2)
    assert 0.02 <= d <= 0.05 and abs(wrap_angle(u.goal[2] - yaw2)) <= 0.3
    np.testing.assert_allclose(obs[6:8], u.goal[:2], atol=1e-6)  # the policy sees the new goal


def _curriculum(num_envs: int, **kwargs: float) -> GoalCurriculum:
    return GoalCurriculum(make_sb3_vec_env(PUSH, num_envs, **kwargs))


def test_level_rises_after_a_window_of_reached_goals_and_not_otherwise() -> None:
    easy = _curriculum(64, success_position=1.0, success_yaw=4.0)  # every step reaches its goal
    easy.reset()
    assert easy.level == 0.0
    assert all(e.resample_goal and e.goal_level == 0.0 for e in easy.venv.venv.envs)
    # Every episode reaches its first goal on its first step and then practises until the
    # 75-step limit: one outcome per episode, so the window fills on the fourth episode's start.
    rose_at = None
    for t in range(1, 4 * 75 + 1):
        easy.step(np.zeros((64, 2)))
        if rose_at is None and easy.level > 0:
            rose_at = t
    assert rose_at == 3 * 75 + 1 and easy.goals_reached == 4 * 75 * 64
    assert easy.level == pytest.approx(cur.LEVEL_STEP)
    assert all(e.goal_level == pytest.approx(cur.LEVEL_STEP) for e in easy.venv.venv.envs)
    hard = _curriculum(64, success_position=1e-6, success_yaw=1e-6)  # never reached
    hard.reset()
    for _ in range(5 * 75):  # five time limits of every sub-environment
        hard.step(np.zeros((64, 2)))
    assert hard.level == 0.0 and hard.goals_reached == 0
    assert len(hard.outcomes) == cur.WINDOW and not any(hard.outcomes)


def test_state_round_trip() -> None:
    a = _curriculum(2)
    a.outcomes.extend([True, False, True])
    a._set(0.3)
    b = _curriculum(2)
    b.load_state(json.loads(json.dumps(a.state())))
    assert (b.level, list(b.outcomes)) == (0.3, [True, False, True])
    assert all(e.goal_level == 0.3 for e in b.venv.venv.envs)


def test_curriculum_needs_a_push_env() -> None:
    with pytest.raises(ValueError, match="push env"):
        GoalCurriculum(make_sb3_vec_env("fignet_gym/Toss-v1", 1))


def test_run_checkpoints_the_level_and_evaluates_on_the_envs_own_goals(tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert main(["ppo", "--dynamics", "mujoco", "--steps", "64", "--num-envs", "2", "--n-steps", "16",
                 "--batch-size", "16", "--n-epochs", "1", "--eval-every", "0", "--final-episodes",
                 "2", "--checkpoint-every", "32", "--curriculum", "--quiet", "--out", str(out)]) == 0
    cfg = RunConfig.from_json(json.loads((out / "config.json").read_text()))
    assert cfg.curriculum
    state = torch.load(out / "checkpoint" / "state.pt", weights_only=False)
    assert state["curriculum"]["level"] == 0.0 and "outcomes" in state["curriculum"]
    rows = (out / "progress.csv").read_text().splitlines()
    assert "curriculum/level" in rows[0]
    # evaluation envs come from the run's arguments: the env's own goals and termination
    from fignet_gym.agents.ppo.eval import run_env_kwargs

    env = gym.make(PUSH, **run_env_kwargs(cfg, "mujoco"))
    assert env.unwrapped.goal_level == 1.0 and not env.unwrapped.resample_goal
    # a resumed run restores the level it checkpointed
    state["curriculum"]["level"] = 0.7
    torch.save(state, out / "checkpoint" / "state.pt")
    seen: list[float] = []
    original = GoalCurriculum.load_state

    def spy(self: GoalCurriculum, s: dict) -> None:
        original(self, s)
        seen.append(self.level)

    GoalCurriculum.load_state = spy  # type: ignore[method-assign]
    try:
        cfg2 = RunConfig.from_json({**cfg.to_json(), "ppo": {**cfg.to_json()["ppo"], "total_timesteps": 96}})
        run_ppo(out, cfg2, resume=True, progress=False)
    finally:
        GoalCurriculum.load_state = original  # type: ignore[method-assign]
    assert seen == [0.7]


def test_a_reached_goal_ends_the_episode_for_ppo_but_not_the_world() -> None:
    """PPO sees each goal as an episode (done, not truncated, so no bootstrapping into the next
    goal's costs); the physical episode goes on from where the object is."""
    c = _curriculum(2, success_position=1.0, success_yaw=4.0)  # every step reaches its goal
    c.reset()
    envs = c.venv.venv.envs
    c.step(np.ones((2, 2)))
    before = [e.data.qpos.copy() for e in envs]
    tips = [e.data.mocap_pos[0].copy() for e in envs]
    _, _, dones, infos = c.step(np.ones((2, 2)))
    assert dones.all() and all(i["goal_reached"] and i["TimeLimit.truncated"] is False for i in infos)
    for e, q, tip in zip(envs, before, tips, strict=True):  # not reset: the tip moved on by one step
        assert np.linalg.norm(e.data.mocap_pos[0, :2] - tip[:2]) == pytest.approx(0.1 * 0.02 * np.sqrt(2))
        assert e.data.time > 0.03 and np.abs(e.data.qpos - q).max() < 0.01
