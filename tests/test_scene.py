"""Scenes from MuJoCo models: kinds, meshes in body frames, properties, clear errors."""

import mujoco
import numpy as np
import pytest
import torch
import trimesh

from fignet_gym.simulator.scene import (
    MeshOptions,
    ObjectKind,
    Scene,
    UnsupportedSceneError,
    dampratio_to_restitution,
    restitution_to_dampratio,
)


def test_kinds_order_and_properties(push_like_xml: str) -> None:
    scene = Scene.from_mjmodel(mujoco.MjModel.from_xml_string(push_like_xml))
    assert scene.object_names == ("world", "box", "tip")
    assert scene.object_kind.tolist() == [ObjectKind.STATIC, ObjectKind.DYNAMIC, ObjectKind.KINEMATIC]
    assert scene.object_props[1, 0].item() == pytest.approx(1.0)  # box mass
    assert scene.object_props[0, 0].item() == 0.0  # static objects have no mass
    # The plane is two triangles with four nodes; a box is its 8 corners.
    assert (scene.face_object == 0).sum().item() == 2
    assert (scene.node_object == 1).sum().item() == 8
    # Tip-floor is not a candidate pair (neither is dynamic).
    assert scene.collision_pairs.tolist() == [[0, 1], [1, 2]]


def test_mesh_geom_vertices_are_in_body_frame() -> None:
    # MuJoCo recentres mesh vertices on the mesh's centre of mass and moves the offset into
    # geom_pos/geom_quat; the scene must undo that, so body-frame vertices equal the file's.
    verts = np.array([[0, 0, 0], [0.2, 0, 0], [0, 0.1, 0], [0, 0, 0.05]]) + [0.3, 0.0, 0.0]
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    vtxt = " ".join(map(str, verts.ravel()))
    ftxt = " ".join(map(str, faces.ravel()))
    xml = f"""<mujoco><asset><mesh name="t" vertex="{vtxt}" face="{ftxt}"/></asset>
      <worldbody><body name="b" pos="1 2 3" euler="0 0 30"><freejoint/>
      <geom type="mesh" mesh="t" mass="1"/></body></worldbody></mujoco>"""
    scene = Scene.from_mjmodel(mujoco.MjModel.from_xml_string(xml))
    got = scene.ref_vertices.double().numpy()
    # Same point set, whatever order MuJoCo stores them in.
    d = np.linalg.norm(got[:, None] - verts[None], axis=-1)
    assert d.min(axis=1).max() < 1e-6 and d.min(axis=0).max() < 1e-6
    # Its pose is the free joint's qpos.
    data = mujoco.MjData(scene_model := mujoco.MjModel.from_xml_string(xml))
    mujoco.mj_forward(scene_model, data)
    assert np.allclose(scene.poses_from_data(data)[0], data.qpos[:7])


def test_primitive_resolution_is_configurable_and_watertight() -> None:
    xml = """<mujoco><worldbody><body name="s"><freejoint/><geom type="sphere" size="0.1"/>
      </body><body name="c" pos="1 0 0"><freejoint/><geom type="cylinder" size="0.1 0.2"/>
      </body><body name="k" pos="2 0 0"><freejoint/><geom type="capsule" size="0.1 0.2"/></body>
      </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    coarse = Scene.from_mjmodel(model, MeshOptions(sphere_subdivisions=0, cylinder_sections=8))
    fine = Scene.from_mjmodel(model, MeshOptions(sphere_subdivisions=2, cylinder_sections=16))
    assert (coarse.node_object == 0).sum() == 12 and (fine.node_object == 0).sum() == 162
    assert (fine.node_object == 1).sum() > (coarse.node_object == 1).sum()
    for o in range(3):
        f = coarse.faces[coarse.face_object == o]
        mesh = trimesh.Trimesh(coarse.ref_vertices.numpy(), f.numpy(), process=False)
        mesh.remove_unreferenced_vertices()
        assert mesh.is_watertight and mesh.volume > 0  # outward winding


@pytest.mark.parametrize("joint", ["hinge", "slide", "ball"])
def test_articulated_bodies_are_rejected_by_name(joint: str) -> None:
    xml = f"""<mujoco><worldbody><body name="arm"><joint type="{joint}"/>
      <geom type="box" size=".1 .1 .1"/></body>
      <body name="free"><freejoint/><geom type="sphere" size=".1"/></body></worldbody></mujoco>"""
    with pytest.raises(UnsupportedSceneError, match="arm"):
        Scene.from_mjmodel(mujoco.MjModel.from_xml_string(xml))


def test_restitution_convention_roundtrip() -> None:
    for e in [0.0, 0.1, 0.3, 0.5, 0.7, 0.95]:
        assert dampratio_to_restitution(restitution_to_dampratio(e)) == pytest.approx(e, abs=1e-9)
    xml = f"""<mujoco><worldbody><body name="b"><freejoint/>
      <geom type="sphere" size=".1" solref="0.02 {restitution_to_dampratio(0.7)}"/></body>
      </worldbody></mujoco>"""
    scene = Scene.from_mjmodel(mujoco.MjModel.from_xml_string(xml))
    assert scene.object_props[0, 2].item() == pytest.approx(0.7, abs=1e-6)


def test_batch_offsets_and_pairs(push_like_xml: str) -> None:
    scene = Scene.from_mjmodel(mujoco.MjModel.from_xml_string(push_like_xml))
    b = scene.repeat(3)
    assert b.num_scenes == 3 and b.num_objects == 3 * scene.num_objects
    assert torch.equal(b.faces[: scene.faces.shape[0]], scene.faces)
    assert torch.equal(b.faces[scene.faces.shape[0]: 2 * scene.faces.shape[0]], scene.faces + scene.num_nodes)
    # No candidate pair crosses scenes.
    pairs = b.collision_pairs
    assert torch.equal(b.object_scene[pairs[:, 0]], b.object_scene[pairs[:, 1]])
    assert pairs.shape[0] == 3 * scene.collision_pairs.shape[0]


def test_memoised_batches_are_bounded_and_rebuilt_equal(push_like_xml: str) -> None:
    """``Scene.cached`` keeps at most ``CACHE_ENTRIES`` values (least recently used dropped):
    batching 40 different counts must not keep 40 batched copies, and a dropped copy is rebuilt
    equal to the first one while a recently used one is the same object."""
    from fignet_gym.simulator.scene import CACHE_ENTRIES

    scene = Scene.from_mjmodel(mujoco.MjModel.from_xml_string(push_like_xml))
    first = scene.repeat(3)
    kept = scene.repeat(2)
    for count in range(4, 44):
        scene.repeat(count)
        scene.repeat(2)  # used again and again: never the least recent
        assert len(scene._cache) <= CACHE_ENTRIES
    assert scene.repeat(2) is kept
    again = scene.repeat(3)
    assert again is not first and torch.equal(again.ref_vertices, first.ref_vertices)
    assert torch.equal(again.node_object, first.node_object)
