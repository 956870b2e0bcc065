"""Synthetic pushes of real objects (the fitted-model prior of ``sim2real --pretrain``): checked
against the scene's own geometry, the limit surface replaying itself, and MuJoCo's push sign."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from fignet_gym.data.format import load_trajectories
from fignet_gym.data.mit import import_mit
from fignet_gym.dynamics.limit_surface import closest_on_hull, planar_geometry
from fignet_gym.pretrained import pretrained_dir
from fignet_gym.train.analytic import ContactParams, Replay
from fignet_gym.train.synthetic_push import (
    GIVEN,
    PushDistribution,
    PushSource,
    outline_motion,
    synthetic_pushes,
)

SAMPLE = Path(__file__).parent / "data" / "mit_sample"
OBJ, TIP = 1, 2  # (world, object, tip), as import-mit writes the scenes


@pytest.fixture(scope="module")
def real(tmp_path_factory) -> list:
    from fignet_gym.data.mit import MitProtocol

    out = tmp_path_factory.mktemp("mit") / "abs.h5"
    import_mit([SAMPLE], out, protocol=MitProtocol(dt=0.02))
    return load_trajectories(out)


def _yaw(q: np.ndarray) -> float:
    return 2.0 * math.atan2(float(q[3]), float(q[0]))


def _rot(a: float) -> np.ndarray:
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


def test_the_tip_touches_the_outline_at_frame_0_and_moves_at_a_rig_speed(real) -> None:
    """Frame 0 of each first window has the tip surface ``gap`` from the object's outline (its
    distance by brute force over the hull's edges), the tip then moves in a straight line at one
    of the sources' speeds, within ``max_angle`` of the inward normal."""
    dist = PushDistribution(max_angle=0.5)
    out = synthetic_pushes(real, PushSource.limit_surface(0.3, 1.0), 12, seed=3, dist=dist,
                           progress=False)
    speeds = {float(t.metadata["vel_mm_s"]) for t in real}
    firsts = [t for t in out if t.metadata["window"] == 0]
    assert len(firsts) >= 6
    for t in firsts:
        geo = planar_geometry(Replay(t).base)
        pose = t.poses[0, OBJ].astype(float)
        rot = _rot(_yaw(pose[3:]))
        com = pose[:2] + rot @ geo.com[:2]
        local = rot.T @ (t.poses[0, TIP, :2].astype(float) - com)
        hull = geo.hull
        seg = np.roll(hull, -1, axis=0) - hull
        s = np.clip(((local - hull) * seg).sum(1) / (seg * seg).sum(1), 0, 1)
        brute = np.linalg.norm(hull + s[:, None] * seg - local, axis=1).min()
        assert brute == pytest.approx(geo.tip_radius + dist.gap, abs=2e-6)  # float32 poses
        assert closest_on_hull(hull, local)[0] == pytest.approx(brute, abs=1e-9)
        step = np.diff(t.poses[:, TIP, :2].astype(float), axis=0)
        speed = np.linalg.norm(step, axis=1) / t.dt * 1000
        np.testing.assert_allclose(speed, t.metadata["vel_mm_s"], rtol=1e-3)
        assert t.metadata["vel_mm_s"] in speeds
        # The push direction against the inward normal at the touch (the closest hull point).
        _, near, out_n = closest_on_hull(hull, local)
        d = rot.T @ step[0] / np.linalg.norm(step[0])
        assert abs(math.acos(np.clip(d @ -out_n, -1, 1))) <= dist.max_angle + 1e-3


def test_the_limit_surface_replays_its_own_windows(real) -> None:
    """The quasi-static model has no momentum: replaying a synthetic window from its given poses
    in the model that made it gives that window back (float32 storage), in each window of a long
    push, and the windows of one push share their ``file``."""
    src = PushSource.limit_surface(0.3, 1.0)
    out = synthetic_pushes(real, src, 6, seed=1, progress=False)
    assert any(t.metadata["window"] == 1 for t in out)
    for t in out:
        again = Replay(t).rollout(src.params, src.dynamics, given=GIVEN)
        np.testing.assert_allclose(again[:, OBJ, :2], t.poses[:, OBJ, :2], atol=2e-5)
        assert t.metadata["file"] == t.name.split("#")[0]
        assert outline_motion(t, planar_geometry(Replay(t).base), OBJ) >= 1e-3


def test_a_straight_mujoco_push_moves_the_object_along_the_push(real) -> None:
    """In the shipped fitted MuJoCo, a push along the inward normal (angle 0) moves the object's
    centre forward along the tip's direction; the same seed gives the same pushes."""
    params = ContactParams.from_json(json.loads((pretrained_dir() / "push-real.mujoco.json")
                                                .read_text()))
    dist = PushDistribution(max_angle=0.0, duration=0.5)
    a = synthetic_pushes(real, PushSource.mujoco(params), 4, seed=5, dist=dist, progress=False)
    b = synthetic_pushes(real, PushSource.mujoco(params), 4, seed=5, dist=dist, progress=False)
    assert len(a) >= 3 and [t.name for t in a] == [t.name for t in b]
    for t, u in zip(a, b, strict=True):
        np.testing.assert_array_equal(t.poses, u.poses)
        d = t.poses[-1, TIP, :2] - t.poses[0, TIP, :2]
        move = t.poses[-1, OBJ, :2] - t.poses[0, OBJ, :2]
        assert move @ d / np.linalg.norm(d) > 0.5 * np.linalg.norm(move)
        # The object follows the tip, never overtakes it by more than the tip's own travel.
        assert np.linalg.norm(move) <= np.linalg.norm(d) + 1e-4


def test_refuses_a_source_without_a_pusher(real) -> None:
    from dataclasses import replace

    still = replace(real[0], kinds=np.array([1, 0, 1]))
    with pytest.raises(ValueError, match="no kinematic pusher"):
        synthetic_pushes([still], PushSource.limit_surface(0.3, 1.0), 1, progress=False)
