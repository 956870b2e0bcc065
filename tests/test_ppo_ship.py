"""Shipped PPO policies: ``fignet-gym ppo-ship`` (its card generated from the run's files, its
refusals) and ``load_policy`` (by name, by folder, unknown names), checked against the run."""

from __future__ import annotations

import csv
import json
import re
import shlex
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import fignet_gym.agents.ppo.shipped as shipped
from fignet_gym.agents.ppo import load_policy, load_run_policy
from fignet_gym.agents.ppo.config import RunConfig
from fignet_gym.agents.ppo.options import config_from_args
from fignet_gym.agents.ppo.run import run_ppo
from fignet_gym.agents.ppo.rundir import RunError
from fignet_gym.agents.ppo.ship import wilson_interval
from fignet_gym.cli import build_parser, main
from tests.test_ppo_run import TINY as TINY_RUN

#: test_ppo_run's tiny run on Push-v1 for two iterations; evaluated after each and on 3 final episodes.
TINY = replace(TINY_RUN, env_id="fignet_gym/Push-v1", ppo=replace(TINY_RUN.ppo, total_timesteps=64),
               final_episodes=3)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("ship") / "run"
    run_ppo(root, TINY, progress=False)
    return root


@pytest.fixture(scope="module")
def shipped_folder(run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    dest = tmp_path_factory.mktemp("dest")
    assert main(["ppo-ship", str(run), "--name", "tiny-ppo", "--dest", str(dest)]) == 0
    return dest / "tiny-ppo"


def test_wilson_interval_hand_computed() -> None:
    # 0 of n: the upper end is z^2 / (n + z^2); n of n mirrors it; 21 of 50: 29-56%.
    z2 = 1.959964**2
    assert wilson_interval(0, 10) == pytest.approx((0.0, z2 / (10 + z2)))
    assert wilson_interval(10, 10) == pytest.approx((10 / (10 + z2), 1.0))
    low, high = wilson_interval(21, 50)
    assert (round(low, 3), round(high, 3)) == (0.294, 0.558)


def test_ship_copies_the_run_and_its_card_carries_the_runs_figures(run: Path, shipped_folder: Path) -> None:
    for name in ("policy.zip", "vecnormalize.pkl", "config.json", "final_eval.json", "eval.csv"):
        assert (shipped_folder / name).read_bytes() == (run / name).read_bytes(), name
    card = (shipped_folder / "tiny-ppo.md").read_text()
    final = json.loads((run / "final_eval.json").read_text())
    for dyn, label in (("mujoco", "MuJoCo"), ("fignet", "FIGNet")):
        rep = final["eval"][dyn]
        k, n = sum(rep["episode_successes"]), rep["n_episodes"]
        low, high = wilson_interval(k, n)
        pos = np.median(rep["episode_position_errors"]) * 1000
        assert (f"| {label} | **{k / n:.0%}** ({k}/{n}) | {low:.0%}-{high:.0%} | "
                f"{rep['mean_return']:.1f} | {pos:.1f} mm |") in card
    assert f"{final['timesteps']:,} environment steps, {final['cpu_seconds'] / 3600:.2f} CPU hours" in card
    with (run / "eval.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 2
    for r in rows:
        assert (f"| {int(r['step']):,} | {float(r['mujoco/success_rate']):.0%} | "
                f"{float(r['fignet/success_rate']):.0%} | {float(r['mujoco/mean_return']):.1f} |") in card


def test_the_cards_command_reruns_the_same_config(run: Path, shipped_folder: Path) -> None:
    card = (shipped_folder / "tiny-ppo.md").read_text()
    command = re.search(r"^```bash\n(fignet-gym ppo .*)\n```", card, re.M).group(1)
    args = build_parser().parse_args(shlex.split(command)[1:])
    assert config_from_args(args) == RunConfig.from_json(json.loads((run / "config.json").read_text()))
    assert "Settings no option" not in card  # every setting of this run has an option


def test_load_policy_by_folder_and_by_name_acts_as_the_run(
    run: Path, shipped_folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(shipped, "policies_dir", lambda: shipped_folder.parent)
    assert shipped.available_policies() == ["tiny-ppo"]
    reference = load_run_policy(run)
    obs = np.random.default_rng(0).normal(size=(5, reference.model.observation_space.shape[0]))
    expected = reference.predict(obs.astype(np.float32), deterministic=True)[0]
    for spec in ("tiny-ppo", shipped_folder, str(run)):
        policy = load_policy(spec)
        assert (policy.env_id, policy.env_kwargs) == ("fignet_gym/Push-v1", {})
        assert policy.config == TINY
        np.testing.assert_array_equal(policy.predict(obs.astype(np.float32), deterministic=True)[0],
                                      expected)


def test_unknown_policy_name_lists_the_shipped_ones(tmp_path: Path) -> None:
    with pytest.raises(RunError, match=r"^no-such-policy: no such run folder, and not a shipped "
                       r"policy name \(.*push-ppo.*\)$"):
        load_policy("no-such-policy")
    with pytest.raises(RunError, match=r"not a finished `fignet-gym ppo` run.*push-ppo"):
        load_policy(tmp_path)  # a folder without policy.zip


def _refused(argv: list[str], capsys: pytest.CaptureFixture, dest: Path) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err
    assert not dest.exists()
    return err


def test_refusals_write_nothing(run: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    dest = tmp_path / "dest"
    ship = ["ppo-ship", "--name", "p", "--dest", str(dest)]
    assert "no such run folder" in _refused([*ship, str(tmp_path / "nope")], capsys, dest)
    stopped = tmp_path / "stopped"
    assert run_ppo(stopped, TINY, stop_at=32, progress=False) == {}
    assert "no policy.zip (not a finished" in _refused([*ship, str(stopped)], capsys, dest)
    assert "--name 'Bad Name'" in _refused(["ppo-ship", str(run), "--name", "Bad Name", "--dest",
                                            str(dest)], capsys, dest)


def test_an_unfinished_extension_is_refused(run: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    import shutil

    extended = tmp_path / "extended"
    shutil.copytree(run, extended)
    bigger = RunConfig.from_json({**TINY.to_json(), "ppo": {**TINY.to_json()["ppo"], "total_timesteps": 128}})
    assert run_ppo(extended, bigger, resume=True, stop_at=96, progress=False) == {}  # killed mid-way
    dest = tmp_path / "dest"
    err = _refused(["ppo-ship", str(extended), "--name", "p", "--dest", str(dest)], capsys, dest)
    assert "the policy has 64 steps, config.json asks for 128" in err


def test_an_existing_policy_is_replaced_only_with_force(
    run: Path, shipped_folder: Path, capsys: pytest.CaptureFixture
) -> None:
    before = (shipped_folder / "tiny-ppo.md").read_text()
    argv = ["ppo-ship", str(run), "--name", "tiny-ppo", "--dest", str(shipped_folder.parent)]
    assert main(argv) == 2
    assert "exists: pass --force" in capsys.readouterr().err
    assert main([*argv, "--force"]) == 0
    assert (shipped_folder / "tiny-ppo.md").read_text() == before  # same run, same card
    assert sorted(p.name for p in shipped_folder.parent.iterdir()) == ["tiny-ppo"]  # no temp left


def test_shipped_push_ppo_under_sb3_evaluate_policy_scores_as_its_own_evaluation() -> None:
    import gymnasium as gym
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import DummyVecEnv

    from fignet_gym.agents.ppo import evaluate_policy_on
    from fignet_gym.agents.ppo.eval import EVAL_SEED

    policy = load_policy("push-ppo")
    assert (policy.env_id, policy.env_kwargs, policy.config.dynamics) == ("fignet_gym/Push-v2", {}, "fignet")
    n = 4
    venv = DummyVecEnv([lambda: gym.make("fignet_gym/Push-v2")] * n)
    venv.seed(EVAL_SEED)  # env i's first reset is seeded EVAL_SEED + i: the evaluation's episode i
    returns, _ = evaluate_policy(policy, venv, n_eval_episodes=n, deterministic=True,
                                 return_episode_rewards=True)
    ours = evaluate_policy_on("mujoco", policy, n_episodes=n, seed=EVAL_SEED)
    # evaluate_policy lists episodes in the order they end: compare the sorted returns.
    assert sorted(returns) == pytest.approx(sorted(ours["episode_returns"]), rel=1e-5)
    assert len(set(np.round(returns, 6))) == n  # distinct episodes: the seeds did reach the envs
    # ... and the shipped final_eval.json, written by the training process, says the same on the
    # learned model. (Its MuJoCo returns move with MuJoCo's patch version: 4.0.0 and 4.0.1 differ
    # by up to 10 in a 75-step push.) Not to the bit: issue 38 changed how the learned step breaks
    # closest-point and span-order ties, which moves these 75-step returns by up to 0.3% (and by
    # as much between two CPUs); the policy and successes must stay the training run's.
    final = json.loads((shipped.policies_dir() / "push-ppo" / "final_eval.json").read_text())
    learned = evaluate_policy_on("fignet", policy, n_episodes=n, seed=EVAL_SEED)
    shipped_eval = final["eval"]["fignet"]
    assert learned["episode_returns"] == pytest.approx(shipped_eval["episode_returns"][:n], rel=1e-2)
    assert learned["episode_successes"] == shipped_eval["episode_successes"][:n]


def test_the_shipped_card_is_the_one_its_files_generate(tmp_path: Path) -> None:
    # A shipped folder has a finished run's layout: shipping it again regenerates its card, which
    # must be the shipped card (no hand edits) but for the line naming the source folder.
    folder = shipped.policies_dir() / "push-ppo"
    assert main(["ppo-ship", str(folder), "--name", "push-ppo", "--dest", str(tmp_path)]) == 0

    def body(path: Path) -> list[str]:
        return [line for line in path.read_text().splitlines() if not line.startswith("Shipped from")]

    assert body(tmp_path / "push-ppo" / "push-ppo.md") == body(folder / "push-ppo.md")
