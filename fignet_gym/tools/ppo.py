"""``fignet-gym ppo`` and ``fignet-gym ppo-table``: arguments around :mod:`fignet_gym.agents.ppo.run`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fignet_gym.agents.ppo.config import ConfigError, PPOConfig, RunConfig
from fignet_gym.agents.ppo.run import check_env_id, run_ppo
from fignet_gym.agents.ppo.rundir import FINAL_EVAL, RunError
from fignet_gym.agents.ppo.table import plot_curves, read_curves, read_final_eval, transfer_table
from fignet_gym.atomic import output_lock

#: The ``fignet-gym ppo`` option of each config field (errors name the option the user typed).
OPTIONS = {
    "total_timesteps": "--steps", "num_envs": "--num-envs", "n_steps": "--n-steps",
    "batch_size": "--batch-size", "n_epochs": "--n-epochs", "learning_rate": "--lr",
    "gamma": "--gamma", "gae_lambda": "--gae-lambda", "ent_coef": "--ent-coef",
    "net_arch": "--net-arch", "log_std_init": "--log-std-init", "use_sde": "--use-sde",
    "seed": "--seed", "dynamics": "--dynamics", "eval_every": "--eval-every",
    "eval_episodes": "--eval-episodes", "final_episodes": "--final-episodes",
    "checkpoint_every": "--checkpoint-every", "observation": "--observation", "shaping": "--shaping",
    "success_bonus": "--success-bonus", "sde_sample_freq": "--sde-sample-freq",
    "curriculum": "--curriculum", "precision": "--precision",
}


def _error(message: str) -> int:
    print(f"error: {message}", file=sys.stderr)
    return 2


def config_from_args(args: argparse.Namespace) -> RunConfig:
    """The :class:`RunConfig` of ``fignet-gym ppo``'s arguments (``ValueError`` naming the option)."""
    try:
        net_arch = tuple(int(x) for x in args.net_arch.split(","))
    except ValueError:
        raise ValueError(f"--net-arch must be comma-separated integers, got {args.net_arch!r}") from None
    try:
        ppo = PPOConfig(
            total_timesteps=args.steps,
            num_envs=args.num_envs,
            n_steps=args.n_steps,
            batch_size=args.batch_size,
            n_epochs=args.n_epochs,
            learning_rate=args.lr,
            gamma=args.gamma,
            gae_lambda=getattr(args, "gae_lambda", PPOConfig.gae_lambda),
            ent_coef=args.ent_coef,
            net_arch=net_arch,
            log_std_init=args.log_std_init,
            use_sde=bool(getattr(args, "use_sde", PPOConfig.use_sde)),
            sde_sample_freq=getattr(args, "sde_sample_freq", PPOConfig.sde_sample_freq),
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
            observation=args.observation,
            shaping=args.shaping,
            success_bonus=args.success_bonus,
            curriculum=bool(getattr(args, "curriculum", RunConfig.curriculum)),
            precision=getattr(args, "precision", RunConfig.precision),
        )
    except ConfigError as err:
        raise ValueError(f"{OPTIONS.get(err.setting, err.setting)} {err.detail}") from None


def run_ppo_command(args: argparse.Namespace) -> int:
    """Train/resume the run, print its transfer-table rows (with ``--compare`` runs).

    Every option, the env id and the ``--compare`` runs are checked before anything is written.
    """
    try:
        check_env_id(args.env)
        cfg = config_from_args(args)
        for run in args.compare:
            path = Path(run) / FINAL_EVAL
            if not path.exists():
                return _error(f"--compare {run}: no {FINAL_EVAL} (not a finished `fignet-gym ppo` run)")
            read_final_eval(path)
        with output_lock(args.out):  # one process per run folder
            run_ppo(args.out, cfg, resume=args.resume, force=args.force, progress=not args.quiet)
        print(transfer_table([args.out, *args.compare]))
    except (RunError, ValueError) as err:
        return _error(str(err))
    return 0


def ppo_table_command(args: argparse.Namespace) -> int:
    """Print (and optionally write) the transfer table of finished runs; every file is checked
    (and the curves read) before anything is printed or written."""
    try:
        table = transfer_table(args.runs)
        if args.plot:
            for run in args.runs:
                read_curves(run)
    except (RunError, ValueError) as err:
        return _error(str(err))
    print(table)
    if args.out:
        Path(args.out).write_text(table + "\n")
    if args.plot:
        print(f"curves: {plot_curves(args.runs, args.plot)}")
    return 0
