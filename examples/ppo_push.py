"""PPO (stable-baselines3) on Push with the batched vector environment, any dynamics.

    python examples/ppo_push.py --dynamics fignet --checkpoint push.pt --num-envs 16 --steps 20000

The N pushes of a batch run as one learned graph per step (``vectorization_mode=
"vector_entry_point"``); ``make_sb3_vec_env`` adapts that vector environment to SB3's ``VecEnv``.
Everything is in one readable file with a typed ``Args``, CleanRL style.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, fields

import fignet_gym.envs  # noqa: F401  (registers the environments)
import gymnasium as gym
import numpy as np
import torch
from fignet_gym.envs import make_sb3_vec_env
from stable_baselines3 import PPO


@dataclass(frozen=True)
class Args:
    dynamics: str = "mujoco"  # "mujoco" or "fignet"
    checkpoint: str | None = None  # learned checkpoint (fignet; default: pretrained)
    num_envs: int = 16
    steps: int = 20_000  # environment steps in total
    seed: int = 0
    eval_episodes: int = 10
    out: str = "ppo_push"
    threads: int = 1  # torch threads (1: best on few shared cores)


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
    torch.set_num_threads(args.threads)
    env_kwargs = {"dynamics": args.dynamics}
    if args.checkpoint:
        env_kwargs["checkpoint"] = args.checkpoint
    vec = make_sb3_vec_env("fignet_gym/Push-v0", args.num_envs, **env_kwargs)
    vec.seed(args.seed)
    model = PPO(
        "MlpPolicy",
        vec,
        n_steps=max(2048 // args.num_envs, 16),
        batch_size=256,
        seed=args.seed,
        device="cpu",
        verbose=1,
    )
    model.learn(total_timesteps=args.steps)
    model.save(args.out)
    # Evaluate on MuJoCo: a policy trained on learned dynamics should still push the real object.
    env = gym.make("fignet_gym/Push-v0", dynamics="mujoco")
    errors = []
    for ep in range(args.eval_episodes):
        obs, _ = env.reset(seed=10_000 + ep)
        done = False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        errors.append(info["position_error"])
    print(f"MuJoCo evaluation: median final position error {np.median(errors) * 1000:.1f} mm")


if __name__ == "__main__":
    main()
