"""Tracked real data: the validated tracks + MJCF path, the ContactNets importer, seeded splits."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch

from fignet_gym.cli import main
from fignet_gym.data.format import (
    TrajectoryFormatError,
    build_scene,
    load_trajectories,
    write_trajectories,
)
from fignet_gym.data.importers import DataImportError
from fignet_gym.data.split import SplitError, split_indices, write_split
from fignet_gym.data.tracked import (
    import_contactnets,
    read_contactnets,
    tracked_trajectory,
)
from fignet_gym.mjcf import cube_scene_xml
from fignet_gym.simulator.scene import ObjectKind

SAMPLE = Path(__file__).parent / "data" / "contactnets_sample"
HALF = 0.0524


def _cube_xml(mass: float = 0.37) -> str:
    return cube_scene_xml(HALF, mass, 8e-4, 0.18, 0.125)


def _track(T: int = 5) -> np.ndarray:
    t = np.arange(T)[:, None] * 0.01
    pos = np.hstack([0.1 * t, 0 * t, 0.2 - 4.9 * t**2])
    return np.hstack([pos, np.tile([1.0, 0, 0, 0], (T, 1))])


def _cli(*argv: str) -> int:
    return main(list(argv))


# --------------------------------------------------------------------------- tracks + MJCF


def test_tracked_trajectory_adds_the_untracked_floor_from_the_mjcf() -> None:
    traj = tracked_trajectory(_cube_xml(), {"cube": _track()}, 0.01, props={"cube": (0.37, 0.18, 0.125)})
    assert traj.names == ("world", "cube")
    assert traj.kinds.tolist() == [ObjectKind.STATIC, ObjectKind.DYNAMIC]
    np.testing.assert_allclose(traj.poses[:, 0], np.tile([0, 0, 0, 1.0, 0, 0, 0], (5, 1)))
    np.testing.assert_allclose(traj.poses[:, 1], _track())
    # the stored scene is MuJoCo's: mass from the compiled model
    model = mujoco.MjModel.from_xml_string(traj.mjcf)
    assert traj.props[1, 0] == pytest.approx(model.body_mass[1])
    assert traj.scene.object_names == ("world", "cube")


def test_tracked_trajectory_errors_name_the_file() -> None:
    src = "recordings/toss7.csv"
    with pytest.raises(DataImportError, match=r"toss7\.csv.*mass 1.*MJCF gives 0\.37"):
        tracked_trajectory(_cube_xml(), {"cube": _track()}, 0.01, props={"cube": (1.0, 0.18, 0.125)},
                           source=src)
    with pytest.raises(DataImportError, match=r"toss7\.csv.*friction 0\.5"):
        tracked_trajectory(_cube_xml(), {"cube": _track()}, 0.01, props={"cube": (0.37, 0.5, 0.125)},
                           source=src)
    with pytest.raises(DataImportError, match=r"toss7\.csv.*\['box'\].*no collidable body"):
        tracked_trajectory(_cube_xml(), {"box": _track()}, 0.01, source=src)
    with pytest.raises(DataImportError, match=r"toss7\.csv.*moving bodies \['cube'\] have no track"):
        tracked_trajectory(_cube_xml(), {"world": np.tile([0, 0, 0, 1.0, 0, 0, 0], (5, 1))}, 0.01,
                           source=src)
    bad = _track()
    bad[2, 3:] = [2.0, 0, 0, 0]
    with pytest.raises(DataImportError, match=r"toss7\.csv.*quaternion norm 2 at row 2"):
        tracked_trajectory(_cube_xml(), {"cube": bad}, 0.01, source=src)
    with pytest.raises(DataImportError, match=r"toss7\.csv.*'mjcf'.*cannot compile"):
        tracked_trajectory("<mujoco><worldbody><body", {"cube": _track()}, 0.01, source=src)


def test_writing_only_the_tracked_cube_is_refused_naming_the_file(tmp_path: Path) -> None:
    """The issue's trap: the cube alone with an MJCF that also has a floor."""
    good = tracked_trajectory(_cube_xml(), {"cube": _track()}, 0.01)
    alone = replace(good, poses=good.poses[:, 1:], kinds=good.kinds[1:], props=good.props[1:],
                    names=good.names[1:])
    out = tmp_path / "cube_only.h5"
    with pytest.raises(TrajectoryFormatError, match=r"cube_only\.h5.*differ from the stored names "
                       r"\('cube',\).*floor"):
        write_trajectories(out, [alone])
    assert not out.exists()


