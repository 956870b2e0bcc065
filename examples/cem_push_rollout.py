"""Model-predictive pushing with the cross-entropy method on ``Dynamics.rollout``.

    python examples/cem_push_rollout.py --dynamics fignet --checkpoint push.pt

Every environment step, CEM samples ``--population`` tip-velocity sequences over ``--horizon``
steps, rolls all of them out in one batched call of the planning dynamics (MuJoCo's threaded
``mujoco.rollout``, or one batched FIGNet graph per step), scores them with the environment's own
reward, keeps the best and refits. The first action of the plan is executed in a MuJoCo
environment: planning with the learned model, acting in "reality".
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import torch

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents import CEMConfig, CEMPlanner, run_episode
from fignet_gym.dynamics import make_dynamics


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dynamics", default="mujoco", help="planning dynamics: mujoco or fignet")
    p.add_argument("--checkpoint", help="learned push checkpoint (fignet; default: pretrained)")
    p.add_argument("--population", type=int, default=64)
    p.add_argument("--horizon", type=int, default=10)
    p.add_argument("--iterations", type=int, default=3)
    p.add_argument("--episodes", type=int, default=3)
    p.add_argument("--steps", type=int, default=100, help="environment steps per episode (2 s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=1, help="torch threads (1: best on few shared cores)")
    args = p.parse_args()
    torch.set_num_threads(args.threads)

    env = gym.make("fignet_gym/Push-v0", dynamics="mujoco", max_episode_steps=args.steps)
    config = CEMConfig(
        horizon=args.horizon,
        population=args.population,
        elites=max(args.population // 8, 2),
        iterations=args.iterations,
        seed=args.seed,
    )
    planner = CEMPlanner(make_dynamics(args.dynamics, args.checkpoint, "push"), config)
    for ep in range(args.episodes):
        out = run_episode(env, planner, seed=args.seed + ep)
        print(
            f"episode {ep}: success {out['is_success']}, "
            f"position error {out['position_error'] * 1000:.1f} mm, "
            f"heading error {out['orientation_error']:.3f} rad, {out['length']} steps, "
            f"{out['plan_seconds'] * 1000:.0f} ms per plan"
        )


if __name__ == "__main__":
    main()
