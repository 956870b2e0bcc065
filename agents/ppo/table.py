"""Finished PPO runs side by side: the transfer table (trained on x evaluated on) and the curves.

Both read files a user can edit or a copy can truncate, so both check what they read and name
the file and the field at fault (``ValueError``) rather than print ``nan%`` or an empty plot.
"""

from __future__ import annotations

import csv
import json
import os
import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fignet_gym.agents.ppo.config import DYNAMICS
from fignet_gym.agents.ppo.rundir import CONFIG, FINAL_EVAL, RunError
from fignet_gym.checks import Range, check_value

#: Fields of each dynamics' report the table reads.
REPORT_FIELDS = ("success_rate", "mean_return", "n_episodes")
#: The columns of ``eval.csv`` the curves read, per dynamics.
CURVE_KEYS = ("success_rate", "mean_return")


#: Allowed values of a final evaluation's top-level fields and of each dynamics' report (also
#: the rules of ``eval.csv``'s columns).
_FINAL = {"timesteps": Range("int", low=0), "cpu_seconds": Range("float", low=0)}
_FINITE = Range("float")
_REPORT = {"success_rate": Range("float", low=0, high=1), "mean_return": _FINITE,
           "n_episodes": Range("int", low=1)}


def read_final_eval(path: Path) -> dict[str, Any]:
    """A run's ``final_eval.json``, checked for what :func:`transfer_table` reads.

    Raises ``ValueError("{path}: ...")`` for a file that is not JSON, lacks a field, or holds a
    value out of its range (a success rate outside [0, 1], a negative step count, a NaN).
    """
    try:
        res = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not valid JSON ({err.msg} at line {err.lineno})") from None
    evals = res.get("eval") if isinstance(res, dict) else None
    ok = (isinstance(res, dict) and isinstance(res.get("config"), dict)
          and "dynamics" in res["config"] and "timesteps" in res and "cpu_seconds" in res
          and isinstance(evals, dict)
          and all(isinstance(evals.get(k), dict) and all(f in evals[k] for f in REPORT_FIELDS)
                  for k in DYNAMICS))
    if not ok:
        raise ValueError(f"{path}: not a final evaluation (needs config.dynamics, timesteps, "
                         "cpu_seconds and eval.mujoco / eval.fignet with success_rate, "
                         "mean_return, n_episodes)")
    check_value("config.dynamics", res["config"]["dynamics"], Range("str", choices=DYNAMICS), f"{path}: ")
    for name, allowed in _FINAL.items():
        check_value(name, res[name], allowed, f"{path}: ")
    for dyn in DYNAMICS:
        for name in REPORT_FIELDS:
            check_value(f"eval.{dyn}.{name}", evals[dyn][name], _REPORT[name], f"{path}: ")
    return res


def _error_mm(report: dict[str, Any]) -> str:
    """Median final position error of an evaluation report in mm (a push's distance to the goal,
    a toss's landing distance from the target); ``-`` when the report has none."""
    errors = [e for e in report.get("episode_position_errors", []) if _FINITE.accepts(e)]
    return f"{1000 * statistics.median(errors):.1f}" if errors else "-"


#: Settings that do not change what a run trains (bookkeeping and how it is evaluated), left out
#: of a recipe with the seed and the budget.
NOT_RECIPE = ("seed", "total_timesteps", "torch_threads", "eval_every", "eval_episodes",
              "final_episodes", "checkpoint_every")


def _recipe(config: dict[str, Any]) -> str:
    """A run's training settings as a key: runs that differ only in seed (or in bookkeeping,
    :data:`NOT_RECIPE`) are one recipe."""
    ppo = {k: v for k, v in config.get("ppo", {}).items() if k not in NOT_RECIPE}
    rest = {k: v for k, v in config.items() if k != "ppo" and k not in NOT_RECIPE}
    return json.dumps({**rest, "ppo": ppo}, sort_keys=True)