def test_stored_props_contradicting_the_mjcf_are_refused(tmp_path: Path) -> None:
    good = tracked_trajectory(_cube_xml(), {"cube": _track()}, 0.01)
    heavy = replace(good, props=good.props * np.array([[1.0, 1, 1], [1.0 / 0.37, 1, 1]]))
    with pytest.raises(TrajectoryFormatError, match=r"heavy\.h5.*'props'.*mass 1.*MJCF gives 0\.37"):
        write_trajectories(tmp_path / "heavy.h5", [heavy])
    # and a file written before the check is refused when its scene is built, naming the file
    path = tmp_path / "old.h5"
    write_trajectories(path, [good])
    import h5py

    with h5py.File(path, "r+") as f:
        f["trajectories/000000/props"][1, 0] = 1.0
    traj = load_trajectories(path)[0]
    with pytest.raises(TrajectoryFormatError, match=r"old\.h5.*mass 1"):
        build_scene(traj)


# --------------------------------------------------------------------------- ContactNets


def test_contactnets_import_converts_units_and_keeps_the_data_dt(tmp_path: Path) -> None:
    params = json.loads((SAMPLE / "params_processed" / "experiment.json").read_text())
    out = tmp_path / "cube.h5"
    assert _cli("import-contactnets", str(SAMPLE), "--out", str(out)) == 0
    trajs = load_trajectories(out)
    assert [t.name for t in trajs] == ["toss-55", "toss-185", "toss-229", "toss-274"]
    unit = 9.81 / params["g"]
    assert unit == pytest.approx(HALF, rel=1e-3)  # the README: half-width 0.0524 m
    raw = torch.load(SAMPLE / "tosses_processed" / "55.pt", weights_only=True)[0].numpy()
    t = trajs[0]
    assert t.dt == params["dt"]
    np.testing.assert_allclose(t.poses[:, 1, :3], raw[:, :3] * unit, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(t.poses[:, 1, 3:], raw[:, 3:7] / np.linalg.norm(raw[:, 3:7], axis=1,
                                                                               keepdims=True), atol=1e-6)
    assert t.props.tolist()[1] == pytest.approx([0.37, 0.18, 0.125], rel=1e-5)
    model = mujoco.MjModel.from_xml_string(t.mjcf)
    box = [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX][0]
    np.testing.assert_allclose(model.geom_size[box], [unit] * 3, rtol=1e-6)
    assert model.opt.gravity[2] == pytest.approx(-9.81)
    np.testing.assert_allclose(model.body_inertia[1], [params["inertia"] * unit**2] * 3, rtol=1e-6)
    # at rest the cube's centre is about one half-width above the floor (within 3 mm)
    assert abs(t.poses[-1, 1, 2] - unit) < 3e-3
    # free flight in the real data: a parabola of roughly standard gravity (README: ~9.6)
    z = t.poses[:12, 1, 2].astype(float)
    acc = np.polyfit(np.arange(12) * t.dt, z, 2)[0] * 2
    assert -10.5 < acc < -8.5


def test_contactnets_import_errors(tmp_path: Path) -> None:
    (tmp_path / "params_processed").mkdir()
    (tmp_path / "tosses_processed").mkdir()
    params = json.loads((SAMPLE / "params_processed" / "experiment.json").read_text())
    del params["mass"]
    (tmp_path / "params_processed" / "experiment.json").write_text(json.dumps(params))
    torch.save(torch.zeros(1, 10, 19, dtype=torch.float64), tmp_path / "tosses_processed" / "0.pt")
    with pytest.raises(DataImportError, match=r"experiment\.json: missing field 'mass'"):
        list(read_contactnets(tmp_path))
    params["mass"] = 0.37
    (tmp_path / "params_processed" / "experiment.json").write_text(json.dumps(params))
    with pytest.raises(DataImportError, match=r"0\.pt.*quaternion norm 0"):
        list(read_contactnets(tmp_path))
    torch.save(torch.zeros(1, 10, 13), tmp_path / "tosses_processed" / "0.pt")
    assert _cli("import-contactnets", str(tmp_path), "--out", str(tmp_path / "x.h5")) == 2
    (tmp_path / "tosses_processed" / "0.pt").write_bytes(b"not a tensor")
    with pytest.raises(DataImportError, match=r"0\.pt: not a readable torch tensor"):
        import_contactnets(tmp_path, tmp_path / "x.h5")
    assert not (tmp_path / "x.h5").exists()


# --------------------------------------------------------------------------- splits


def test_split_is_seeded_disjoint_and_complete() -> None:
    a, b = split_indices(400, seed=3), split_indices(400, seed=3)
    assert a == b and split_indices(400, seed=4) != a
    assert (len(a.train), len(a.valid), len(a.test)) == (240, 80, 80)
    everything = sorted(a.train + a.valid + a.test)
    assert everything == list(range(400))
    # the stated rule: positions of the seeded permutation
    order = np.random.default_rng(3).permutation(400).tolist()
    assert list(a.train) == order[:240] and list(a.test) == order[320:]
    assert a.subset(16) == a.train[:16] and a.subset(None) == a.train
    with pytest.raises(SplitError, match="training split has 240"):
        a.subset(241)


def test_split_with_too_few_trajectories_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(SplitError, match=r"my\.h5: 2 trajectories are too few.*valid \(0 < 1\)"):
        split_indices(2, where="my.h5")
    trajs = [tracked_trajectory(_cube_xml(), {"cube": _track()}, 0.01, name=f"t{i}") for i in range(2)]
    write_trajectories(tmp_path / "two.h5", trajs)
    assert _cli("split", str(tmp_path / "two.h5"), "--out", str(tmp_path / "s")) == 2


def test_write_split_files_hold_the_split(tmp_path: Path) -> None:
    trajs = [tracked_trajectory(_cube_xml(), {"cube": _track()}, 0.01, name=f"t{i}") for i in range(10)]
    write_trajectories(tmp_path / "ten.h5", trajs)
    paths = write_split(tmp_path / "ten.h5", tmp_path / "s", (0.6, 0.2, 0.2), seed=1)
    info = json.loads(paths["json"].read_text())
    split = split_indices(10, seed=1)
    for s in ("train", "valid", "test"):
        assert [t.name for t in load_trajectories(paths[s])] == [f"t{i}" for i in getattr(split, s)]
        assert info[s] == list(getattr(split, s))


def _windows(files: list[str | None]) -> list:
    """One tracked trajectory per entry, its metadata ``file`` the entry (None: no ``file``)."""
    return [tracked_trajectory(_cube_xml(), {"cube": _track()}, 0.01, name=f"w{i}",
                               metadata={} if f is None else {"file": f})
            for i, f in enumerate(files)]


def test_split_keeps_the_windows_of_one_recording_on_one_side(tmp_path: Path) -> None:
    """Windows cut from one push share ``metadata["file"]``: a split by trajectory would put
    some of a long push's windows in training and others in test (a leak)."""
    files = ["p0", "p0", "p1", "p2", "p2", "p2", "p3", None, "p4", "p5", "p5", "p6"]
    write_trajectories(tmp_path / "w.h5", _windows(files))
    paths = write_split(tmp_path / "w.h5", tmp_path / "s", (0.6, 0.2, 0.2), seed=0)
    info = json.loads(paths["json"].read_text())
    side = {}
    for s in ("train", "valid", "test"):
        for t in load_trajectories(paths[s]):
            side.setdefault(t.metadata.get("file", t.name), set()).add(s)
    assert all(len(v) == 1 for v in side.values()), side
    assert sorted(info["train"] + info["valid"] + info["test"]) == list(range(len(files)))
    # the rule by hand: 8 recordings (w7 has no file: its own), in order of first appearance,
    # permuted by the seed; 5 train, 2 valid, 1 test; a recording's windows in file order
    members = [[0, 1], [2], [3, 4, 5], [6], [7], [8], [9, 10], [11]]
    order = np.random.default_rng(0).permutation(8).tolist()
    expect = [[i for g in order[a:b] for i in members[g]] for a, b in ((0, 5), (5, 7), (7, 8))]
    assert [info["train"], info["valid"], info["test"]] == expect
    assert info["grouped_by"] == "file" and sum(map(len, info["recordings"].values())) == 7
    split = split_indices(len(files), seed=0, groups=files)
    assert split.groups == 8 and list(split.train) == expect[0]
    # the same file without the grouping splits p2's three windows (the leak the grouping stops)
    flat = split_indices(len(files), seed=0)
    assert len({s for s in ("train", "valid", "test") if {3, 4, 5} & set(getattr(flat, s))}) > 1


def test_split_by_recording_with_too_few_recordings_is_a_clear_error(tmp_path: Path,
                                                                     capsys) -> None:
    files = ["a"] * 4 + ["b"] * 4 + ["c"] * 2
    with pytest.raises(SplitError, match=r"w\.h5: 10 trajectories from 3 recordings "
                                         r"\(metadata 'file'\) are too few.*test \(0 < 1\).*"
                                         r"need at least 4 recordings"):
        split_indices(10, where="w.h5", groups=files)
    write_trajectories(tmp_path / "w.h5", _windows(files))
    assert _cli("split", str(tmp_path / "w.h5"), "--out", str(tmp_path / "s")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "3 recordings" in err[0]
    assert not (tmp_path / "s").exists()


def test_split_refuses_an_existing_split_without_force(tmp_path: Path, capsys) -> None:
    trajs = [tracked_trajectory(_cube_xml(), {"cube": _track()}, 0.01, name=f"t{i}") for i in range(10)]
    write_trajectories(tmp_path / "ten.h5", trajs)
    out = tmp_path / "s"
    assert _cli("split", str(tmp_path / "ten.h5"), "--out", str(out), "--seed", "1") == 0
    before = json.loads((out / "split.json").read_text())
    capsys.readouterr()
    assert _cli("split", str(tmp_path / "ten.h5"), "--out", str(out), "--seed", "2") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(out) in err[0] and "--force" in err[0]
    assert json.loads((out / "split.json").read_text()) == before
    assert _cli("split", str(tmp_path / "ten.h5"), "--out", str(out), "--seed", "2", "--force") == 0
    after = json.loads((out / "split.json").read_text())
    assert after["train"] == list(split_indices(10, seed=2).train) != before["train"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s", "ten.h5"]  # no temp folder left


def test_mit_standin_and_contactnets_refuse_bad_numbers(tmp_path: Path) -> None:
    bad = [("mit-standin", "--num", "-1"), ("mit-standin", "--num", "0"),
           ("mit-standin", "--noise", "nan"), ("mit-standin", "--seed", "-1"),
           ("mit-standin", "--penetration", "-0.001"),
           ("import-contactnets", str(tmp_path), "--length-unit", "0"),
           ("import-contactnets", str(tmp_path), "--floor-half-size", "-2")]
    for cmd, *argv in bad:
        with pytest.raises(SystemExit) as exc:
            _cli(cmd, "--out", str(tmp_path / "o"), *argv)
        assert exc.value.code == 2, (cmd, argv)
    assert not (tmp_path / "o").exists()
