"""Accuracy against CPU hours for training runs (reads each run's ``curve.jsonl``).

    python examples/plot_training_curves.py runs/toss3 runs/toss_mgn --out curves.png
    python examples/plot_training_curves.py runs/push8 runs/push9:0.31 --out push.png

``RUN:HOURS`` shifts a fine-tuning run by the CPU hours of the run it started from.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", help="run folders (with curve.jsonl), optionally RUN:HOURS")
    p.add_argument("--out", default="training_curves.png")
    args = p.parse_args()
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    for spec in args.runs:
        run, _, offset = spec.partition(":")
        recs = [json.loads(line) for line in (Path(run) / "curve.jsonl").read_text().splitlines()]
        hours = [r["cpu_hours"] + float(offset or 0) for r in recs]
        ax[0].plot(hours, [r["translation_rmse_ratio_still"] for r in recs], "o-", label=Path(run).name)
        ax[1].plot(hours, [r["rotation_deg_ratio_still"] for r in recs], "o-", label=Path(run).name)
    for a, what in zip(ax, ("translation", "rotation"), strict=True):
        a.axhline(1.0, color="gray", lw=0.8, ls="--")
        a.set(xlabel="CPU hours (one core)", ylabel=f"{what} error / no-motion error",
              title=f"validation rollouts: {what}")
        a.grid(alpha=0.3)
    ax[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out, dpi=90)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
