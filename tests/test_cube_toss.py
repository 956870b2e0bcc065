"""CubeToss-v0: API checks, seeded reproducibility, action mapping, heading, MuJoCo vs FIGNet."""

from __future__ import annotations

import math

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from sim_factories import quiet_simulator, wild_simulator

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.envs.cube_toss import (
    DATA_DT,
    CubeTossEnv,
    cube_toss_xml,
    mujoco_parameters,
    resting_yaw,
)
from fignet_gym.simulator.scene import Scene

ENV_ID = "fignet_gym/CubeToss-v0"


def _quick_sim(factory=quiet_simulator):  # noqa: ANN001, ANN202
    return factory("cube-real", dt=DATA_DT)


@pytest.mark.parametrize("dynamics", ["mujoco", "fignet"])
def test_check_env_and_seeded_episodes(dynamics: str) -> None:
    kw = {"dynamics": "mujoco"} if dynamics == "mujoco" else {
        "dynamics": "fignet", "checkpoint": _quick_sim(), "settle_steps": 3}
    env = gym.make(ENV_ID, render_mode="rgb_array", width=64, height=64, **kw)
    gym_check_env(env.unwrapped, skip_render_check=False)
    runs = []
    for seed in (5, 5, 6):
        obs0, _ = env.reset(seed=seed)
        obs1, reward, terminated, truncated, info = env.step(np.array([0.3, -0.2, 0.1, 0.5, -0.5, 0.2]))
        assert terminated and not truncated
        # one key per meaning: SB3's is_success (the former duplicate "success" is gone)
        assert isinstance(info["is_success"], bool) and "success" not in info
        assert reward == pytest.approx(sum(v for k, v in info.items() if k.startswith("reward_")))
        runs.append(np.concatenate([obs0, obs1]))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], runs[2])
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(6))
    env.close()


def test_action_sets_release_velocity_and_world_spin() -> None:
    env = CubeTossEnv(settle_steps=1)
    env.reset(seed=1)
    action = np.array([0.5, 1.0, -1.0, 1.0, -0.5, 0.0])  # heading pi/2, fastest, lowest vz
    env._apply_action(action)
    # Heading pi/2 is +y; world angular velocity (4, -2, 0) whatever the cube's orientation.
    vel = np.zeros(6)
    mujoco.mj_forward(env.model, env.data)
    mujoco.mj_objectVelocity(env.model, env.data, mujoco.mjtObj.mjOBJ_BODY, 1, vel, 0)
    np.testing.assert_allclose(vel[3:], [0.0, 1.27, -0.4], atol=1e-9)
    np.testing.assert_allclose(vel[:3], [4.0, -2.0, 0.0], atol=1e-9)


def test_resting_heading_has_the_cubes_quarter_turn_symmetry() -> None:
    def q_axis(axis: np.ndarray, angle: float) -> np.ndarray:
        return np.array([math.cos(angle / 2), *(np.sin(angle / 2) * np.asarray(axis, float))])

    def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        out = np.empty(4)
        mujoco.mju_mulQuat(out, a, b)
        return out

    z, x = np.array([0, 0, 1.0]), np.array([1.0, 0, 0])
    assert resting_yaw(q_axis(z, 0.3)) == pytest.approx(0.3)
    assert resting_yaw(q_axis(z, 0.3 + math.pi / 2)) == pytest.approx(0.3)
    assert resting_yaw(q_axis(z, -1.0)) == pytest.approx(-1.0 + math.pi / 2)
    # Tipped onto another face (a quarter turn about a body axis), the heading is unchanged.
    for body_axis in (x, np.array([0, 1.0, 0])):
        tipped = mul(q_axis(z, 0.3), q_axis(body_axis, math.pi / 2))
        assert resting_yaw(tipped) == pytest.approx(0.3)


def test_learned_model_gets_the_training_scene_and_mujoco_the_fit(tmp_path) -> None:  # noqa: ANN001
    fit = tmp_path / "fit.json"
    fit.write_text('{"friction": 0.3, "dampratio": 0.5, "cone": "elliptic", "source": "test fit"}')
    mj = CubeTossEnv(dynamics="mujoco", mujoco_params=str(fit))
    learned = CubeTossEnv(dynamics="fignet", checkpoint=_quick_sim(), mujoco_params=str(fit))
    assert mj.model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert mj.model.geom_friction[1, 0] == pytest.approx(0.3)
    # The learned model's inputs include friction and restitution: they must be the data's.
    nominal = Scene.from_mjmodel(mujoco.MjModel.from_xml_string(cube_toss_xml(mujoco_parameters("nominal"))))
    np.testing.assert_allclose(Scene.from_mjmodel(learned.model).object_props, nominal.object_props)
    assert learned.model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
    with pytest.raises(ValueError, match="unknown contact parameters"):
        mujoco_parameters({"frcition": 0.2})


