"""MuJoCo replay of trajectory files, system identification, and the sim2real command."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pytest

from fignet_gym.cli import main
from fignet_gym.data.format import load_trajectories, write_trajectories
from fignet_gym.data.generate import iter_trajectories
from fignet_gym.data.tracked import import_contactnets, tracked_trajectory
from fignet_gym.dynamics.contact_params import ContactParams
from fignet_gym.dynamics.mujoco import MujocoDynamics
from fignet_gym.mjcf import cube_scene_xml
from fignet_gym.train.analytic import Replay, finite_difference_state
from fignet_gym.train.sysid import DEFAULT_SPACE, Dimension, ReplaySet, fit_contact_params, replay_loss

SAMPLE = Path(__file__).parent / "data" / "contactnets_sample"
MIT_SAMPLE = Path(__file__).parent / "data" / "mit_sample"
DT = 1 / 148


def _quat_about(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])


def test_finite_differences_are_exact_for_free_flight() -> None:
    """Uniform acceleration and a constant spin: central differences give the state exactly."""
    v0, g, axis, rate = np.array([0.3, -0.2, 1.0]), np.array([0, 0, -9.81]), np.array([1.0, 2, 3]), 7.0
    q0 = _quat_about(np.array([0.0, 1, 0]), 0.4)
    poses = np.zeros((3, 1, 7))
    for k in range(3):
        t = k * DT
        poses[k, 0, :3] = v0 * t + 0.5 * g * t**2
        dq = np.empty(4)
        mujoco.mju_mulQuat(dq, _quat_about(axis, rate * t), q0)
        poses[k, 0, 3:] = dq
    k, qvel = finite_difference_state(poses, DT)
    assert k == 1
    np.testing.assert_allclose(qvel[0, :3], v0 + g * DT, atol=1e-9)
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, poses[1, 0, 3:])
    w_world = rate * axis / np.linalg.norm(axis)
    np.testing.assert_allclose(qvel[0, 3:], rot.reshape(3, 3).T @ w_world, atol=1e-9)


def test_replay_of_generated_pushes_reproduces_them() -> None:
    """MuJoCo itself is the oracle: replaying a generated push with its own MJCF and substeps
    (objects at rest for the first poses, the tip on its recorded path) gives back its poses."""
    dyn = MujocoDynamics(nthread=1)
    for t in iter_trajectories("push", 2, seed=5):
        pred = Replay(t).rollout(ContactParams(substeps=t.metadata["substeps"]), dyn, given=3)
        obj = t.kinds == 0
        err = np.abs(pred[:, obj, :3] - t.poses[:, obj, :3]).max()
        moved = np.abs(t.poses[-1, obj, :3] - t.poses[0, obj, :3]).max()
        assert moved > 5e-3 and err < 0.02 * moved
        # wrong physics is visible: ten times the friction moves the object differently
        wrong = Replay(t).rollout(ContactParams(substeps=t.metadata["substeps"], friction=2.5,
                                                friction_kinematic=2.5), dyn, given=3)
        assert np.abs(wrong[:, obj, :3] - t.poses[:, obj, :3]).max() > 5 * err


def _synthetic_tosses(n: int, friction: float, dampratio: float, cone: str, seed: int = 0) -> list:
    """Cube tosses simulated here in MuJoCo with known contact parameters (4 substeps per pose)."""
    rng = np.random.default_rng(seed)
    xml = cube_scene_xml(0.0524, 0.37, 8e-4, 0.18, 0.125, timestep=DT / 4)
    model = mujoco.MjModel.from_xml_string(xml)
    ContactParams(friction=friction, dampratio=dampratio, cone=cone, substeps=4).apply(model, DT)
    data = mujoco.MjData(model)
    out = []
    for i in range(n):
        mujoco.mj_resetData(model, data)
        data.qpos[:3] = [0, 0, rng.uniform(0.15, 0.25)]
        data.qpos[3:7] = _quat_about(rng.normal(size=3), rng.uniform(0, np.pi))
        data.qvel[:3] = [rng.uniform(0.5, 1.5), rng.uniform(-0.3, 0.3), rng.uniform(-0.5, 0.5)]
        data.qvel[3:] = rng.normal(scale=4.0, size=3)
        track = []
        for k in range(90):
            if k:
                mujoco.mj_step(model, data, 4)
            track.append(data.qpos[:7].copy())
        out.append(tracked_trajectory(xml, {"cube": np.array(track)}, DT, name=f"syn{i}"))
    return out


def test_system_identification_recovers_a_known_friction(tmp_path: Path) -> None:
    true_mu = 0.45
    trajs = _synthetic_tosses(8, true_mu, 1.0, "elliptic")
    train, valid = trajs[:5], trajs[5:]
    rs = ReplaySet(train)
    at = lambda mu: replay_loss(rs.frame_errors(rs.predict(ContactParams(  # noqa: E731
        friction=mu, dampratio=1.0, cone="elliptic"))), 3)
    # the loss has its minimum at the truth (the oracle for the optimiser below)
    assert at(true_mu) < at(0.18) and at(true_mu) < at(1.0)
    space = (Dimension("friction", 0.05, 1.5),)
    fit = fit_contact_params(train, valid, tmp_path / "fit.json", base=ContactParams(dampratio=1.0),
                             space=space, cones=("elliptic",), evaluations=24, substeps=(4,),
                             progress=False)
    assert fit["params"]["friction"] == pytest.approx(true_mu, rel=0.1)
    assert fit["params"]["cone"] == "elliptic"
    # a finished fit is read back, not redone
    again = fit_contact_params(train, valid, tmp_path / "fit.json", space=space, evaluations=1)
    assert again == json.loads((tmp_path / "fit.json").read_text())


def test_contact_params_apply_and_round_trip() -> None:
    model = mujoco.MjModel.from_xml_string(cube_scene_xml(0.05, 0.37, 8e-4, 0.18, 0.125))
    p = ContactParams(friction=0.3, timeconst=0.01, dampratio=0.9, cone="elliptic", impratio=3.0,
                      gravity=-9.6, substeps=5)
    p.apply(model, 0.01)
    assert model.geom_friction[:, 0].tolist() == [0.3, 0.3]
    assert model.geom_solref.tolist() == [[0.01, 0.9], [0.01, 0.9]]
    assert model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and model.opt.impratio == 3.0
    assert model.opt.timestep == pytest.approx(0.002) and model.opt.gravity[2] == -9.6
    assert ContactParams.from_json(p.to_json()) == p
    with pytest.raises(ValueError, match="unknown contact parameters"):
        ContactParams.from_json({"frction": 0.2})
    assert {d.name for d in DEFAULT_SPACE} <= set(ContactParams.__dataclass_fields__)


def test_sim2real_mujoco_stages_on_the_real_sample(tmp_path: Path, capsys) -> None:
    data = tmp_path / "cube.h5"
    import_contactnets(SAMPLE, data)
    out = tmp_path / "run"
    argv = ["sim2real", "--data", str(data), "--out", str(out), "--no-fignet", "--fractions", "0.5",
            "0.25", "0.25", "--fit-evaluations", "6", "--fit-trajectories", "2"]
    assert main(argv) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["split"] == {"train": 2, "valid": 1, "test": 1}
    for key in ("mujoco_nominal", "mujoco_fitted", "no_motion"):
        assert math.isfinite(res[key]["translation_rmse_final"])
        assert res[key]["horizon_step"] == 50
    assert res["no_motion"]["translation_rmse_final_ratio_still"] == 1.0
    assert "MuJoCo, fitted" in (out / "table.md").read_text()
    assert (out / "errors_vs_size.png").stat().st_size > 0
    env = ContactParams.load(out / "mujoco_fitted_env.json")  # the shipped format: no conversion
    assert env == replace(ContactParams.from_json(res["fit"]["params"]), source=env.source)
    # a second run without --resume refuses to overwrite; with it, nothing is redone
    assert main(argv) == 2
    assert "--resume" in capsys.readouterr().err
    before = (out / "mujoco_fit.json").stat().st_mtime_ns
    assert main(argv + ["--resume"]) == 0
    assert (out / "mujoco_fit.json").stat().st_mtime_ns == before
    # too few trajectories for the split, and sizes beyond the training split, are errors
    assert main(["sim2real", "--data", str(data), "--out", str(tmp_path / "r2"), "--sizes", "3",
                 "--fractions", "0.5", "0.25", "0.25"]) == 2
    err = capsys.readouterr().err
    assert "error: " in err and "cube.h5" in err and "size 3 exceeds" in err
    assert main(["sim2real", "--data", str(data), "--out", str(tmp_path / "r3"), "--no-fignet",
                 "--fractions", "0.9", "0.05", "0.05"]) == 2
    assert "too few" in capsys.readouterr().err


def test_sim2real_splits_by_recording(tmp_path: Path, capsys) -> None:
    """sim2real's split is ``split``'s: trajectories sharing ``metadata["file"]`` (windows of one
    push) count as one recording, and too few recordings are refused before anything is written."""
    data = tmp_path / "cube.h5"
    import_contactnets(SAMPLE, data)
    trajs = load_trajectories(data)
    files = ["a", "a", "b", "c"]  # 4 trajectories, 3 recordings: 0.5/0.25/0.25 leaves no test
    shared = tmp_path / "shared.h5"
    write_trajectories(shared, [replace(t, metadata={**t.metadata, "file": f})
                                for t, f in zip(trajs, files, strict=True)])
    argv = ["sim2real", "--data", str(shared), "--out", str(tmp_path / "run"), "--no-fignet",
            "--fractions", "0.5", "0.25", "0.25"]
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "shared.h5" in err[0] and "from 3 recordings" in err[0]
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
def test_sim2real_evaluates_a_trained_fignet_against_fitted_mujoco(tmp_path: Path) -> None:
    """The FIGNet stage calls the training function and scores its checkpoint on the test split."""
    from fignet_gym.train.sim2real import run_sim2real

    data = tmp_path / "cube.h5"
    import_contactnets(SAMPLE, data)
    calls = []

    def train(train_file: Path, valid_file: Path, size: int | None, out_dir: Path) -> Path:
        from fignet_gym.train.real import train_on_split

        calls.append(size)
        return train_on_split(train_file, valid_file, size, out_dir, budget=2,
                              overrides={"training.valid_every": 1, "training.batch_size": 1,
                                         "training.valid_trajectories": 1})

    res = run_sim2real(data, tmp_path / "run", sizes=(1, None), fractions=(0.5, 0.25, 0.25),
                       fit_evaluations=4, fit_trajectories=2, train_fn=train)
    assert calls == [1, None]
    assert set(res["fignet"]) == {"1", "all"}
    r = res["fignet"]["all"]
    assert r["training_trajectories"] == 2
    ratio, lo, hi = r["vs_fitted_mujoco"]["translation_rmse"]
    fitted = res["mujoco_fitted"]["translation_rmse_final"]
    assert ratio == pytest.approx(r["translation_rmse_final"] / fitted)
    assert lo <= ratio <= hi


def _outline_distance(outline: np.ndarray, p: np.ndarray) -> float:
    """Distance from point ``p float[2]`` to a closed polygon's boundary."""
    a, b = outline, np.roll(outline, -1, 0)
    ab = b - a
    t = np.clip(((p - a) * ab).sum(1) / (ab * ab).sum(1), 0, 1)
    return float(np.linalg.norm(a + t[:, None] * ab - p, axis=1).min())


