"""ScenePushEnv: the Push env's task on a user's own MJCF file (issue 41, item 3)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from fignet_gym.envs.scene_push import ScenePushEnv, object_outline
from fignet_gym.envs.tasks import PushTask

BOX = """<mujoco>
  <option timestep="0.002" {cone}/>
  <worldbody>
    <geom name="ground" type="plane" size="1 1 0.1" friction="0.3"/>
    <body name="crate" pos="0.2 0.1 0.03">
      <freejoint/>
      <geom type="box" size="0.05 0.03 0.03" mass="0.5" friction="0.3"/>
    </body>
    <body name="finger" mocap="true" pos="-0.2 0 0.03">
      <geom type="cylinder" size="0.006 0.03" contype="1" conaffinity="1"/>
    </body>
    {extra}
  </worldbody>
</mujoco>
"""


def _scene(tmp_path: Path, cone: str = 'cone="elliptic"', extra: str = "") -> Path:
    path = tmp_path / "my_scene.xml"
    path.write_text(BOX.format(cone=cone, extra=extra))
    return path


def test_a_users_box_is_pushed_to_its_goal_by_the_push_task(tmp_path: Path) -> None:
    env = ScenePushEnv(_scene(tmp_path), object="crate", pusher="finger", tip_start="behind",
                       goal_distance_min=0.02, goal_distance=0.05)
    assert isinstance(env.task, PushTask) and env.task.tip_radius == pytest.approx(0.006)
    obs, _ = env.reset(seed=0)
    start = env.data.qpos[env._qadr:env._qadr + 3].copy()
    assert start[2] == pytest.approx(0.03)  # the MJCF's resting height, at the origin
    # Push from behind the object straight at the goal: the object must move towards it.
    goal = env.goal[:2]
    for _ in range(25):
        direction = goal - env.data.qpos[env._qadr:env._qadr + 2]
        obs, reward, terminated, truncated, info = env.step(direction / np.abs(direction).max())
        if terminated or truncated:
            break
    moved = env.data.qpos[env._qadr:env._qadr + 2] - start[:2]
    assert np.linalg.norm(moved) > 0.01
    assert np.linalg.norm(goal - env.data.qpos[env._qadr:env._qadr + 2]) < np.linalg.norm(goal)
    # The reward is the task's formula on the env's own state (the env's step calls the task).
    err = info["position_error"]
    assert reward <= -env.task.position_weight * err + 1e-9


def test_the_outline_of_a_box_is_its_four_corners(tmp_path: Path) -> None:
    env = ScenePushEnv(_scene(tmp_path), object="crate", pusher="finger")
    outline = object_outline(env.model, "crate")
    assert sorted(map(tuple, np.round(outline, 6))) == sorted(
        [(-0.05, -0.03), (-0.05, 0.03), (0.05, -0.03), (0.05, 0.03)])
    x, y = outline[:, 0], outline[:, 1]
    assert (x * np.roll(y, -1) - np.roll(x, -1) * y).sum() / 2 == pytest.approx(0.1 * 0.06)  # CCW


def test_planning_and_learned_dynamics_run_on_the_users_scene(tmp_path: Path) -> None:
    from fignet_gym.agents import make_planner
    from fignet_gym.dynamics import MujocoDynamics

    env = ScenePushEnv(_scene(tmp_path), object="crate", pusher="finger", tip_start="behind")
    env.reset(seed=1)
    planner = make_planner("cem", MujocoDynamics(), "push", env=env, horizon=3, population=8,
                           iterations=1)
    action, _ = planner.predict(env._observe(), deterministic=True)
    assert action.shape == (2,) and np.all(np.abs(action) <= 1.0)
    # A learned model trained on push scenes steps it too (here the shipped one: the env has no
    # default model of its own).
    learned = ScenePushEnv(_scene(tmp_path), object="crate", pusher="finger", dynamics="fignet",
                           checkpoint="push", tip_start="behind")
    learned.reset(seed=1)
    obs, *_ = learned.step(np.array([1.0, 0.0]))
    assert np.isfinite(obs).all()


@pytest.mark.parametrize(("kwargs", "extra", "message"), [
    ({"object": "finger"}, "", "not a free body"),
    ({"pusher": "crate"}, "", "pusher 'crate' is not a mocap body; mocap bodies: finger"),
    ({"friction": 0.5}, "", "friction come from the MJCF file"),
    ({"dynamics": "fignet"}, "", "needs checkpoint="),
    ({"camera": "side"}, "", "no camera 'side'"),
    ({}, '<body name="door"><joint type="hinge"/><geom type="box" size="0.01 0.01 0.01"/></body>',
     "door"),
])
def test_scenes_and_arguments_it_cannot_use_are_one_line_errors(tmp_path: Path, kwargs, extra,
                                                                message) -> None:
    args = {"object": "crate", "pusher": "finger", **kwargs}
    with pytest.raises(ValueError, match=message) as err:
        ScenePushEnv(_scene(tmp_path, extra=extra), **args)
    assert "\n" not in str(err.value)


def test_a_pyramidal_cone_is_kept_with_one_warning(tmp_path: Path) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = ScenePushEnv(_scene(tmp_path, cone=""), object="crate", pusher="finger")
    texts = [str(w.message) for w in caught if "pyramidal" in str(w.message)]
    assert len(texts) == 1 and 'cone="elliptic"' in texts[0]
    import mujoco

    assert env.model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL


def test_the_registered_id_makes_single_and_batched_envs_that_agree(tmp_path: Path) -> None:
    import gymnasium as gym

    import fignet_gym.envs  # noqa: F401  (registers the ids)

    kwargs = {"mjcf": str(_scene(tmp_path)), "object": "crate", "pusher": "finger"}
    single = gym.make("fignet_gym/ScenePush-v0", **kwargs)
    assert single.spec.max_episode_steps == 75 and single.unwrapped.tip_start == "behind"
    vec = gym.make_vec("fignet_gym/ScenePush-v0", num_envs=2, vectorization_mode="vector_entry_point",
                       **kwargs)
    obs_v, _ = vec.reset(seed=[3, 4])
    obs_s, _ = single.reset(seed=3)
    np.testing.assert_array_equal(obs_v[0], obs_s)
    action = np.array([0.5, -0.2], np.float32)
    step_v = vec.step(np.stack([action, action]))
    step_s = single.step(action)
    np.testing.assert_array_equal(step_v[0][0], step_s[0])
    assert step_v[1][0] == step_s[1]


@pytest.mark.parametrize(("geom", "width", "depth"), [
    ('type="cylinder" size="0.02 0.03"', 0.04, 0.04),  # upright: a disc
    ('type="capsule" fromto="-0.04 0 0 0.04 0 0" size="0.01"', 0.10, 0.02),  # lying along x
    ('type="ellipsoid" size="0.03 0.02 0.01"', 0.06, 0.04),
])
def test_outlines_of_round_primitives_span_their_extent(tmp_path: Path, geom: str, width: float,
                                                        depth: float) -> None:
    text = BOX.format(cone='cone="elliptic"', extra="").replace(
        'type="box" size="0.05 0.03 0.03" mass="0.5"', f'{geom} mass="0.5"')
    path = tmp_path / "round.xml"
    path.write_text(text)
    env = ScenePushEnv(path, object="crate", pusher="finger")
    outline = object_outline(env.model, "crate")
    extent = outline.max(axis=0) - outline.min(axis=0)
    np.testing.assert_allclose(extent, (width, depth), rtol=1e-6)


def test_plan_runs_on_a_users_scene_through_env_kwargs(tmp_path: Path, capsys) -> None:
    import json

    from fignet_gym.cli import main

    kwargs = json.dumps({"mjcf": str(_scene(tmp_path)), "object": "crate", "pusher": "finger"})
    out = tmp_path / "plan"
    argv = ["plan", "--env", "fignet_gym/ScenePush-v0", "--env-kwargs", kwargs, "--episodes", "1",
            "--horizon", "2", "--population", "4", "--iterations", "1", "--out", str(out)]
    assert main(argv) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["episodes"] == 1 and summary["env_kwargs"]["object"] == "crate"
    # The env's own refusal, and an argument plan sets itself, are one error line each.
    capsys.readouterr()
    bad = json.dumps({"mjcf": str(_scene(tmp_path)), "object": "crate", "pusher": "crate"})
    assert main([*argv[:4], bad, "--out", str(tmp_path / "p2")]) == 2
    assert "pusher 'crate' is not a mocap body" in capsys.readouterr().err
    assert main([*argv[:4], '{"dynamics": "fignet"}', "--out", str(tmp_path / "p3")]) == 2
    err = capsys.readouterr().err
    assert "dynamics cannot be set" in err and len(err.strip().splitlines()) == 1
