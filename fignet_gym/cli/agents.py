"""``fignet-gym demo``, ``plan`` and ``collect``: the main job, seeded planning episodes, and a
planner's episodes recorded as training data (:mod:`fignet_gym.tools.demo`, ``.plan``,
``.collect`` do the work)."""

from __future__ import annotations

import argparse

from fignet_gym.cli.options import int_at_least
from fignet_gym.tools import collect, plan
from fignet_gym.tools.collect import PLANNERS
from fignet_gym.tools.plan import BASELINES


def _demo(args: argparse.Namespace) -> int:
    from fignet_gym.tools.demo import run_demo  # deferred: stable-baselines3; `--help` stays fast

    run_demo(args.out, quick=args.quick, episodes=args.episodes, rollouts=args.rollouts)
    return 0


def _plan(args: argparse.Namespace) -> int:
    plan.run(args)
    return 0


def _collect(args: argparse.Namespace) -> int:
    collect.collect(args)
    return 0


def _plan_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--env", default="fignet_gym/Push-v2", help="environment id")
    p.add_argument("--dynamics", default="mujoco", choices=["mujoco", "fignet"],
                   help="the planner's model")
    p.add_argument("--checkpoint", help="fignet: checkpoint path or pretrained name (default: "
                   "the shipped simulator of the env's scene)")
    p.add_argument("--planner", default="cem", choices=["cem", "mppi", *BASELINES])
    p.add_argument("--act-dynamics", default="mujoco", choices=["mujoco", "fignet"],
                   help="what the environment acts with")
    p.add_argument("--episodes", type=int_at_least(1), default=10)
    p.add_argument("--seed", type=int_at_least(0), default=0, help="episode k is reset with seed + k")
    p.add_argument("--out", required=True, help="folder for summary.json, episodes.jsonl, videos")
    p.add_argument("--videos", type=int_at_least(0), default=0,
                   help="side-by-side videos of the first K")
    p.add_argument("--resume", action="store_true", help="skip episodes already in OUT (the "
                   "settings must be the run's: env, planner, dynamics, checkpoint, budget, seed, "
                   "MuJoCo and torch versions)")
    p.add_argument("--force", action="store_true", help="replace a run already in OUT")
    p.add_argument("--horizon", type=int, help="override the preset planning horizon")
    p.add_argument("--population", type=int, help="override the preset candidates per iteration")
    p.add_argument("--iterations", type=int, help="override the preset iterations")
    p.add_argument("--replan-every", type=int, help="override the preset re-planning period")
    p.add_argument("--env-kwargs", default="{}", metavar="JSON",
                   help="env arguments as a JSON object, e.g. ScenePush-v0's "
                        "'{\"mjcf\": \"my_scene.xml\", \"object\": \"crate\", \"pusher\": \"finger\"}'")
    p.add_argument("--threads", type=int_at_least(1), default=1,
                   help="torch and MuJoCo rollout threads")

def _collect_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--env", default="fignet_gym/Push-v2", help="environment id (a push env)")
    p.add_argument("--planner", default="cem", choices=PLANNERS)
    p.add_argument("--dynamics", default="mujoco", choices=["mujoco", "fignet"],
                   help="the planner's model (the episodes are always acted in MuJoCo)")
    p.add_argument("--checkpoint", help="fignet: checkpoint path or pretrained name")
    p.add_argument("--episodes", type=int_at_least(1), default=100)
    p.add_argument("--seed", type=int_at_least(0), default=100000,
                   help="episode k is reset with seed + k (keep clear of benchmark seeds)")
    p.add_argument("--action-noise", type=float, default=0.0,
                   help="std of Gaussian noise added to each planned action (action units)")
    p.add_argument("--epsilon", type=float, default=0.0,
                   help="probability of a uniformly random action instead of the plan's")
    p.add_argument("--env-kwargs", default="{}", metavar="JSON",
                   help="extra env arguments as a JSON object, e.g. '{\"goal_distance\": 0.02, "
                   "\"goal_yaw\": 0.8}' (over the registered ones; dynamics is always mujoco)")
    p.add_argument("--out", required=True, help="trajectory file (.h5) to write")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")

def register(sub: argparse._SubParsersAction) -> None:
    """Add ``demo``, ``plan`` and ``collect`` to the ``fignet-gym`` subparsers."""
    d = sub.add_parser("demo", help="MPC planning on the shipped learned simulator vs on MuJoCo, "
                       "acting in MuJoCo (table, video, plot)")
    d.add_argument("--out", default="outputs/demo", help="folder for videos, plots and JSON")
    d.add_argument("--episodes", type=int_at_least(1), default=3, help="seeded Push-v2 episodes per model")
    d.add_argument("--rollouts", action="store_true",
                   help="also compare open-loop rollouts of the shipped simulators with MuJoCo")
    d.add_argument("--quick", action="store_true", help="a tiny budget (for tests)")
    d.set_defaults(func=_demo)

    pl = sub.add_parser("plan", help="MPC (CEM, MPPI) or a baseline on seeded episodes: "
                        "success table, summary.json, side-by-side videos")
    _plan_arguments(pl)
    pl.set_defaults(func=_plan)
    co = sub.add_parser("collect", help="record a planner's episodes, acted in MuJoCo, as "
                        "training trajectories (on-policy data)")
    _collect_arguments(co)
    co.set_defaults(func=_collect)
