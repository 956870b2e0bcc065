"""``fignet-gym bench SUBCOMMAND``: the benchmarks, each printing CPU-time figures as ratios measured
in one run (learned against MuJoCo on the same scene, batched against single) and writing them to
``--json``. Speed goes here, never into a test."""

from __future__ import annotations

import argparse
from collections.abc import Callable

import torch

from fignet_gym.cli.options import int_at_least, positive_float
from fignet_gym.dynamics.learned import PRECISIONS
from fignet_gym.tools import bench, bench_collision

#: ``bench envs`` names -> env ids (the module itself imports Gymnasium, so it is loaded on use).
BENCH_ENVS = ("push", "toss")


def _envs(args: argparse.Namespace) -> None:
    from fignet_gym.tools.bench_envs import run  # deferred: Gymnasium's envs; `--help` stays fast

    run(args)


def _call(run: Callable[[argparse.Namespace], object]) -> Callable[[argparse.Namespace], int]:
    """The command of a benchmark: ``--threads`` set once here for every one of them."""
    def command(args: argparse.Namespace) -> int:
        if args.threads:
            torch.set_num_threads(args.threads)
        run(args)
        return 0
    return command


def _common(p: argparse.ArgumentParser, threads_default: int = 0) -> None:
    p.add_argument("--threads", type=int_at_least(0), default=threads_default,
                   help="torch threads (0: torch's default)")
    p.add_argument("--json", metavar="PATH", help="write every figure to this JSON file")


def _model_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--repeats", type=int_at_least(1), default=20, help="timed repetitions (median reported)")
    p.add_argument("--dtype", choices=sorted(PRECISIONS), default="float32",
                   help="network precision at inference (LearnedSimulator.inference_dtype)")
    _common(p)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``bench`` and its subcommands to the ``fignet-gym`` subparsers."""
    b = sub.add_parser("bench", help="benchmarks: learned step vs MuJoCo, shipped models, rollouts, "
                       "the PPO loop, the envs, contact detection (`fignet-gym bench SUB --help`)",
                       description=bench.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    kinds = b.add_subparsers(dest="bench", required=True, metavar="SUB")

    p = kinds.add_parser("step", help="one learned step (paper and CPU sizes) against MuJoCo")
    p.add_argument("--batch", type=int_at_least(1), nargs="+", default=[1, 16], help="scene batch sizes")
    _model_options(p)
    p.set_defaults(func=_call(bench.run_step))

    p = kinds.add_parser("shipped", help="the shipped models' batched step: FLOPs, GFLOP/s against "
                         "the machine's matmul rate on the same shapes")
    p.add_argument("--batch", type=int_at_least(1), nargs="+", default=[1, 16], help="scene batch sizes")
    _model_options(p)
    p.set_defaults(func=_call(bench.run_shipped))

    p = kinds.add_parser("rollout", help="scene-steps/s of Dynamics.rollout, learned vs mujoco.rollout")
    p.add_argument("--batch", dest="rollout_batch", type=int_at_least(1), nargs="+",
                   default=[1, 64, 256, 1024], help="rollout batch sizes")
    p.add_argument("--steps", dest="rollout_steps", type=int_at_least(1), default=25,
                   help="steps per rollout")
    _model_options(p)
    p.set_defaults(func=_call(bench.run_rollout))

    p = kinds.add_parser("ppo", help="env steps per CPU-second of the PPO loop (rollouts and updates) "
                         "on MuJoCo and on FIGNet in float32 and bfloat16")
    p.add_argument("--env", dest="ppo_env", default="fignet_gym/Push-v2", help="the env id")
    p.add_argument("--setting", dest="ppo_setting", type=int_at_least(1), nargs=4,
                   default=[256, 32, 2048, 5], metavar=("ENVS", "N_STEPS", "BATCH", "EPOCHS"),
                   help="sub-environments, steps per update, minibatch, epochs")
    p.add_argument("--repeats", type=int_at_least(1), default=3, help="repetitions (median reported)")
    _common(p)
    p.set_defaults(func=_call(bench.run_ppo))

    p = kinds.add_parser("envs", help="env steps per second of the envs, single and vectorised")
    p.add_argument("--envs", nargs="+", default=list(BENCH_ENVS), choices=BENCH_ENVS)
    p.add_argument("--dynamics", nargs="+", default=["mujoco", "fignet"], choices=["mujoco", "fignet"])
    p.add_argument("--nums", nargs="+", type=int_at_least(1), default=[1, 16, 64], help="vector sizes N")
    p.add_argument("--seconds", type=positive_float, default=3.0, help="time budget per measurement")
    p.add_argument("--checkpoint-push", help="learned push checkpoint (default: pretrained or untrained)")
    p.add_argument("--checkpoint-toss", help="learned toss checkpoint (default: pretrained or untrained)")
    _common(p, threads_default=1)
    p.set_defaults(func=_call(_envs))

    p = kinds.add_parser("collision", help="face-contact detection timings at several radii")
    p.add_argument("--radii", type=positive_float, nargs="+", default=[0.005, 0.01, 0.02])
    p.add_argument("--repeats", type=int_at_least(1), default=100)
    _common(p)
    p.set_defaults(func=_call(bench_collision.run))
