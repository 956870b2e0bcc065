"""``fignet-gym ppo``: a run folder that resumes after a stop, its logs, errors and transfer table."""

from __future__ import annotations

import csv
import json
import pickle
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from fignet_gym.agents.ppo.config import PPOConfig, RunConfig
from fignet_gym.agents.ppo.eval import EVAL_SEED
from fignet_gym.agents.ppo.logging import read_csv
from fignet_gym.agents.ppo.policy import NormalizedPolicy, load_run_policy
from fignet_gym.agents.ppo.run import run_ppo
from fignet_gym.agents.ppo.rundir import RunError
from fignet_gym.agents.ppo.table import exploitation_gap, plot_curves, transfer_table
from fignet_gym.cli import main

PUSH = "fignet_gym/Push-v1"
#: 2 envs x 16 steps = 32 steps per PPO iteration, 2 minibatches of 16, 1 epoch.
TINY = RunConfig(
    env_id=PUSH,
    dynamics="mujoco",
    ppo=PPOConfig(total_timesteps=128, num_envs=2, n_steps=16, batch_size=16, n_epochs=1),
    eval_every=32,
    eval_episodes=1,
    final_episodes=2,
    checkpoint_every=64,
)


def steps(path: Path) -> list[int]:
    return [int(r["step"]) for r in read_csv(path)]


def tb_steps(root: Path, tag: str) -> list[int]:
    acc = EventAccumulator(str(root / "tb"))
    acc.Reload()
    return [e.step for e in acc.Scalars(tag)]


