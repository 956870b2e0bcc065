"""``fignet-gym ppo`` and ``fignet-gym ppo-table``: arguments around :mod:`fignet_gym.agents.ppo_run`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fignet_gym.agents.ppo import PPOConfig
from fignet_gym.agents.ppo_run import RunConfig, RunError, plot_curves, run_ppo, transfer_table
from fignet_gym.atomic import output_lock


def _error(message: str) -> int:
    print(f"error: {message}", file=sys.stderr)
    return 2


def config_from_args(args: argparse.Namespace) -> RunConfig:
    """The :class:`RunConfig` of ``fignet-gym ppo``'s arguments (``ValueError`` if invalid)."""
    try:
        net_arch = tuple(int(x) for x in args.net_arch.split(","))
    except ValueError:
        raise ValueError(f"--net-arch must be comma-separated integers, got {args.net_arch!r}") from None
    ppo = PPOConfig(
        total_timesteps=args.steps,
        num_envs=args.num_envs,
        n_steps=args.n_steps,
        batch_size=args.batch_size,
        n_epochs=args.n_epochs,
        learning_rate=args.lr,
        gamma=args.gamma,
        ent_coef=args.ent_coef,
        net_arch=net_arch,
        log_std_init=args.log_std_init,
        seed=args.seed,
    )
    return RunConfig(
        env_id=args.env,
        dynamics=args.dynamics,
        ppo=ppo,
        simulator=args.simulator,
        norm_obs=not args.no_normalize,
        norm_reward=not args.no_normalize,
        eval_every=args.eval_every,
        eval_episodes=args.eval_episodes,
        final_episodes=args.final_episodes,
        checkpoint_every=args.checkpoint_every,
    )


def run_ppo_command(args: argparse.Namespace) -> int:
    """Train/resume the run, print its transfer-table rows (with ``--compare`` runs)."""
    import gymnasium as gym

    import fignet_gym.envs  # noqa: F401  (registers the environments)

    if args.env not in gym.registry:
        ids = sorted(k for k in gym.registry if k.startswith("fignet_gym/"))
        return _error(f"--env {args.env!r} is not registered (fignet_gym ids: {', '.join(ids)})")
    for run in args.compare:
        if not (Path(run) / "final_eval.json").exists():
            return _error(f"--compare {run}: no final_eval.json (not a finished `fignet-gym ppo` run)")
    try:
        cfg = config_from_args(args)
        with output_lock(args.out):  # one process per run folder
            run_ppo(args.out, cfg, resume=args.resume, force=args.force, progress=not args.quiet)
        print(transfer_table([args.out, *args.compare]))
    except (RunError, ValueError) as err:
        return _error(str(err))
    return 0


def ppo_table_command(args: argparse.Namespace) -> int:
    """Print (and optionally write) the transfer table of finished runs."""
    try:
        table = transfer_table(args.runs)
    except RunError as err:
        return _error(str(err))
    print(table)
    if args.out:
        Path(args.out).write_text(table + "\n")
    if args.plot:
        print(f"curves: {plot_curves(args.runs, args.plot)}")
    return 0
