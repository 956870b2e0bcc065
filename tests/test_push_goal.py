"""The goal view of Push: its reward and success agree with the env's own, on the env's steps."""

from __future__ import annotations

import numpy as np
import pytest

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents.push_goal import GoalReward, PushGoalVecEnv, goal_errors, goal_observation
from fignet_gym.envs.sb3 import make_sb3_vec_env
from fignet_gym.envs.tasks import wrap_angle

PUSH = "fignet_gym/Push-v1"
N_ENVS = 8
STEPS = 90  # past Push-v1's 75-step limit: ended episodes and their terminal observations
#: Goals moved next to the object: offsets up to twice the tolerances (1 cm, 0.2 rad), so steps
#: fall on both sides of the success rule.
NEAR_POSITION, NEAR_YAW = 0.02, 0.4


def _goal_env(reward: str) -> PushGoalVecEnv:
    return PushGoalVecEnv(make_sb3_vec_env(PUSH, N_ENVS, dynamics="mujoco"), reward)


def _near_goals(venv: PushGoalVecEnv, rng: np.random.Generator) -> None:
    """Move every sub-environment's goal to within twice the tolerances of its object."""
    for env in venv.venv.venv.envs:
        xy, yaw, _ = env._object_pose()
        r, phi = rng.uniform(0, NEAR_POSITION), rng.uniform(-np.pi, np.pi)
        env.goal = np.array([xy[0] + r * np.cos(phi), xy[1] + r * np.sin(phi),
                             wrap_angle(yaw + rng.uniform(-NEAR_YAW, NEAR_YAW))])


@pytest.mark.parametrize("reward", ["sparse", "dense"])
def test_goal_reward_and_success_match_the_env(reward: str) -> None:
    venv = _goal_env(reward)
    venv.seed(0)
    obs = venv.reset()
    rng = np.random.default_rng(0)
    seen = {True: 0, False: 0}
    ended = 0
    for t in range(STEPS):
        if t % 3 == 0:
            _near_goals(venv, rng)
        actions = rng.uniform(-1, 1, (N_ENVS, 2)).astype(np.float32) * 0.2
        obs, rewards, dones, infos = venv.step(actions)
        for i, info in enumerate(infos):
            last = info["terminal_observation"] if dones[i] else {k: v[i] for k, v in obs.items()}
            success = bool(info["is_success"])
            seen[success] += 1
            ended += int(dones[i])
            # The env's success rule, from the goals alone.
            assert venv.goal_reward.is_success(last["achieved_goal"], last["desired_goal"]) == success
            # The env's errors, from the goals alone (float32 observations).
            pos, yaw = goal_errors(last["achieved_goal"], last["desired_goal"])
            assert pos == pytest.approx(info["position_error"], abs=1e-6)
            assert yaw == pytest.approx(info["orientation_error"], abs=1e-5)
            if reward == "sparse":
                expected = 0.0 if success else -1.0
            else:  # the env's reward without its action term
                expected = info["reward_position"] + info["reward_orientation"] + info["reward_success"]
            assert rewards[i] == pytest.approx(expected, abs=1e-4)
            # compute_reward, as HER calls it, on the env's own goals gives the step's reward.
            again = venv.env_method("compute_reward", last["achieved_goal"][None],
                                    last["desired_goal"][None], [info], indices=[0])[0]
            assert again[0] == rewards[i]
    assert seen[True] > 10 and seen[False] > 10  # both sides of the rule were checked
    assert ended > N_ENVS  # successes and the 75-step limit: terminal observations were checked


def test_goal_view_splits_the_observation_without_the_goal_in_it() -> None:
    venv = _goal_env("sparse")
    venv.seed(1)
    obs = venv.reset()
    assert set(obs) == {"observation", "achieved_goal", "desired_goal"}
    assert obs["observation"].shape == (N_ENVS, 11)
    # Moving the goal changes desired_goal only: the observation HER keeps names no goal.
    before = {k: v.copy() for k, v in obs.items()}
    env = venv.venv.venv.envs[0]
    env.goal = env.goal + np.array([0.01, 0.0, 0.1])
    obs, *_ = venv.step(np.zeros((N_ENVS, 2), np.float32))
    assert np.allclose(obs["observation"][0], before["observation"][0], atol=1e-6)
    assert np.allclose(obs["desired_goal"][0, :2], before["desired_goal"][0, :2] + [0.01, 0.0], atol=1e-6)


def test_heading_error_wraps_around() -> None:
    at = lambda yaw: np.array([0.0, 0.0, np.cos(yaw), np.sin(yaw)])  # noqa: E731
    _, yaw = goal_errors(at(3.1), at(-3.1))
    assert yaw == pytest.approx(2 * np.pi - 6.2)
    reward = GoalReward("sparse", 0.01, 0.2)
    assert reward(at(3.1), at(-3.1)) == 0.0 and reward(at(0.0), at(0.25)) == -1.0
    obs = goal_observation(np.arange(19, dtype=np.float32))
    assert obs["achieved_goal"].tolist() == [0, 1, 2, 3] and obs["desired_goal"].tolist() == [6, 7, 8, 9]