def test_mit_standin_has_noise_per_push_friction_and_pusher_penetration(tmp_path: Path) -> None:
    from fignet_gym.data.mit import MitProtocol, import_mit
    from fignet_gym.mjcf import MIT_OBJECTS

    raw = tmp_path / "raw"
    assert main(["mit-standin", "--out", str(raw), "--num", "3", "--seed", "2"]) == 0
    files = sorted(raw.glob("*.json"))
    frictions = {json.loads(f.read_text())["standin"]["friction"] for f in files}
    assert len(files) == 3 and len(frictions) == 3
    whole = MitProtocol(dt=0.02, window=0.0, start="file", keep_still=True)
    assert import_mit([raw], tmp_path / "p.h5", protocol=whole).windows == 3
    closest = []
    for t in load_trajectories(tmp_path / "p.h5"):
        obj, tip = t.poses[:, 1], t.poses[:, 2]
        outline = MIT_OBJECTS[t.metadata["shape"]].outline
        for k in range(t.num_steps):
            yaw = 2 * math.atan2(obj[k, 6], obj[k, 3])
            c, s = math.cos(yaw), math.sin(yaw)
            local = np.array([[c, s], [-s, c]]) @ (tip[k, :2] - obj[k, :2])
            closest.append(_outline_distance(outline, local))
        # tracking noise: the recorded object jitters while it is still at rest
        still = obj[:5, :2]
        assert 1e-5 < np.abs(np.diff(still, axis=0)).max() < 5e-3
    # in contact (tip centre within 6 mm of the outline), the recorded tip centre is ~1 mm closer
    # than the imported tip's 4.75 mm radius: the median contact distance is about 3.75 mm
    near = np.array([d for d in closest if d < 0.006])
    assert len(near) > 10 and float(np.median(near)) < 0.0043


