"""RealPush-v0: Push-v1's task on the MuJoCo fitted to the real pushes (and push-real)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.envs.real_push import STEP_SECONDS, RealPushEnv, load_fitted_params
from fignet_gym.registration import PUSH_V1_KWARGS

ENV_ID = "fignet_gym/RealPush-v0"


def test_check_env_and_seeded_episodes() -> None:
    env = gym.make(ENV_ID)
    gym_check_env(env.unwrapped, skip_render_check=True)
    runs = []
    for seed in (3, 3, 4):
        obs0, _ = env.reset(seed=seed)
        obs1, reward, *_ , info = env.step(np.array([0.5, -0.2]))
        assert reward == pytest.approx(sum(v for k, v in info.items() if k.startswith("reward_")))
        runs.append(np.concatenate([obs0, obs1]))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], runs[2])
    env.close()


def test_mujoco_backend_carries_the_fitted_parameters() -> None:
    """The model the env steps has the fit's frictions, solref and timestep; a step is 0.02 s;
    the task is Push-v1's."""
    import mujoco

    fit = load_fitted_params()
    env = RealPushEnv()
    m = env.model
    tip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "tip")
    obj = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "object")
    assert m.geom_friction[obj, 0] == pytest.approx(fit.friction)
    assert m.geom_friction[tip, 0] == pytest.approx(fit.friction_kinematic)
    assert m.geom_solref[obj, 0] == pytest.approx(fit.timeconst)
    assert env.nstep == fit.substeps and env.step_time == pytest.approx(STEP_SECONDS)
    assert env.task.success_yaw == pytest.approx(PUSH_V1_KWARGS["success_yaw"])


def test_refuses_unknown_shapes_and_parameters_the_fit_sets() -> None:
    with pytest.raises(ValueError, match="shape"):
        RealPushEnv(shape="tri3")
    with pytest.raises(ValueError, match="friction"):
        RealPushEnv(friction=0.3)
