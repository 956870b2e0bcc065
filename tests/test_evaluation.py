"""Evaluation metrics against reference models whose errors are known by construction."""

import json
import math
import re
from dataclasses import replace
from pathlib import Path
from tempfile import TemporaryDirectory

import numpy as np
import pytest
import torch

from fignet_gym.cli import main
from fignet_gym.data.format import TrajectoryWriter, build_scene, load_trajectories, write_trajectories
from fignet_gym.data.generate import TossConfig, iter_trajectories
from fignet_gym.data.tracked import import_contactnets
from fignet_gym.simulator.checkpoint import save
from fignet_gym.simulator.config import SimulatorConfig
from fignet_gym.simulator.geometry import quat_mul
from fignet_gym.simulator.model import LearnedSimulator
from fignet_gym.simulator.scene import Scene
from fignet_gym.train.data_checks import truth_label
from fignet_gym.train.evaluation import evaluate, rollout_metrics
from fignet_gym.train.floor import perturbation_floor
from fignet_gym.train.metrics import predictor_metrics, rotation_gain
from fignet_gym.train.one_step import one_step_errors, spin_change
from fignet_gym.train.stats import median_ratio_interval, paired_ratios, per_recording
from tests.sim_factories import SMALL, quiet_simulator, zero_simulator


@pytest.fixture(scope="module")
def pushes() -> list:
    return list(iter_trajectories("push", 2, seed=11))


def test_zero_network_scores_as_constant_velocity(pushes: list) -> None:
    # A network that outputs zero (no gravity prior) extrapolates every node linearly: its one-step
    # errors are the constant-velocity model's up to the rotation's linearisation.
    sim = zero_simulator("push")
    scene = Scene.batch([build_scene(t, sim.config.mesh_options) for t in pushes])
    true = torch.cat([torch.as_tensor(t.poses[:30], dtype=torch.float32) for t in pushes], 1)
    m = one_step_errors(sim, scene, true)
    assert m["one_step_constvel_translation"] > 0.01  # the pushes start and stop: real errors
    assert m["one_step_translation"] == pytest.approx(m["one_step_constvel_translation"], rel=1e-3)
    assert m["one_step_rotation"] == pytest.approx(m["one_step_constvel_rotation"], rel=2e-2)
    # It keeps every spin as it is: no change of angular velocity, whatever the true one.
    assert abs(m["one_step_spin_gain"]) < 0.05


def test_rollout_metrics_of_a_model_that_never_moves_is_the_no_motion_reference(pushes: list) -> None:
    sim = zero_simulator("push")
    # Pushes start at rest, so a zero network keeps the object where it is: the no-motion model.
    m = rollout_metrics(sim, pushes, horizon=25)
    assert m["still_translation_rmse_final"] > 1e-3
    assert m["translation_rmse_ratio_still"] == pytest.approx(1.0, abs=1e-4)
    # Shape matching in float32 leaves ~1e-3 deg of jitter.
    assert m["rotation_deg_final"] == pytest.approx(m["still_rotation_deg_final"], abs=0.01)
    assert math.isfinite(m["penetration_m"])


def test_median_ratio_interval_brackets_known_ratios() -> None:
    ref = np.random.default_rng(1).uniform(0.5, 2.0, 80)
    # A model at exactly half the reference's error on every trajectory: the ratio is 0.5 in every
    # resample, so the interval collapses onto it.
    assert median_ratio_interval(0.5 * ref, ref) == pytest.approx([0.5, 0.5])
    # Independent errors of equal distribution: the interval is wide and contains 1.
    other = np.random.default_rng(2).uniform(0.5, 2.0, 80)
    lo, hi = median_ratio_interval(other, ref)
    assert lo < 1.0 < hi and hi - lo > 0.1
    assert all(math.isnan(x) for x in median_ratio_interval(np.zeros(0), np.zeros(0)))