def _spread(values: Sequence[float], points: bool = False) -> str:
    """``mean [min, max]`` of rates as percentages, or of rate differences as signed percentage
    points (``points``)."""
    def fmt(x: float) -> str:
        return f"{100 * x:+.0f} pts" if points else f"{x:.0%}"
    return f"{fmt(statistics.mean(values))} [{fmt(min(values))}, {fmt(max(values))}]"


def transfer_table(runs: Sequence[str | os.PathLike]) -> str:
    """Markdown tables: each run (its training dynamics) x evaluated on MuJoCo / on FIGNet, then,
    when several runs share a recipe (the same settings but the seed), one row per recipe.

    Reads every run's ``final_eval.json`` (same seeds ``EVAL_SEED + k`` for all runs and both
    dynamics). Cells: success rate, median final position error (mm: a push's distance to the
    goal, a toss's landing distance) and mean return (the env's reward) over the episodes. The
    exploitation gap is the success on the training dynamics minus the success on MuJoCo (what a
    policy gains from the learned model's errors; 0 for a run trained on MuJoCo). Recipe rows:
    mean and [min, max] over the seeds.
    """
    lines = [
        "| trained on | seed | steps | CPU h | eval on MuJoCo: success | error mm | return "
        "| eval on FIGNet: success | error mm | return | gap | episodes |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    recipes: dict[str, list[dict[str, Any]]] = {}
    for run in runs:
        path = Path(run) / FINAL_EVAL
        if not path.exists():
            raise RunError(f"{path}: missing (the run has not finished)")
        res = read_final_eval(path)
        m, f = res["eval"]["mujoco"], res["eval"]["fignet"]
        trained = res["config"]["dynamics"]
        gap = res["eval"][trained]["success_rate"] - m["success_rate"]
        seed = res["config"].get("ppo", {}).get("seed", "-")
        lines.append(
            f"| {trained} ({Path(run).name}) | {seed} | {res['timesteps']:,} | "
            f"{res['cpu_seconds'] / 3600:.2f} | {m['success_rate']:.0%} | {_error_mm(m)} | "
            f"{m['mean_return']:.1f} | {f['success_rate']:.0%} | {_error_mm(f)} | "
            f"{f['mean_return']:.1f} | {100 * gap:+.0f} pts | "
            f"{m['n_episodes']} / {f['n_episodes']} |"
        )
        recipes.setdefault(_recipe(res["config"]), []).append({**res, "gap": gap})
    if all(len(group) == 1 for group in recipes.values()):
        return "\n".join(lines)
    lines += [
        "",
        "| trained on | runs (seeds) | steps | CPU h per run | eval on MuJoCo: success "
        "| eval on FIGNet: success | gap |",
        "|---|---|---|---|---|---|---|",
    ]
    for group in recipes.values():
        rate = {d: [r["eval"][d]["success_rate"] for r in group] for d in DYNAMICS}
        steps = sorted({r["timesteps"] for r in group})
        seeds = ", ".join(str(r["config"].get("ppo", {}).get("seed", "-")) for r in group)
        lines.append(
            f"| {group[0]['config']['dynamics']} | {len(group)} ({seeds}) | "
            f"{' / '.join(f'{s:,}' for s in steps)} | "
            f"{sum(r['cpu_seconds'] for r in group) / len(group) / 3600:.2f} | "
            f"{_spread(rate['mujoco'])} | {_spread(rate['fignet'])} | "
            f"{_spread([r['gap'] for r in group], points=True)} |"
        )
    return "\n".join(lines)


def read_curves(run: str | os.PathLike) -> tuple[str, list[int], dict[str, list[float]]]:
    """A run's periodic evaluations: training dynamics, steps ``int[R]`` and each
    ``"<dynamics>/<key>"`` column ``float[R]`` of ``eval.csv``.

    Raises ``ValueError`` naming the file for a missing config, an ``eval.csv`` without rows, a
    row cut short, a value that is not a number in its range, or steps that do not increase.
    """
    root = Path(run)
    path = root / "eval.csv"
    try:
        trained = json.loads((root / CONFIG).read_text())["dynamics"]
        with path.open(newline="") as f:
            rows = list(csv.DictReader(f))
    except (OSError, json.JSONDecodeError, KeyError, TypeError) as err:
        raise ValueError(f"{root}: not a PPO run folder ({type(err).__name__}: {err})") from None
    if not rows:
        raise ValueError(f"{path}: no periodic evaluations to plot (a run with --eval-every 0?)")
    columns = [f"{d}/{k}" for d in DYNAMICS for k in CURVE_KEYS]
    steps: list[int] = []
    values: dict[str, list[float]] = {c: [] for c in columns}
    for line, row in enumerate(rows, start=2):
        try:
            step = int(row["step"])
            parsed = {c: float(row[c]) for c in columns}
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"{path}: line {line} is incomplete or not numeric (the file is "
                             f"truncated or edited; it needs step and {', '.join(columns)})") from None
        bad = [c for c, v in parsed.items() if not _REPORT[c.split("/")[1]].accepts(v)]
        if bad or (steps and step <= steps[-1]) or step < 0:
            raise ValueError(f"{path}: line {line} has out-of-range values "
                             f"({', '.join(bad) or 'step'})")
        steps.append(step)
        for c in columns:
            values[c].append(parsed[c])
    return trained, steps, values


