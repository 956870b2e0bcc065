"""Importers, on small files written here in the real layouts (MIT raw / pdproc, Kubric MOVi)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import trimesh

from fignet_gym.data.cli import register
from fignet_gym.data.format import load_trajectories, write_trajectories
from fignet_gym.data.importers import (
    DataImportError,
    MitSelection,
    import_mit,
    import_movi,
    load_mesh_map,
    parse_mit_name,
    read_mit_pdproc,
    read_mit_raw,
    read_movi_json,
)
from fignet_gym.mjcf import MIT_OBJECTS
from fignet_gym.simulator.scene import ObjectKind

RAW = "motion_surface={surface}_shape={shape}_a={a}_v=20_i=0.000_s=0.500_t=0.349{ext}"


def _object_motion(t: np.ndarray) -> np.ndarray:
    """Analytic planar motion (x, y, yaw) whose yaw crosses +pi (stored wrapped)."""
    return np.stack([0.3 + 0.02 * t, -0.1 + 0.01 * t, 3.0 + 0.5 * t], axis=1)


def _streams(t0: float = 1.46e9, shift: float = 0.0) -> dict[str, list[list[float]]]:
    """Three unsynchronised ~250 Hz streams of unix times, like the real files (the object
    ``shift`` m along x: distinct pushes)."""
    t_obj = t0 + np.arange(0, 0.8, 1 / 247)
    t_tip = t0 + 0.003 + np.arange(0, 0.8, 1 / 250)
    t_ft = t0 + 0.011 + np.arange(0, 0.8, 1 / 251)
    obj = _object_motion(t_obj - t0)
    obj[:, 0] += shift
    obj[:, 2] = np.angle(np.exp(1j * obj[:, 2]))  # wrapped to (-pi, pi], as Vicon reports
    tip = np.stack([0.2 + 0.02 * (t_tip - t0), -0.1 + 0 * t_tip, 0.1 + 0 * t_tip], 1)
    ft = np.stack([np.sin(t_ft - t0), 2 + 0 * t_ft, 0 * t_ft], 1)
    return {"tip_pose": np.c_[t_tip, tip].tolist(), "object_pose": np.c_[t_obj, obj].tolist(),
            "ft_wrench": np.c_[t_ft, ft].tolist()}


def _write_raw(folder: Path, surface: str = "abs", shape: str = "rect1", a: int = 0,
               ext: str = ".json", content: dict | None = None) -> Path:
    path = folder / RAW.format(surface=surface, shape=shape, a=a, ext=ext)
    content = _streams() if content is None else content
    if ext == ".json":
        path.write_text(json.dumps(content))
    else:
        with h5py.File(path, "w") as f:
            for k, v in content.items():
                f[k] = np.asarray(v)
    return path


def _yaw(quats: np.ndarray) -> np.ndarray:
    return 2 * np.arctan2(quats[:, 3], quats[:, 0])


@pytest.mark.parametrize("ext", [".json", ".h5"])
def test_mit_raw_resamples_onto_one_clock(tmp_path: Path, ext: str) -> None:
    traj = read_mit_raw(_write_raw(tmp_path, ext=ext), dt=0.02)
    t0 = 1.46e9
    start = 0.011  # the latest stream start (ft_wrench)
    assert traj.metadata["t0"] == pytest.approx(t0 + start)
    times = start + 0.02 * np.arange(traj.num_steps)
    end = 197 / 247  # the earliest stream end (object_pose)
    assert traj.num_steps == int(np.floor((end - start) / 0.02)) + 1 == 40
    truth = _object_motion(times)
    np.testing.assert_allclose(traj.poses[:, 1, :2], truth[:, :2], atol=1e-6)
    # yaw went through +-pi: interpolated the short way, equal up to 2 pi
    dyaw = np.angle(np.exp(1j * (_yaw(traj.poses[:, 1, 3:]) - truth[:, 2])))
    np.testing.assert_allclose(dyaw, 0, atol=1e-5)
    np.testing.assert_allclose(traj.poses[:, 1, 2], MIT_OBJECTS["rect1"].thickness / 2)
    np.testing.assert_allclose(traj.poses[:, 2, 0], 0.2 + 0.02 * times, atol=1e-6)
    np.testing.assert_allclose(traj.extras["force"][:, 0], np.sin(times), atol=5e-6)
    assert traj.names == ("world", "object", "tip") and traj.dt == 0.02
    m = traj.metadata
    assert (m["surface"], m["shape"], m["acc"], m["vel_mm_s"]) == ("abs", "rect1", 0.0, 20.0)
    assert m["angle"] == pytest.approx(0.349)
    # the stored MJCF rebuilds the scene, whose object starts where the data does
    assert traj.scene.object_names == traj.names
    np.testing.assert_allclose(traj.scene.static_poses[1, :2].numpy(), traj.poses[0, 1, :2],
                               atol=1e-6)


def test_mit_max_duration_cuts(tmp_path: Path) -> None:
    traj = read_mit_raw(_write_raw(tmp_path), dt=0.02, max_duration=0.5)
    assert traj.num_steps == 26  # 0 .. 0.5 s


def test_mit_pdproc(tmp_path: Path) -> None:
    folder = tmp_path / "abs" / "tri2"
    folder.mkdir(parents=True)
    n = 144  # 0.8 s at 180 Hz
    t = np.arange(n) / 180
    path = folder / "a=0_v=50_i=1.000_s=0.300_t=-0.524.h5"
    with h5py.File(path, "w") as f:
        f["object"] = np.stack([0.05 * t, 0 * t, 0.2 * t], 1).astype(np.float32)
        f["tip"] = np.stack([-0.06 + 0.05 * t, 0 * t], 1).astype(np.float32)
        f["force"] = np.stack([0 * t, 0 * t, 0 * t], 1).astype(np.float32)[..., None]  # (N,3,1)
        f["acc"], f["push_velocity"], f["push_angle"] = 0, 50, -30.0
        f["push_side"], f["push_point"] = 1, 0.3
    traj = read_mit_pdproc(path, dt=0.02)
    times = 0.02 * np.arange(traj.num_steps)
    np.testing.assert_allclose(traj.poses[:, 1, 0], 0.05 * times, atol=1e-6)
    np.testing.assert_allclose(_yaw(traj.poses[:, 1, 3:]), 0.2 * times, atol=1e-6)
    np.testing.assert_allclose(traj.poses[:, 2, 0], -0.06 + 0.05 * times, atol=1e-6)
    m = traj.metadata
    assert (m["surface"], m["shape"], m["vel_mm_s"], m["side"]) == ("abs", "tri2", 50.0, 1)
    assert m["angle"] == pytest.approx(np.deg2rad(-30.0))


def test_mit_selection_and_cli(tmp_path: Path) -> None:
    src = tmp_path / "src"
    src.mkdir()
    _write_raw(src, "abs", "rect1", 0)
    _write_raw(src, "abs", "hex", 0, ext=".h5")
    _write_raw(src, "delrin", "rect1", 0, content=_streams(shift=1e-3))  # distinct pushes: the
    _write_raw(src, "abs", "rect1", 1000, content=_streams(shift=2e-3))  # importer drops copies
    out = tmp_path / "mit.h5"
    assert import_mit([src], out) == 2  # the paper's: abs, zero acceleration
    assert {t.metadata["shape"] for t in load_trajectories(out)} == {"rect1", "hex"}
    assert import_mit([src], out, MitSelection(surfaces=None, shapes=("rect1",))) == 2
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="cmd", required=True))
    argv = ["import-mit", str(src), "--out", str(out), "--surface", "any", "--any-acceleration",
            "--duration", "0"]
    args = parser.parse_args(argv)
    assert args.func(args) == 2  # an existing --out is never replaced silently
    assert len(load_trajectories(out)) == 2
    args = parser.parse_args([*argv, "--force"])
    assert args.func(args) == 0
    trajs = load_trajectories(out)
    assert len(trajs) == 4 and max(t.num_steps for t in trajs) == 40


def test_mit_bad_input_names_file_and_field(tmp_path: Path, capsys) -> None:
    with pytest.raises(DataImportError, match=r"shape=square.*'shape'.*unknown shape 'square'"):
        read_mit_raw(_write_raw(tmp_path, shape="square"))
    content = _streams()
    del content["ft_wrench"]
    with pytest.raises(DataImportError, match=r"\.json: missing field 'ft_wrench'"):
        read_mit_raw(_write_raw(tmp_path, shape="hex", content=content))
    content = _streams()
    content["object_pose"][5][2] = float("nan")
    bad = _write_raw(tmp_path, shape="tri1", content=content)
    with pytest.raises(DataImportError, match=r"tri1.*'object_pose'.*non-finite.*row 5"):
        read_mit_raw(bad)
    truncated = _write_raw(tmp_path, shape="tri3")
    truncated.write_text(truncated.read_text()[:100])
    with pytest.raises(DataImportError, match="tri3.*not a readable JSON"):
        read_mit_raw(truncated)
    with pytest.raises(DataImportError, match="does not follow"):
        parse_mit_name(tmp_path / "push_001.json")
    # a bad file aborts an import without touching an existing output
    out = tmp_path / "out.h5"
    write_trajectories(out, [read_mit_raw(_write_raw(tmp_path, shape="rect2"))])
    before = out.read_bytes()
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="cmd", required=True))
    args = parser.parse_args(["import-mit", str(tmp_path), "--out", str(out), "--force"])
    assert args.func(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "Traceback" not in err and "field '" in err
    assert out.read_bytes() == before
    with pytest.warns(UserWarning, match="skipped"):
        assert import_mit([tmp_path], out, skip_bad=True) == 1  # only rect2 is good


# --------------------------------------------------------------------------- MOVi


def _movi_scene(tmp_path: Path, layout: str = "list") -> tuple[Path, Path]:
    cube = tmp_path / "cube.obj"
    trimesh.creation.box(extents=(2, 2, 2)).export(cube)
    sphere = tmp_path / "sphere.obj"
    trimesh.creation.icosphere(subdivisions=1).export(sphere)
    mesh_map = tmp_path / "meshes.json"
    mesh_map.write_text(json.dumps({"cube": "cube.obj", "sphere": str(sphere)}))
    s = 24
    t = np.arange(s) / 12
    half = np.sqrt(0.5)
    instances = [
        {"shape_label": "cube", "size_label": "small", "material_label": "metal",
         "positions": np.stack([t, 0 * t, 2 - t], 1).tolist(),
         "quaternions": np.tile([half, 0, 0, half], (s, 1)).tolist(),
         "velocities": np.zeros((s, 3)).tolist(), "angular_velocities": np.zeros((s, 3)).tolist(),
         "mass": 7.4, "friction": 0.4, "restitution": 0.3},
        {"shape_label": "sphere", "scale": 1.4, "material_label": "rubber",
         "positions": np.stack([0 * t, t, 0 * t + 3], 1).tolist(),
         "quaternions": np.tile([1.0, 0, 0, 0], (s, 1)).tolist(),
         "mass": 13.0, "friction": 0.8, "restitution": 0.7},
    ]
    if layout == "arrays":  # the TFDS layout: one array per field, instances first
        keys = ("shape_label", "positions", "quaternions", "mass", "friction", "restitution")
        inst = {k: [i[k] for i in instances] for k in keys}
        inst["scale"] = [0.7, 1.4]
        instances = inst
    scene = tmp_path / "scene_0001"
    scene.mkdir()
    record = {"metadata": {"frame_rate": 12, "step_rate": 240, "num_frames": s},
              "instances": instances}
    (scene / "metadata.json").write_text(json.dumps(record))
    return scene / "metadata.json", mesh_map


@pytest.mark.parametrize("layout", ["list", "arrays"])
def test_movi_record(tmp_path: Path, layout: str) -> None:
    path, mesh_map = _movi_scene(tmp_path, layout)
    traj = read_movi_json(path, load_mesh_map(mesh_map))
    assert traj.name == "scene_0001" and traj.dt == pytest.approx(1 / 12)
    assert traj.poses.shape == (24, 3, 7)
    np.testing.assert_allclose(traj.poses[5, 1, :3], [5 / 12, 0, 2 - 5 / 12])
    np.testing.assert_allclose(traj.props, [[0, 0.3, 0.5], [7.4, 0.4, 0.3], [13.0, 0.8, 0.7]])
    scene = traj.scene
    assert scene.object_kind.tolist() == [ObjectKind.STATIC, ObjectKind.DYNAMIC, ObjectKind.DYNAMIC]
    cube_nodes = scene.ref_vertices[scene.node_object == 1].numpy()
    np.testing.assert_allclose(np.abs(cube_nodes), 0.7, atol=1e-6)  # size_label small
    sphere_nodes = scene.ref_vertices[scene.node_object == 2].numpy()
    np.testing.assert_allclose(np.linalg.norm(sphere_nodes, axis=1), 1.4, atol=1e-5)
    out = tmp_path / "movi.h5"
    assert import_movi([tmp_path], load_mesh_map(mesh_map), out) == 1
    back = load_trajectories(out)[0]
    assert back.meshes is not None and back.scene.num_nodes == scene.num_nodes


def test_movi_bad_input(tmp_path: Path) -> None:
    path, mesh_map = _movi_scene(tmp_path)
    with pytest.raises(DataImportError, match=r"instance 1.*'shape_label'.*no mesh for shape 'sp"):
        read_movi_json(path, {"cube": tmp_path / "cube.obj"})
    record = json.loads(path.read_text())
    record["instances"][0]["quaternions"][3] = [1.0, 1.0, 0, 0]
    del record["instances"][1]["restitution"]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(record))
    with pytest.raises(DataImportError, match=r"bad\.json: instance 1: missing field 'restit"):
        read_movi_json(bad, load_mesh_map(mesh_map))
    record["instances"][1]["restitution"] = 0.7
    bad.write_text(json.dumps(record))
    with pytest.raises(DataImportError, match=r"bad\.json.*'poses'.*not unit.*step 3, object 1"):
        read_movi_json(bad, load_mesh_map(mesh_map))
    del record["instances"]
    bad.write_text(json.dumps(record))
    with pytest.raises(DataImportError, match=r"bad\.json: missing field 'instances'"):
        read_movi_json(bad, load_mesh_map(mesh_map))
