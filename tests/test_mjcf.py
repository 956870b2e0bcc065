"""MJCF builders: the scenes compile, match datasets.md and rebuild as the expected Scene."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import trimesh

from fignet_gym.mjcf import (
    MATERIALS,
    MIT_OBJECTS,
    TOSS_SHAPES,
    TossObject,
    push_object,
    push_scene_xml,
    toss_scene_xml,
    unit_shape_mesh,
)
from fignet_gym.simulator.scene import MeshOptions, ObjectKind, Scene


def _inertia_matrix(model: mujoco.MjModel, body: int) -> np.ndarray:
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, model.body_iquat[body])
    rot = rot.reshape(3, 3)
    return rot @ np.diag(model.body_inertia[body]) @ rot.T


@pytest.mark.parametrize("shape", sorted(MIT_OBJECTS))
def test_push_scene_compiles_with_table_mass_and_inertia(shape: str) -> None:
    obj = MIT_OBJECTS[shape]
    model = mujoco.MjModel.from_xml_string(push_scene_xml(shape))
    b = model.body("object").id
    assert model.body_mass[b] == pytest.approx(obj.mass)
    assert _inertia_matrix(model, b)[2, 2] == pytest.approx(obj.inertia_z, rel=1e-6)
    # the outline is counter-clockwise (positive signed area)
    x, y = obj.outline.T
    assert (x * np.roll(y, -1) - np.roll(x, -1) * y).sum() > 0
    scene = Scene.from_mjmodel(model)
    assert scene.object_names == ("world", "object", "tip")
    kinds = [ObjectKind.STATIC, ObjectKind.DYNAMIC, ObjectKind.KINEMATIC]
    assert scene.object_kind.tolist() == kinds


def test_push_outlines_follow_datasets_md() -> None:
    # rectangles: corners [[a,b],[-a,b],[-a,-b],[a,-b]]; triangles [[d,d],[d-b,d],[d,d-a]], d=0.045
    np.testing.assert_allclose(MIT_OBJECTS["rect3"].outline,
                               [[0.067505, 0.04497], [-0.067505, 0.04497],
                                [-0.067505, -0.04497], [0.067505, -0.04497]])
    d = 0.045
    np.testing.assert_allclose(MIT_OBJECTS["tri2"].outline,
                               [[d, d], [d - 0.151, d], [d, d - 0.12587]])
    np.testing.assert_allclose(np.linalg.norm(MIT_OBJECTS["hex"].outline, axis=1), 0.0605)
    # a triangle's centroid is the mean of its corners (the object frame is not at the centroid)
    np.testing.assert_allclose(MIT_OBJECTS["tri3"].centroid(), MIT_OBJECTS["tri3"].outline.mean(0))


def test_push_object_body_frame_is_dataset_frame_and_rests_on_floor() -> None:
    obj = MIT_OBJECTS["tri1"]
    model = mujoco.MjModel.from_xml_string(push_scene_xml("tri1", object_pose=(0.1, -0.05, 0.3)))
    scene = Scene.from_mjmodel(model)
    verts = scene.ref_vertices[scene.node_object == 1].double().numpy()
    # every outline corner is a node at both faces of the 13 mm prism, in the object frame
    for z in (-obj.thickness / 2, obj.thickness / 2):
        for corner in obj.outline:
            assert np.min(np.linalg.norm(verts - [*corner, z], axis=1)) < 1e-7
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data, nstep=500)
    assert data.qpos[2] == pytest.approx(obj.thickness / 2, abs=2e-4)
    np.testing.assert_allclose(data.qpos[:2], [0.1, -0.05], atol=1e-5)
    # the tip never touches the floor
    tip = model.geom("tip").id
    assert all(tip not in (c.geom1, c.geom2) for c in data.contact[:data.ncon])
    tip_bottom = model.body_pos[model.body("tip").id][2] - model.geom_size[tip][1]
    assert tip_bottom == pytest.approx(0.001)
    assert model.geom_size[tip][0] == pytest.approx(0.00475)


def test_push_contact_friction_uses_floor_and_tip_values() -> None:
    model = mujoco.MjModel.from_xml_string(
        push_scene_xml("rect1", friction=0.2, tip_friction=0.6, tip_xy=(-0.0497, 0.0)))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)  # contacts of the initial state
    floor, tip = model.geom("floor").id, model.geom("tip").id
    frictions = {(min(c.geom1, c.geom2)): c.friction[0] for c in data.contact[:data.ncon]}
    assert frictions[floor] == pytest.approx(0.2)
    obj_tip = [c.friction[0] for c in data.contact[:data.ncon] if tip in (c.geom1, c.geom2)]
    assert obj_tip and obj_tip[0] == pytest.approx(0.6)


def test_unknown_shapes_list_valid_names() -> None:
    with pytest.raises(ValueError, match="rect1.*butter"):
        push_object("square")
    with pytest.raises(ValueError, match="cube.*torus_knot"):
        TossObject("teapot", 1.0)
    with pytest.raises(ValueError, match="metal"):
        TossObject("cube", 1.0, "wood")


@pytest.mark.parametrize("shape", TOSS_SHAPES)
def test_toss_shapes_are_closed_outward_meshes_in_unit_box(shape: str) -> None:
    v, f = unit_shape_mesh(shape)
    mesh = trimesh.Trimesh(v, f, process=False)
    assert mesh.is_watertight
    assert mesh.volume > 0
    assert np.abs(v).max() == pytest.approx(1.0)
    if shape not in ("cube", "sphere", "cylinder"):
        assert 100 <= len(v) <= 1100


def test_toss_scene_objects_materials_and_keyframe() -> None:
    objects = [TossObject("cube", 0.7, "metal"), TossObject("sphere", 1.4, "rubber"),
               TossObject("torus", 1.0, "metal")]
    poses = np.array([[0, 0, 1, 1, 0, 0, 0], [3, 0, 2, 0, 1, 0, 0], [-3, 0, 2, 1, 0, 0, 0]], float)
    vel = np.arange(18, dtype=float).reshape(3, 6) / 10
    model = mujoco.MjModel.from_xml_string(toss_scene_xml(objects, poses=poses, velocities=vel))
    scene = Scene.from_mjmodel(model)
    assert scene.object_names == ("world", "obj0", "obj1", "obj2")
    # cube of half side 0.7 with Kubric's metal density
    assert model.body_mass[1] == pytest.approx(1.4**3 * MATERIALS["metal"][2], rel=1e-6)
    props = scene.object_props.double().numpy()
    np.testing.assert_allclose(props[1:, 1], [0.4, 0.8, 0.4])
    np.testing.assert_allclose(props[:, 2], [0.5, 0.3, 0.7, 0.3], atol=1e-6)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    np.testing.assert_allclose(data.qvel, vel.ravel())
    np.testing.assert_allclose(data.qpos, poses.ravel())
    # default sparse resolution: cube 8 nodes, icosphere level 1 42 nodes
    counts = np.bincount(scene.node_object.numpy())
    assert counts[1] == 8 and counts[2] == 42


def test_toss_mesh_options_control_resolution() -> None:
    xml = toss_scene_xml([TossObject("sphere", 1.0), TossObject("cylinder", 1.0)],
                         mesh_options=MeshOptions(sphere_subdivisions=2, cylinder_sections=20))
    scene = Scene.from_mjmodel(mujoco.MjModel.from_xml_string(xml))
    counts = np.bincount(scene.node_object.numpy())
    assert counts[1] == 162 and counts[2] == 42
