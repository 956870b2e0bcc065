"""examples/ppo_push.py runs end to end with a tiny budget, and its defaults match its env."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import gymnasium as gym
import pytest

import fignet_gym.envs  # noqa: F401  (registers the environments)

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "ppo_push.py"


def load_example():
    spec = importlib.util.spec_from_file_location("ppo_push_example", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_defaults_match_the_env() -> None:
    args = load_example().Args()
    assert args.env in gym.registry and args.dynamics == "fignet"
    assert args.steps % (args.num_envs * args.n_steps) == 0  # whole PPO iterations
    assert args.final_episodes >= 50


def test_defaults_are_the_shipped_policys_recipe() -> None:
    from dataclasses import replace

    from fignet_gym.agents.ppo import load_policy

    ex = load_example()
    shipped = load_policy(ex.SHIPPED).config
    assert ex.config(ex.parse(["--full"])) == shipped  # the whole budget: exactly what was shipped
    small = ex.config(ex.Args())
    assert small == replace(shipped, ppo=replace(shipped.ppo, total_timesteps=small.ppo.total_timesteps))
    assert small.ppo.total_timesteps < shipped.ppo.total_timesteps


def test_tiny_run_then_resume_then_ship(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    ex = load_example()
    out = tmp_path / "run"
    argv = ["--env", "fignet_gym/Push-v1", "--steps", "32", "--num-envs", "2", "--n-steps", "16",
            "--final-episodes", "1", "--eval-every", "0", "--out", str(out)]
    ex.main(argv)
    assert json.loads((out / "final_eval.json").read_text())["timesteps"] == 32
    assert "| fignet (run) | 0 | 32 |" in capsys.readouterr().out
    dest = tmp_path / "shipped"
    ex.main([*argv[:3], "64", *argv[4:], "--ship", "tiny", "--ship-dest", str(dest)])  # continues
    assert json.loads((out / "final_eval.json").read_text())["timesteps"] == 64
    assert json.loads((dest / "tiny" / "final_eval.json").read_text())["timesteps"] == 64
    assert "64 environment steps" in (dest / "tiny" / "tiny.md").read_text()
