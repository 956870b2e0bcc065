"""Training on real-data splits: the measured gravity prior, train_on_split, --init by name."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch

from fignet_gym.data.format import Trajectory, write_trajectories
from fignet_gym.envs.cube_toss import DATA_DT, cube_toss_xml, mujoco_parameters
from fignet_gym.pretrained import load_pretrained
from fignet_gym.simulator.checkpoint import save
from fignet_gym.simulator.normalization import Normalizer
from fignet_gym.simulator.scene import Scene
from fignet_gym.train.config import load_run_config
from fignet_gym.train.real import (
    TrainingInterrupted,
    default_steps,
    free_flight_gravity,
    train_on_split,
)
from fignet_gym.train.rundir import RunFolderError
from fignet_gym.train.trainer import Trainer

TINY = {"simulator.latent_size": 8, "simulator.message_passing_steps": 1,
        "training.batch_size": 2, "training.valid_trajectories": 2, "training.valid_horizon": 20}


def cube_tosses(n: int, gravity: float, poses: int = 40, seed: int = 0) -> list[Trajectory]:
    """MuJoCo tosses of the ContactNets cube (nominal contact) under ``gravity`` (m/s^2)."""
    params = replace(mujoco_parameters("nominal"), gravity=gravity)
    xml = cube_toss_xml(params)
    model = mujoco.MjModel.from_xml_string(xml)
    scene = Scene.from_mjmodel(model)
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        data = mujoco.MjData(model)
        q = rng.normal(size=4)
        data.qpos[:7] = (*rng.uniform(-0.2, 0.2, 2), rng.uniform(0.13, 0.17), *(q / np.linalg.norm(q)))
        data.qvel[:6] = (*rng.uniform(-1, 1, 2), 0.0, *rng.uniform(-3, 3, 3))
        mujoco.mj_forward(model, data)
        track = np.empty((poses, scene.num_objects, 7))
        for k in range(poses):
            if k:
                mujoco.mj_step(model, data, nstep=4)
            track[k] = scene.poses_from_data(data)
        out.append(Trajectory(poses=track.astype(np.float32), dt=DATA_DT,
                              kinds=scene.object_kind.numpy(), props=scene.object_props.double().numpy(),
                              names=scene.object_names, mjcf=xml, name=f"toss-{i}"))
    return out


def test_free_flight_gravity_measures_the_simulated_gravity() -> None:
    # MuJoCo's semi-implicit Euler moves a free body on an exact parabola in time.
    assert free_flight_gravity(cube_tosses(4, -9.6)) == pytest.approx(-9.6, abs=0.01)
    assert free_flight_gravity(cube_tosses(4, -9.81)) == pytest.approx(-9.81, abs=0.01)
    landed = cube_tosses(1, -9.6)[0]
    landed.poses = landed.poses[-5:]  # at rest on the floor: no free flight to fit
    with pytest.raises(ValueError, match="free flight"):
        free_flight_gravity([landed])


def test_smaller_training_sets_get_fewer_steps() -> None:
    sizes = [8, 16, 32, 64, 128, 240]
    steps = [default_steps(s) for s in sizes]
    assert steps == sorted(steps) and steps[0] < steps[-1]


def test_train_on_split_subsets_measures_gravity_and_resumes(tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    trajs = cube_tosses(4, -9.6)
    train_file = tmp_path / "train.h5"
    write_trajectories(train_file, trajs[:3])
    out = tmp_path / "run"
    # First call killed after 2 of its 4 steps (as an interruption would stop it).
    original = Trainer.run
    monkeypatch.setattr(Trainer, "run", lambda self, stop_after=None: original(self, stop_after=2))
    with pytest.raises(TrainingInterrupted, match="interrupted at step 2 of 4"):
        train_on_split(train_file, trajs[3:], 2, out, budget=4, overrides=TINY)
    assert torch.load(out / "last.pt", weights_only=True)["meta"]["train_state"]["step"] == 2
    monkeypatch.setattr(Trainer, "run", original)
    best = train_on_split(train_file, trajs[3:], 2, out, budget=4, overrides=TINY)
    assert best == out / "best.pt" and best.is_file()
    info = json.loads((out / "split.json").read_text())
    assert info["train"] == ["toss-0", "toss-1"] and info["valid"] == ["toss-3"]
    assert info["gravity"][2] == pytest.approx(-9.6, abs=0.01)
    config = json.loads((out / "config.json").read_text())
    assert config["simulator"]["gravity"][2] == pytest.approx(-9.6, abs=0.01)
    assert config["simulator"]["dt"] == DATA_DT  # the data's own, not rounded
    assert json.loads((out / "done.json").read_text())["step"] == 4
    # A finished run is returned as is, not trained again.
    stamp = (out / "last.pt").stat().st_mtime_ns
    assert train_on_split(train_file, trajs[3:], 2, out, budget=4, overrides=TINY) == best
    assert (out / "last.pt").stat().st_mtime_ns == stamp
    # ... but only when it is the run asked for: another budget is refused, not answered stale.
    with pytest.raises(RunFolderError, match="finished run of 4 steps, asked for 6"):
        train_on_split(train_file, trajs[3:], 2, out, budget=6, overrides=TINY)
    with pytest.raises(ValueError, match="subset of 9"):
        train_on_split(train_file, trajs[3:], 9, tmp_path / "x", budget=4, overrides=TINY)


def test_init_accepts_a_pretrained_name(tmp_path: Path) -> None:
    source = load_pretrained("toss")
    sim_cfg = {k: v for k, v in source.config.to_dict().items() if k != "dt"}
    from fignet_gym.data.generate import iter_trajectories

    trajs = list(iter_trajectories("toss-simple", 2, seed=3))
    _, cfg = load_run_config(None, {"training.steps": 1, "training.threads": 1})
    trainer = Trainer(sim_cfg, cfg, trajs[:1], trajs[1:], tmp_path / "ft", init="toss")
    for (name, a), b in zip(source.state_dict().items(), trainer.sim.state_dict().values(), strict=True):
        assert torch.equal(a, b), name


def test_a_warm_start_is_validated_before_its_first_step_and_can_stay_best(tmp_path: Path) -> None:
    trajs = cube_tosses(4, -9.6)
    base = train_on_split(trajs[:2], trajs[3:], None, tmp_path / "base", budget=4, overrides=TINY)
    # Saturate the start's normalisers, as a trained model's are: otherwise fine-tuning batches
    # still move their statistics, and with them the model, whatever the learning rate.
    start_sim = load_pretrained(base)
    for module in start_sim.modules():
        if isinstance(module, Normalizer):
            module.calls.fill_(module.max_accumulations)
    save(start_sim, base)
    sim_cfg, cfg = load_run_config("cube-real", {**TINY, "training.steps": 2, "training.lr": 1e-12,
                                                 "training.lr_final": 1e-12})
    trainer = Trainer(sim_cfg, cfg, trajs[:2], trajs[3:], tmp_path / "ft", init=str(base))
    trainer.run()
    steps = [json.loads(line)["step"] for line in (tmp_path / "ft" / "curve.jsonl").read_text().splitlines()]
    assert steps[0] == 0 and steps[1:] == sorted(steps[1:]) and steps[-1] == 2
    # A learning rate below float32's resolution leaves the weights as they were, so every later
    # validation ties with step 0 and the start stays the best checkpoint.
    best = torch.load(tmp_path / "ft" / "best.pt", weights_only=True)
    assert best["meta"]["valid"]["step"] == 0
    start = load_pretrained(base).state_dict()
    for name, value in load_pretrained(tmp_path / "ft" / "best.pt").state_dict().items():
        assert torch.equal(value, start[name]), name
    # A run from scratch has no step-0 validation.
    first = json.loads((tmp_path / "base" / "curve.jsonl").read_text().splitlines()[0])["step"]
    assert first > 0


def test_cli_init_with_an_unknown_name_is_one_error_line(tmp_path: Path) -> None:
    data = tmp_path / "t.h5"
    write_trajectories(data, cube_tosses(2, -9.6, poses=12))
    cmd = [sys.executable, "-m", "fignet_gym", "train", "--data", str(data), "--config", "cube-real",
           "--out", str(tmp_path / "r"), "--init", "no-such-model", "--set", json.dumps(TINY)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert lines[-1].startswith("error: no-such-model") and "toss" in lines[-1]
    assert "Traceback" not in done.stderr



def test_sim2real_warm_start_raises_when_interrupted(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    trajs = cube_tosses(4, -9.6)
    train_file, valid_file = tmp_path / "train.h5", tmp_path / "valid.h5"
    write_trajectories(train_file, trajs[:3])
    write_trajectories(valid_file, trajs[3:])
    init = train_on_split(train_file, trajs[3:], 2, tmp_path / "init", budget=2, overrides=TINY)
    out = tmp_path / "warm"
    original = Trainer.run
    monkeypatch.setattr(Trainer, "run", lambda self, stop_after=None: original(self, stop_after=2))
    with pytest.raises(TrainingInterrupted, match="interrupted at step 2 of 4"):
        train_on_split(train_file, valid_file, 2, out, 4, overrides=TINY, init=str(init))
    assert not (out / "done.json").exists()
    monkeypatch.setattr(Trainer, "run", original)  # called again: resumes and finishes
    assert train_on_split(train_file, valid_file, 2, out, 4, overrides=TINY, init=str(init)).is_file()
    assert json.loads((out / "done.json").read_text())["step"] == 4
    # On the same tosses the fine-tune gets the prior its accelerations are residuals of (the
    # measured one again), not the preset's rounded one.
    prior = json.loads((tmp_path / "init" / "config.json").read_text())["simulator"]["gravity"]
    assert abs(prior[2] + 9.61) > 1e-3
    assert json.loads((out / "config.json").read_text())["simulator"]["gravity"] == prior


def test_polish_fine_tunes_the_selected_model_through_rollouts(tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    from fignet_gym.train import real

    monkeypatch.setattr(real, "POLISH_STEPS", 2)
    trajs = cube_tosses(4, -9.6)
    out = tmp_path / "run"
    best = train_on_split(trajs[:2], trajs[3:], None, out, budget=4, overrides=TINY, polish=True)
    assert best == out / "polish" / "best.pt" and best.is_file()
    base_cfg = json.loads((out / "config.json").read_text())
    cfg = json.loads((out / "polish" / "config.json").read_text())
    assert cfg["training"]["rollout_steps"] == 10 and base_cfg["training"]["rollout_steps"] == 0
    assert cfg["training"]["steps"] == 2 and cfg["training"]["lr"] == pytest.approx(1e-4)
    # The recipe and the prior carry over; the base run's schedule does not.
    assert cfg["simulator"] == base_cfg["simulator"]
    assert cfg["training"]["batch_size"] == 2
    # It starts from the base run's selected model: validated first, it scores what that scored.
    first = json.loads((out / "polish" / "curve.jsonl").read_text().splitlines()[0])
    base_best = json.loads((out / "done.json").read_text())["best_score"]
    assert first["step"] == 0 and first["score"] == pytest.approx(base_best, rel=1e-6)
    hours = [json.loads((d / "done.json").read_text())["cpu_hours"] for d in (out, out / "polish")]
    assert real.run_cpu_hours(out) == pytest.approx(sum(hours))
    assert np.isnan(real.run_cpu_hours(tmp_path / "none"))
    # Called again, the finished base and polish runs are returned, not trained again.
    stamp = (out / "polish" / "last.pt").stat().st_mtime_ns
    assert train_on_split(trajs[:2], trajs[3:], None, out, budget=4, overrides=TINY, polish=True) == best
    assert (out / "polish" / "last.pt").stat().st_mtime_ns == stamp


def test_sim2real_polishes_only_large_training_sets(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    from fignet_gym.train import real
    from fignet_gym.train.sim2real import default_train

    monkeypatch.setattr(real, "POLISH_MIN_SIZE", 3)
    train_file = tmp_path / "t.h5"
    write_trajectories(train_file, cube_tosses(4, -9.6, poses=12))
    asked: list = []
    monkeypatch.setattr(real, "train_on_split", lambda *a, polish, **k: asked.append((a[2], polish)))
    for size in (2, 3, None):  # None: all 4
        default_train()(train_file, tmp_path / "v.h5", size, tmp_path / str(size))
    default_train(polish=False)(train_file, tmp_path / "v.h5", None, tmp_path / "n")
    assert asked == [(2, False), (3, True), (None, True), (None, False)]
    monkeypatch.setattr(real, "POLISH_MIN_SIZE", 5)  # "all" is counted, not taken as large
    default_train()(train_file, tmp_path / "v.h5", None, tmp_path / "m")
    assert asked[-1] == (None, False)
