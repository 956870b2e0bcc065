"""``fignet-gym`` command line: demo, plan, collect, ppo, ppo-table, ppo-ship, bench, train,
evaluate, floor, ship, data."""

from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

# The commands that load the trainer (TensorBoard), Gymnasium's envs or stable-baselines3 import
# their module when they run (`# deferred:` below), so `fignet-gym --help` stays fast.
from fignet_gym.atomic import output_lock
from fignet_gym.data.cli import int_at_least, nonnegative_float
from fignet_gym.data.cli import register as register_data
from fignet_gym.data.generate import GenerationError
from fignet_gym.dynamics.mujoco import collect_warnings
from fignet_gym.tools import bench, bench_collision, collect, plan
from fignet_gym.train.evaluation import evaluate
from fignet_gym.train.floor import floor_table
from fignet_gym.train.ship import ship
from fignet_gym.train.sim2real import PRIORS, parse_sizes, run_sim2real
from fignet_gym.train.sim2real_report import compare_runs


# ----------------------------------------------------------------------------- user errors
def user_error(err: BaseException) -> str | None:
    """The one-line message for an error caused by the user's input, ``None`` for a bug.

    Known user errors: bad or missing files (checkpoints, trajectory files, run folders,
    unreadable paths), refused overwrites, unsupported scenes, and ``ValueError`` from argument
    and config checks. Their messages already name the file and field.
    """
    # CheckpointError, TrajectoryFormatError, RunFolderError and UnsupportedSceneError are
    # ValueErrors.
    if isinstance(err, OSError) and not isinstance(err, (FileExistsError, FileNotFoundError)):
        name = err.filename if err.filename is not None else ""
        return f"{name}: {err.strerror or err}" if name else str(err)
    if isinstance(err, (ValueError, FileExistsError, FileNotFoundError, GenerationError)):
        return str(err)
    return None


def run_command(func: Callable[[argparse.Namespace], int | None], args: argparse.Namespace) -> int:
    """Run a subcommand: a user error prints ``error: <file>: <what>`` and returns 2 (set
    ``FIGNET_GYM_TRACEBACK=1`` for the traceback); anything else (a bug) propagates. MuJoCo's
    warnings are counted into one line at the end (stages that expect them, such as the contact
    fit, summarise their own), never printed one by one nor written to ``MUJOCO_LOG.TXT``."""
    default_show = warnings.showwarning

    def one_line(message: Warning | str, category: type[Warning], *rest: object, **kw: object) -> None:
        if issubclass(category, DeprecationWarning):  # for developers: as Python shows them
            default_show(message, category, *rest, **kw)  # type: ignore[arg-type]
            return
        print(f"warning: {message}", file=sys.stderr)  # a user reads the fix, not our source line

    with collect_warnings() as warned, warnings.catch_warnings():
        warnings.showwarning = one_line
        try:
            return int(func(args) or 0)
        except KeyboardInterrupt:
            print("error: interrupted", file=sys.stderr)
            return 130
        except Exception as err:  # noqa: BLE001 - classified below, re-raised if not a user error
            msg = user_error(err)
            if msg is None or os.environ.get("FIGNET_GYM_TRACEBACK"):
                raise
            print(f"error: {msg}", file=sys.stderr)
            return 2
        finally:
            if warned:
                times = "once" if len(warned) == 1 else f"{len(warned)} times"
                print(f"MuJoCo warned {times} (first: {warned[0]}); a simulation that "
                      "went unstable holds its last finite poses and is scored as it is",
                      file=sys.stderr)


def _overrides(text: str | None) -> dict:
    if not text:
        return {}
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise ValueError(f"--set: not JSON ({exc}): {text!r}") from None
    if not isinstance(value, dict):
        raise ValueError(f'--set: expected a JSON object such as \'{{"training.steps": 500}}\', got {text!r}')
    return value


# ----------------------------------------------------------------------------- commands
def _train(args: argparse.Namespace) -> int:
    from fignet_gym.train.trainer import train_from_files  # deferred: TensorBoard; `--help` stays fast

    overrides = _overrides(args.set)
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
    sizes, overrides = parse_sizes(args.sizes), _overrides(args.set) or None
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


def _bench(args: argparse.Namespace) -> int:
    bench.run(args)
    return 0


