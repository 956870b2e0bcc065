"""MIT Pushing importer: synthetic streams (exact values) and the shipped real sample pushes."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import h5py
import mujoco
import numpy as np
import pytest

from fignet_gym.cli import main
from fignet_gym.data import mit_geometry as geo
from fignet_gym.data.format import load_trajectories, write_trajectories
from fignet_gym.data.mit import (
    DataImportError,
    MitProtocol,
    MitSelection,
    analyse,
    import_mit,
    offsets_from_report,
    parse_mit_name,
    push_windows,
    read_push,
)
from fignet_gym.data.mit_scene import convex_pieces

SAMPLE = Path(__file__).parent / "data" / "mit_sample"
RAW = "motion_surface={surface}_shape={shape}_a={a}_v=20_i=0.000_s=0.500_t=0.349{ext}"
WHOLE = MitProtocol(dt=0.02, window=0.0, start="file", keep_still=True)


def _object_motion(t: np.ndarray) -> np.ndarray:
    """Analytic planar motion (x, y, yaw) whose yaw crosses +pi (stored wrapped)."""
    return np.stack([0.3 + 0.02 * t, -0.1 + 0.01 * t, 3.0 + 0.5 * t], axis=1)


def _streams(t0: float = 1.46e9, shift: float = 0.0) -> dict[str, list[list[float]]]:
    """Three unsynchronised ~250 Hz streams of unix times, like the real files (the object and
    tip ``shift`` m along x: distinct pushes, which the importer's copy check tells apart)."""
    t_obj = t0 + np.arange(0, 0.8, 1 / 247)
    t_tip = t0 + 0.003 + np.arange(0, 0.8, 1 / 250)
    t_ft = t0 + 0.011 + np.arange(0, 0.8, 1 / 251)
    obj = _object_motion(t_obj - t0)
    obj[:, 0] += shift
    obj[:, 2] = np.angle(np.exp(1j * obj[:, 2]))  # wrapped to (-pi, pi], as Vicon reports
    tip = np.stack([0.2 + 0.02 * (t_tip - t0), -0.1 + 0 * t_tip, 0.1 + 0 * t_tip], 1)
    tip[:, 0] += shift
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


def _one(path: Path, protocol: MitProtocol = WHOLE):
    push = read_push(path)
    return push_windows(push, geo.FrameOffset(), protocol)[0]


@pytest.mark.parametrize("ext", [".json", ".h5"])
def test_raw_streams_resample_onto_one_clock(tmp_path: Path, ext: str) -> None:
    traj = _one(_write_raw(tmp_path, ext=ext))
    t0 = 1.46e9
    start = 0.011  # the latest stream start (ft_wrench)
    assert traj.metadata["t0"] == pytest.approx(t0 + start)
    times = start + 0.02 * np.arange(traj.num_steps)
    end = 197 / 247  # the earliest stream end (object_pose)
    assert traj.num_steps == int(np.floor((end - start) / 0.02)) + 1 == 40
    truth = _object_motion(times)
    np.testing.assert_allclose(traj.poses[:, 1, :2], truth[:, :2], atol=1e-6)
    dyaw = np.angle(np.exp(1j * (_yaw(traj.poses[:, 1, 3:]) - truth[:, 2])))
    np.testing.assert_allclose(dyaw, 0, atol=1e-5)
    np.testing.assert_allclose(traj.poses[:, 1, 2], geo.REAL_THICKNESS / 2)
    np.testing.assert_allclose(traj.poses[:, 2, 0], 0.2 + 0.02 * times, atol=1e-6)
    np.testing.assert_allclose(traj.extras["force"][:, 0], np.sin(times), atol=5e-6)
    assert traj.names == ("world", "object", "tip") and traj.dt == 0.02
    m = traj.metadata
    assert (m["surface"], m["shape"], m["acc"], m["vel_mm_s"]) == ("abs", "rect1", 0.0, 20.0)
    assert m["angle"] == pytest.approx(0.349)
    assert traj.scene.object_names == traj.names
    np.testing.assert_allclose(traj.scene.static_poses[1, :2].numpy(), traj.poses[0, 1, :2],
                               atol=1e-6)


def test_pdproc(tmp_path: Path) -> None:
    folder = tmp_path / "abs" / "tri2"
    folder.mkdir(parents=True)
    t = np.arange(144) / 180  # 0.8 s at 180 Hz
    path = folder / "a=0_v=50_i=1.000_s=0.300_t=-0.524.h5"
    with h5py.File(path, "w") as f:
        f["object"] = np.stack([0.05 * t, 0 * t, 0.2 * t], 1).astype(np.float32)
        f["tip"] = np.stack([-0.06 + 0.05 * t, 0 * t], 1).astype(np.float32)
        f["force"] = np.stack([0 * t, 0 * t, 0 * t], 1).astype(np.float32)[..., None]  # (N,3,1)
        f["acc"], f["push_velocity"], f["push_angle"] = 0, 50, -30.0
        f["push_side"], f["push_point"] = 1, 0.3
    traj = _one(path)
    times = 0.02 * np.arange(traj.num_steps)
    np.testing.assert_allclose(traj.poses[:, 1, 0], 0.05 * times, atol=1e-6)
    np.testing.assert_allclose(_yaw(traj.poses[:, 1, 3:]), 0.2 * times, atol=1e-6)
    np.testing.assert_allclose(traj.poses[:, 2, 0], -0.06 + 0.05 * times, atol=1e-6)
    m = traj.metadata
    assert (m["surface"], m["shape"], m["vel_mm_s"], m["side"]) == ("abs", "tri2", 50.0, 1)
    assert m["angle"] == pytest.approx(np.deg2rad(-30.0))


def test_selection_and_cli(tmp_path: Path) -> None:
    src = tmp_path / "src"
    src.mkdir()
    _write_raw(src, "abs", "rect1", 0)
    _write_raw(src, "abs", "hex", 0, ext=".h5")
    _write_raw(src, "delrin", "rect1", 0, content=_streams(shift=0.001))
    _write_raw(src, "abs", "rect1", 1000, content=_streams(shift=0.002))
    out = tmp_path / "mit.h5"
    assert import_mit([src], out, protocol=WHOLE).windows == 3  # any surface, zero acceleration
    assert {t.metadata["shape"] for t in load_trajectories(out)} == {"rect1", "hex"}
    only_pu = MitSelection(surfaces=("pu",))
    with pytest.raises(DataImportError, match=r"4 MIT pushes, none selected.*'abs', 'delrin'"):
        import_mit([src], out, only_pu, protocol=WHOLE)
    sel = MitSelection(surfaces=None, shapes=("rect1",))
    assert import_mit([src], out, sel, protocol=WHOLE).windows == 2
    assert main(["import-mit", str(src), "--out", str(out), "--surface", "any",
                              "--any-acceleration", "--duration", "0", "--start", "file",
                              "--dt", "0.02", "--keep-still", "--force"]) == 0
    trajs = load_trajectories(out)
    assert len(trajs) == 4 and max(t.num_steps for t in trajs) == 40


def test_bad_input_names_file_and_field(tmp_path: Path, capsys) -> None:
    with pytest.raises(DataImportError, match=r"shape=square.*'shape'.*unknown shape 'square'"):
        read_push(_write_raw(tmp_path, shape="square"))
    content = _streams()
    del content["ft_wrench"]
    with pytest.raises(DataImportError, match=r"\.json: missing field 'ft_wrench'"):
        read_push(_write_raw(tmp_path, shape="hex", content=content))
    content = _streams()
    content["object_pose"][5][2] = float("nan")
    with pytest.raises(DataImportError, match=r"tri1.*'object_pose'.*non-finite.*row 5"):
        read_push(_write_raw(tmp_path, shape="tri1", content=content))
    truncated = _write_raw(tmp_path, shape="tri3")
    truncated.write_text(truncated.read_text()[:100])
    with pytest.raises(DataImportError, match="tri3.*not a readable JSON"):
        read_push(truncated)
    with pytest.raises(DataImportError, match="does not follow"):
        parse_mit_name(tmp_path / "push_001.json")
    out = tmp_path / "out.h5"  # a bad file aborts an import without touching an existing output
    write_trajectories(out, [_one(_write_raw(tmp_path, shape="rect2"))])
    before = out.read_bytes()
    assert main(["import-mit", str(tmp_path), "--out", str(out), "--force"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "Traceback" not in err and "field '" in err
    assert out.read_bytes() == before
    with pytest.warns(UserWarning, match="skipped"):
        assert import_mit([tmp_path], out, protocol=WHOLE, skip_bad=True).windows == 1


# --------------------------------------------------------------------------- the real sample


@pytest.fixture(scope="module")
def sample_report():
    pushes = [read_push(p) for p in sorted(SAMPLE.glob("*.h5"))]
    return pushes, analyse(pushes, MitProtocol())


def test_sample_offsets_are_the_quarter_turns_and_the_tip_touches(sample_report) -> None:
    _, report = sample_report
    butter, ellip3 = report.shapes["butter"], report.shapes["ellip3"]
    # hand-checked: both outlines lie along x while the recorded frames have them along y; the
    # butter is symmetric under a half turn, so 90 and 270 degrees are the same offset
    assert math.degrees(butter.offset.theta) % 180 == pytest.approx(90, abs=3)
    assert math.degrees(ellip3.offset.theta) % 180 == pytest.approx(90, abs=3)
    assert butter.offset.status == ellip3.offset.status == "quarter"
    for c in (butter, ellip3):
        assert np.median(c.distances) == pytest.approx(geo.TIP_RADIUS, abs=0.0005)
        assert c.inside_fraction < 0.05
    # the steep push (80 degrees) slides off without moving the butter: reported, not imported
    assert butter.still == ["motion_surface=abs_shape=butter_a=0_v=50_i=0.000_s=0.850_t=1.396.h5"]


def test_offset_follows_a_turn_of_the_recorded_yaw_with_its_sign(sample_report,
                                                                  monkeypatch) -> None:
    """Recorded yaw + 20 deg: a recorded-frame point is 20 deg back, so theta grows by 20 deg
    (q_outline = R(theta) q_recorded). With the convention flipped it would shrink by 20."""
    pushes, _ = sample_report
    monkeypatch.setattr(geo, "QUARTER_TURN_DEG", 0.0)  # compare free rotations
    report = analyse([p for p in pushes if p.shape == "ellip3"], MitProtocol())
    turn = 20.0
    turned = [copy.deepcopy(p) for p in pushes if p.shape == "ellip3"]
    for p in turned:
        p.obj[:, 3] += math.radians(turn)
    again = analyse(turned, MitProtocol()).shapes["ellip3"].offset
    before = math.degrees(report.shapes["ellip3"].offset.theta)
    change = (math.degrees(again.theta) - before + 90) % 180 - 90  # the ellipse: mod a half turn
    assert change == pytest.approx(turn, abs=1.5)


def test_sample_windows_start_at_contact_and_mujoco_agrees(sample_report) -> None:
    pushes, report = sample_report
    push = next(p for p in pushes if "butter_a=0_v=100" in p.path.name)
    windows = push_windows(push, report.shapes["butter"].offset, MitProtocol())
    # hand-checked on this file: the tip rests against the butter (gap 0.0 mm) until it starts
    # to move, 0.5 mm by 0.224 s; the object has moved 0.5 mm by 0.244 s. The window starts
    # just before: the +-20 ms speed window sees the tip move from 0.1965 s on.
    start = windows[0].metadata["window_start_s"]
    assert start == pytest.approx(0.1965, abs=0.004) and start < 0.224
    assert windows[0].dt == 0.012 and windows[0].num_steps == 43  # 42 steps: 0.504 s
    # MuJoCo's own distance between the tip and the imported object, in the contact frames: this
    # push is in one of the butter's waists, where the convex hull would be 12 mm deep
    traj = windows[0]
    model = mujoco.MjModel.from_xml_string(traj.mjcf)
    data = mujoco.MjData(model)
    pieces = [g for g in range(model.ngeom) if model.geom_bodyid[g] == model.body("object").id]
    tip_g = model.geom("tip").id
    assert len(pieces) > 1
    moving = geo.contact_mask(np.arange(traj.num_steps) * traj.dt,
                              np.column_stack([traj.poses[:, 1, :2],
                                               np.unwrap(_yaw(traj.poses[:, 1, 3:]))]))
    dists = []
    for k in np.flatnonzero(moving):
        data.qpos[:7] = traj.poses[k, 1]
        data.mocap_pos[0], data.mocap_quat[0] = traj.poses[k, 2, :3], traj.poses[k, 2, 3:]
        mujoco.mj_kinematics(model, data)
        dists.append(min(mujoco.mj_geomDistance(model, data, g, tip_g, 0.05, None)
                         for g in pieces))
    assert len(dists) > 10
    assert np.mean(np.array(dists) < -geo.INSIDE_TOLERANCE) < 0.05
    assert abs(float(np.median(dists))) < 0.001


def test_check_cli_reports_every_shape(tmp_path: Path, capsys) -> None:
    out = tmp_path / "check.json"
    assert main(["check-mit", str(SAMPLE), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "butter" in text and "ellip3" in text and "still (never moves the object)" in text
    check = json.loads(out.read_text())
    assert set(check["shapes"]) == {"butter", "ellip3"}
    assert check["shapes"]["butter"]["inside_fraction"] < 0.05


def test_too_few_pushes_fall_back_to_the_reference_or_to_none(sample_report,
                                                             tmp_path: Path) -> None:
    pushes, _ = sample_report
    one = [p for p in pushes if p.shape == "ellip3"][:1]
    offset = analyse(one, MitProtocol()).shapes["ellip3"].offset
    assert offset.status == "reference" and math.degrees(offset.theta) == pytest.approx(90)
    # the user's own outlines may have another frame: no reference, no offset, flagged
    (tmp_path / "ellip3_ext.npy").write_bytes((geo.outline_dir() / "ellip3_ext.npy").read_bytes())
    offset = analyse(one, MitProtocol(outlines=str(tmp_path))).shapes["ellip3"].offset
    assert offset.status == "default" and offset.theta == 0.0


@pytest.mark.parametrize("shape", geo.MIT_SHAPES)
def test_convex_pieces_tile_the_outline(shape: str) -> None:
    poly = geo.outline(shape)
    pieces = convex_pieces(poly)
    assert all(geo.polygon_area(p) > 0 for p in pieces)
    assert sum(geo.polygon_area(p) for p in pieces) == pytest.approx(geo.polygon_area(poly))
    pts = np.random.default_rng(0).uniform(poly.min(0), poly.max(0), size=(2000, 2))
    inside = geo.signed_distance(pts, poly) < 0
    in_piece = np.stack([geo.signed_distance(pts, p) < 1e-12 for p in pieces]).any(axis=0)
    far = np.abs(geo.signed_distance(pts, poly)) > 1e-9
    np.testing.assert_array_equal(inside[far], in_piece[far])
    for p in pieces:  # each piece convex: every turn is to the left
        d = np.roll(p, -1, 0) - p
        assert np.all(d[:, 0] * np.roll(d[:, 1], -1) - d[:, 1] * np.roll(d[:, 0], -1) > -1e-12)


def test_offsets_from_a_report_are_used_as_given(tmp_path: Path, sample_report) -> None:
    _, report = sample_report
    path = tmp_path / "check.json"
    path.write_text(json.dumps(report.as_json()))
    given = offsets_from_report(path)
    assert set(given) == {"butter", "ellip3"}
    assert given["butter"][0] == pytest.approx(report.shapes["butter"].offset.theta)
    out = tmp_path / "w.h5"
    again = import_mit([SAMPLE], out, protocol=MitProtocol(offsets=given))
    assert again.shapes["butter"].offset.status == "given"
    assert again.windows == len(load_trajectories(out)) >= 4
    meta = load_trajectories(out)[0].metadata
    assert meta["frame_offset"]["status"] == "given"


def test_still_pushes_are_in_the_file_and_kept_on_request(tmp_path: Path) -> None:
    from fignet_gym.data.format import TrajectoryFile

    out = tmp_path / "a.h5"
    import_mit([SAMPLE], out)
    with TrajectoryFile(out) as f:
        files = {f[i].metadata["file"] for i in range(len(f))}
        check = f.metadata["check"]
    still = "motion_surface=abs_shape=butter_a=0_v=50_i=0.000_s=0.850_t=1.396.h5"
    assert still not in files and check["shapes"]["butter"]["still_pushes"] == [still]
    import_mit([SAMPLE], tmp_path / "b.h5", protocol=MitProtocol(keep_still=True))
    assert still in {t.metadata["file"] for t in load_trajectories(tmp_path / "b.h5")}


def test_moving_mask_ignores_tracking_noise_at_rest() -> None:
    rng = np.random.default_rng(0)
    times = np.arange(500) * 0.004
    rest = np.column_stack([np.zeros(500), np.zeros(500), np.zeros(500)])
    noisy = rest + rng.normal(size=rest.shape) * [5e-4, 5e-4, math.radians(0.5)]
    assert not geo.contact_mask(times, noisy).any()  # 0.5 mm white noise reads ~18 mm/s
    moving = noisy.copy()
    moving[250:, 0] += 0.2 * (times[250:] - times[250])  # 200 mm/s from sample 250 on
    mask = geo.contact_mask(times, moving)
    assert mask[270:490].all() and not mask[:230].any()


@pytest.mark.parametrize(("shape", "degrees"), [("rect1", 90), ("rect2", 180), ("hex", 60),
                                                 ("tri1", 360), ("butter", 180), ("ellip3", 180)])
def test_symmetry_angles_of_the_outlines(shape: str, degrees: float) -> None:
    assert math.degrees(geo.symmetry_angle(geo.outline(shape))) == pytest.approx(degrees)


def test_a_window_shorter_than_a_step_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="at least one step"):
        import_mit([SAMPLE], tmp_path / "x.h5", protocol=MitProtocol(window=0.005))
    assert not (tmp_path / "x.h5").exists()


def _square_contacts(shift: np.ndarray, turn_deg: float) -> list[np.ndarray]:
    """Tip centres ``TIP_RADIUS`` outside each side of rect1 (40 per side, one push per side),
    expressed in a recorded frame turned by ``turn_deg`` and shifted by ``shift`` (m) from the
    outline's: ``outline = R(turn) q + shift``."""
    poly, rng = geo.outline("rect1"), np.random.default_rng(0)
    pushes = []
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        edge = b - a
        normal = np.array([edge[1], -edge[0]]) / np.linalg.norm(edge)
        normal *= np.sign(np.dot(normal, (a + b) / 2 - poly.mean(0)))
        p = a + rng.uniform(0.2, 0.8, (40, 1)) * edge + geo.TIP_RADIUS * normal
        pushes.append((p - shift) @ geo.rotation(math.radians(turn_deg)))
    return pushes


@pytest.mark.parametrize("theta0", [0.0, 4.16e-16, 1e-12, 2 * math.pi - 4e-16])
def test_shift_refit_at_a_fixed_rotation_leaves_its_start(theta0: float) -> None:
    """A user's surface: a quarter-turn rounding left theta0 = 4.16e-16 instead of 0, and the
    shift-only refit, with the rotation boxed to theta0 +- 1e-9, never moved from (0, 0)."""
    shift = np.array([0.0006, -0.0004])
    pts = np.concatenate(_square_contacts(shift, 0.0))
    theta, found, _, (ended, evals) = geo._refine(pts, np.ones(len(pts)), geo.outline("rect1"),
                                                  theta0, False)
    assert theta == pytest.approx(theta0 % (2 * math.pi))
    np.testing.assert_allclose(found, shift, atol=2e-5)
    assert ended == "converged" and evals > 1


def test_the_report_says_how_each_shapes_refit_ended() -> None:
    """``check-mit``'s convergence column: a shift the contacts pin converges; one beyond
    ``MAX_OFFSET_SHIFT`` stops at the bound and says so (weakly determined or wrong outline)."""
    from fignet_gym.data.mit import MitReport, _refit_label

    pinned = np.concatenate(_square_contacts(np.array([0.0006, -0.0004]), 0.0))
    far = np.concatenate(_square_contacts(np.array([2.0 * geo.MAX_OFFSET_SHIFT, 0.0]), 0.0))
    poly = geo.outline("rect1")
    ok = geo.estimate_offset(poly, [pinned[i::4] for i in range(4)])
    bound = geo.estimate_offset(poly, [far[i::4] for i in range(4)])
    assert ok.refit == "converged" and bound.refit == "at bound"
    assert ok.as_json()["refit"] == "converged" and ok.evaluations > 1
    assert _refit_label(ok).startswith("converged (") and _refit_label(geo.FrameOffset()) == "-"
    report = MitReport()
    assert "refit" in report.table().splitlines()[0]


@pytest.mark.parametrize("turn", [-1.0, 0.5, 2.0, 89.0])
def test_square_frame_turned_by_a_small_angle_gives_the_quarter_turn_and_the_shift(turn: float) -> None:
    """Recorded frame turned by ``turn`` (within QUARTER_TURN_DEG of a quarter turn) and shifted
    by (0.6, -0.4) mm: the rotation rounds to the quarter turn and the shift is the turned shift
    to 0.25 mm (the residual turn of up to 2 deg moves the contacts by about that)."""
    shift = np.array([0.0006, -0.0004])
    off = geo.estimate_offset(geo.outline("rect1"), _square_contacts(shift, turn))
    assert off.status == "quarter"
    degrees = math.degrees(off.theta) % 90
    assert min(degrees, 90 - degrees) < 1e-9
    # the square is symmetric under quarter turns: the shift is the true one turned to the
    # quarter turn the fit picked
    k = round(math.degrees(off.theta) / 90)
    quarter = math.radians(90 * k - round(turn / 90) * 90)
    expected = geo.rotation(quarter) @ shift
    assert np.linalg.norm(np.asarray(off.shift) - expected) < 2.5e-4