def test_grouped_bootstrap_resamples_whole_recordings() -> None:
    rng = np.random.default_rng(3)
    model, ref = rng.uniform(0.5, 2.0, 15), rng.uniform(0.5, 2.0, 15)
    plain = median_ratio_interval(model, ref)
    # One trajectory per group (or no label at all) is the plain bootstrap, draw for draw.
    assert median_ratio_interval(model, ref, groups=[f"r{i}" for i in range(15)]) == plain
    assert median_ratio_interval(model, ref, groups=[None] * 15) == plain
    # Every recording cut into 4 identical windows: resampling recordings sees 15 independent
    # units, exactly the original data's interval; resampling windows would pretend 60 and
    # narrow it.
    copies, labels = np.repeat(model, 4), np.repeat(np.arange(15), 4).tolist()
    grouped = median_ratio_interval(copies, np.repeat(ref, 4), groups=labels)
    assert grouped == pytest.approx(plain)
    naive = median_ratio_interval(copies, np.repeat(ref, 4))
    assert naive[1] - naive[0] < 0.8 * (plain[1] - plain[0])
    with pytest.raises(ValueError, match="1 keys for 15 trajectories"):
        median_ratio_interval(model, ref, groups=["a"])


def test_per_recording_medians_average_each_recordings_windows_first() -> None:
    """Hand case: windows (1, 3) of push a and (10) of push b average to (2, 10), median 6; the
    reference (1, 1) and (5) gives (1, 5), median 3, so the ratio is 2. Over windows the medians
    would be 3 and 1 (ratio 3): a push cut into many windows must not count many times."""
    res = {"translation_rmse_per_trajectory": [1.0, 3.0, 10.0],
           "still_translation_rmse_per_trajectory": [4.0, 4.0, 4.0],
           "rotation_deg_per_trajectory": [2.0, 2.0, 2.0],
           "still_rotation_deg_per_trajectory": [1.0, 1.0, 1.0], "groups_final": ["a", "a", "b"]}
    res.update({k.replace("_per", "_last_per"): v for k, v in res.items() if "per_traj" in k},
               groups_last=["a", "a", "b"])
    ref = {k: v for k, v in res.items()}
    ref["translation_rmse_per_trajectory"] = [1.0, 1.0, 5.0]
    ref["translation_rmse_last_per_trajectory"] = [1.0, 1.0, 5.0]
    out = per_recording(res, ref)
    assert out["recordings_final"] == 2 and out["translation_rmse_final"] == 6.0
    assert out["still_translation_rmse_final"] == 4.0
    assert out["vs"]["translation_rmse"][0] == pytest.approx(2.0)
    assert out["vs"]["rotation_deg"][0] == pytest.approx(1.0)
    assert per_recording(ref)["translation_rmse_final"] == 3.0
    mixed = dict(ref, groups_final=["a", "b", "b"])
    with pytest.raises(ValueError, match="recordings differ"):
        per_recording(res, mixed)


def test_rotation_gain_hand_cases() -> None:
    def about(axis: int, deg: float) -> torch.Tensor:  # pose at the origin, turned about an axis
        q = torch.zeros(7)
        q[3] = math.cos(math.radians(deg) / 2)
        q[4 + axis] = math.sin(math.radians(deg) / 2)
        return q

    start = torch.stack([about(2, 0.0)] * 4)
    true = torch.stack([about(2, 10.0), about(2, 20.0), about(2, 0.5), about(2, 30.0)])
    dyn = torch.tensor([True, True, True, False])  # object 3 is kinematic, object 2 barely turns
    half = torch.stack([about(2, 5.0), about(0, 10.0), about(2, 40.0), about(2, 0.0)])
    assert rotation_gain(dyn, start, half, true) == pytest.approx(0.5, abs=1e-4)  # size, not axis
    assert rotation_gain(dyn, start, true, true) == pytest.approx(1.0, abs=1e-4)
    assert rotation_gain(dyn, start, start, true) == pytest.approx(0.0, abs=1e-4)
    assert math.isnan(rotation_gain(dyn, start, true, start))  # nothing turns: undefined


def test_spin_change_hand_case() -> None:
    def about_z(rad: float) -> torch.Tensor:
        return torch.tensor([[math.cos(rad / 2), 0.0, 0.0, math.sin(rad / 2)]], dtype=torch.float64)

    # Turning 0.1 rad, then 0.3 rad: the spin grew by 0.2 rad per step about z.
    out = spin_change(about_z(0.0), about_z(0.1), about_z(0.4))
    assert torch.allclose(out, torch.tensor([[0.0, 0.0, 0.2]], dtype=torch.float64), atol=1e-9)
    # A steady spin (also about a tilted axis, from a turned start) does not change.
    tilt = torch.tensor([[math.cos(0.3), math.sin(0.3), 0.0, 0.0]], dtype=torch.float64)
    steady = [quat_mul(quat_mul(about_z(0.2 * k), tilt), about_z(0.7)) for k in range(3)]
    assert torch.allclose(spin_change(*steady), torch.zeros(1, 3, dtype=torch.float64), atol=1e-9)