def _bench_tool(args: argparse.Namespace) -> int:
    """``bench-envs`` / ``bench-collision``: the tool's own options (``--help`` lists them)."""
    if args.tool == "bench-envs":
        from fignet_gym.tools.bench_envs import main as tool  # deferred: Gymnasium; `--help` stays fast
    else:
        tool = bench_collision.main
    try:
        tool(args.rest)
    except SystemExit as exc:  # argparse's own exit (--help: 0, a bad option: 2)
        return int(exc.code or 0)
    return 0


def _one_line_errors(run: Callable[[argparse.Namespace], object], user_error: type[Exception],
                     args: argparse.Namespace) -> int:
    """``run(args)``; a ``user_error`` is one ``error:`` line and exit 2, never a traceback."""
    try:
        run(args)
    except user_error as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


def _plan(args: argparse.Namespace) -> int:
    return _one_line_errors(plan.run, plan.PlanError, args)


def _collect(args: argparse.Namespace) -> int:
    return _one_line_errors(collect.collect, collect.CollectError, args)


def _demo(args: argparse.Namespace) -> int:
    from fignet_gym.tools.demo import run_demo  # deferred: stable-baselines3; `--help` stays fast

    run_demo(args.out, quick=args.quick, episodes=args.episodes, rollouts=args.rollouts)
    return 0


def _ppo(args: argparse.Namespace) -> int:
    from fignet_gym.tools.ppo import run_ppo_command  # deferred: stable-baselines3; `--help` stays fast

    return run_ppo_command(args)


def _ppo_table(args: argparse.Namespace) -> int:
    from fignet_gym.tools.ppo import ppo_table_command  # deferred: stable-baselines3; `--help` stays fast

    return ppo_table_command(args)


def _ppo_ship(args: argparse.Namespace) -> int:
    from fignet_gym.tools.ppo_ship import ppo_ship_command  # deferred: stable-baselines3; `--help` stays fast

    return ppo_ship_command(args)


