"""Shipping a PPO run (``fignet-gym ppo-ship``): a finished run becomes a named policy with a card.

The run's ``policy.zip``, ``vecnormalize.pkl``, ``config.json``, ``final_eval.json`` and
``eval.csv`` are copied to ``<dest>/<name>/`` (default: the package's shipped policies, which
:func:`~fignet_gym.agents.load_policy` reads by name) and the card ``<name>.md`` is written from
them: the command that reproduces the run, its settings, budget (steps, CPU hours), success on
MuJoCo and on FIGNet with Wilson intervals, and the periodic evaluation curve. Re-shipping a
better run is the same command with ``--force``; no number in the card is typed by hand.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import binomtest

from fignet_gym.agents.ppo.config import DYNAMICS, RunConfig
from fignet_gym.agents.ppo.eval import EVAL_SEED
from fignet_gym.agents.ppo.options import command_line
from fignet_gym.agents.ppo.policy import load_run_policy
from fignet_gym.agents.ppo.rundir import CONFIG, FINAL_EVAL, NORMALIZER, POLICY
from fignet_gym.agents.ppo.shipped import policies_dir
from fignet_gym.agents.ppo.table import read_curves, read_final_eval
from fignet_gym.dynamics import DYNAMICS_LABELS

#: A shipped name: what ``load_policy`` takes and the folder's name.
NAME = re.compile(r"^[a-z0-9][a-z0-9._-]*$")
#: The periodic evaluations of a run.
EVAL_CSV = "eval.csv"


class ShipError(ValueError):
    """A run that cannot be shipped, or a name or destination refused (one line)."""


def wilson_interval(successes: int, n: int) -> tuple[float, float]:
    """95% Wilson score interval ``(low, high)`` of a success rate from ``successes`` of ``n``."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    ci = binomtest(successes, n).proportion_ci(confidence_level=0.95, method="wilson")
    return float(ci.low), float(ci.high)


def _flat(config: dict[str, Any]) -> dict[str, Any]:
    """A run config's JSON with its ``ppo`` settings lifted to the top level."""
    return {**{k: v for k, v in config.items() if k != "ppo"}, **config["ppo"]}


