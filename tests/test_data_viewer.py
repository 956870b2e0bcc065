"""Viewer: poses land in MuJoCo as given, frames and videos come out (headless, EGL)."""

from __future__ import annotations

from pathlib import Path

import imageio.v2 as imageio
import mujoco
import numpy as np
import pytest

from fignet_gym.cli import main
from fignet_gym.data import viewer
from fignet_gym.data.format import ObjectMeshes, Trajectory, write_trajectories
from fignet_gym.data.generate import PushConfig, _one
from fignet_gym.mjcf import push_scene_xml


@pytest.fixture(scope="module")
def gl_ok() -> None:
    model = mujoco.MjModel.from_xml_string(push_scene_xml())
    try:
        viewer.OffscreenRenderer(model, 32, 32).close()
    except Exception as err:  # no usable OpenGL backend on this machine
        pytest.skip(f"no offscreen OpenGL: {err}")


def _push_poses() -> tuple[str, np.ndarray]:
    traj = _one(("push", PushConfig(duration=0.1), 4, 0))
    return traj.mjcf, traj.poses


def test_set_poses_puts_bodies_where_asked() -> None:
    model = mujoco.MjModel.from_xml_string(push_scene_xml("tri1"))
    data = mujoco.MjData(model)
    bodies = [0, model.body("object").id, model.body("tip").id]
    pose = np.array([[0, 0, 0, 1, 0, 0, 0], [0.1, 0.2, 0.0065, 0.6, 0, 0, 0.8],
                     [-0.3, 0.05, 0.021, 1, 0, 0, 0]], float)
    viewer.set_poses(model, data, bodies, pose)
    np.testing.assert_allclose(data.xpos[bodies[1:]], pose[1:, :3], atol=1e-12)
    np.testing.assert_allclose(data.xquat[bodies[1:]], pose[1:, 3:], atol=1e-12)


def test_frames_show_the_motion(gl_ok: None) -> None:
    mjcf, poses = _push_poses()
    poses = poses[:2].copy()
    poses[1, 1, :2] += [0.03, 0.0]  # move the object visibly
    frames = viewer.render_frames(mjcf, poses, width=64, height=48)
    assert len(frames) == 2 and frames[0].shape == (48, 64, 3) and frames[0].dtype == np.uint8
    assert frames[0].std() > 5  # not a blank image
    assert np.abs(frames[0].astype(int) - frames[1]).sum() > 0
    both = viewer.side_by_side(frames, frames)
    assert both[0].shape == (48, 128, 3)
    with pytest.raises(ValueError, match="float\\[T, 3, 7\\]"):
        viewer.render_frames(mjcf, poses[:, :2])


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_videos_are_written(gl_ok: None, tmp_path: Path, suffix: str) -> None:
    mjcf, poses = _push_poses()
    out = viewer.render_trajectory(mjcf, poses[:4], tmp_path / f"v{suffix}", fps=10,
                                   width=64, height=64)
    frames = imageio.mimread(out)
    assert len(frames) == 4 and frames[0].shape[:2] == (64, 64)
    with pytest.raises(ValueError, match="unsupported video format"):
        viewer.write_video(frames, tmp_path / "v.avi", fps=10)


def test_mesh_only_trajectory_and_cli_show(gl_ok: None, tmp_path: Path) -> None:
    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    floor = np.array([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], float)
    poses = np.tile([0, 0, 0, 1.0, 0, 0, 0], (3, 2, 1))
    poses[:, 1, 2] = [2.0, 1.5, 1.0]
    traj = Trajectory(poses=poses, dt=0.1, kinds=np.array([1, 0]),
                      props=np.array([[0, 0.3, 0.5], [1, 0.4, 0.3]]), names=("floor", "tet"),
                      meshes=ObjectMeshes((floor, tet), (np.array([[0, 1, 2], [0, 2, 3]]),
                                                         np.array([[0, 2, 1], [0, 1, 3],
                                                                   [0, 3, 2], [1, 2, 3]])),
                                          np.zeros((2, 3))), name="tet")
    path = tmp_path / "d.h5"
    write_trajectories(path, [traj])
    out = tmp_path / "tet.gif"
    assert main(["show", str(path), "--traj", "0", "--out", str(out),
                              "--width", "64", "--height", "64"]) == 0
    assert len(imageio.mimread(out)) == 3
    assert main(["show", str(path), "--traj", "4", "--out", str(out)]) == 2
