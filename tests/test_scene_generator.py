"""``fignet-gym generate scene``: a user's MJCF, seeded starts and strokes, MuJoCo's own replay,
and one-line refusals of what FIGNet cannot represent."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import mujoco
import numpy as np
import pytest

from fignet_gym.cli import main
from fignet_gym.data.format import load_trajectories
from fignet_gym.data.generate import resimulate
from fignet_gym.data.scene_generator import AnisotropicFrictionWarning, SceneConfig, check_scene

SCENE = """<mujoco model="box_push">
  <option timestep="0.002" cone="{cone}"/>
  {assets}
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <body name="box" pos="0.1 -0.05 0.03">
      <freejoint/>
      {box}
    </body>
    <body name="tip" mocap="true" pos="0.3 0 0.02">
      <geom type="cylinder" size="0.005 0.02"/>
    </body>
    {extra}
  </worldbody>
</mujoco>"""
BOX = '<geom type="box" size="0.05 0.03 0.03" mass="0.5"/>'


def _write(tmp: Path, cone: str = "elliptic", box: str = BOX, assets: str = "", extra: str = "") -> Path:
    path = tmp / "scene.xml"
    path.write_text(SCENE.format(cone=cone, box=box, assets=assets, extra=extra))
    return path


def test_generated_scene_replays_in_mujoco_and_starts_as_documented(tmp_path: Path) -> None:
    """Each record is MuJoCo's own simulation (``resimulate`` from the stored MJCF and
    metadata gives the poses back), seeded (same seed, same file), the box starts at rest within
    its yaw range, and each stroke starts the documented distance from the box's centre:
    ``clearance`` plus the two bounding radii back, ``offset`` aside."""
    path = _write(tmp_path)
    out = tmp_path / "a.h5"
    argv = ["generate", "scene", "--mjcf", str(path), "--num", "4", "--seed", "3", "--workers", "1",
            "--yaw-range", "0.5", "--offset", "0.01", "0.01", "--no-progress"]
    assert main(argv + ["--out", str(out)]) == 0
    assert main(argv + ["--out", str(tmp_path / "b.h5")]) == 0
    trajs = load_trajectories(out)
    model = mujoco.MjModel.from_xml_path(str(path))
    cfg = SceneConfig.from_file(path)
    r_box = float(model.geom_rbound[1])  # the box geom, at its body's origin
    r_tip = float(model.geom_rbound[2])
    moved = 0
    for t, u in zip(trajs, load_trajectories(tmp_path / "b.h5"), strict=True):
        np.testing.assert_array_equal(t.poses, u.poses)
        np.testing.assert_allclose(resimulate(t), t.poses, atol=1e-6)  # float32 records
        q = t.poses[0, 1, 3:]
        assert abs(2 * math.atan2(q[3], q[0])) <= 0.5 + 1e-9 and t.poses[0, 1, 2] == pytest.approx(0.03)
        (stroke,) = t.metadata["strokes"]
        start = np.asarray(stroke["pieces"][0]["start"])
        back = r_box + r_tip + cfg.clearance
        assert np.linalg.norm(start - t.poses[0, 1, :2]) == pytest.approx(math.hypot(back, 0.01))
        np.testing.assert_allclose(t.poses[1, 2, :2] - t.poses[0, 2, :2],
                                   np.asarray(stroke["pieces"][0]["velocity"]) * t.dt, atol=1e-7)
        moved += np.linalg.norm(t.poses[-1, 1, :2] - t.poses[0, 1, :2]) > 1e-3
    assert moved >= 2 and trajs[0].dt == pytest.approx(0.02) and trajs[0].num_steps == 51


def test_mesh_files_are_inlined_so_the_record_stands_alone(tmp_path: Path) -> None:
    """A mesh read from a file (``meshdir``) is stored in the record's MJCF as vertices: it
    loads without the file and compiles to the same mesh as MuJoCo reads from the file."""
    (tmp_path / "meshes").mkdir()
    v = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * [0.05, 0.03, 0.03]
    import trimesh

    trimesh.convex.convex_hull(v + [0.01, 0.0, 0.0]).export(tmp_path / "meshes" / "box.obj")
    path = _write(tmp_path, box='<geom type="mesh" mesh="box" mass="0.5"/>',
                  assets='<compiler meshdir="meshes"/><asset><mesh name="box" file="box.obj"/></asset>')
    cfg = SceneConfig.from_file(path)
    assert "box.obj" not in cfg.mjcf
    a, b = mujoco.MjModel.from_xml_path(str(path)), mujoco.MjModel.from_xml_string(cfg.mjcf)
    np.testing.assert_allclose(np.sort(b.mesh_vert, axis=0), np.sort(a.mesh_vert, axis=0), atol=1e-6)
    np.testing.assert_allclose(b.geom_pos, a.geom_pos, atol=1e-9)
    assert main(["generate", "scene", "--mjcf", str(path), "--num", "1", "--out",
                 str(tmp_path / "m.h5"), "--workers", "1", "--no-progress"]) == 0


@pytest.mark.parametrize(("change", "message"), [
    (dict(extra='<body name="door"><joint type="hinge"/><geom size="0.01"/></body>'),
     "body 'door' has joints"),
    (dict(), None),
])
def test_refusals_name_the_body_or_value(tmp_path: Path, change: dict, message: str | None,
                                          capsys) -> None:
    path = _write(tmp_path, **change)
    argv = ["generate", "scene", "--mjcf", str(path), "--num", "1", "--out", str(tmp_path / "x.h5"),
            "--workers", "1", "--no-progress"]
    if message is None:  # the control: the same scene without the change is generated
        assert main(argv) == 0
        return
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "x.h5").exists()


def test_other_refusals_and_the_pyramidal_cone_warning(tmp_path: Path, capsys) -> None:
    path = _write(tmp_path)
    base = ["generate", "scene", "--mjcf", str(path), "--num", "1", "--workers", "1",
            "--no-progress", "--out", str(tmp_path / "x.h5")]
    for extra, message in ((["--dt", "0.005"], "does not divide the step dt 0.005"),
                           (["--target", "tip"], "--target 'tip' is not a free body; free bodies: box"),
                           (["--cone", "elliptic"], "keeps the scene's own friction cone")):
        assert main(base + extra) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
    no_pusher = tmp_path / "still.xml"
    no_pusher.write_text(path.read_text().replace('mocap="true"', ""))
    with pytest.raises(ValueError, match="no mocap body"):
        check_scene(SceneConfig.from_file(no_pusher))
    pyramidal = _write(tmp_path, cone="pyramidal")
    with pytest.warns(AnisotropicFrictionWarning, match='cone="elliptic"'):
        check_scene(SceneConfig.from_file(pyramidal))
    with warnings.catch_warnings():  # as a user runs it: shown, not the test config's error
        warnings.simplefilter("default", AnisotropicFrictionWarning)
        assert main(base[:3] + [str(pyramidal)] + base[4:]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert len(err) == 1 and err[0].startswith("warning: ") and "isotropic friction" in err[0]