def test_divergence_truncates() -> None:
    env = gym.make(ENV_ID, dynamics="fignet", checkpoint=_quick_sim(wild_simulator), settle_steps=3)
    env.reset(seed=0)
    _, reward, terminated, truncated, info = env.step(np.zeros(6))
    assert truncated and "diverged" in info and np.isfinite(reward)


def test_vector_env_equals_single_envs() -> None:
    venv = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point")
    singles = [gym.make(ENV_ID) for _ in range(2)]
    obs, _ = venv.reset(seed=3)
    np.testing.assert_array_equal(obs, np.stack([e.reset(seed=3 + i)[0] for i, e in enumerate(singles)]))
    acts = np.random.default_rng(0).uniform(-1, 1, (2, 6))
    obs, rew, *_ = venv.step(acts)
    for i, e in enumerate(singles):
        o, r, *_ = e.step(acts[i])
        np.testing.assert_array_equal(obs[i], o)
        assert rew[i] == pytest.approx(r)


def test_learned_models_scene_is_the_imported_datas() -> None:
    # The learned model's inputs (node layout, mass, friction, restitution) must be those of the
    # data it was trained on: import-contactnets on the shipped 4-toss sample.
    from pathlib import Path

    from fignet_gym.data.format import build_scene
    from fignet_gym.data.tracked import read_contactnets

    sample = Path(__file__).parent / "data" / "contactnets_sample"
    traj = next(iter(read_contactnets(sample)))
    assert traj.dt == pytest.approx(DATA_DT)
    imported = build_scene(traj)
    env = CubeTossEnv(dynamics="fignet", checkpoint=_quick_sim())
    ours = Scene.from_mjmodel(env.model)
    assert ours.object_names == imported.object_names
    np.testing.assert_array_equal(ours.object_kind, imported.object_kind)
    np.testing.assert_allclose(ours.object_props, imported.object_props, rtol=1e-6)
    np.testing.assert_allclose(ours.ref_vertices, imported.ref_vertices, atol=1e-6)
    np.testing.assert_allclose(ours.node_positions(ours.static_poses),
                               imported.node_positions(imported.static_poses), atol=1e-6)


def test_a_long_toss_accepts_a_checkpoint_dt_stored_to_nine_digits() -> None:
    # 148 learned steps of a dt rounded to 1e-9 s miss 1 s by ~5e-6 steps: still whole steps.
    sim = quiet_simulator("cube-real", dt=round(DATA_DT, 9))
    env = CubeTossEnv(dynamics="fignet", checkpoint=sim)
    assert env.dynamics.learned_steps(env.model, env.frame_skip) == 148


def test_fitted_mujoco_and_cube_real_land_the_cube_close_together() -> None:
    # Two independent fits of the same real tosses (CMA-ES on MuJoCo's contact parameters, the
    # learned simulator): seeded random tosses of ~0.4 m should come to rest within a few cm of
    # each other (figures: experiments/README.md, "Issue 14: FIGNet on real tosses").
    n = 16
    landed = {}
    for dyn in ("mujoco", "fignet"):
        venv = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", dynamics=dyn)
        assert "NOMINAL" not in venv.unwrapped.envs[0].mujoco_params.source or dyn == "fignet"
        venv.reset(seed=0)
        obs, *_ = venv.step(np.random.default_rng(1).uniform(-1, 1, (n, 6)))
        landed[dyn] = obs[:, 1:3]
        venv.close()
    travel = np.linalg.norm(landed["mujoco"], axis=1)
    gap = np.linalg.norm(landed["mujoco"] - landed["fignet"], axis=1)
    assert np.median(travel) > 0.25  # the tosses do go somewhere
    assert np.median(gap) < 0.06 and gap.max() < 0.15, gap


def test_cube_task_matches_mujoco_rotations() -> None:
    """The batched task's heading and release agree with MuJoCo's own rotation matrices."""
    from fignet_gym.envs.tasks import resting_yaw, wrap_quarter

    env = gym.make(ENV_ID).unwrapped
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    quats = rng.normal(size=(64, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    for q, yaw in zip(quats, resting_yaw(quats), strict=True):
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, q)
        axes = rot.reshape(3, 3).T
        side = axes[(int(np.argmax(np.abs(axes[:, 2]))) + 1) % 3]
        assert yaw == pytest.approx(float(wrap_quarter(np.arctan2(side[1], side[0]))), abs=1e-12)
    actions = rng.uniform(-1, 1, (8, 6))
    states = np.repeat(env.get_state()[None], 8, 0)
    states[:, 4:8] = quats[:8]
    released = env.task.release(states, actions)
    for s, a, r in zip(states, actions, released, strict=True):
        lin, ang = env.task.release_velocity(a)
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, s[4:8])
        qv = r[1 + env.model.nq : 1 + env.model.nq + 6]
        np.testing.assert_allclose(qv, np.concatenate([lin, rot.reshape(3, 3).T @ ang]), atol=1e-12)