def test_free_flight_error_hand_case() -> None:
    # Tosses start in the air. A zero network with the gravity prior predicts exactly g dt^2 for
    # every node, so its free-flight error is 0; shifting its output by half of g dt^2 (through
    # the target normaliser's mean) makes it exactly 0.5.

    trajs = list(iter_trajectories("toss-simple", 2, seed=3))
    sim = LearnedSimulator(SimulatorConfig(**SMALL, gravity=(0.0, 0.0, -10.0), scene_type="toss")).eval()
    with torch.no_grad():
        for p in sim.net.parameters():
            p.zero_()
    scene = Scene.batch([build_scene(t, sim.config.mesh_options) for t in trajs])
    true = torch.cat([torch.as_tensor(t.poses[:12], dtype=torch.float32) for t in trajs], 1)
    assert one_step_errors(sim, scene, true)["one_step_free_flight"] < 1e-3
    half = 0.5 * 10.0 * 0.02**2
    sim.target_norm.accumulate(torch.tensor([[0.0, half, 0.0]], dtype=torch.float64).repeat(100, 1))
    assert one_step_errors(sim, scene, true)["one_step_free_flight"] == pytest.approx(0.5, rel=1e-3)
    # Without a gravity prior, free flight is not defined.
    assert math.isnan(one_step_errors(zero_simulator("toss"), scene, true)["one_step_free_flight"])


def test_evaluate_against_a_second_checkpoint_pairs_the_trajectories(pushes: list, tmp_path) -> None:
    data = tmp_path / "pushes.h5"
    write_trajectories(data, pushes)
    zero, quiet = tmp_path / "zero.pt", tmp_path / "quiet.pt"
    save(zero_simulator("push"), zero)
    torch.manual_seed(0)
    save(quiet_simulator("push"), quiet)
    same = evaluate(str(zero), str(data), str(tmp_path / "a"), num=2, horizon=10, videos=0, against=str(zero))
    assert same["against"]["ratios"]["translation_rmse"] == pytest.approx([1.0, 1.0, 1.0])
    res = evaluate(str(quiet), str(data), str(tmp_path / "b"), num=2, horizon=10, videos=0, against=str(zero))
    ratio, lo, hi = res["against"]["ratios"]["translation_rmse"]
    assert ratio == pytest.approx(res["translation_rmse_final"] / same["translation_rmse_final"])
    assert ratio != pytest.approx(1.0)
    assert lo <= ratio <= hi
    with pytest.raises(ValueError, match="same trajectories"):
        paired_ratios(res, {k: v[:1] if k.endswith("per_trajectory") else v for k, v in same.items()})


def test_perturbation_floor_of_free_flight_is_the_nudge() -> None:
    # Tosses whose recorded objects fly freely (second differences exactly g dt^2) for 0.16 s:
    # ballistic motion carries a position offset unchanged, so MuJoCo's own error is the nudge at
    # every step, and nothing turns. (Some tosses collide in the air at once: left out.)
    tosses = []
    for t in iter_trajectories("toss-simple", 6, seed=4, config=replace(TossConfig(), duration=0.16)):
        pos = t.poses[:, t.kinds == 0, :3]
        acc = pos[2:] - 2 * pos[1:-1] + pos[:-2]
        if np.allclose(acc, [0.0, 0.0, -10.0 * t.dt**2], atol=1e-9):
            tosses.append(t)
    assert len(tosses) >= 2
    res = perturbation_floor(tosses, 2e-3, history=2, horizon=5)
    assert res["horizon_step"] == 5
    np.testing.assert_allclose(res["translation_rmse_per_trajectory"], 2e-3, rtol=1e-3)
    np.testing.assert_allclose(res["translation_rmse_curve"], 2e-3, rtol=1e-3)
    assert res["rotation_deg_final"] < 1e-3
    assert res["translation_rmse_ratio_still"] == pytest.approx(2e-3 / res["still_translation_rmse_final"],
                                                                rel=1e-3)
    exact = perturbation_floor(tosses, 0.0, horizon=5)
    assert exact["translation_rmse_final"] < 1e-6 and exact["rotation_deg_final"] < 1e-3


