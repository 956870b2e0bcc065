"""``fignet-gym ppo``, ``ppo-table`` and ``ppo-ship``: PPO runs, their transfer table, shipping one.

The ``ppo`` options are generated from the run config (:mod:`fignet_gym.agents.ppo.options`): each
default is the config's own. The commands' work is in :mod:`fignet_gym.agents.ppo`; importing this
module loads neither stable-baselines3 nor TensorBoard, so ``fignet-gym --help`` stays fast.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from fignet_gym.agents.ppo.options import add_options, config_from_args
from fignet_gym.atomic import output_lock


def _ppo(args: argparse.Namespace) -> int:
    """Train/resume the run, print its transfer-table rows (with ``--compare`` runs).

    Every option, the env id and the ``--compare`` runs are checked before anything is written.
    """
    from fignet_gym.agents.ppo.run import check_env_id, run_ppo  # deferred: stable-baselines3
    from fignet_gym.agents.ppo.rundir import FINAL_EVAL  # deferred: stable-baselines3 (the run itself)
    from fignet_gym.agents.ppo.table import read_final_eval, transfer_table  # deferred: stable-baselines3

    check_env_id(args.env)
    cfg = config_from_args(args)
    for run in args.compare:
        path = Path(run) / FINAL_EVAL
        if not path.exists():
            raise ValueError(f"--compare {run}: no {FINAL_EVAL} (not a finished `fignet-gym ppo` run)")
        read_final_eval(path)
    with output_lock(args.out):  # one process per run folder
        run_ppo(args.out, cfg, resume=args.resume, force=args.force, progress=not args.quiet)
    print(transfer_table([args.out, *args.compare]))
    return 0


def _ppo_table(args: argparse.Namespace) -> int:
    """Print (and optionally write) the transfer table of finished runs; every file is checked
    (and the curves read) before anything is printed or written."""
    from fignet_gym.agents.ppo.table import plot_curves, read_curves, transfer_table  # deferred: SB3

    table = transfer_table(args.runs)
    if args.plot:
        for run in args.runs:
            read_curves(run)
    print(table)
    if args.out:
        Path(args.out).write_text(table + "\n")
    if args.plot:
        print(f"curves: {plot_curves(args.runs, args.plot)}")
    return 0


def _ppo_ship(args: argparse.Namespace) -> int:
    """``fignet-gym ppo-ship RUN --name NAME [--dest DIR] [--force]``."""
    from fignet_gym.agents.ppo.ship import ship_policy  # deferred: stable-baselines3, scipy

    folder = ship_policy(args.run, args.name, args.dest, args.force)
    size = sum(p.stat().st_size for p in folder.iterdir())
    print(f"shipped {folder} ({size / 1e6:.1f} MB); card {folder / (args.name + '.md')}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``ppo``, ``ppo-table`` and ``ppo-ship`` to the ``fignet-gym`` subparsers."""
    o = sub.add_parser("ppo", help="train PPO on either dynamics (resumable), evaluate on both")
    add_options(o)
    o.add_argument("--out", required=True, help="run folder (checkpoints, TensorBoard, CSV, policy)")
    o.add_argument("--resume", action="store_true", help="continue OUT from its last checkpoint")
    o.add_argument("--force", action="store_true", help="delete an existing OUT first")
    o.add_argument("--compare", nargs="*", default=[],
                   help="finished run folders to print in the transfer table beside this one")
    o.add_argument("--quiet", action="store_true", help="no progress bar")
    o.set_defaults(func=_ppo)

    t = sub.add_parser("ppo-table", help="transfer table of finished PPO runs (trained on x evaluated on)")
    t.add_argument("runs", nargs="+", help="run folders of `fignet-gym ppo`")
    t.add_argument("--out", help="also write the Markdown table to this file")
    t.add_argument("--plot", help="also plot the runs' periodic evaluations to this image")
    t.set_defaults(func=_ppo_table)

    s = sub.add_parser("ppo-ship", help="ship a finished PPO run as a named policy with a generated card "
                       "(fignet_gym.agents.load_policy(NAME))")
    s.add_argument("run", help="finished run folder of `fignet-gym ppo`")
    s.add_argument("--name", required=True, help="policy name, e.g. push-ppo")
    s.add_argument("--dest", help="folder (default: the package's shipped policies)")
    s.add_argument("--force", action="store_true", help="replace a shipped policy of that name")
    s.set_defaults(func=_ppo_ship)
