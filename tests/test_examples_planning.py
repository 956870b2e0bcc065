"""Smoke tests of the planning and dynamics-swap examples with tiny budgets (issue 13)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import gymnasium as gym
import numpy as np
import pytest

import fignet_gym.envs  # noqa: F401  (registers the environments)

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("dynamics", ["mujoco", "fignet"])
def test_mpc_example_runs_on_either_dynamics(dynamics: str) -> None:
    out = load("cem_push_rollout").main(
        ["--dynamics", dynamics, "--episodes", "1", "--steps", "2", "--horizon", "2",
         "--population", "4", "--iterations", "1"]
    )
    assert len(out) == 1 and out[0]["length"] == 2


def test_mpc_example_defaults_match_its_env() -> None:
    """Without --steps an episode runs to the env's own end (Push-v1: 75 steps), not past it."""
    out = load("cem_push_rollout").main(
        ["--dynamics", "mujoco", "--episodes", "1", "--horizon", "2", "--population", "4",
         "--iterations", "1"]
    )[0]
    limit = gym.make("fignet_gym/Push-v1").spec.max_episode_steps
    assert out["length"] == limit or (out["is_success"] and out["length"] < limit)


def test_swap_example_pushes_towards_the_goal(tmp_path: Path) -> None:
    out = load("swap_dynamics").main(
        ["--episodes", "1", "--push-steps", "4", "--max-steps", "30", "--size", "48",
         "--out", str(tmp_path / "swap.mp4")]
    )
    ep = out["episodes"][0]
    # judged by MuJoCo: the scripted pusher brings the object nearer its goal
    assert ep["errors"]["mujoco"] < ep["start_error"] - 0.005
    for xy in out["own_scene"].values():  # the box in the user's own scene moved along +x
        assert np.isfinite(xy).all() and xy[0] > 0.0
    assert (tmp_path / "swap.mp4").stat().st_size > 0


def test_own_scene_example_goes_from_an_mjcf_file_to_a_planned_episode(tmp_path: Path) -> None:
    """examples/own_scene.py at a tiny budget: data from the user's file, a trained checkpoint,
    its evaluation against the MuJoCo pushes, and a planned episode on the registered scene env."""
    out = load("own_scene").main(["--num", "4", "--steps", "2", "--episode-steps", "3",
                                  "--planner-budget", "tiny", "--out", str(tmp_path)])
    assert (tmp_path / "run" / "best.pt").is_file() and (tmp_path / "eval" / "metrics.json").is_file()
    assert out["metrics"]["trajectories"] >= 1 and np.isfinite(out["metrics"]["translation_rmse_final"])
    assert out["episode"]["steps"] == 3 and np.isfinite(out["episode"]["position_error"])
