"""``fignet-gym train``, ``evaluate``, ``floor``, ``ship``, ``sim2real`` and ``sim2real-compare``:
the learned simulator's workflows (:mod:`fignet_gym.train` does the work)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from fignet_gym.atomic import output_lock
from fignet_gym.cli.options import int_at_least, json_overrides, nonnegative_float
from fignet_gym.train.evaluation import evaluate
from fignet_gym.train.floor import floor_table
from fignet_gym.train.ship import ship
from fignet_gym.train.sim2real import PRIORS, parse_sizes, run_sim2real
from fignet_gym.train.sim2real_report import compare_runs


def _train(args: argparse.Namespace) -> int:
    from fignet_gym.train.trainer import train_from_files  # deferred: TensorBoard; `--help` stays fast

    overrides = json_overrides(args.set)
    train_from_files(args.data, args.valid, args.config, args.out, resume=args.resume,
                     overrides=overrides, max_train=args.max_train, init=args.init,
                     force=args.force)
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    evaluate(args.checkpoint, args.data, args.out, num=args.num, horizon=args.horizon,
             videos=args.videos, against=args.against)
    return 0


def _floor(args: argparse.Namespace) -> int:
    floor_table(args.data, args.noise, out=args.out, num=args.num, horizon=args.horizon,
                history=args.history)
    return 0


def _ship(args: argparse.Namespace) -> int:
    ship(args.run, args.name, args.data, args.horizon, num=args.num, dest=args.dest, notes=args.notes)
    return 0


def _sim2real(args: argparse.Namespace) -> int:
    sizes, overrides = parse_sizes(args.sizes), json_overrides(args.set) or None
    with output_lock(args.out):  # one process per run folder
        run_sim2real(args.data, args.out, sizes, fractions=args.fractions,
                     seed=args.seed, horizon=args.horizon, resume=args.resume,
                     fit_evaluations=args.fit_evaluations, fit_trajectories=args.fit_trajectories,
                     fignet=not args.no_fignet, pretrain=args.pretrain, config=args.config,
                     budget=args.budget, overrides=overrides, init=args.init,
                     polish=not args.no_polish, prior=args.prior,
                     pretrain_budget=args.pretrain_budget)
    return 0


def _sim2real_compare(args: argparse.Namespace) -> int:
    labels = args.labels or [Path(r).name for r in args.runs]
    if len(labels) != len(args.runs):
        raise ValueError(f"--labels: {len(labels)} labels for {len(args.runs)} runs")
    runs = {}
    for label, run in zip(labels, args.runs, strict=True):
        path = Path(run) / "results.json"
        if not path.is_file():
            raise ValueError(f"{run}: no results.json (a finished sim2real run folder?)")
        runs[label] = json.loads(path.read_text())
    print(compare_runs(runs, Path(args.out)))
    print(f"wrote {Path(args.out) / 'compare.md'} and {Path(args.out) / 'compare.png'}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the simulator workflows to the ``fignet-gym`` subparsers."""
    t = sub.add_parser("train", help="train a simulator on trajectory files")
    t.add_argument("--data", required=True, nargs="+",
                   help="training trajectories (HDF5; several files are pooled)")
    t.add_argument("--valid", help="validation trajectories (default: last 4 of --data)")
    t.add_argument("--config",
                   help="preset name (push-cpu, push-finetune, push-scratch, toss-cpu, cube-real, "
                   "paper) or JSON file")
    t.add_argument("--set", help='JSON overrides, e.g. \'{"training.steps": 500}\'')
    t.add_argument("--out", required=True, help="run folder (checkpoints, logs)")
    t.add_argument("--resume", action="store_true", help="continue from OUT/last.pt (the run's "
                   "own config unless --config is given, which must then match it)")
    t.add_argument("--force", action="store_true", help="replace a run already in OUT")
    t.add_argument("--max-train", type=int_at_least(1),
                   help="use only the first N training trajectories")
    t.add_argument("--init", help="start from this checkpoint's weights (fine-tuning a new run): "
                   "a checkpoint file or a pretrained name (push, toss, cube-real)")
    t.set_defaults(func=_train)

    e = sub.add_parser("evaluate", help="rollout metrics, plots and videos of a checkpoint")
    e.add_argument("--checkpoint", required=True, help="checkpoint file or pretrained name")
    e.add_argument("--data", required=True, help="held-out trajectories (HDF5)")
    e.add_argument("--out", default="outputs/eval",
                   help="folder for metrics.json, plots, videos (default: outputs/eval)")
    e.add_argument("--num", type=int_at_least(1), default=None, help="first N trajectories (default: all)")
    e.add_argument("--horizon", type=int_at_least(1), default=None,
                   help="frame of the headline errors, counted from frame 0 of each trajectory "
                   "(default: 50, or the longest trajectory's last frame if shorter; each "
                   "trajectory's last frame is scored too)")
    e.add_argument("--videos", type=int_at_least(0), default=2, help="side-by-side videos to write")
    e.add_argument("--against", help="second checkpoint (e.g. a baseline), or MuJoCo: "
                   "mujoco:nominal (the data's own MJCF), a shipped fit (mujoco:push-real, "
                   "mujoco:cube-real) or a parameters .json, or the quasi-static pushing model "
                   "limit-surface:push-real (or limit-surface:FIT.json), on the same trajectories: "
                   "ratio of median errors with a bootstrap interval, per trajectory and per "
                   "recording")
    e.set_defaults(func=_evaluate)

    f = sub.add_parser("floor", help="MuJoCo's own rollout error from a slightly wrong start "
                       "(how chaotic the data is: a floor under learned rollouts)")
    f.add_argument("--data", required=True, help="generated trajectories (HDF5)")
    f.add_argument("--noise", type=nonnegative_float, nargs="+", default=[1e-4, 1e-3, 1e-2],
                   help="start position errors (m): every free body moved horizontally")
    f.add_argument("--num", type=int_at_least(1), default=None,
                   help="first N trajectories to re-simulate (default: all)")
    f.add_argument("--horizon", type=int_at_least(1), default=50,
                   help="step at which errors are reported")
    f.add_argument("--history", type=int_at_least(1), default=2,
                   help="velocities a learned rollout is given "
                   "(the nudge is at the last of its history + 1 poses)")
    f.add_argument("--out", help="JSON file for the table")
    f.set_defaults(func=_floor)

    s = sub.add_parser("ship", help="export a run's best checkpoint with a model card")
    s.add_argument("--run", required=True, help="run folder (with best.pt, curve.jsonl)")
    s.add_argument("--name", required=True, help="pretrained name, e.g. push")
    s.add_argument("--data", required=True, help="held-out trajectories for the card's scores")
    s.add_argument("--horizon", type=int_at_least(1), default=50,
                   help="step at which errors are reported")
    s.add_argument("--num", type=int_at_least(1), default=None,
                   help="first N held-out trajectories to evaluate (default: all)")
    s.add_argument("--dest", help="folder (default: the package's pretrained/)")
    s.add_argument("--notes", default="", help="extra Markdown for the card")
    s.set_defaults(func=_ship)

    r = sub.add_parser("sim2real", help="nominal and fitted MuJoCo vs FIGNet at several training-set "
                       "sizes on real trajectories (split, fit, train, table, plot; resumable)")
    r.add_argument("--data", required=True, help="trajectory file (e.g. from import-contactnets)")
    r.add_argument("--out", required=True, help="run folder")
    r.add_argument("--sizes", nargs="+", default=["8", "16", "32", "64", "128", "all"],
                   help="FIGNet training-set sizes (first k of the training split; 'all')")
    r.add_argument("--resume", action="store_true", help="continue a run in OUT")
    r.add_argument("--fractions", type=nonnegative_float, nargs=3, default=[0.6, 0.2, 0.2],
                   metavar=("TRAIN", "VALID", "TEST"))
    r.add_argument("--seed", type=int, default=0, help="split, fit and training seed")
    r.add_argument("--horizon", type=int_at_least(1), default=50,
                   help="frame of the headline errors (from 0)")
    r.add_argument("--fit-evaluations", type=int_at_least(1), default=240,
                   help="CMA-ES candidates per friction cone")
    r.add_argument("--fit-trajectories", type=int_at_least(1), default=64,
                   help="training trajectories each candidate replays")
    r.add_argument("--config", default="cube-real", help="FIGNet training preset or JSON")
    r.add_argument("--budget", type=int_at_least(1), default=None,
                   help="optimiser steps per FIGNet run (default: the recipe's, by size)")
    r.add_argument("--init", default=None, help="warm-start FIGNet from a checkpoint or pretrained name")
    r.add_argument("--set", help='JSON overrides of the training config, e.g. \'{"training.lr": 5e-4}\'')
    r.add_argument("--no-fignet", action="store_true", help="MuJoCo stages only")
    r.add_argument("--no-polish", action="store_true",
                   help="skip the rollout polish of models with 64 or more training trajectories")
    r.add_argument("--pretrain", type=int_at_least(0), default=0, metavar="N",
                   help="pretrain FIGNet on N synthetic tosses or pushes from the model(s) fitted "
                        "on the smallest size's trajectories, then fine-tune each size (0: none)")
    r.add_argument("--prior", choices=PRIORS, default="mujoco",
                   help="--pretrain on pushes: the fitted model(s) the synthetic pushes come from "
                        "(both: half each); pretraining starts from --init (default: %(default)s)")
    r.add_argument("--pretrain-budget", type=int_at_least(1), default=None, metavar="STEPS",
                   help="--pretrain: optimiser steps on the synthetic data (default: 2000 for "
                        "pushes, 8000 for tosses)")
    r.set_defaults(func=_sim2real)

    c = sub.add_parser("sim2real-compare", help="several sim2real runs of one split side by side "
                       "(FIGNet recipes against the analytic models): table and plot")
    c.add_argument("runs", nargs="+", help="sim2real run folders (each with results.json)")
    c.add_argument("--labels", nargs="+", help="one label per run (default: the folder names)")
    c.add_argument("--out", required=True, help="folder for compare.md and compare.png")
    c.set_defaults(func=_sim2real_compare)