def test_floor_command_prints_and_writes_each_noise_level(pushes: list, tmp_path, capsys) -> None:
    data, out = tmp_path / "p.h5", tmp_path / "floor.json"
    with TrajectoryWriter(data) as w:
        for t in pushes:
            w.add(t)
    assert main(["floor", "--data", str(data), "--noise", "0", "1e-3", "--horizon", "20",
                 "--out", str(out)]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert [r["position_noise"] for r in rows] == [0.0, 1e-3]
    assert rows[0]["translation_rmse_final"] < 1e-6 < rows[1]["translation_rmse_final"]
    assert "MuJoCo re-run" in capsys.readouterr().out
    assert out.with_suffix(".png").stat().st_size > 0


def test_every_trajectory_is_scored_over_its_own_length_from_frame_0(pushes: list) -> None:
    """A zero network keeps pushed objects still (they start at rest): its errors are the motion
    since the last given pose, computed here by hand at the horizon and at each last frame."""
    short = replace(pushes[0], poses=pushes[0].poses[:30], extras={})
    trajs = [short, pushes[1]]
    sim = zero_simulator("push")
    m = rollout_metrics(sim, trajs, horizon=40)
    H = sim.config.history + 1
    motion = []
    for t in trajs:
        scene = build_scene(t, sim.config.mesh_options)
        com = scene.com_positions(torch.as_tensor(t.poses, dtype=torch.float32))[:, t.kinds == 0]
        motion.append((com - com[H - 1]).norm(dim=-1).squeeze(-1))
    assert m["horizon_trajectories"] == 1 and m["trajectories"] == 2  # only the full push has frame 40
    assert m["translation_rmse_final"] == pytest.approx(float(motion[1][40]), rel=1e-4, abs=1e-6)
    np.testing.assert_allclose(m["translation_rmse_last_per_trajectory"],
                               [float(motion[0][29]), float(motion[1][50])], rtol=1e-4, atol=1e-6)
    assert m["translation_rmse_last_ratio_still"] == pytest.approx(1.0, abs=1e-4)
    assert len(m["translation_rmse_curve"]) == 51 - H
    with pytest.raises(ValueError, match="no trajectory reaches frame 60"):
        rollout_metrics(sim, trajs, horizon=60)
    with pytest.raises(ValueError, match="inside the 3 given poses"):
        rollout_metrics(sim, trajs, horizon=2)


def test_data_dt_must_be_the_models(pushes: list, tmp_path) -> None:
    with pytest.raises(ValueError, match=r"trajectory .*field 'dt' is 0.02 s, the model steps 0.01 s"):
        rollout_metrics(zero_simulator("push", dt=0.01), pushes, horizon=10)
    data, ckpt = tmp_path / "p.h5", tmp_path / "m.pt"
    write_trajectories(data, pushes)
    save(zero_simulator("push", dt=0.01), ckpt)
    assert main(["evaluate", "--checkpoint", str(ckpt), "--data", str(data), "--out",
                 str(tmp_path / "e"), "--videos", "0"]) == 2


def test_free_flight_metric_on_real_tracked_tosses(tmp_path) -> None:
    """On the real tosses the old test (second differences within 2% of g) never held; free flight
    is now found by geometry, and the data's own acceleration (~9.6 m/s^2 down) is measured."""
    data = tmp_path / "cube.h5"
    import_contactnets(Path(__file__).parent / "data" / "contactnets_sample", data)
    trajs = load_trajectories(data)
    cfg = SimulatorConfig(**{**SMALL, "dt": trajs[0].dt}, collision_radius=0.02,
                          gravity=(0.0, 0.0, -9.81), scene_type="toss")
    sim = LearnedSimulator(cfg).eval()
    with torch.no_grad():
        for p in sim.net.parameters():
            p.zero_()
    m = rollout_metrics(sim, trajs, horizon=50)
    assert m["free_flight_steps"] > 10
    assert -10.2 < m["free_flight_acceleration"] < -9.2
    # the zero network predicts exactly the 9.81 prior: its error is the prior's 2% mismatch
    # with the data's fall, plus tracking noise through the history
    assert 0.005 < m["one_step_free_flight"] < 1.0
    assert "one_step_free_flight_absent" not in m
    still = rollout_metrics(zero_simulator("toss", dt=trajs[0].dt), trajs, horizon=50)
    assert math.isnan(still["one_step_free_flight"])
    assert "no gravity prior" in still["one_step_free_flight_absent"]


def test_evaluate_against_a_fitted_mujoco_file(pushes: list, tmp_path, capsys) -> None:
    """MuJoCo is the oracle: a parameters file that keeps the generator's MJCF and substeps
    replays generated pushes almost exactly, so its errors are a small fraction of no motion's."""
    data = tmp_path / "pushes.h5"
    write_trajectories(data, pushes)
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({"substeps": pushes[0].metadata["substeps"], "source": "generator"}))
    zero = tmp_path / "zero.pt"
    save(zero_simulator("push"), zero)
    res = evaluate(str(zero), str(data), str(tmp_path / "a"), horizon=30, videos=0, against=str(fit))
    ag = res["against"]
    assert ag["mujoco"] == str(fit) and ag["params"]["substeps"] == pushes[0].metadata["substeps"]
    assert ag["translation_rmse_final"] < 0.05 * res["still_translation_rmse_final"]
    ratio = ag["ratios"]["translation_rmse"][0]
    assert ratio == pytest.approx(res["translation_rmse_final"] / ag["translation_rmse_final"])
    # No contact parameter in the file: MuJoCo as the data were made, not a fit.
    assert "(nominal MuJoCo (the data's own MJCF) replaying the data)" in capsys.readouterr().out
    fitted = tmp_path / "fitted.json"
    fitted.write_text(json.dumps({"substeps": pushes[0].metadata["substeps"], "friction": 0.3}))
    evaluate(str(zero), str(data), str(tmp_path / "f"), num=1, horizon=30, videos=0, against=str(fitted))
    printed = capsys.readouterr().out
    assert "(fitted MuJoCo replaying the data)" in printed
    assert re.search(r"^no motion +\d+\.\d\d +", printed, re.M)  # millimetres, 2 decimals
    # mujoco:nominal: each trajectory's own MJCF, which for generated pushes is the generator's
    # scene, so it replays them as the parameters file above does.
    nominal = evaluate(str(zero), str(data), str(tmp_path / "n"), horizon=30, videos=0,
                       against="mujoco:nominal")["against"]
    assert nominal["translation_rmse_final"] == pytest.approx(ag["translation_rmse_final"],
                                                              rel=1e-6, abs=1e-9)
    assert "(nominal MuJoCo (the data's own MJCF) replaying the data)" in capsys.readouterr().out
    # An unknown shipped fit is refused before anything is written.
    out = tmp_path / "none"
    assert main(["evaluate", "--checkpoint", str(zero), "--data", str(data), "--out", str(out),
                 "--against", "mujoco:no-such-fit"]) == 2
    assert "available: mujoco:cube-real" in capsys.readouterr().err
    assert not out.exists()