# --------------------------------------------------------------------------- synthetic pretraining


def _horizontal_speed(poses: np.ndarray, o: int, dt: float) -> float:
    return float(np.linalg.norm((poses[2, o, :2] - poses[0, o, :2]) / (2 * dt)))


def test_synthetic_tosses_are_mujoco_from_a_varied_release(tmp_path: Path) -> None:
    from fignet_gym.train.synthetic import Perturbation, synthetic_tosses

    data = tmp_path / "cube.h5"
    import_contactnets(SAMPLE, data)
    src = load_trajectories(data)
    params = ContactParams(friction=0.18, cone="elliptic", substeps=4)
    synth = synthetic_tosses(src, params, 4, seed=3, progress=False)
    again_seeded = synthetic_tosses(src, params, 4, seed=3, progress=False)
    assert all(np.array_equal(a.poses, b.poses) for a, b in zip(synth, again_seeded, strict=True))
    other = synthetic_tosses(src, params, 4, seed=4, progress=False)
    assert not np.array_equal(synth[0].poses, other[0].poses)
    by_name = {t.name: t for t in src}
    dyn = MujocoDynamics(nthread=1)
    for t in synth:
        s = by_name[t.metadata["synthetic_from"]]
        assert t.poses.shape == s.poses.shape and t.mjcf == s.mjcf
        o = int(np.flatnonzero(t.kinds == 0)[0])
        # The release is the source's, varied within the stated ranges: the horizontal speed
        # (central difference of poses 0 and 2, as MuJoCo starts) by 0.85-1.15x, a new orientation.
        ratio = _horizontal_speed(t.poses, o, t.dt) / _horizontal_speed(s.poses, o, s.dt)
        assert 0.85 - 1e-3 <= ratio <= 1.15 + 1e-3
        assert abs(abs(float(t.poses[1, o, 3:] @ s.poses[1, o, 3:])) - 1) > 1e-3
        assert t.poses[1, o, 2] == pytest.approx(s.poses[1, o, 2], abs=1e-6)  # same release height
        # Every later pose is the fitted MuJoCo's from that release: replaying the synthetic
        # toss's own first poses in MuJoCo follows it through the free flight (not exactly: pose
        # 2 is MuJoCo's, so the replay's central difference differs by MuJoCo's integration
        # error of one step, tens of micrometres) ...
        again = Replay(t).rollout(params, dyn, given=3)
        assert np.abs(again[:8, o, :3] - t.poses[:8, o, :3]).max() < 3e-4
        # ... which the source's own release does not.
        assert np.abs(Replay(s).rollout(params, dyn, given=3)[:8, o, :3] - t.poses[:8, o, :3]).max() > 3e-3
        assert t.poses[1:, o, 2].min() < t.poses[1, o, 2] - 0.05  # it falls and lands
    narrow = synthetic_tosses(src, params, 2, seed=3, progress=False,
                              perturbation=Perturbation(speed_scale=(1.0, 1.0), random_orientation=False))
    for t in narrow:
        s = by_name[t.metadata["synthetic_from"]]
        o = int(np.flatnonzero(t.kinds == 0)[0])
        speed = _horizontal_speed(s.poses, o, s.dt)
        assert _horizontal_speed(t.poses, o, t.dt) == pytest.approx(speed, rel=1e-4)