def check_run(run: Path) -> tuple[RunConfig, dict[str, Any], tuple[list[int], dict[str, list[float]]] | None]:
    """A finished run's config, final evaluation and periodic evaluations (``None`` without
    any); ``ShipError`` naming the file for anything missing, unfinished or inconsistent."""
    if not run.is_dir():
        raise ShipError(f"{run}: no such run folder")
    for needed in (CONFIG, POLICY, FINAL_EVAL):
        if not (run / needed).is_file():
            raise ShipError(f"{run}: no {needed} (not a finished `fignet-gym ppo` run; "
                            "finish it with --resume)")
    try:
        cfg = RunConfig.from_json(json.loads((run / CONFIG).read_text()))
    except (ValueError, KeyError, TypeError) as err:
        raise ShipError(f"{run / CONFIG}: not a PPO run config ({err})") from None
    if cfg.norm_obs and not (run / NORMALIZER).is_file():
        raise ShipError(f"{run}: no {NORMALIZER} (the policy's observation normaliser)")
    final = read_final_eval(run / FINAL_EVAL)
    if final["timesteps"] < cfg.ppo.total_timesteps:
        raise ShipError(f"{run / FINAL_EVAL}: the policy has {final['timesteps']} steps, "
                        f"{CONFIG} asks for {cfg.ppo.total_timesteps} (an extension not finished; "
                        "finish it with --resume)")
    if RunConfig.from_json(final["config"]).to_json() != cfg.to_json():
        raise ShipError(f"{run / FINAL_EVAL}: its config differs from {run / CONFIG}")
    for dyn in DYNAMICS:
        if len(final["eval"][dyn].get("episode_successes", [])) != final["eval"][dyn]["n_episodes"]:
            raise ShipError(f"{run / FINAL_EVAL}: eval.{dyn}.episode_successes does not list "
                            "every episode")
    curve = None
    if (run / EVAL_CSV).is_file() and cfg.eval_every > 0:
        _, steps, values = read_curves(run)
        curve = (steps, values)
    return cfg, final, curve


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def policy_card(name: str, run: Path, cfg: RunConfig, final: dict[str, Any],
                curve: tuple[list[int], dict[str, list[float]]] | None, files: dict[str, Path]) -> str:
    """Markdown card of a shipped policy, every figure read from the run's files."""
    trained = DYNAMICS_LABELS[cfg.dynamics]
    sim = cfg.simulator or "the shipped simulator of the env's scene"
    source = (f"FIGNet (learned dynamics: {sim})" if cfg.dynamics == "fignet" else "MuJoCo")
    cpu_h, wall_h = final["cpu_seconds"] / 3600, final.get("wall_seconds", math.nan) / 3600
    lines = [
        f"# PPO policy `{name}`",
        "",
        f"A stable-baselines3 PPO policy for `{cfg.env_id}`, trained only on {source} for "
        f"{final['timesteps']:,} environment steps, then evaluated on MuJoCo and on FIGNet. "
        "Generated by `fignet-gym ppo-ship` from the run's files; re-ship to update it.",
        "",
        "```python",
        "import gymnasium as gym",
        "from stable_baselines3.common.evaluation import evaluate_policy",
        "",
        "import fignet_gym.envs  # registers the environments",
        "from fignet_gym.agents.ppo import load_policy",
        "",
        f'policy = load_policy("{name}")  # SB3 predict on raw observations (normaliser inside)',
        'env = gym.make(policy.env_id, **policy.env_kwargs, dynamics="mujoco")',
        "print(evaluate_policy(policy, env, n_eval_episodes=20))",
        "```",
        "",
        "## Scores",
        "",
        f"Deterministic policy (its mean action), episodes seeded {EVAL_SEED} + k, the same episodes "
        "on both dynamics; success: the env's `is_success` at the episode's end; 95% Wilson "
        "intervals; errors: medians of the final errors.",
        "",
        "| evaluated on | success | 95% interval | mean return | final position error | "
        "final heading error | episodes |",
        "|---|---|---|---|---|---|---|",
    ]
    for dyn in DYNAMICS:
        rep = final["eval"][dyn]
        n, k = rep["n_episodes"], int(sum(bool(s) for s in rep["episode_successes"]))
        low, high = wilson_interval(k, n)
        pos = float(np.median(rep["episode_position_errors"])) * 1000
        yaw = float(np.median(rep["episode_orientation_errors"]))
        lines.append(f"| {DYNAMICS_LABELS[dyn]} | **{k / n:.0%}** ({k}/{n}) | {low:.0%}-{high:.0%} | "
                     f"{rep['mean_return']:.1f} | {pos:.1f} mm | {yaw:.3f} rad | {n} |")
    other = "mujoco" if cfg.dynamics == "fignet" else "fignet"
    gap = final["eval"][cfg.dynamics]["success_rate"] - final["eval"][other]["success_rate"]
    lines += ["", f"Success on the training dynamics ({trained}) minus on {DYNAMICS_LABELS[other]}: "
              f"{gap * 100:+.0f} points.", ""]
    lines += [
        "## Budget",
        "",
        f"{final['timesteps']:,} environment steps, {cpu_h:.2f} CPU hours ({final['cpu_seconds']:.0f} "
        f"CPU-s, training and periodic evaluations), {wall_h:.2f} wall hours.",
        "",
        "## Recipe",
        "",
    ]
    args, unset = command_line(cfg, f"runs/{name}")
    lines += ["```bash", "fignet-gym ppo " + " ".join(args), "```", ""]
    if unset:
        lines += [f"Settings no option of `fignet-gym ppo` sets (from `{CONFIG}`): "
                  + ", ".join(f"`{k}`" for k in unset) + ".", ""]
    flat = _flat(cfg.to_json())
    lines += ["| setting | value |", "|---|---|"]
    lines += [f"| `{k}` | `{json.dumps(v)}` |" for k, v in flat.items()]
    lines += ["", f"## Periodic evaluation ({cfg.eval_episodes} episodes each)", ""]
    if curve is None:
        lines += ["None (the run had no periodic evaluations).", ""]
    else:
        steps, values = curve
        lines += ["| steps | success on MuJoCo | on FIGNet | return on MuJoCo | on FIGNet |",
                  "|---|---|---|---|---|"]
        for i, s in enumerate(steps):
            lines.append(f"| {s:,} | {values['mujoco/success_rate'][i]:.0%} | "
                         f"{values['fignet/success_rate'][i]:.0%} | "
                         f"{values['mujoco/mean_return'][i]:.1f} | {values['fignet/mean_return'][i]:.1f} |")
        lines.append("")
    lines += ["## Files", "", "| file | bytes | sha256 |", "|---|---|---|"]
    lines += [f"| `{n}` | {p.stat().st_size:,} | `{_sha256(p)[:16]}` |" for n, p in files.items()]
    lines += ["", f"Shipped from the run folder `{run}` (its `{CONFIG}`, `{FINAL_EVAL}` and "
              f"`{EVAL_CSV}` are copied here). License: Apache-2.0, as the package (trained on the "
              "package's own simulators).", ""]
    return "\n".join(lines)


def ship_policy(run: str | Path, name: str, dest: str | Path | None = None,
                force: bool = False) -> Path:
    """Copy a finished run to ``<dest>/<name>/`` with its generated card; returns the folder.

    Every check comes first (``ShipError``: bad name, missing or unfinished run, existing
    destination without ``force``); the folder is written beside its final place and renamed
    over it, so a crash leaves the old shipped policy or the new one.
    """
    if not NAME.match(name):
        raise ShipError(f"--name {name!r}: use lower-case letters, digits, '.', '_' and '-' "
                        "(e.g. push-ppo)")
    run = Path(run)
    cfg, final, curve = check_run(run)
    root = Path(dest) if dest is not None else policies_dir()
    final_dir = root / name
    if final_dir.exists() and not force:
        raise ShipError(f"{final_dir} exists: pass --force to replace it")
    root.mkdir(parents=True, exist_ok=True)
    tmp = root / f".{name}.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    try:
        for item in (POLICY, NORMALIZER, CONFIG, FINAL_EVAL, EVAL_CSV):
            if (run / item).is_file():
                shutil.copy2(run / item, tmp / item)
        load_run_policy(tmp)  # the copy loads as a policy before it replaces anything
        files = {p.name: p for p in sorted(tmp.iterdir())}
        (tmp / f"{name}.md").write_text(policy_card(name, run, cfg, final, curve, files))
        old = root / f".{name}.old"
        shutil.rmtree(old, ignore_errors=True)
        if final_dir.exists():
            final_dir.rename(old)
        tmp.rename(final_dir)
        shutil.rmtree(old, ignore_errors=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return final_dir