def test_videos_label_recorded_data_as_recorded(pushes: list) -> None:
    sample = Path(__file__).parent / "data" / "contactnets_sample"
    assert truth_label(pushes[0]) == "MuJoCo (ground truth)"
    assert truth_label(replace(pushes[0], metadata={"source": "mit_pushing/json"})) == "recorded"
    assert truth_label(replace(pushes[0], metadata={"source": "kubric_movi"})) == "Kubric (ground truth)"
    with TemporaryDirectory() as tmp:
        import_contactnets(sample, Path(tmp) / "cube.h5")
        assert {truth_label(t) for t in load_trajectories(Path(tmp) / "cube.h5")} == {"recorded"}


def test_no_motion_intervals_resample_whole_recordings() -> None:
    # Three identical windows per recording: the interval over recordings is the interval of one
    # window each (5 independent units); resampling the 15 windows would narrow it.
    sim = quiet_simulator("push")
    originals = list(iter_trajectories("push", 5, seed=12))
    windows = [replace(t, metadata={**t.metadata, "file": f"push{i}"})
               for i, t in enumerate(originals) for _ in range(3)]
    once = rollout_metrics(sim, originals, horizon=25)
    grouped = rollout_metrics(sim, windows, horizon=25)
    naive = rollout_metrics(sim, [replace(t, metadata={}) for t in windows], horizon=25)
    for key in ("translation_rmse_ratio_still_ci95", "rotation_deg_last_ratio_still_ci95"):
        assert grouped[key] == pytest.approx(once[key], rel=1e-3)
        assert naive[key][1] - naive[key][0] < 0.9 * (once[key][1] - once[key][0])