def test_synthetic_tosses_refuse_pushes_and_tosses_that_start_on_the_ground(tmp_path: Path) -> None:
    from fignet_gym.train.synthetic import check_tosses, synthetic_tosses

    push = next(iter_trajectories("push", 1, seed=5))
    with pytest.raises(ValueError, match="kinematic objects"):
        synthetic_tosses([push], ContactParams(), 1, progress=False)
    data = tmp_path / "cube.h5"
    import_contactnets(SAMPLE, data)
    toss = load_trajectories(data)[0]
    o = int(np.flatnonzero(toss.kinds == 0)[0])
    poses = toss.poses.copy()
    poses[:, o, 2] -= poses[1, o, 2] - 0.05  # the cube's centre 5 cm up: a corner is in the ground
    from dataclasses import replace

    with pytest.raises(ValueError, match="starts on the ground"):
        check_tosses([replace(toss, poses=poses)])
    check_tosses([toss])
    # Released face-down 1.1 cm above the ground: almost no random orientation clears 1 cm.
    low = toss.poses.copy()
    low[:, o, 2] += 0.0635 - low[1, o, 2]
    low[:, o, 3:] = [1.0, 0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="releases drawn"):
        synthetic_tosses([replace(toss, poses=low)], ContactParams(), 1, progress=False)


