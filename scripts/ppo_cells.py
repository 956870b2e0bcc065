"""Per-cell errors of finished PPO runs: success, median final errors and the exploitation gap.

    python scripts/ppo_cells.py RUN [RUN ...]

``fignet-gym ppo-table`` prints success and return; this prints, for each run (its training
dynamics) and each evaluation dynamics, from ``final_eval.json``: successes out of the episodes,
the median (and mean) final position error in mm (a push's distance to the goal, a toss's
landing distance from the target), the median absolute heading error in degrees, the run's CPU
hours, and the **exploitation gap**: success on the training dynamics minus success on the other
one, with the episodes (same seeds on both) that succeed on both / only on the training one /
only on the other.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

#: The two evaluation dynamics of a run, in table order.
DYNAMICS = ("mujoco", "fignet")
MM_PER_M = 1000.0
SECONDS_PER_HOUR = 3600.0


def cell(rep: dict) -> str:
    """One table cell group of an evaluation report: ``n/N | median (mean) mm | median deg``."""
    pos = np.asarray(rep["episode_position_errors"], dtype=float) * MM_PER_M
    yaw = np.degrees(np.asarray(rep["episode_orientation_errors"], dtype=float))
    wins = sum(bool(s) for s in rep["episode_successes"])
    return (f"{wins}/{rep['n_episodes']} ({wins / rep['n_episodes']:.0%}) | "
            f"{np.median(pos):.1f} ({np.mean(pos):.1f}) | {np.median(yaw):.1f}")


def row(run: Path) -> str:
    """The table row of one run folder."""
    res = json.loads((run / "final_eval.json").read_text())
    trained = res["config"]["dynamics"]
    other = next(d for d in DYNAMICS if d != trained)
    ev = res["eval"]
    s_train = np.asarray(ev[trained]["episode_successes"], dtype=bool)
    s_other = np.asarray(ev[other]["episode_successes"], dtype=bool)
    gap = s_train.mean() - s_other.mean()
    paired = "/".join(str(int(m.sum())) for m in (s_train & s_other, s_train & ~s_other, ~s_train & s_other))
    cpu_h = res["cpu_seconds"] / SECONDS_PER_HOUR
    return (f"| {trained} ({run.name}) | {res['timesteps']:,} | {cpu_h:.3f} | {cell(ev['mujoco'])} | "
            f"{cell(ev['fignet'])} | {100 * gap:+.0f} pts ({paired}) |")


def main() -> None:
    """Print the table of the run folders given on the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="finished `fignet-gym ppo` run folders")
    args = parser.parse_args()
    print("| trained on | steps | CPU h | on MuJoCo: success | final error median (mean) mm "
          "| heading median deg | on FIGNet: success | median (mean) mm | heading median deg "
          "| gap: train - other (both/train only/other only) |")
    print("|" + "---|" * 10)
    for run in args.runs:
        print(row(run))


if __name__ == "__main__":
    main()
