"""Importers, on small files written here in the real layouts (Kubric MOVi; MIT Pushing: test_mit_*)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from fignet_gym.data.format import load_trajectories
from fignet_gym.data.importers import (
    DataImportError,
    import_movi,
    load_mesh_map,
    read_movi_json,
)
from fignet_gym.simulator.scene import ObjectKind

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