def test_sim2real_pretrain_fits_on_the_smallest_subset_and_fine_tunes_each_size(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    import fignet_gym.train.sim2real as s2r

    data = tmp_path / "cube.h5"
    import_contactnets(SAMPLE, data)
    monkeypatch.setattr(s2r, "PRETRAIN_STEPS", 2)
    out = tmp_path / "run"
    tiny = json.dumps({"training.valid_every": 1, "training.batch_size": 1,
                       "training.valid_trajectories": 1})
    argv = ["sim2real", "--data", str(data), "--out", str(out), "--fractions", "0.5", "0.25",
            "0.25", "--fit-evaluations", "4", "--fit-trajectories", "2", "--sizes", "1", "all",
            "--budget", "2", "--pretrain", "3", "--set", tiny]
    assert main(argv) == 0
    res = json.loads((out / "results.json").read_text())
    pre = res["pretrain"]
    assert pre["source_trajectories"] == 1 and pre["synthetic_tosses"] == 3
    assert len(load_trajectories(out / "pretrain" / "synthetic.h5")) == 3
    split = json.loads((out / "split" / "split.json").read_text())
    fit = json.loads((out / "pretrain" / "fit.json").read_text())
    assert fit["params"] != res["fit"]["params"]  # fitted on 1 trajectory, not the split's 2
    synth_from = {t.metadata["synthetic_from"] for t in load_trajectories(out / "pretrain" / "synthetic.h5")}
    assert synth_from == {load_trajectories(out / "split" / "train.h5")[0].name}
    assert len(split["train"]) == 2
    for label in ("1", "all"):
        run_cfg = json.loads((out / f"fignet_{label}" / "config.json").read_text())
        assert run_cfg["training"]["lr"] == s2r.FINETUNE_OVERRIDES["training.lr"]
    assert set(res["cpu_hours"]["fignet"]) == {"1", "all"}
    parts = res["cpu_hours"]
    stages = (parts["mujoco_fit"] + parts["pretrain"] + parts["noise_floor"]  # tosses: no limit surface
              + sum(parts["fignet"].values()))
    assert "limit_surface" not in parts
    assert parts["total"] == pytest.approx(stages)
    assert "initialised from" in capsys.readouterr().out
    # --pretrain and --init exclude each other; a run started without --pretrain is not resumed with it
    # Refused before anything is written: tosses pretrain from scratch, on the MuJoCo prior only.
    fresh = [str(tmp_path / "fresh") if a == str(out) else a for a in argv]
    assert main(fresh + ["--init", "push"]) == 2
    assert "--pretrain and --init: synthetic tosses pretrain from scratch" in capsys.readouterr().err
    assert main(fresh + ["--prior", "limit-surface"]) == 2
    assert "the limit surface models pushes" in capsys.readouterr().err
    assert not (tmp_path / "fresh").exists()
    assert main([a if a != "3" else "0" for a in argv] + ["--resume"]) == 2
    assert "started with pretrain 3 (now 0):" in capsys.readouterr().err
    assert main(argv + ["--resume", "--no-polish"]) == 2  # polished sizes would be stale
    assert "started with polish True (now False):" in capsys.readouterr().err


# --------------------------------------------------------------------------- the pushing path


def test_pushes_rest_on_the_floor_and_tosses_do_not(tmp_path: Path) -> None:
    """Pushes carry no free flight: they are recognised from their poses (so no gravity is
    measured), tosses are not; lifting a push's object by 2 cm makes it a non-resting file."""
    from fignet_gym.train.sim2real import rests_on_floor

    raw = tmp_path / "raw"
    assert main(["mit-standin", "--out", str(raw), "--num", "2", "--seed", "1"]) == 0
    assert main(["import-mit", str(raw), "--out", str(tmp_path / "p.h5")]) == 0
    pushes = load_trajectories(tmp_path / "p.h5")
    assert rests_on_floor(pushes)
    lifted = pushes[0]
    lifted.poses[5:, 1, 2] += 0.02
    assert not rests_on_floor([lifted])
    tosses = list(iter_trajectories("toss-simple", 1, seed=0))
    assert not rests_on_floor(tosses)


def test_sim2real_pushing_standin_command_runs_end_to_end(tmp_path: Path, capsys) -> None:
    """The documented stand-in commands (docs/sim2real.md), on a tiny file and budget: a fine-tune
    of ``push`` keeps its own gravity prior (a pushed object never flies), the fit searches
    no gravity, and a fresh run says nothing about resuming."""
    raw, data, out = tmp_path / "raw", tmp_path / "standin.h5", tmp_path / "s2r"
    assert main(["mit-standin", "--out", str(raw), "--num", "10", "--seed", "0"]) == 0
    assert main(["import-mit", str(raw), "--out", str(data)]) == 0
    assert main(["sim2real", "--data", str(data), "--out", str(out), "--horizon", "10",
                 "--sizes", "2", "--config", "push-finetune", "--init", "push", "--budget", "2",
                 "--fit-evaluations", "3", "--fit-trajectories", "2", "--no-polish"]) == 0
    assert "--resume" not in capsys.readouterr().out
    results = json.loads((out / "results.json").read_text())
    assert results["rests_on_floor"] and set(results["fignet"]) == {"2"}
    fit = json.loads((out / "mujoco_fit.json").read_text())
    assert "gravity" not in fit["params"] and "friction_kinematic" in fit["params"]
    from fignet_gym.pretrained import load_pretrained

    gravity = json.loads((out / "fignet_2" / "split.json").read_text())["gravity"]
    assert gravity == list(load_pretrained("push").config.gravity)
    assert {"limit_surface", "noise_floor"} <= set(results)
    table = (out / "table.md").read_text()
    assert "limit surface, fitted" in table and "noise floor" in table
    sides = [{t.metadata["file"] for t in load_trajectories(out / "split" / f"{s}.h5")}
             for s in ("train", "valid", "test")]
    assert not (sides[0] & sides[1] or sides[0] & sides[2] or sides[1] & sides[2])


def test_tracking_noise_recovers_known_noise_and_zero_noise_has_no_floor() -> None:
    """White noise of known size on smooth planar tracks is estimated within 10%; the fitted
    MuJoCo replayed from unperturbed starts reproduces itself (zero floor, to rounding)."""
    from fignet_gym.train.real_baselines import noise_floor, tracking_noise

    trajs = list(iter_trajectories("push", 3, seed=3))  # MuJoCo pushes: smooth tracks
    rng = np.random.default_rng(0)
    sigma, sigma_deg = 2e-4, 0.2
    noisy = []
    for t in trajs:
        poses = np.array(t.poses)
        poses[:, 1, :2] += rng.normal(0, sigma, poses[:, 1, :2].shape)
        yaw = 2 * np.arctan2(poses[:, 1, 6], poses[:, 1, 3]) + np.radians(
            rng.normal(0, sigma_deg, len(poses)))
        poses[:, 1, 3:] = np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], 1)
        noisy.append(type(t)(**{**t.__dict__, "poses": poses}))
    est = tracking_noise(noisy)
    assert est["planar"]
    assert est["position_m"] == pytest.approx(sigma, rel=0.1)
    assert est["rotation_deg"] == pytest.approx(sigma_deg, rel=0.1)
    floor = noise_floor(trajs[:2], ContactParams(substeps=trajs[0].metadata["substeps"]),
                        {"position_m": 0.0, "rotation_deg": 0.0, "planar": True}, horizon=10,
                        samples=1)
    assert floor["translation_rmse_final"] < 1e-8 and floor["rotation_deg_final"] < 1e-5