def exploitation_gap(run: str | os.PathLike) -> tuple[list[int], list[float]]:
    """Steps ``int[R]`` and the exploitation gap ``float[R]`` at each periodic evaluation of a run:
    success on its training dynamics minus success on MuJoCo (all zeros when it trained on MuJoCo)."""
    trained, steps, values = read_curves(run)
    gap = [a - b for a, b in zip(values[f"{trained}/success_rate"], values["mujoco/success_rate"],
                                 strict=True)]
    return steps, gap


def plot_curves(runs: Sequence[str | os.PathLike], path: str | os.PathLike) -> Path:
    """Periodic evaluation of each run (``eval.csv``): success rate and return vs training steps,
    and the exploitation gap (success on the training dynamics minus on MuJoCo) of runs trained
    on a learned model.

    One line per run and evaluation dynamics (solid: MuJoCo, dashed: FIGNet); saved as an image.
    Every run is read (and checked, :func:`read_curves`) before anything is drawn.
    """
    curves = [read_curves(run) for run in runs]

    # deferred: Matplotlib loads, and its Agg backend is chosen, when a plot is drawn, not to read tables
    import matplotlib
    import matplotlib.ticker  # deferred: as matplotlib above

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: after the backend is chosen

    fig, axes = plt.subplots(1, 3, figsize=(15, 3.8))
    for i, (trained, x, values) in enumerate(curves):
        for dyn, style in (("mujoco", "-"), ("fignet", "--")):
            for ax, key in zip(axes[:2], CURVE_KEYS, strict=True):
                ax.plot(x, values[f"{dyn}/{key}"], style, color=f"C{i}",
                        label=f"{Path(runs[i]).name} (trained on {trained}), eval on {dyn}")
        if trained != "mujoco":
            axes[2].plot(*exploitation_gap(runs[i]), color=f"C{i}",
                         label=f"{Path(runs[i]).name} (trained on {trained})")
    axes[0].set_ylabel("success rate")
    axes[1].set_ylabel("mean episode return (env reward)")
    axes[2].set_ylabel("gap: training model - MuJoCo")
    axes[2].set_title("exploitation gap (success)", fontsize=9)
    axes[2].axhline(0.0, color="k", lw=0.8)
    for ax in axes:
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v / 1000:g}k"))
        ax.set_xlabel("training environment steps")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    if any(trained != "mujoco" for trained, _, _ in curves):
        axes[2].legend(fontsize=8)
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