def build_parser() -> argparse.ArgumentParser:
    """The full ``fignet-gym`` argument parser."""
    p = argparse.ArgumentParser(prog="fignet-gym", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    d = sub.add_parser("demo", help="MPC planning on the shipped learned simulator vs on MuJoCo, "
                       "acting in MuJoCo (table, video, plot)")
    d.add_argument("--out", default="outputs/demo", help="folder for videos, plots and JSON")
    d.add_argument("--episodes", type=int, default=3, help="seeded Push-v2 episodes per model")
    d.add_argument("--rollouts", action="store_true",
                   help="also compare open-loop rollouts of the shipped simulators with MuJoCo")
    d.add_argument("--quick", action="store_true", help="a tiny budget (for tests)")
    d.set_defaults(func=_demo)

    pl = sub.add_parser("plan", help="MPC (CEM, MPPI) or a baseline on seeded episodes: "
                        "success table, summary.json, side-by-side videos")
    plan.add_arguments(pl)
    pl.set_defaults(func=_plan)
    co = sub.add_parser("collect", help="record a planner's episodes, acted in MuJoCo, as "
                        "training trajectories (on-policy data)")
    collect.add_arguments(co)
    co.set_defaults(func=_collect)

    b = sub.add_parser("bench", help="learned step vs MuJoCo timings")
    bench.add_arguments(b)
    b.set_defaults(func=_bench)

    for name, what in (("bench-envs", "env steps per second of the envs, single and vectorised"),
                       ("bench-collision", "face-contact detection timings at several radii")):
        sub.add_parser(name, help=f"{what} (`fignet-gym {name} --help`)", add_help=False)

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

    o = sub.add_parser("ppo", help="train PPO on either dynamics (resumable), evaluate on both")
    o.add_argument("--env", default="fignet_gym/Push-v2", help="environment id")
    o.add_argument("--dynamics", choices=["mujoco", "fignet"], required=True,
                   help="training dynamics (evaluation always runs on both)")
    o.add_argument("--steps", type=int, required=True, help="environment steps in total")
    o.add_argument("--out", required=True, help="run folder (checkpoints, TensorBoard, CSV, policy)")
    o.add_argument("--resume", action="store_true", help="continue OUT from its last checkpoint")
    o.add_argument("--force", action="store_true", help="delete an existing OUT first")
    o.add_argument("--seed", type=int, default=0, help="PPO and training-env seed")
    o.add_argument("--simulator", help="learned simulator: pretrained name or checkpoint (default: "
                   "the pretrained one of the env's scene)")
    o.add_argument("--num-envs", type=int, default=32, help="sub-environments stepped as one batch")
    o.add_argument("--n-steps", type=int, default=64, help="steps per sub-environment per update")
    o.add_argument("--batch-size", type=int, default=256, help="PPO minibatch")
    o.add_argument("--n-epochs", type=int, default=10, help="passes over each rollout")
    o.add_argument("--lr", type=float, default=3e-4, help="Adam learning rate")
    o.add_argument("--gamma", type=float, default=0.99, help="discount")
    o.add_argument("--gae-lambda", type=float, default=0.95, help="GAE lambda")
    o.add_argument("--ent-coef", type=float, default=0.0, help="entropy bonus")
    o.add_argument("--net-arch", default="256,256", help="hidden sizes of policy and value MLPs")
    o.add_argument("--log-std-init", type=float, default=-1.0,
                   help="initial log std of the Gaussian policy (exploration noise)")
    o.add_argument("--use-sde", action="store_true",
                   help="state-dependent exploration noise (gSDE) instead of white Gaussian noise")
    o.add_argument("--sde-sample-freq", type=int, default=-1,
                   help="with --use-sde: new noise weights every N steps (-1: once per rollout)")
    o.add_argument("--no-normalize", action="store_true",
                   help="no VecNormalize of observations and rewards")
    o.add_argument("--observation", choices=["env", "push-features"], default="env",
                   help="what the policy sees: the env's observation, or it and the pushing geometry")
    o.add_argument("--shaping", type=float, default=0.0,
                   help="weight of the potential-based progress reward during training (0: none)")
    o.add_argument("--success-bonus", type=float, default=0.0,
                   help="extra reward of a successful step during training (0: none)")
    o.add_argument("--curriculum", action="store_true",
                   help="goal curriculum in training: new goals on success within an episode, the "
                   "goal range widening from easy to the env's own as success rises")
    o.add_argument("--precision", choices=["float32", "bfloat16"], default="float32",
                   help="network precision of the learned training env (evaluation: float32)")
    o.add_argument("--eval-every", type=int, default=50_000,
                   help="evaluate on both dynamics every N steps (0: never)")
    o.add_argument("--eval-episodes", type=int, default=32, help="episodes per periodic evaluation")
    o.add_argument("--final-episodes", type=int, default=50,
                   help="episodes per dynamics of the final evaluation")
    o.add_argument("--checkpoint-every", type=int, default=20_000, help="resumable checkpoint every N steps")
    o.add_argument("--compare", nargs="*", default=[],
                   help="finished run folders to print in the transfer table beside this one")
    o.add_argument("--quiet", action="store_true", help="no progress bar")
    o.set_defaults(func=_ppo)

    o = sub.add_parser("ppo-table", help="transfer table of finished PPO runs (trained on x evaluated on)")
    o.add_argument("runs", nargs="+", help="run folders of `fignet-gym ppo`")
    o.add_argument("--out", help="also write the Markdown table to this file")
    o.add_argument("--plot", help="also plot the runs' periodic evaluations to this image")
    o.set_defaults(func=_ppo_table)

    o = sub.add_parser("ppo-ship", help="ship a finished PPO run as a named policy with a generated card "
                       "(fignet_gym.agents.load_policy(NAME))")
    o.add_argument("run", help="finished run folder of `fignet-gym ppo`")
    o.add_argument("--name", required=True, help="policy name, e.g. push-ppo")
    o.add_argument("--dest", help="folder (default: the package's shipped policies)")
    o.add_argument("--force", action="store_true", help="replace a shipped policy of that name")
    o.set_defaults(func=_ppo_ship)

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

    register_data(sub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``fignet-gym`` script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in ("bench-envs", "bench-collision"):  # tools with their own options
        args = argparse.Namespace(tool=argv[0], rest=argv[1:], func=_bench_tool)
    else:
        args = build_parser().parse_args(argv)
    return run_command(args.func, args)


if __name__ == "__main__":
    sys.exit(main())
