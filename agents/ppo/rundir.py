"""The PPO run folder: its layout, starting / resuming / refusing it, and its atomic checkpoints.

A run folder holds::

    config.json          how the run was started (env, dynamics, budget, PPO settings)
    checkpoint/          the latest resumable state (written every ``checkpoint_every`` steps)
        model.zip        SB3 PPO: policy and Adam optimizer state, timestep count
        vecnormalize.pkl observation / return normaliser statistics
        state.pt         timestep count, RNG states (torch, numpy, random, every sub-env), the
                         logger's values recorded but not yet written, CPU and wall seconds
    tb/                  TensorBoard: rollout/ep_rew_mean, rollout/success_rate, train/*,
                         eval/{mujoco,fignet}/{success_rate,mean_return,...}
    progress.csv         the same scalars, one row per PPO iteration
    eval.csv             one row per periodic evaluation (both dynamics)
    policy.zip, vecnormalize.pkl   the final policy and its normaliser
    final_eval.json      the final policy on both dynamics (``final_episodes`` episodes each)

Nothing here knows how a run trains: :mod:`fignet_gym.agents.ppo.run` calls these functions.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

from fignet_gym.agents.ppo.config import RunConfig
from fignet_gym.atomic import write_text

CONFIG = "config.json"
CHECKPOINT = "checkpoint"
STATE = "state.pt"
MODEL = "model.zip"
NORMALIZER = "vecnormalize.pkl"
POLICY = "policy.zip"
FINAL_EVAL = "final_eval.json"


class RunError(ValueError):
    """A user error about a run folder (exists, not resumable, settings differ)."""


def recover_checkpoint(root: Path) -> None:
    """Finish a checkpoint swap a kill interrupted between its two renames."""
    if not (root / CHECKPOINT).exists() and (root / "checkpoint.old").exists():
        (root / "checkpoint.old").rename(root / CHECKPOINT)


def read_state(root: Path) -> dict[str, Any] | None:
    """The checkpoint's ``state.pt`` (``None`` without a checkpoint)."""
    path = root / CHECKPOINT / STATE
    return torch.load(path, weights_only=False) if path.exists() else None


def saved_config(root: Path) -> RunConfig | None:
    """The run's ``config.json`` (``None`` if absent)."""
    path = root / CONFIG
    return RunConfig.from_json(json.loads(path.read_text())) if path.exists() else None


def check_resume(root: Path, given: RunConfig) -> RunConfig:
    """The config a resumed run continues with: the saved one with the given budget.

    ``RunError`` when any other setting differs, or when the budget is below the steps the
    checkpoint has already done (a finished run may be re-run with its own budget).
    """
    saved = saved_config(root)
    if saved is None:
        raise RunError(f"{root}: nothing to resume (no {CONFIG}); start it without --resume")
    same_budget = replace(given, ppo=replace(given.ppo, total_timesteps=saved.ppo.total_timesteps))
    a, b = saved.to_json(), same_budget.to_json()
    diff = [k for k in a if a[k] != b[k]]
    if diff:
        raise RunError(f"{root}/{CONFIG}: --resume with different settings ({', '.join(diff)}); "
                       f"saved {', '.join(f'{k}={a[k]}' for k in diff)}")
    recover_checkpoint(root)
    state = read_state(root)
    done = 0 if state is None else int(state["num_timesteps"])
    budget = given.ppo.total_timesteps
    if budget < min(done, saved.ppo.total_timesteps):
        raise RunError(f"--steps {budget} is below the {done} steps {root} has already done; "
                       f"pass at least {min(done, saved.ppo.total_timesteps)}")
    return replace(saved, ppo=replace(saved.ppo, total_timesteps=budget))


def start(root: Path, cfg: RunConfig, resume: bool, force: bool) -> tuple[RunConfig, bool]:
    """Prepare ``root`` for a run: ``(config to run, whether to resume from its checkpoint)``.

    Every refusal (``RunError``) comes before anything is written. Without ``resume`` an
    existing non-empty folder needs ``force`` (then it is deleted). With ``resume``, a folder
    stopped before its first checkpoint starts again without the stopped process's logs.
    """
    if resume:
        cfg = check_resume(root, cfg)
        if read_state(root) is not None:
            write_text(root / CONFIG, json.dumps(cfg.to_json(), indent=2))
            return cfg, True
        for item in root.iterdir():
            if item.name != CONFIG:
                shutil.rmtree(item) if item.is_dir() else item.unlink()
    elif root.exists() and any(root.iterdir()):
        if not force:
            raise RunError(f"{root} exists: pass --resume to continue it or --force to overwrite it")
        shutil.rmtree(root)
    root.mkdir(parents=True, exist_ok=True)
    write_text(root / CONFIG, json.dumps(cfg.to_json(), indent=2))
    return cfg, False


def save_checkpoint(root: Path, write: Callable[[Path], None], state: Mapping[str, Any]) -> None:
    """Write ``root/checkpoint/`` atomically: ``write(folder)`` fills a new folder (model and
    normaliser), ``state`` goes to its ``state.pt``, then the folder is renamed over the old."""
    tmp, final = root / "checkpoint.tmp", root / CHECKPOINT
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    write(tmp)
    torch.save(dict(state), tmp / STATE)
    old = root / "checkpoint.old"
    shutil.rmtree(old, ignore_errors=True)
    if final.exists():
        final.rename(old)
    tmp.rename(final)
    shutil.rmtree(old, ignore_errors=True)


def replace_file(path: Path, write: Callable[[Path], None]) -> None:
    """``write(tmp)`` then rename over ``path``: a kill mid-write never leaves a torn file."""
    tmp = path.with_name(f"{path.stem}.tmp{path.suffix}")
    write(tmp)
    os.replace(tmp, path)
