"""Training: exact resumption after an interruption, data-parallel processes, sampling."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from fignet_gym.data.format import load_trajectories
from fignet_gym.data.generate import iter_trajectories
from fignet_gym.train import trainer as training
from fignet_gym.train.config import TrainConfig, load_run_config
from fignet_gym.train.sampling import WindowSampler, mirror_asymmetric, mirror_y, rotate_about_z
from fignet_gym.train.trainer import Trainer

TINY = {"simulator.latent_size": 8, "simulator.message_passing_steps": 1,
        "training.batch_size": 2, "training.steps": 6, "training.valid_every": 100,
        "training.valid_trajectories": 1, "training.threads": 1, "training.unroll_steps": 2}


def _trainer(push_file: Path, out: Path, resume: bool = False) -> Trainer:
    trajs = load_trajectories(push_file)
    sim_cfg, cfg = load_run_config("push-cpu", TINY)
    return Trainer(sim_cfg, cfg, trajs[:2], trajs[2:], out, resume=resume)


def test_resume_after_interruption_continues_exactly(push_file: Path, tmp_path: Path) -> None:
    straight = _trainer(push_file, tmp_path / "a")
    straight.run()
    interrupted = _trainer(push_file, tmp_path / "b")
    interrupted.run(stop_after=3)
    assert torch.load(tmp_path / "b" / "last.pt", weights_only=True)["meta"]["train_state"]["step"] == 3
    resumed = _trainer(push_file, tmp_path / "b", resume=True)
    assert resumed.state.step == 3
    resumed.run()
    for (name, a), b in zip(straight.sim.state_dict().items(), resumed.sim.state_dict().values(),
                            strict=True):
        assert torch.equal(a, b), name
    # The weight average resumes too, and it is an average: not the last weights.
    for (name, a), b in zip(straight.ema.state_dict().items(), resumed.ema.state_dict().values(),
                            strict=True):
        assert torch.equal(a, b), name
    assert any(not torch.equal(a, b)
               for a, b in zip(straight.ema.parameters(), straight.sim.parameters(), strict=True))


def test_two_data_parallel_processes_stay_identical(push_file: Path, tmp_path: Path) -> None:
    # torchrun with two CPU processes (gloo); the trainer raises if the replicas drift apart.
    sets = json.dumps({**TINY, "training.steps": 3})
    train = ["-m", "fignet_gym", "train", "--data", str(push_file), "--config", "push-cpu",
             "--set", sets, "--out"]
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
           *train, str(tmp_path / "ddp")]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    ddp = torch.load(tmp_path / "ddp" / "last.pt", weights_only=True)
    state = ddp["meta"]["train_state"]
    assert state["step"] == 3 and state["graphs_seen"] == 3 * 2 * 2
    assert json.loads((tmp_path / "ddp" / "config.json").read_text())["processes"] == 2
    # Rank 0 draws the windows a single process with the same seed draws; rank 1's gradients
    # enter the average, so the weights differ from that single process's.
    single = subprocess.run([sys.executable, *train, str(tmp_path / "one")], capture_output=True,
                            text=True, timeout=300)
    assert single.returncode == 0, single.stderr[-3000:]
    one = torch.load(tmp_path / "one" / "last.pt", weights_only=True)["state_dict"]
    moved = [k for k, v in ddp["state_dict"].items() if v.is_floating_point() and not torch.equal(v, one[k])]
    assert any(k.startswith("net.") for k in moved)


def test_rotation_about_z_keeps_heights_and_relative_geometry() -> None:
    poses = torch.tensor([[[0.3, 0.1, 0.2, 1.0, 0.0, 0.0, 0.0],
                           [0.0, 0.5, 0.7, 0.5, 0.5, 0.5, 0.5]]])
    out = rotate_about_z(poses, 0.7)
    assert torch.allclose(out[..., 2], poses[..., 2])
    d_in = (poses[0, 0, :3] - poses[0, 1, :3]).norm()
    d_out = (out[0, 0, :3] - out[0, 1, :3]).norm()
    assert torch.isclose(d_in, d_out)
    assert torch.allclose(out[..., 3:].norm(dim=-1), torch.ones(1, 2))


def _cube_toss(qpos: np.ndarray, qvel: np.ndarray, steps: int) -> np.ndarray:
    """MuJoCo's poses ``float64[steps + 1, 7]`` of a spinning cube thrown onto the floor."""
    import mujoco

    from fignet_gym.mjcf import cube_scene_xml

    model = mujoco.MjModel.from_xml_string(
        cube_scene_xml(0.05, 0.37, 6e-4, 0.3, 0.3, cone="elliptic"))
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = qpos, qvel
    mujoco.mj_forward(model, data)
    out = [data.qpos.copy()]
    for _ in range(steps):
        mujoco.mj_step(model, data)
        out.append(data.qpos.copy())
    return np.asarray(out)


