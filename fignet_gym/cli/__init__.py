"""``fignet-gym``: the command line, one module per command group.

* :mod:`~fignet_gym.cli.agents`: ``demo`` (the main job), ``plan``, ``collect``;
* :mod:`~fignet_gym.cli.ppo`: ``ppo`` (options generated from the run config), ``ppo-table``,
  ``ppo-ship``;
* :mod:`~fignet_gym.cli.training`: ``train``, ``evaluate``, ``floor``, ``ship``, ``sim2real``,
  ``sim2real-compare``;
* :mod:`~fignet_gym.cli.data`: ``generate``, ``show``, the importers, ``split``;
* :mod:`~fignet_gym.cli.bench`: ``bench step | shipped | rollout | ppo | envs | collision``.

Every command runs through :func:`~fignet_gym.cli.errors.run_command`, the one error path: a
user's mistake is one ``error:`` line and exit status 2, a bug keeps its traceback. Commands that
load the trainer (TensorBoard), Gymnasium's envs or stable-baselines3 import them when they run
(``# deferred:``), so ``fignet-gym --help`` stays fast.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from fignet_gym.cli import agents, bench, data, ppo, training
from fignet_gym.cli.errors import run_command, user_error

__all__ = ["build_parser", "main", "run_command", "user_error"]

#: Command groups in ``--help`` order.
GROUPS = (agents, ppo, bench, training, data)


def build_parser() -> argparse.ArgumentParser:
    """The full ``fignet-gym`` argument parser."""
    p = argparse.ArgumentParser(prog="fignet-gym", description="fignet_gym: a learned rigid-body "
                                "simulator (FIGNet) and MuJoCo behind the same step and envs")
    sub = p.add_subparsers(dest="command", required=True)
    for group in GROUPS:
        group.register(sub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``fignet-gym`` script."""
    args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    return run_command(args.func, args)


if __name__ == "__main__":
    sys.exit(main())
