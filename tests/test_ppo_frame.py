"""The object-frame view of the push task (observation and action), against the env itself."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents.ppo_features import ObservationTransform, TransformedObservations
from fignet_gym.agents.ppo_frame import N_OBJECT_FRAME, object_frame_observation, object_to_world
from fignet_gym.envs.sb3 import make_sb3_vec_env
from fignet_gym.envs.tasks import wrap_angle

PUSH = "fignet_gym/Push-v1"


def _to_object(yaw: float, v: np.ndarray) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, s], [-s, c]]) @ v


def test_observation_equals_the_task_on_the_state() -> None:
    """Every value from the observation alone equals the env's own state and task (its goal, its
    pushing point), rotated into the object's frame by hand."""
    env = gym.make(PUSH)
    u = env.unwrapped
    rng = np.random.default_rng(0)
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        for _ in range(int(rng.integers(5, 25))):
            obs, *_ = env.step(rng.uniform(-1, 1, 2))
        f = object_frame_observation(obs[None], u.task.outline, u.task.tip_radius)[0]
        assert f.shape == (N_OBJECT_FRAME,)
        q = u.data.qpos[u._qadr : u._qadr + 7]
        obj, yaw = q[:2], 2 * np.arctan2(q[6], q[3])
        tip = u.data.mocap_pos[u._tip_mocap, :2]
        pp = u.task.pushing_point(u.get_state(), u.goal)
        np.testing.assert_allclose(f[0:2], _to_object(yaw, u.goal[:2] - obj), atol=1e-5)
        np.testing.assert_allclose(f[4:6], _to_object(yaw, tip - obj), atol=1e-5)
        np.testing.assert_allclose(f[6:8], _to_object(yaw, u.data.qvel[u._dadr : u._dadr + 2]), atol=1e-5)
        assert f[9] == pytest.approx(float(wrap_angle(u.goal[2] - yaw)), abs=1e-5)
        np.testing.assert_allclose(f[10:12], _to_object(yaw, pp - tip), atol=1e-5)
        np.testing.assert_allclose(f[12:14], _to_object(yaw, u.goal[:2] - tip), atol=1e-5)


def test_observation_is_invariant_to_moving_the_whole_scene() -> None:
    """A rigid motion of object, tip and goal together (world observation rebuilt by hand) leaves
    every object-frame value unchanged, while the world observation changes."""
    env = gym.make(PUSH)
    u = env.unwrapped
    obs, _ = env.reset(seed=7)
    for _ in range(15):
        obs, *_ = env.step(np.array([0.4, -0.3]))
    a, shift = 1.1, np.array([0.03, -0.02])
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    moved = obs.astype(np.float64).copy()
    for sl in (slice(0, 2), slice(4, 6), slice(6, 8)):  # object, tip, goal positions
        moved[sl] = rot @ obs[sl] + shift
    for sl in (slice(2, 4), slice(8, 10), slice(16, 18)):  # headings and the velocity
        moved[sl] = rot @ obs[sl]
    before = object_frame_observation(obs[None], u.task.outline, u.task.tip_radius)
    after = object_frame_observation(moved[None], u.task.outline, u.task.tip_radius)
    np.testing.assert_allclose(after, before, atol=1e-6)


def test_object_frame_action_moves_the_tip_along_the_objects_axis() -> None:
    """Action (0.5, 0) in the object frame moves the MuJoCo tip by 0.5 * max_speed * dt along the
    object's heading; (0, 0.5) along its left axis."""
    env = gym.make(PUSH)
    u = env.unwrapped
    obs, _ = env.reset(seed=3)
    yaw = float(np.arctan2(obs[3], obs[2]))
    for local, axis in (((0.5, 0.0), yaw), ((0.0, 0.5), yaw + np.pi / 2)):
        before = u.data.mocap_pos[u._tip_mocap, :2].copy()
        world = object_to_world(np.array([local]), obs[None])[0]
        env.step(world)
        moved = u.data.mocap_pos[u._tip_mocap, :2] - before
        step = 0.5 * u.max_speed * u.dt
        np.testing.assert_allclose(moved, step * np.array([np.cos(axis), np.sin(axis)]), atol=1e-9)
        obs = u.observe()
        yaw = float(np.arctan2(obs[3], obs[2]))


def test_rotated_actions_keep_their_direction_inside_the_box() -> None:
    obs = np.zeros((1, 19))
    obs[0, 2:4] = (np.cos(np.pi / 4), np.sin(np.pi / 4))
    world = object_to_world(np.array([[1.0, 0.0]]), obs)[0]
    np.testing.assert_allclose(world, [np.sqrt(0.5), np.sqrt(0.5)], atol=1e-6)  # inside: rotated only
    world = object_to_world(np.array([[1.0, 1.0]]), obs)[0]
    np.testing.assert_allclose(world, [0.0, 1.0], atol=1e-6)  # (0, sqrt 2): scaled, not clipped


def test_training_env_sends_the_rotated_actions() -> None:
    """The wrapper PPO trains through rotates the policy's actions with the observation they
    answer: the tips of a plain env stepped with ``object_to_world`` end at the same place."""
    vec = make_sb3_vec_env(PUSH, 2)
    plain = make_sb3_vec_env(PUSH, 2)
    transform = ObservationTransform.of_env("object-frame", vec.venv.envs[0])
    wrapped = TransformedObservations(vec, transform)
    assert wrapped.observation_space.shape == (N_OBJECT_FRAME,)
    wrapped.seed(1)
    plain.seed(1)
    wrapped.reset()
    raw = plain.reset()
    rng = np.random.default_rng(2)
    for _ in range(5):
        local = rng.uniform(-1, 1, (2, 2)).astype(np.float32)
        wrapped.step_async(local)
        wrapped.step_wait()
        plain.step_async(object_to_world(local, raw))
        raw, *_ = plain.step_wait()
        for a, b in zip(vec.venv.envs, plain.venv.envs):
            np.testing.assert_allclose(a.data.mocap_pos, b.data.mocap_pos, atol=1e-12)