@pytest.fixture(scope="module")
def stopped_and_resumed(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """A run stopped at step 96 (last checkpoint: 64), facts about it, then resumed to 128."""
    root = tmp_path_factory.mktemp("ppo") / "run"
    assert run_ppo(root, TINY, stop_at=96, progress=False) == {}
    facts: dict[str, object] = {
        "root": root,
        "steps_stopped": steps(root / "progress.csv"),
        "rows_stopped": read_csv(root / "progress.csv"),
        "tb_stopped": tb_steps(root, "eval/mujoco/mean_return"),
        "ckpt_state": torch.load(root / "checkpoint" / "state.pt", weights_only=False),
        "ckpt_model": PPO.load(root / "checkpoint" / "model.zip", device="cpu"),
    }
    with (root / "checkpoint" / "vecnormalize.pkl").open("rb") as f:
        facts["ckpt_count"] = float(pickle.load(f).obs_rms.count)
    facts["result"] = run_ppo(root, TINY, resume=True, progress=False)
    return facts


def test_stopped_run_checkpoints_policy_optimizer_and_counter(stopped_and_resumed: dict) -> None:
    f = stopped_and_resumed
    assert f["steps_stopped"] == [32, 64, 96]  # the row at 96 was logged after the checkpoint
    assert f["tb_stopped"] == [32, 64, 96]
    assert f["ckpt_state"]["num_timesteps"] == 64
    assert len(f["ckpt_state"]["rng"]["envs"]) == 2
    # Adam's own step counter: 2 updates x 1 epoch x (32 / 16) minibatches.
    adam = f["ckpt_model"].policy.optimizer.state_dict()["state"]
    assert adam and {int(s["step"]) for s in adam.values()} == {4}


def test_resumed_run_reaches_the_budget_and_logs_each_step_once(stopped_and_resumed: dict) -> None:
    f = stopped_and_resumed
    root: Path = f["root"]
    assert f["result"]["timesteps"] == 128
    assert steps(root / "progress.csv") == [32, 64, 96, 128]
    assert steps(root / "eval.csv") == [32, 64, 96, 128]
    # TensorBoard hides the killed process's events after the checkpoint (purge_step).
    assert tb_steps(root, "eval/mujoco/mean_return") == [32, 64, 96, 128]
    assert len(list((root / "tb").glob("events.out.tfevents.*"))) == 2
    its = [float(r["time/iterations"]) for r in read_csv(root / "progress.csv")]
    assert its == [1, 2, 3, 4]  # counted from the run's start, not from the resumed process's
    # The normaliser continued from the checkpoint: + 2 reset observations + 32 steps x 2 envs.
    with (root / "vecnormalize.pkl").open("rb") as fh:
        assert float(pickle.load(fh).obs_rms.count) == pytest.approx(f["ckpt_count"] + 2 + 64)
    # ... and so did the optimizer: 2 more updates of 2 minibatches.
    adam = PPO.load(root / "policy.zip", device="cpu").policy.optimizer.state_dict()["state"]
    assert {int(s["step"]) for s in adam.values()} == {8}


def test_resumed_run_logs_the_update_its_checkpoint_carried(stopped_and_resumed: dict) -> None:
    """SB3 writes an update's train/* with the next row; the checkpoint at 64 fell in between.

    The stopped process wrote row 96 with the update made at 64; the resumed one, redoing row
    96 from the checkpoint, must write the same values (it used to write none).
    """
    f = stopped_and_resumed
    before = {r["step"]: r for r in f["rows_stopped"]}["96"]
    after = {r["step"]: r for r in read_csv(f["root"] / "progress.csv")}
    train = [k for k in before if k.startswith("train/") and before[k] != ""]
    assert "train/loss" in train and "train/approx_kl" in train
    assert {k: after["96"][k] for k in train} == {k: before[k] for k in train}
    # Every row after the first update carries train/* (the first has no update before it).
    assert after["32"].get("train/loss", "") == ""
    assert all(after[s]["train/loss"] != "" for s in ("64", "96", "128"))


def test_final_eval_covers_both_dynamics_on_the_same_seeds(stopped_and_resumed: dict) -> None:
    res = stopped_and_resumed["result"]
    assert set(res["eval"]) == {"mujoco", "fignet"}
    for rep in res["eval"].values():
        assert rep["n_episodes"] == TINY.final_episodes
        assert np.isfinite(rep["episode_returns"]).all()
    # Same seeds, same episodes: each episode starts where its namesake on the other dynamics
    # does, and the episodes differ from each other (distinct seeds).
    starts = {d: np.array(rep["episode_initial_observations"]) for d, rep in res["eval"].items()}
    assert starts["mujoco"].shape[0] == TINY.final_episodes
    np.testing.assert_array_equal(starts["mujoco"], starts["fignet"])
    assert not np.array_equal(starts["mujoco"][0], starts["mujoco"][1])
    saved = json.loads((stopped_and_resumed["root"] / "final_eval.json").read_text())
    assert saved["eval"]["mujoco"]["episode_returns"] == res["eval"]["mujoco"]["episode_returns"]
    assert EVAL_SEED > TINY.ppo.seed + TINY.ppo.num_envs


def test_transfer_table_aggregates_seeds_of_one_recipe(stopped_and_resumed: dict, tmp_path: Path) -> None:
    """Runs that differ only in seed become one recipe row: mean and [min, max] of each cell, and
    the exploitation gap (success on the training dynamics minus on MuJoCo), hand-computed."""
    src: Path = stopped_and_resumed["root"]
    runs = []
    for seed, (on_mujoco, on_fignet) in enumerate([(0.40, 0.55), (0.30, 0.50), (0.50, 0.50)]):
        run = tmp_path / f"s{seed}"
        run.mkdir()
        res = json.loads((src / "final_eval.json").read_text())
        res["config"]["dynamics"] = "fignet"
        res["config"]["ppo"]["seed"] = seed
        res["config"]["checkpoint_every"] = 64 * (seed + 1)  # bookkeeping: still one recipe
        res["eval"]["mujoco"]["success_rate"] = on_mujoco
        res["eval"]["fignet"]["success_rate"] = on_fignet
        (run / "final_eval.json").write_text(json.dumps(res))
        runs.append(run)
    other = tmp_path / "other"
    other.mkdir()
    (other / "final_eval.json").write_text((src / "final_eval.json").read_text())
    lines = transfer_table([*runs, other]).splitlines()
    assert "| +15 pts |" in lines[2] and "| +20 pts |" in lines[3] and "| +0 pts |" in lines[4]
    recipe = [line for line in lines if line.startswith("| fignet | 3 (0, 1, 2) |")]
    assert len(recipe) == 1
    assert "| 40% [30%, 50%] | 52% [50%, 55%] | +12 pts [+0 pts, +20 pts] |" in recipe[0]
    assert any(line.startswith("| mujoco | 1 (") for line in lines)
    assert "[" not in transfer_table(runs[:1])  # one run: no recipe table


def test_exploitation_gap_is_training_model_minus_mujoco(stopped_and_resumed: dict, tmp_path: Path) -> None:
    """The gap curve of a run trained on FIGNet, against eval.csv's own columns; plotted too."""
    src: Path = stopped_and_resumed["root"]
    run = tmp_path / "fig"
    run.mkdir()
    rows = list(csv.DictReader((src / "eval.csv").open()))
    rows[0]["fignet/success_rate"], rows[0]["mujoco/success_rate"] = "0.75", "0.5"
    with (run / "eval.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    cfg = json.loads((src / "config.json").read_text())
    (run / "config.json").write_text(json.dumps({**cfg, "dynamics": "fignet"}))
    steps, gap = exploitation_gap(run)
    assert steps == [int(r["step"]) for r in rows]
    assert gap[0] == pytest.approx(0.25)
    assert gap == pytest.approx([float(r["fignet/success_rate"]) - float(r["mujoco/success_rate"])
                                 for r in rows])
    assert exploitation_gap(src)[1] == [0.0] * len(rows)  # trained on MuJoCo
    assert plot_curves([run, src], tmp_path / "c.png").stat().st_size > 10_000


def test_transfer_table_rows_and_cli(stopped_and_resumed: dict, capsys: pytest.CaptureFixture) -> None:
    root: Path = stopped_and_resumed["root"]
    res = stopped_and_resumed["result"]
    table = transfer_table([root])
    row = table.splitlines()[2]
    m, f = res["eval"]["mujoco"], res["eval"]["fignet"]
    assert row.startswith(f"| mujoco (run) | {TINY.ppo.seed} | 128 |")
    assert "| +0 pts |" in row  # trained on MuJoCo: nothing to exploit
    median_mm = 1000 * float(np.median(m["episode_position_errors"]))
    assert f"| {m['success_rate']:.0%} | {median_mm:.1f} |" in row
    assert f"| {m['mean_return']:.1f} |" in row and f"| {f['mean_return']:.1f} |" in row
    assert main(["ppo-table", str(root), "--out", str(root / "table.md"),
                 "--plot", str(root / "curves.png")]) == 0
    assert capsys.readouterr().out.strip().splitlines()[:-1] == table.splitlines()
    assert (root / "curves.png").stat().st_size > 10_000
    assert (root / "table.md").read_text().strip() == table
    assert main(["ppo-table", str(root.parent / "missing")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "final_eval.json" in err[0]


def test_normalized_policy_acts_on_raw_observations(stopped_and_resumed: dict) -> None:
    policy = load_run_policy(stopped_and_resumed["root"])
    rms = policy.normalizer.obs_rms
    raw = np.random.default_rng(0).normal(size=(3, 19)).astype(np.float32)
    by_hand = np.clip((raw - rms.mean) / np.sqrt(rms.var + policy.normalizer.epsilon), -10, 10)
    expected = policy.model.predict(by_hand.astype(np.float32), deterministic=True)[0]
    np.testing.assert_allclose(policy.predict(raw, deterministic=True)[0], expected, rtol=1e-6)
    bare = NormalizedPolicy(policy.model, None)  # without it, a different action: the stats matter
    assert not np.allclose(bare.predict(raw, deterministic=True)[0], expected)


def test_existing_folder_needs_resume_or_force(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    args = ["ppo", "--env", PUSH, "--dynamics", "mujoco", "--steps", "32", "--out", str(out),
            "--num-envs", "2", "--n-steps", "16", "--batch-size", "16", "--n-epochs", "1",
            "--eval-every", "0", "--final-episodes", "1", "--quiet"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "--resume" in err[0]
    assert (out / "notes.txt").exists()
    assert main(["ppo", *args[1:], "--env", "fignet_gym/Nope-v0"]) == 2
    assert "not registered" in capsys.readouterr().err
    assert main([*args, "--force"]) == 0
    assert not (out / "notes.txt").exists() and (out / "final_eval.json").exists()
    assert "| mujoco (run) | 0 | 32 |" in capsys.readouterr().out
    # Resuming with other settings than the saved ones is refused, naming them.
    with pytest.raises(RunError, match="dynamics"):
        run_ppo(out, RunConfig.from_json({**json.loads((out / "config.json").read_text()),
                                          "dynamics": "fignet"}), resume=True, progress=False)
    assert main([*args, "--resume", "--seed", "3"]) == 2
    assert "ppo" in capsys.readouterr().err


def test_finished_run_can_be_extended(tmp_path: Path) -> None:
    out = tmp_path / "run"
    cfg = RunConfig(env_id=PUSH, dynamics="mujoco", eval_every=0, final_episodes=1,
                    ppo=PPOConfig(total_timesteps=32, num_envs=2, n_steps=16, batch_size=16, n_epochs=1))
    assert run_ppo(out, cfg, progress=False)["timesteps"] == 32
    more = RunConfig.from_json({**cfg.to_json(), "ppo": {**cfg.to_json()["ppo"], "total_timesteps": 64}})
    assert run_ppo(out, more, resume=True, progress=False)["timesteps"] == 64
    assert steps(out / "progress.csv") == [32, 64]
    shutil.rmtree(out)


@pytest.mark.slow
def test_killed_process_resumes(tmp_path: Path) -> None:
    """SIGKILL a `fignet-gym ppo` process after its first checkpoint; --resume completes it."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "run"
    args = [sys.executable, "-m", "fignet_gym.cli", "ppo", "--env", PUSH, "--dynamics", "mujoco",
            "--steps", "4096", "--out", str(out), "--num-envs", "2", "--n-steps", "16",
            "--batch-size", "16", "--n-epochs", "1", "--eval-every", "0", "--final-episodes", "1",
            "--checkpoint-every", "64", "--quiet"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(args, env=env)
    try:
        while not (out / "checkpoint" / "state.pt").exists():
            assert proc.poll() is None, "the run ended before its first checkpoint"
            time.sleep(0.2)
        time.sleep(1.0)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    done = torch.load(out / "checkpoint" / "state.pt", weights_only=False)["num_timesteps"]
    assert 64 <= done < 4096
    subprocess.run([*args, "--resume"], env=env, check=True, capture_output=True)
    rows = steps(out / "progress.csv")
    assert rows == list(range(32, 4096 + 1, 32))
    assert json.loads((out / "final_eval.json").read_text())["timesteps"] == 4096


@pytest.mark.parametrize("content", ["{}", "[1]", '{"config": {"dynamics": "mujoco"}, "eval": {}}',
                                     '{"config": {"dyn'])
def test_ppo_table_names_a_wrong_final_eval(tmp_path: Path, capsys: pytest.CaptureFixture,
                                            content: str) -> None:
    from fignet_gym.cli import main

    (tmp_path / "final_eval.json").write_text(content)
    assert main(["ppo-table", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {tmp_path / 'final_eval.json'}: ")


# ----------------------------------------------------------------------------- refused before writing
TINY_ARGS = ["--env", PUSH, "--dynamics", "mujoco", "--steps", "32", "--num-envs", "2",
             "--n-steps", "16", "--batch-size", "16", "--n-epochs", "1", "--eval-every", "0",
             "--final-episodes", "1", "--quiet"]


def one_error_line(capsys: pytest.CaptureFixture) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


@pytest.mark.parametrize(
    ("option", "value", "allowed"),
    [("--n-epochs", "0", "[1, 1000]"), ("--ent-coef", "nan", "[0, 1]"),
     ("--log-std-init", "inf", "[-20, 2]"), ("--gamma", "2", "[0, 1]"),
     ("--num-envs", "100000000", "[1, 1024]"), ("--lr", "-1", "(0, 1]"),
     ("--steps", "0", ">= 1"), ("--seed", "-1", "[0, "), ("--net-arch", "0", "[1, "),
     ("--eval-every", "-5", ">= 0"), ("--batch-size", "1000", "n_steps * num_envs")],
)
def test_every_setting_is_checked_before_anything_is_written(
    tmp_path: Path, capsys: pytest.CaptureFixture, option: str, value: str, allowed: str
) -> None:
    out = tmp_path / "run"
    assert main(["ppo", *TINY_ARGS, "--out", str(out), option, value]) == 2
    line = one_error_line(capsys)
    assert line.startswith(f"error: {option} must be") and allowed in line and value in line
    assert not out.exists()


def test_non_fignet_env_is_refused_before_anything_is_written(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "run"
    args = ["ppo", *TINY_ARGS, "--out", str(out)]
    assert main([*args, "--env", "CartPole-v1"]) == 2
    line = one_error_line(capsys)
    assert "CartPole-v1" in line and "not a fignet_gym environment" in line
    assert "fignet_gym/Push-v1" in line  # the allowed ids
    assert not out.exists()
    with pytest.raises(RunError, match="not a fignet_gym"):
        run_ppo(out, RunConfig(env_id="CartPole-v1"), progress=False)
    assert not out.exists()


def test_resume_below_the_steps_done_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "run"
    args = ["ppo", *TINY_ARGS, "--out", str(out), "--steps", "64"]
    assert main(args) == 0
    capsys.readouterr()
    files = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert main([*args, "--resume", "--steps", "32"]) == 2
    line = one_error_line(capsys)
    assert "--steps 32" in line and "64" in line
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == files  # nothing written
    assert main([*args, "--resume"]) == 0  # the run's own budget again: accepted (re-evaluated)


# ----------------------------------------------------------------------------- ppo-table on bad files
def _finished(tmp_path: Path) -> Path:
    out = tmp_path / "run"
    cfg = RunConfig(env_id=PUSH, dynamics="mujoco", eval_every=32, eval_episodes=1, final_episodes=1,
                    ppo=PPOConfig(total_timesteps=64, num_envs=2, n_steps=16, batch_size=16, n_epochs=1))
    run_ppo(out, cfg, progress=False)
    return out


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _finished(tmp_path_factory.mktemp("finished"))


@pytest.mark.parametrize(
    ("edit", "named"),
    [(lambda r: r["eval"]["mujoco"].update(success_rate=float("nan")), "eval.mujoco.success_rate"),
     (lambda r: r["eval"]["fignet"].update(success_rate=1.5), "eval.fignet.success_rate"),
     (lambda r: r.update(timesteps=-64), "timesteps"),
     (lambda r: r.update(cpu_seconds=-1.0), "cpu_seconds"),
     (lambda r: r["eval"]["mujoco"].update(n_episodes=0), "eval.mujoco.n_episodes"),
     (lambda r: r["config"].update(dynamics="bullet"), "config.dynamics")],
)
def test_ppo_table_refuses_hand_edited_values(finished_run: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture, edit, named: str) -> None:
    run = tmp_path / "copy"
    shutil.copytree(finished_run, run)
    res = json.loads((run / "final_eval.json").read_text())
    edit(res)
    (run / "final_eval.json").write_text(json.dumps(res))
    assert main(["ppo-table", str(run), "--out", str(tmp_path / "t.md")]) == 2
    line = one_error_line(capsys)
    assert f"final_eval.json: {named} must be" in line
    assert not (tmp_path / "t.md").exists()


@pytest.mark.parametrize("cut", ["header", "half_row", "empty"])
def test_ppo_table_plot_refuses_a_truncated_eval_csv(finished_run: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture, cut: str) -> None:
    run = tmp_path / "copy"
    shutil.copytree(finished_run, run)
    text = (run / "eval.csv").read_text()
    lines = text.splitlines()
    assert len(lines) == 3  # header, rows at 32 and 64
    cuts = {"header": lines[0] + "\n", "half_row": "\n".join(lines[:2]) + "\n" + lines[2][:12],
            "empty": ""}
    (run / "eval.csv").write_text(cuts[cut])
    assert main(["ppo-table", str(run), "--plot", str(tmp_path / "c.png")]) == 2
    line = one_error_line(capsys)
    assert "eval.csv" in line
    assert not (tmp_path / "c.png").exists()
    assert capsys.readouterr().out == ""  # nothing printed before the refusal
    (run / "eval.csv").write_text(text)
    assert main(["ppo-table", str(run), "--plot", str(tmp_path / "c.png")]) == 0


def test_recipe_options_reach_the_saved_config(tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert main(["ppo", *TINY_ARGS, "--env", "fignet_gym/Push-v1", "--out", str(out), "--use-sde",
                 "--sde-sample-freq", "4", "--observation", "push-features", "--shaping", "0.5",
                 "--success-bonus", "2"]) == 0
    saved = RunConfig.from_json(json.loads((out / "config.json").read_text()))
    assert saved.ppo.use_sde and saved.ppo.sde_sample_freq == 4
    assert (saved.observation, saved.shaping, saved.success_bonus) == ("push-features", 0.5, 2.0)
    assert PPO.load(out / "policy.zip", device="cpu").use_sde


def test_cube_toss_run_reports_landing_errors_of_the_fit_and_of_cube_real(tmp_path: Path) -> None:
    """A run on CubeToss-v0 evaluates on the fitted MuJoCo and on ``cube-real``, and its final
    errors are each toss's landing error: the ``info`` of the same toss played by hand."""
    cube = "fignet_gym/CubeToss-v0"
    cfg = RunConfig(env_id=cube, dynamics="mujoco",
                    ppo=PPOConfig(total_timesteps=16, num_envs=2, n_steps=8, batch_size=8, n_epochs=1),
                    eval_every=0, final_episodes=2, checkpoint_every=16)
    res = run_ppo(tmp_path / "run", cfg, progress=False)
    policy = load_run_policy(tmp_path / "run")
    backends = {"mujoco": {"mujoco_params": "fitted"}, "fignet": {"checkpoint": "cube-real"}}
    for dyn, kwargs in backends.items():
        rep = res["eval"][dyn]
        env = gym.make(cube, dynamics=dyn, **kwargs)
        for k in range(cfg.final_episodes):
            obs, _ = env.reset(seed=EVAL_SEED + k)
            np.testing.assert_array_equal(obs, np.float32(rep["episode_initial_observations"][k]))
            _, reward, terminated, _, info = env.step(policy.predict(obs[None], deterministic=True)[0][0])
            assert terminated and rep["episode_returns"][k] == pytest.approx(reward, rel=1e-5)
            assert rep["episode_position_errors"][k] == pytest.approx(info["distance"], rel=1e-5)
            assert rep["episode_orientation_errors"][k] == pytest.approx(
                abs(np.radians(info["yaw_error_deg"])), rel=1e-5, abs=1e-7)
        env.close()
        if dyn == "mujoco":  # the shipped fit, not the nominal parameters
            assert not info["mujoco_source"].startswith("NOMINAL")
    # The two backends land the same tosses apart: the fit is not the learned model.
    errors = {dyn: res["eval"][dyn]["episode_position_errors"] for dyn in backends}
    assert errors["mujoco"] != errors["fignet"]


@pytest.mark.parametrize(("column", "value"), [("fignet/success_rate", "1.5"), ("mujoco/mean_return", "nan")])
def test_read_curves_refuses_a_value_out_of_its_range(tmp_path: Path, column: str, value: str) -> None:
    from fignet_gym.agents.ppo.config import DYNAMICS
    from fignet_gym.agents.ppo.rundir import CONFIG
    from fignet_gym.agents.ppo.table import read_curves

    (tmp_path / CONFIG).write_text(json.dumps({"dynamics": "fignet"}))
    columns = [f"{d}/{k}" for d in DYNAMICS for k in ("success_rate", "mean_return")]
    row = {c: "0.5" for c in columns} | {column: value}
    (tmp_path / "eval.csv").write_text("step," + ",".join(columns) + "\n"
                                       + "10," + ",".join(row[c] for c in columns) + "\n")
    with pytest.raises(ValueError, match=f"line 2 has out-of-range values \\({column}\\)"):
        read_curves(tmp_path)
    row[column] = "0.5"
    (tmp_path / "eval.csv").write_text("step," + ",".join(columns) + "\n"
                                       + "10," + ",".join(row[c] for c in columns) + "\n")
    assert read_curves(tmp_path)[1] == [10]
