"""Trajectory format: round trip, errors naming file / trajectory / field, atomic writes."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from fignet_gym.data.format import (
    INCOMPLETE_SUFFIX,
    ObjectMeshes,
    Trajectory,
    TrajectoryFile,
    TrajectoryFormatError,
    TrajectoryWriter,
    load_trajectories,
    write_trajectories,
)
from fignet_gym.mjcf import push_scene_xml
from fignet_gym.simulator.scene import ObjectKind, dampratio_to_restitution


def _push_traj(name: str = "p0", steps: int = 4, shift: float = 0.0) -> Trajectory:
    """A hand-made push trajectory (world, object, tip) whose MJCF is a real push scene."""
    poses = np.zeros((steps, 3, 7))
    poses[..., 3] = 1.0
    poses[:, 1, 0] = shift + 0.01 * np.arange(steps)
    poses[:, 1, 2] = 0.0065
    poses[:, 2, 0] = -0.1
    # props as Scene.from_mjmodel reads the MJCF (writing checks them against it)
    tip_rest = dampratio_to_restitution(0.5)
    return Trajectory(poses=poses, dt=0.02, kinds=np.array([1, 0, 2]),
                      props=np.array([[0, 0.25, 0], [0.8374, 0.25, 0], [0.00283529, 0.25, tip_rest]]),
                      names=("world", "object", "tip"), mjcf=push_scene_xml("rect1"),
                      metadata={"seed": 3, "note": "unit test"},
                      extras={"force": np.ones((steps, 3))}, name=name)


def _mesh_traj(name: str = "m0") -> Trajectory:
    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    tet_f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    floor = np.array([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], float)
    poses = np.tile([0, 0, 0, 1.0, 0, 0, 0], (5, 2, 1))
    poses[:, 1, 2] = np.linspace(1, 0.5, 5)
    return Trajectory(poses=poses, dt=1 / 12, kinds=np.array([1, 0]),
                      props=np.array([[0, 0.3, 0.5], [2.0, 0.4, 0.3]]), names=("floor", "tet"),
                      meshes=ObjectMeshes((floor, tet), (np.array([[0, 1, 2], [0, 2, 3]]), tet_f),
                                          np.array([[0, 0, 0], [0.25, 0.25, 0.25]])),
                      name=name)


def test_round_trip_keeps_everything(tmp_path: Path) -> None:
    path = tmp_path / "d.h5"
    originals = [_push_traj("a"), _mesh_traj("b")]
    assert write_trajectories(path, originals, metadata={"kind": "test"}) == 2
    with TrajectoryFile(path) as f:
        assert len(f) == 2 and f.names == ["a", "b"] and f.metadata == {"kind": "test"}
    loaded = load_trajectories(path)
    for orig, got in zip(originals, loaded, strict=True):
        np.testing.assert_allclose(got.poses, orig.poses, atol=1e-7)
        assert got.dt == orig.dt and got.names == orig.names and got.name == orig.name
        np.testing.assert_array_equal(got.kinds, orig.kinds)
        np.testing.assert_allclose(got.props, orig.props, rtol=1e-6)
        assert got.mjcf == orig.mjcf and got.metadata == orig.metadata
    np.testing.assert_allclose(loaded[0].extras["force"], 1.0)
    # scenes rebuild from the MJCF and from the meshes
    assert loaded[0].scene.object_names == ("world", "object", "tip")
    scene = loaded[1].scene
    assert scene.object_kind.tolist() == [ObjectKind.STATIC, ObjectKind.DYNAMIC]
    assert scene.num_nodes == 8
    np.testing.assert_allclose(scene.object_com[1].numpy(), 0.25)


def _write_one(path: Path, traj: Trajectory) -> None:
    with TrajectoryWriter(path) as w:
        w.add(traj)


@pytest.mark.parametrize("corrupt, field, detail", [
    (lambda t: t.poses.__setitem__((2, 1, 0), np.nan), "poses", "step 2, object 1"),
    (lambda t: t.poses.__setitem__((1, 2, 3), 0.5), "poses", "step 1, object 2"),
    (lambda t: setattr(t, "poses", t.poses[..., :6]), "poses", "(T, O, 7)"),
    (lambda t: setattr(t, "kinds", np.array([1, 0, 7])), "kinds", "{0, 1, 2}"),
    (lambda t: setattr(t, "props", t.props[:2]), "props", "[3, 3]"),
    (lambda t: setattr(t, "dt", -1.0), "dt", "positive"),
])
def test_bad_trajectories_are_refused_on_write_naming_field(tmp_path, corrupt, field, detail):
    traj = _push_traj("bad-one")
    corrupt(traj)
    with pytest.raises(TrajectoryFormatError) as err:
        _write_one(tmp_path / "x.h5", traj)
    msg = str(err.value)
    assert "x.h5" in msg and "'bad-one'" in msg and f"'{field}'" in msg and detail in msg
    assert not (tmp_path / "x.h5").exists()
    assert not (tmp_path / ("x.h5" + INCOMPLETE_SUFFIX)).exists()


def test_bad_values_in_a_file_are_reported_on_load(tmp_path: Path) -> None:
    path = tmp_path / "d.h5"
    write_trajectories(path, [_push_traj("good"), _push_traj("tampered")])
    with h5py.File(path, "r+") as f:  # damage the second trajectory behind the writer's back
        f["trajectories/000001/poses"][1, 1, 4] = 3.0
        del f["trajectories/000001/props"]
    with TrajectoryFile(path) as tf:
        assert tf[0].name == "good"
        with pytest.raises(TrajectoryFormatError, match=r"d\.h5: trajectory 'tampered'.*'props'"):
            tf[1]
    with h5py.File(path, "r+") as f:
        f["trajectories/000001/props"] = np.zeros((3, 3))
    with pytest.raises(TrajectoryFormatError, match=r"'tampered'.*'poses'.*not unit.*step 1"):
        load_trajectories(path)


def test_foreign_truncated_and_garbage_files(tmp_path: Path) -> None:
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["data"] = np.zeros(3)
    with pytest.raises(TrajectoryFormatError, match="foreign.h5: not a fignet_gym trajectory"):
        TrajectoryFile(foreign)
    good = tmp_path / "good.h5"
    write_trajectories(good, [_push_traj()])
    truncated = tmp_path / "truncated.h5"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(TrajectoryFormatError, match="truncated.h5"):
        load_trajectories(truncated)
    garbage = tmp_path / "garbage.h5"
    garbage.write_bytes(b"not hdf5 at all" * 100)
    with pytest.raises(TrajectoryFormatError, match="garbage.h5: not a readable HDF5"):
        TrajectoryFile(garbage)
    with pytest.raises(FileNotFoundError, match="missing.h5"):
        TrajectoryFile(tmp_path / "missing.h5")
    with TrajectoryFile(good) as f, pytest.raises(IndexError, match="holds 1"):
        f[5]


def test_failed_write_leaves_old_file_intact(tmp_path: Path) -> None:
    path = tmp_path / "d.h5"
    write_trajectories(path, [_push_traj("old", shift=0.5)])
    before = path.read_bytes()

    def trajs():
        yield _push_traj("new0")
        raise RuntimeError("generator crashed midway")

    with pytest.raises(RuntimeError, match="midway"):
        write_trajectories(path, trajs())
    assert path.read_bytes() == before
    assert not path.with_name(path.name + INCOMPLETE_SUFFIX).exists()
    assert load_trajectories(path)[0].name == "old"


def test_killed_writer_leaves_only_an_incomplete_file(tmp_path: Path) -> None:
    path = tmp_path / "d.h5"
    w = TrajectoryWriter(path)
    w.add(_push_traj())
    w._file.flush()  # a killed process never reaches close(): no rename happens
    assert not path.exists()
    assert path.with_name("d.h5" + INCOMPLETE_SUFFIX).exists()
    w.abort()