def test_a_mirrored_toss_is_what_mujoco_simulates_from_the_mirrored_start() -> None:
    # Independent truth: reflecting a recorded toss (impact, sliding and tumbling included) must
    # give the toss MuJoCo simulates from the reflected initial state; a wrong quaternion sign
    # gives a cube that is not the mirror image and moves differently.
    quat = np.array([0.9, 0.2, -0.3, 0.25])
    qpos = np.concatenate(([0.1, -0.2, 0.25], quat / np.linalg.norm(quat)))
    qvel = np.array([1.0, 0.4, -0.5, 3.0, -2.0, 1.5])  # world linear, body-frame angular
    toss = _cube_toss(qpos, qvel, 200)
    assert toss[-1, 2] < 0.06  # it landed (the centre is within a half-diagonal of the floor)
    reflect_v, reflect_w = np.array([1, -1, 1]), np.array([-1, 1, -1])  # w a pseudovector
    start = mirror_y(torch.as_tensor(qpos)).numpy()
    mirrored_run = _cube_toss(start, np.concatenate((qvel[:3] * reflect_v, qvel[3:] * reflect_w)), 200)
    mirrored = mirror_y(torch.as_tensor(toss)).numpy()
    assert np.abs(mirrored_run[:, :3] - mirrored[:, :3]).max() < 1e-6
    dots = np.abs((mirrored_run[:, 3:] * mirrored[:, 3:]).sum(-1))
    assert dots.min() > 1 - 1e-9
    # Not trivially so: the toss itself is not mirror symmetric.
    assert np.abs(toss[:, :3] - mirrored[:, :3]).max() > 0.05


def test_mirror_training_refuses_objects_that_are_not_mirror_symmetric(tmp_path: Path) -> None:
    from fignet_gym.data.format import build_scene

    trajs = list(iter_trajectories("push", 6, seed=7))
    flags = [bool(mirror_asymmetric(build_scene(t))) for t in trajs]
    assert True in flags and False in flags  # the generator's shapes include both kinds
    sim_cfg, cfg = load_run_config("push-cpu", {**TINY, "training.mirror": True})
    symmetric = [t for t, f in zip(trajs, flags, strict=True) if not f]
    Trainer(sim_cfg, cfg, symmetric[:2], symmetric[2:3], tmp_path / "ok")
    # Wired into the batches: with rotations off, about half the windows are reflected copies.
    sim_cfg, cfg = load_run_config("push-cpu", {**TINY, "training.mirror": True,
                                                "training.rotate_z": False, "training.batch_size": 1})
    trainer = Trainer(sim_cfg, cfg, symmetric[:1], symmetric[1:2], tmp_path / "wired")
    kinds = []
    for k in range(40):
        trainer.sampler.rng = np.random.default_rng(k)
        (i, t), = trainer.sampler.sample(1)
        trainer.sampler.rng = np.random.default_rng(k)  # batch() draws the same window
        _, poses = trainer.batch()
        raw = torch.as_tensor(symmetric[i].poses[t:t + trainer.sampler.span], dtype=torch.float32)
        kinds.append("same" if torch.equal(poses, raw) else
                     "mirrored" if torch.equal(poses, mirror_y(raw)) else "other")
    assert "other" not in kinds and 8 < kinds.count("mirrored") < 32
    bad = trajs[flags.index(True)]
    with pytest.raises(ValueError, match=f"'object' of trajectory '{bad.name}' is not symmetric"):
        Trainer(sim_cfg, cfg, [bad], symmetric[:1], tmp_path / "bad")


def test_unknown_training_keys_are_rejected() -> None:
    with pytest.raises(ValueError, match="unknown training config keys"):
        TrainConfig.from_dict({"stepz": 3})
    assert np.isfinite(TrainConfig().lr)


def test_pushforward_feeds_the_models_own_rollout(push_file: Path, tmp_path: Path) -> None:
    trajs = load_trajectories(push_file)
    sim_cfg, cfg = load_run_config("push-cpu", {**TINY, "training.unroll_steps": 3,
                                                "training.noise_std": 0.0, "training.noise_fraction": 0.0})
    trainer = Trainer(sim_cfg, cfg, trajs[:2], trajs[2:], tmp_path / "pf")
    with torch.no_grad():
        for p in trainer.sim.net.parameters():  # zero network: every object keeps its velocity
            p.zero_()
    H = trainer.sim.config.history + 1
    scene, window = trainer.batch()
    assert window.shape[0] == H + 1 + 3
    dyn = scene.dynamic_mask
    for k in range(4):
        poses, hist = trainer.pushforward(scene, window, k)
        assert torch.equal(poses, window[-(H + 1):])  # always supervised on the window's last step
        if k == 0:
            assert hist is None
            continue
        # Kinematic and static objects follow their true poses; a zero network extrapolates the
        # dynamic objects' centres of mass linearly from the window's start.
        assert torch.equal(hist[:, ~dyn], window[3:3 + H][:, ~dyn])
        start = scene.com_positions(window[3 - k:3 - k + H])
        expect = start[-1] + k * (start[-1] - start[-2])
        assert torch.allclose(scene.com_positions(hist[-1])[dyn], expect[dyn], atol=2e-5)
    draws = {trainer.pushforward(scene, window)[1] is None for _ in range(30)}
    assert draws == {True, False}
    assert torch.isfinite(trainer.loss(scene, window))


