"""PPO on learned dynamics: train on FIGNet's Push-v1, check the policy on MuJoCo.

    python examples/ppo_push.py                       # FIGNet, 102k steps (resumable: re-run it)
    python examples/ppo_push.py --dynamics mujoco     # the same budget on MuJoCo, for comparison
    fignet-gym ppo-table runs/ppo_push_fignet runs/ppo_push_mujoco    # the transfer table
    python examples/ppo_push.py --steps 1001472 --final-episodes 100  # the full budget (re-run
                                                  # to extend: about 0.16 CPU h per 1M steps on
                                                  # MuJoCo, 2.5 times that on FIGNet)

The N pushes of a batch run as one learned graph per step; a run folder holds checkpoints
(re-running resumes), TensorBoard logs (``tensorboard --logdir runs``), ``progress.csv``,
``eval.csv`` (success and return on both dynamics during training) and ``final_eval.json``.
Everything is in one readable file with a typed ``Args``, CleanRL style; the work is done by
``fignet_gym.agents.ppo_run.run_ppo`` (what ``fignet-gym ppo`` runs).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path

from fignet_gym.agents import PPOConfig, RunConfig, run_ppo, transfer_table


@dataclass(frozen=True)
class Args:
    env: str = "fignet_gym/Push-v1"
    dynamics: str = "fignet"  # training dynamics: "fignet" or "mujoco"; evaluation runs on both
    steps: int = 102_400  # environment steps in total (50 PPO updates of 32 x 64 steps)
    num_envs: int = 32  # sub-environments stepped as one batched call
    n_steps: int = 64  # steps per sub-environment between PPO updates
    net_arch: str = "256,256"  # hidden sizes of the policy and value MLPs
    log_std_init: float = -1.0  # initial exploration noise: std e^-1 = 0.37 of the action range
    seed: int = 0
    eval_every: int = 25_000
    final_episodes: int = 50  # episodes per dynamics of the final transfer table
    out: str = ""  # run folder (default: runs/ppo_push_<dynamics>)


def parse(argv: Sequence[str] | None = None) -> Args:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    for f in fields(Args):
        p.add_argument(f"--{f.name.replace('_', '-')}", type=type(f.default), default=f.default)
    return Args(**vars(p.parse_args(argv)))


def main(argv: Sequence[str] | None = None) -> None:
    args = parse(argv)
    out = args.out or f"runs/ppo_push_{args.dynamics}"
    cfg = RunConfig(
        env_id=args.env,
        dynamics=args.dynamics,
        ppo=PPOConfig(
            total_timesteps=args.steps,
            num_envs=args.num_envs,
            n_steps=args.n_steps,
            batch_size=min(256, args.num_envs * args.n_steps),
            net_arch=tuple(int(x) for x in args.net_arch.split(",")),
            log_std_init=args.log_std_init,
            seed=args.seed,
        ),
        eval_every=args.eval_every,
        eval_episodes=min(32, args.final_episodes),
        final_episodes=args.final_episodes,
        checkpoint_every=max(args.num_envs * args.n_steps, 20_000),
    )
    run_ppo(out, cfg, resume=Path(out, "config.json").exists())  # a stopped run continues
    print(transfer_table([out]))


if __name__ == "__main__":
    main()
