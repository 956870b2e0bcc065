"""PushT-v0: the T scene, coverage against a scalar clipping oracle and a hand case, success and
the fixed goal."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.envs.pusht import PushTEnv
from fignet_gym.mjcf.pusht import PUSHT_DENSITY, pusht_outline, pusht_rectangles, pusht_scene_xml

PUSHT_V0 = dict(gym.spec("fignet_gym/PushT-v0").kwargs)


def _clip(subject: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: the convex polygon ``subject`` clipped by the convex CCW ``clip``."""
    out = list(subject)
    for a, b in zip(clip, np.roll(clip, -1, axis=0), strict=True):
        def side(p: np.ndarray, a: np.ndarray = a, b: np.ndarray = b) -> float:
            return (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
        src, out = out, []
        for p, q in zip(src, src[1:] + src[:1], strict=True):
            sp, sq = side(p), side(q)
            if sp >= 0:
                out.append(p)
            if sp * sq < 0:
                out.append(p + (q - p) * sp / (sp - sq))
        if not out:
            return np.zeros((0, 2))
    return np.array(out)


def _area(poly: np.ndarray) -> float:
    if len(poly) < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _placed(rect: np.ndarray, pose: np.ndarray) -> np.ndarray:
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return rect @ np.array([[c, s], [-s, c]]) + pose[:2]


def exact_coverage(pose: np.ndarray, goal: np.ndarray) -> float:
    """The T at ``pose`` over the T at ``goal``: the exact area of their intersection (the two
    pieces are disjoint, so pairwise convex intersections add up) over the T's area."""
    rects = pusht_rectangles()
    total = sum(_area(r) for r in rects)
    inter = sum(_area(_clip(_placed(a, pose), _placed(b, goal))) for a in rects for b in rects)
    return inter / total


def _state_at(env: PushTEnv, pose: np.ndarray) -> np.ndarray:
    """The env's state with the T moved to ``pose`` (x, y, yaw) at its resting height."""
    state = env.get_state().copy()
    i = env.task.layout.qpos + env.task.qadr
    state[i:i + 3] = (pose[0], pose[1], env.task.rest_z)
    state[i + 3:i + 7] = (np.cos(pose[2] / 2), 0.0, 0.0, np.sin(pose[2] / 2))
    return state


@pytest.fixture(scope="module")
def env() -> PushTEnv:
    e = PushTEnv(**PUSHT_V0)
    e.reset(seed=0)
    return e


def test_the_t_has_push_t_proportions_and_its_frame_at_its_centroid() -> None:
    rects = pusht_rectangles()
    span = np.ptp(np.concatenate(rects), axis=0)
    np.testing.assert_allclose(span, [0.1, 0.1])  # 4 x 4 units of 2.5 cm
    areas = [_area(r) for r in rects]
    np.testing.assert_allclose(areas, [4 * 0.025**2, 3 * 0.025**2])
    centroid = sum(a * r.mean(0) for a, r in zip(areas, rects, strict=True)) / sum(areas)
    np.testing.assert_allclose(centroid, [0.0, 0.0], atol=1e-12)
    assert _area(pusht_outline()) == pytest.approx(sum(areas))  # the outline is the union, CCW


def test_the_mass_and_inertia_written_are_mujocos_own_of_the_two_meshes() -> None:
    xml = pusht_scene_xml()
    written = mujoco.MjModel.from_xml_string(xml)
    # MuJoCo computes the body's inertia itself from the meshes when no <inertial> is given.
    start = xml.index("<inertial")
    own = mujoco.MjModel.from_xml_string(
        xml[:start] + xml[xml.index("/>", start) + 2:]
        .replace('rgba=".75 .35 .2 1"/>', f'density="{PUSHT_DENSITY}" rgba=".75 .35 .2 1"/>'))
    b = written.body("object").id
    assert written.body_mass[b] == pytest.approx(own.body_mass[b], rel=1e-6)
    np.testing.assert_allclose(np.sort(written.body_inertia[b]), np.sort(own.body_inertia[b]),
                               rtol=1e-6)
    np.testing.assert_allclose(own.body_ipos[b], 0.0, atol=1e-6)  # the frame is the centroid


def test_coverage_matches_the_exact_polygon_intersection(env: PushTEnv) -> None:
    rng = np.random.default_rng(3)
    poses = np.column_stack([rng.uniform(-0.03, 0.03, (40, 2)), rng.uniform(-np.pi, np.pi, 40)])
    goals = poses + np.column_stack([rng.normal(0, 0.01, (40, 2)), rng.normal(0, 0.3, 40)])
    states = np.stack([_state_at(env, p) for p in poses])
    batched = env.task.coverage(states, goals)
    exact = np.array([exact_coverage(p, g) for p, g in zip(poses, goals, strict=True)])
    assert exact.min() < 0.4 < 0.9 < exact.max()  # the cases span the range
    np.testing.assert_allclose(batched, exact, atol=1e-9)
    np.testing.assert_allclose(env.task.coverage(states, poses), 1.0)


def test_a_shift_along_the_bar_uncovers_a_strip_of_both_pieces(env: PushTEnv) -> None:
    # Hand case: 5 mm along the body x uncovers a 5 mm strip of the bar (2.5 cm tall) and of the
    # stem (7.5 cm): 5e-4 m^2 of the T's 43.75e-4 m^2.
    yaw = 0.7
    pose = np.array([0.01, -0.02, yaw])
    goal = pose + np.array([0.005 * np.cos(yaw), 0.005 * np.sin(yaw), 0.0])
    cov = env.task.coverage(_state_at(env, pose), goal)
    assert cov == pytest.approx(1 - 5e-4 / 43.75e-4, abs=1e-9)


def test_coverage_is_unchanged_when_pose_and_goal_turn_and_shift_together(env: PushTEnv) -> None:
    pose, goal = np.array([0.01, 0.0, 0.3]), np.array([0.0, 0.012, 0.55])
    turn, shift = 1.1, np.array([0.04, -0.02])
    c, s = np.cos(turn), np.sin(turn)
    rot = np.array([[c, -s], [s, c]])

    def moved(p: np.ndarray) -> np.ndarray:
        return np.array([*(rot @ p[:2] + shift), p[2] + turn])

    a = env.task.coverage(_state_at(env, pose), goal)
    b = env.task.coverage(_state_at(env, moved(pose)), moved(goal))
    assert 0.3 < a < 0.95
    assert b == pytest.approx(a, abs=1e-9)


def test_success_terminates_at_the_coverage_threshold_and_info_reports_it() -> None:
    env = PushTEnv(**PUSHT_V0)
    env.reset(seed=4)
    env.set_state(_state_at(env, env.goal))
    _, reward, terminated, _, info = env.step(np.zeros(2))
    assert terminated and info["is_success"] and info["coverage"] > 0.99
    assert reward == pytest.approx(sum(v for k, v in info.items() if k.startswith("reward_")))
    env.reset(seed=4)
    env.set_state(_state_at(env, env.goal + np.array([0.0, 0.0, 0.15])))  # about 0.83 covered
    _, _, terminated, _, info = env.step(np.zeros(2))
    assert not terminated and not info["is_success"]
    assert info["coverage"] == pytest.approx(exact_coverage(env.goal + (0, 0, 0.15), env.goal),
                                             abs=1e-6)
    # Pose tolerances alone would call it solved (0.15 rad < success_yaw): coverage decides.
    assert info["position_error"] < PUSHT_V0["success_position"]
    assert info["orientation_error"] < PUSHT_V0["success_yaw"]


def test_a_fixed_goal_is_the_drawn_start_moved_rigidly_onto_it() -> None:
    goal = np.array([0.05, -0.03, np.pi / 4])  # gym-pusht's goal heading
    drawn, fixed = PushTEnv(**PUSHT_V0), PushTEnv(goal_pose=goal, **PUSHT_V0)
    drawn.reset(seed=7)
    obs_fixed, _ = fixed.reset(seed=7)
    np.testing.assert_allclose(fixed.goal, goal)
    obs_drawn = drawn._observe()
    # Everything seen in the object's frame (goal and tip relative, rows 10:16) is unchanged.
    np.testing.assert_allclose(obs_fixed[10:16], obs_drawn[10:16], atol=1e-6)
    np.testing.assert_allclose(fixed.workspace_origin, fixed.get_state()[
        fixed.task.layout.qpos + fixed.task.qadr:][:2])
    with pytest.raises(ValueError, match="goal_pose must be three finite numbers"):
        PushTEnv(goal_pose=(0.0, 1.0), **PUSHT_V0)


def test_the_registered_env_runs_and_learned_dynamics_need_no_checkpoint_argument() -> None:
    env = gym.make("fignet_gym/PushT-v0")
    obs, _ = env.reset(seed=1)
    assert obs.shape == (19,)
    _, _, _, _, info = env.step(env.action_space.sample())
    assert 0.0 <= info["coverage"] <= 1.0
    assert env.spec.max_episode_steps == 100


def _generalisation() -> Any:
    spec = importlib.util.spec_from_file_location(
        "pusht_generalisation", Path(__file__).resolve().parents[1] / "scripts" / "pusht_generalisation.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_unseen_shapes_are_centred_prisms_of_their_pieces_area() -> None:
    g = _generalisation()
    for name, pieces in g.SHAPES.items():
        model = mujoco.MjModel.from_xml_string(g.shape_xml(name))
        b = model.body("object").id
        area = sum(_area(p) for p in pieces)
        assert model.body_mass[b] == pytest.approx(PUSHT_DENSITY * area * g.THICKNESS, rel=1e-5)
        np.testing.assert_allclose(model.body_ipos[b], 0.0, atol=1e-6)  # frame at the centroid


def test_the_generalisation_driver_writes_its_table_at_a_tiny_budget(tmp_path: Path) -> None:
    table = _generalisation().main(["--out", str(tmp_path), "--num", "2", "--test", "2",
                                    "--steps", "2", "--pusht", "push"])
    assert set(table) == {"L", "triangle", "big box", "pebble"}
    for row in table.values():
        assert len(row) == 3 and np.isfinite(np.array(list(row.values()))).all()
    assert (tmp_path / "table.md").read_text().count("\n") == 2 + len(table)