def test_paired_ratios_of_recordings_shorter_than_the_horizon() -> None:
    # A recording too short for the horizon drops out of the *_final medians: the pairing must
    # resample the recordings of the trajectories behind them, not of every trajectory.
    trajs = [replace(t, metadata={**t.metadata, "file": f"p{i // 2}"})
             for i, t in enumerate(iter_trajectories("push", 4, seed=3))]
    trajs[0] = replace(trajs[0], poses=trajs[0].poses[:10])
    shifted = [t.poses + np.array([1e-3, 0, 0, 0, 0, 0, 0]) for t in trajs]  # 1 mm along x
    res = predictor_metrics(trajs, shifted, horizon=20)
    assert res["horizon_trajectories"] == 3 and res["groups_final"] == ["p0", "p1", "p1"]
    ratios = paired_ratios(res, res)
    assert ratios["translation_rmse"] == pytest.approx([1.0, 1.0, 1.0])
    assert ratios["translation_rmse_last"] == pytest.approx([1.0, 1.0, 1.0])


def test_yaw_change_is_the_signed_turn_about_the_vertical() -> None:
    import math

    import torch
    from scipy.spatial.transform import Rotation

    from fignet_gym.train.metrics import yaw_change, yaw_fit

    def pose(yaw: float, tilt: float = 0.0, flip: bool = False) -> list[float]:
        q = (Rotation.from_euler("z", yaw) * Rotation.from_euler("x", tilt)).as_quat(scalar_first=True)
        return [0.0, 0.0, 0.0, *(-q if flip else q)]

    start = torch.tensor([pose(0.3), pose(3.0), pose(-1.0, 0.2)], dtype=torch.float32)
    end = torch.tensor([pose(0.8, flip=True), pose(-3.0), pose(-1.4, 0.2)], dtype=torch.float32)
    # +0.5; across the +-pi seam the short way (+0.283); a tilted object turned by -0.4 about z.
    want = torch.tensor([0.5, 2 * math.pi - 6.0, -0.4])
    assert torch.allclose(yaw_change(start, end), want, atol=1e-6)
    true = [0.1, -0.2, 0.3, 0.05]
    assert yaw_fit(true, true) == pytest.approx((1.0, 1.0))
    assert yaw_fit([0.5 * t + 0.01 for t in true], true)[0] == pytest.approx(0.5)


def test_evaluate_horizon_defaults_to_what_the_data_reaches_and_refuses_before_rolling_out(
        pushes: list, tmp_path, monkeypatch, capsys) -> None:
    """26-pose windows (0.5 s of a real push at 0.02 s): the default horizon is their last frame,
    25, not 50; an explicit horizon past every trajectory is refused in one line before any
    rollout runs."""
    data, ckpt = tmp_path / "short.h5", tmp_path / "m.pt"
    write_trajectories(data, [replace(t, poses=t.poses[:26]) for t in pushes])
    save(zero_simulator("push"), ckpt)
    assert evaluate(str(ckpt), str(data), str(tmp_path / "a"), videos=0)["horizon_step"] == 25
    import fignet_gym.train.evaluation as evaluation

    def no_rollouts(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        raise AssertionError("a rollout ran before the horizon was checked")

    monkeypatch.setattr(evaluation, "rollout_metrics", no_rollouts)
    assert main(["evaluate", "--checkpoint", str(ckpt), "--data", str(data), "--out",
                 str(tmp_path / "b"), "--videos", "0", "--horizon", "50"]) == 2
    assert "no trajectory reaches frame 50 (the longest has 26 poses): pass --horizon 25" in \
        capsys.readouterr().err


def test_dt_refusal_of_mit_data_names_the_import_flag(pushes: list) -> None:
    mit = [replace(t, metadata={**t.metadata, "source": "mit_pushing/h5"}) for t in pushes]
    with pytest.raises(ValueError, match=r"re-import with `fignet-gym import-mit \.\.\. --dt 0\.01`"):
        rollout_metrics(zero_simulator("push", dt=0.01), mit, horizon=10)


def test_no_per_recording_view_where_every_trajectory_is_its_own_recording(tmp_path: Path) -> None:
    """Generated trajectories carry no recording key: each is its own, so ``evaluate`` adds no
    per-recording view (one would be the same medians under another name)."""
    data = tmp_path / "p.h5"
    write_trajectories(data, list(iter_trajectories("push", 3, seed=2)))
    sim = zero_simulator("push", dt=0.02)
    save(sim, tmp_path / "z.pt")
    res = evaluate(str(tmp_path / "z.pt"), str(data), str(tmp_path / "e"), horizon=25, videos=0)
    assert "per_recording" not in res