def test_sim2real_refuses_before_writing_and_a_corrected_rerun_needs_no_resume(tmp_path: Path) -> None:
    """A size larger than the training split, and a fine-tune of a 0.02 s model on 0.012 s
    pushes, are refused in one line with nothing written, so the corrected command runs as is."""
    from fignet_gym.train.sim2real import Sim2RealError, run_sim2real

    raw, out = tmp_path / "raw", tmp_path / "s2r"
    assert main(["mit-standin", "--out", str(raw), "--num", "10", "--seed", "0"]) == 0
    fast, data = tmp_path / "fast.h5", tmp_path / "standin.h5"
    assert main(["import-mit", str(raw), "--out", str(fast), "--dt", "0.012"]) == 0
    assert main(["import-mit", str(raw), "--out", str(data)]) == 0  # default: the models' 0.02 s
    assert load_trajectories(data)[0].dt == pytest.approx(0.02)
    common = ["--out", str(out), "--horizon", "10", "--config", "push-finetune", "--init", "push",
              "--budget", "2", "--fit-evaluations", "3", "--fit-trajectories", "2", "--no-polish"]
    with pytest.raises(Sim2RealError, match=r"poses every 0.012 s, but --init push steps 0.02 s .*--dt 0.02"):
        run_sim2real(fast, out, sizes=(2,), horizon=10, config="push-finetune", init="push", budget=2)
    assert not out.exists()
    assert main(["sim2real", "--data", str(data), "--sizes", "500", *common]) == 2
    assert not out.exists()  # so the corrected command (the end-to-end test above) runs as is