def test_pushforward_waits_for_unroll_after(push_file: Path, tmp_path: Path) -> None:
    trajs = load_trajectories(push_file)
    sim_cfg, cfg = load_run_config("push-cpu", {**TINY, "training.unroll_steps": 3,
                                                "training.unroll_after": 5})
    trainer = Trainer(sim_cfg, cfg, trajs[:2], trajs[2:], tmp_path / "warm")
    H = trainer.sim.config.history + 1
    scene, window = trainer.batch()
    rng_state = trainer.gen.get_state()
    for _ in range(20):  # warm-up: plain one-step examples, and no random draw is spent on k
        poses, hist = trainer.pushforward(scene, window)
        assert hist is None and torch.equal(poses, window[-(H + 1):])
    assert torch.equal(trainer.gen.get_state(), rng_state)
    trainer.run(stop_after=5)
    assert trainer.state.step == 5
    draws = {trainer.pushforward(scene, window)[1] is None for _ in range(30)}
    assert draws == {True, False}


def test_sampler_weights_still_windows_near_motion_above_other_still_windows(push_file: Path) -> None:
    from fignet_gym.data.format import build_scene

    traj = load_trajectories(push_file)[0]
    # The object settles onto the floor by a few micrometres over the first steps; hold it at its
    # settled pose there so the push starts from rest, as the weights below assume.
    traj.poses[:6] = traj.poses[6]
    scene = build_scene(traj)
    dyn = scene.dynamic_mask.numpy()
    moved = np.abs(np.diff(traj.poses[:, dyn, :3], axis=0)).max(axis=(1, 2)) > 1e-6  # step i: pose i -> i+1
    first, last = int(np.argmax(moved)), int(len(moved) - 1 - np.argmax(moved[::-1]))
    sampler = WindowSampler([traj], [scene], history=2, still_weight=0.1, seed=0, near=3, near_weight=5.0)
    span = sampler.span  # window t covers poses t .. t + span - 1, i.e. steps t .. t + span - 2
    assert first > span + 4 and last < len(moved) - 5, "fixture push must start and end at rest"
    w = sampler.prob / sampler.prob[0]  # window 0 is still and far from any motion
    for t, wt in enumerate(w):
        steps = range(t, t + span - 1)
        if any(moved[i] for i in steps):
            assert wt > 10.0, t  # moving windows: at least 1 / still_weight
        elif first - (t + span - 2) <= 3 and first > t or 0 < t - last <= 3:
            assert wt == pytest.approx(50.0), t  # approach or just stopped
        else:
            assert wt == pytest.approx(1.0), t


def test_several_data_files_are_pooled_in_order(push_file: Path, tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    seen = {}

    class Capture:
        def __init__(self, sim_cfg, cfg, train, valid, out, **kw) -> None:  # noqa: ANN001
            seen.update(train=train, valid=valid)

        def run(self) -> None:
            return None

    monkeypatch.setattr(training, "Trainer", Capture)
    one = load_trajectories(push_file)
    training.train_from_files([str(push_file), str(push_file)], None, "push-cpu", str(tmp_path))
    assert [t.name for t in seen["train"]] == [t.name for t in one] * 2
    assert [t.name for t in seen["valid"]] == [t.name for t in one * 2][-4:]  # the default


def test_push_scratch_is_the_finetune_model_with_the_rigid_projection() -> None:
    # The from-scratch push recipe must train the same network as the fine-tuning one (so either
    # can continue the other's checkpoints), apart from the output projection.
    scratch, _ = load_run_config("push-scratch")
    finetune, _ = load_run_config("push-finetune")
    assert scratch["rigid_output"] and not finetune.get("rigid_output", False)
    assert {k: v for k, v in scratch.items() if k != "rigid_output"} == finetune


def test_selection_score_sums_no_motion_ratios_and_names_undefined_terms() -> None:
    """Hand-computed: 0.2 + 0.5 at the horizon, 0.5 x (0.3 + 1.0) at the last frame. A validation
    set where nothing turns (no-motion rotation error exactly 0, ratio nan) scores its
    translation alone, so selection still works; a diverged model (nan error) scores inf."""
    rec = {"translation_rmse_ratio_still": 0.2, "rotation_deg_ratio_still": 0.5,
           "translation_rmse_last_ratio_still": 0.3, "rotation_deg_last_ratio_still": 1.0}
    assert training.selection_score(rec, 0.0) == pytest.approx(0.7)
    assert training.selection_score(rec, 0.5) == pytest.approx(0.7 + 0.65)
    still = {"translation_rmse_ratio_still": 0.2, "rotation_deg_ratio_still": float("nan"),
             "still_rotation_deg_final": 0.0, "rotation_deg_final": 0.01}
    assert training.selection_score(still, 0.0) == pytest.approx(0.2)
    diverged = {**still, "rotation_deg_final": float("nan")}
    assert training.selection_score(diverged, 0.0) == float("inf")
    assert training.selection_score({}, 0.0) == float("inf")
