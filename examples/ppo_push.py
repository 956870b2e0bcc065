"""PPO (stable-baselines3) on Push with the batched vector environment, checked on MuJoCo.

    python examples/ppo_push.py --dynamics fignet --checkpoint push.pt --num-envs 16 --steps 20000

Train on either dynamics (the N pushes of a batch run as one learned graph per step), save the
policy, then run it on MuJoCo: a policy trained on the learned simulator should still push the
real object. Everything is in one readable file with a typed ``Args``, CleanRL style; the work is
done by ``fignet_gym.agents.train_ppo`` and ``evaluate_policy_on``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, fields

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents import PPOConfig, evaluate_policy_on, train_ppo


@dataclass(frozen=True)
class Args:
    dynamics: str = "mujoco"  # training dynamics: "mujoco" or "fignet"
    checkpoint: str | None = None  # learned checkpoint (fignet; default: pretrained)
    num_envs: int = 16
    steps: int = 20_000  # environment steps in total
    seed: int = 0
    eval_episodes: int = 10
    out: str = "ppo_push"  # writes ppo_push.zip and ppo_push.json


def parse() -> Args:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    for f in fields(Args):
        p.add_argument(
            f"--{f.name.replace('_', '-')}",
            type=type(f.default) if f.default is not None else str,
            default=f.default,
        )
    return Args(**vars(p.parse_args()))


def main() -> None:
    args = parse()
    config = PPOConfig(
        total_timesteps=args.steps,
        num_envs=args.num_envs,
        n_steps=max(2048 // args.num_envs, 16),
        batch_size=256,
        seed=args.seed,
    )
    model = train_ppo(args.dynamics, checkpoint=args.checkpoint, config=config, save_path=args.out, verbose=1)
    for dynamics in dict.fromkeys([args.dynamics, "mujoco"]):  # training dynamics, then MuJoCo
        report = evaluate_policy_on(
            dynamics,
            model,
            n_episodes=args.eval_episodes,
            seed=10_000,
            checkpoint=args.checkpoint if dynamics == "fignet" else None,
        )
        print(
            f"{dynamics}: success {report['success_rate']:.0%}, "
            f"mean return {report['mean_return']:.1f}, "
            f"final position error {report['final_position_error'] * 1000:.1f} mm, "
            f"heading error {report['final_orientation_error']:.3f} rad"
        )


if __name__ == "__main__":
    main()