def test_sim2real_pretrains_pushes_on_both_fitted_models_from_init(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    """``--pretrain N --prior both`` on real pushes: half the synthetic pushes from the MuJoCo and
    half from the limit surface fitted on the smallest size, pretrained from ``--init``; each
    size then fine-tunes it with the pushes' own recipe (not the tosses' gentle one)."""
    import fignet_gym.train.sim2real as s2r
    from fignet_gym.train.config import PRESETS

    data, out = tmp_path / "abs.h5", tmp_path / "run"
    assert main(["import-mit", str(MIT_SAMPLE), "--out", str(data), "--dt", "0.02"]) == 0
    monkeypatch.setattr(s2r, "PUSH_PRETRAIN_STEPS", 2)
    tiny = json.dumps({"training.valid_every": 1, "training.batch_size": 1,
                       "training.valid_trajectories": 1})
    assert main(["sim2real", "--data", str(data), "--out", str(out), "--fractions", "0.34", "0.33",
                 "0.33", "--horizon", "25", "--fit-evaluations", "3", "--fit-trajectories", "1",
                 "--sizes", "1", "--config", "push-finetune", "--init", "push", "--budget", "2",
                 "--no-polish", "--pretrain", "4", "--prior", "both", "--set", tiny]) == 0
    res = json.loads((out / "results.json").read_text())
    pre = res["pretrain"]
    assert pre["prior"] == "both" and pre["synthetic_pushes"] == 4 and pre["source_trajectories"] == 1
    synth = load_trajectories(out / "pretrain" / "synthetic.h5")
    pushes = {(t.metadata["synthetic_source"], t.metadata["file"]) for t in synth}
    assert {src for src, _ in pushes} <= {"mujoco", "limit-surface"} and len(pushes) <= 4
    assert json.loads((out / "pretrain" / "limit_surface_fit.json").read_text())["tip_friction"] > 0
    assert json.loads((out / "run.json").read_text())["prior"] == "both"
    printed = capsys.readouterr().out
    pretraining = printed[printed.index("pretraining: FIGNet"):printed.index("FIGNet on 1 training")]
    assert "initialised from push" in pretraining
    fine = json.loads((out / "fignet_1" / "config.json").read_text())
    assert fine["training"]["lr"] == PRESETS["push-finetune"]["training"]["lr"]
    assert fine["training"]["lr"] != s2r.FINETUNE_OVERRIDES["training.lr"]


def test_fit_counts_mujoco_instabilities_in_one_line_and_its_bar_ends_at_its_total(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    """MuJoCo's 'Nan, Inf or huge value' warnings during the fit are counted per candidate and
    summarised in one line, never printed raw nor appended to ``MUJOCO_LOG.TXT`` in the working
    directory; the progress bar's total is the evaluations CMA-ES really runs (whole
    generations), and it ends there."""
    import fignet_gym.train.sysid as sysid

    trajs = _synthetic_tosses(3, 0.45, 1.0, "elliptic")
    blow = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint/><geom size='1'/></body></worldbody></mujoco>")
    calls = {"n": 0}
    predict = ReplaySet.predict

    def unstable_every_third(self, params):
        calls["n"] += 1
        if calls["n"] % 3 == 0:  # a real MuJoCo instability warning
            d = mujoco.MjData(blow)
            d.qvel[:] = 1e30
            mujoco.mj_step(blow, d)
        return predict(self, params)

    bars = []

    class Bar:
        def __init__(self, total=None, **_):
            self.total, self.first_total, self.n = total, total, 0
            bars.append(self)

        def update(self, k):
            self.n += k

        def close(self):
            self.closed = (self.n, self.total)

    monkeypatch.setattr(ReplaySet, "predict", unstable_every_third)
    monkeypatch.setattr(sysid, "tqdm", Bar)
    monkeypatch.chdir(tmp_path)
    fit = fit_contact_params(trajs[:2], trajs[2:], None, base=ContactParams(dampratio=1.0),
                             space=(Dimension("friction", 0.05, 1.5),), cones=("elliptic",),
                             evaluations=7, substeps=(4,))
    run = fit["cone_runs"][0]
    out = capsys.readouterr().out
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
    assert "WARNING" not in out and "Nan, Inf" in out and out.count("went unstable") == 1
    assert run["unstable_candidates"] == run["evaluations"] // 3  # the fit's own replays
    (bar,) = bars
    assert bar.closed == (run["evaluations"], run["evaluations"]) and run["evaluations"] > 7
    assert bar.first_total == run["evaluations"]  # shown from the start, not corrected at the end
    assert mujoco.get_mju_user_warning() is None  # MuJoCo's own handler is back


def test_the_table_orders_sizes_and_says_seconds_and_the_per_recording_view() -> None:
    """Rows by training-set size whatever order ``--sizes`` was typed in; the horizon in seconds
    beside its frame; the per-recording block when the run has one."""
    from fignet_gym.train.sim2real_report import format_table

    def r(tr: float, n: int | None = None) -> dict:
        out = {k: tr for k in ("translation_rmse_final", "rotation_deg_final",
                               "translation_rmse_last", "rotation_deg_last")}
        out.update({f"{k}_ratio_still": 0.5 for k in list(out)}, horizon_step=25, trajectories=22,
                   seconds=0.5)
        if n is not None:
            out.update(training_trajectories=n, vs_fitted_mujoco={
                k: [1.0, 0.5, 2.0] for k in ("translation_rmse", "rotation_deg",
                                             "translation_rmse_last", "rotation_deg_last")})
        return out

    rec = {"recordings_final": 11, "translation_rmse_final": 0.004, "rotation_deg_final": 6.0,
           "still_translation_rmse_final": 0.03, "still_rotation_deg_final": 7.7,
           "vs": {"translation_rmse": [0.5, 0.3, 1.2], "rotation_deg": [0.4, 0.2, 1.1]}}
    results = {"mujoco_fitted": r(0.001), "mujoco_nominal": r(0.002), "no_motion": r(0.008),
               "fignet": {"all": r(0.003, 47), "8": r(0.004, 8)},
               "per_recording": {"MuJoCo, fitted": rec, "FIGNet, 8 train": rec}}
    table = format_table(results)
    assert table.index("FIGNet, 8 train |") < table.index("FIGNet, 47 train |")
    assert table.index("| 8 |") < table.index("| 47 |")
    assert "frame 25 (0.50 s)" in table and "over the 11 recordings" in table
    assert "| FIGNet, 8 train | 4.00 | 6.00 | 0.50 [0.30, 1.20] | 0.40 [0.20, 1.10] |" in table


def test_every_command_counts_mujocos_warnings_into_one_line(tmp_path: Path, monkeypatch, capsys) -> None:
    """A command during which MuJoCo warns prints one summary line on stderr at the end, not
    MuJoCo's own lines, and writes no MUJOCO_LOG.TXT in the working directory."""
    import argparse

    from fignet_gym.cli import run_command

    def unstable(_: argparse.Namespace) -> int:
        model = mujoco.MjModel.from_xml_string(
            "<mujoco><worldbody><body><freejoint/><geom size='1'/></body></worldbody></mujoco>")
        for _ in range(3):  # MuJoCo warns once per kind and MjData
            data = mujoco.MjData(model)
            data.qvel[:] = 1e30
            mujoco.mj_step(model, data)
        return 0

    monkeypatch.chdir(tmp_path)
    assert run_command(unstable, argparse.Namespace()) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("MuJoCo warned 3 times (first: Nan, Inf")
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_compare_runs_puts_arms_side_by_side_and_refuses_other_splits(tmp_path: Path, capsys) -> None:
    """``sim2real-compare``: every arm's sizes under the analytic rows, windows and per push, a
    plot; runs of another split are refused in one line."""
    def m(tr: float, n: int | None = None) -> dict:
        out = {"translation_rmse_final": tr, "rotation_deg_final": 1000 * tr, "horizon_step": 25,
               "trajectories": 22, "seconds": 0.5}
        if n is not None:
            out.update(training_trajectories=n, vs_fitted_mujoco={
                "translation_rmse": [tr / 0.001, 0.1, 9.0], "rotation_deg": [tr / 0.001, 0.1, 9.0]})
        return out

    def rec(tr: float) -> dict:
        return {"translation_rmse_final": 2 * tr, "rotation_deg_final": 2000 * tr,
                "vs": {"translation_rmse": [2.0, 1.0, 3.0], "rotation_deg": [2.0, 1.0, 3.0]}}

    def run(arm: float) -> dict:
        return {"split": {"train": 34, "valid": 11, "test": 11}, "mujoco_fitted": m(0.001),
                "mujoco_nominal": {**m(0.002), "vs_fitted_mujoco": {"translation_rmse": [2, 1, 3],
                                                                    "rotation_deg": [2, 1, 3]}},
                "fignet": {"all": m(arm, 47), "8": m(2 * arm, 8)},
                "per_recording": {"MuJoCo, fitted": rec(0.001), "FIGNet, 8 train": rec(2 * arm),
                                  "FIGNet, 47 train": rec(arm)}}

    for label, arm in (("a", 0.003), ("b", 0.0015)):
        (tmp_path / label).mkdir()
        (tmp_path / label / "results.json").write_text(json.dumps(run(arm)))
    out = tmp_path / "cmp"
    assert main(["sim2real-compare", str(tmp_path / "a"), str(tmp_path / "b"), "--labels",
                 "from push", "prior", "--out", str(out)]) == 0
    table = (out / "compare.md").read_text()
    assert (out / "compare.png").stat().st_size > 0
    rows = [[c.strip() for c in r.strip("|").split("|")] for r in table.splitlines()
            if r.startswith("| ")][1:]
    assert [r[:2] for r in rows] == [["MuJoCo, nominal", ""], ["MuJoCo, fitted", ""],
                                     ["from push", "8"], ["from push", "47"], ["prior", "8"],
                                     ["prior", "47"]]
    assert "| prior | 47 | 1.50 | 1.50 | 1.50 [0.10, 9.00] | 1.50 [0.10, 9.00] | 3.00 | 3.00 |" in table
    other = run(0.003)
    other["split"] = {"train": 30, "valid": 11, "test": 15}
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "results.json").write_text(json.dumps(other))
    capsys.readouterr()
    assert main(["sim2real-compare", str(tmp_path / "a"), str(tmp_path / "c"), "--out", str(out)]) == 2
    assert "scored on another split" in capsys.readouterr().err
