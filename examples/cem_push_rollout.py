"""Model-predictive pushing (CEM or MPPI) on either dynamics, acting in MuJoCo.

    python examples/cem_push_rollout.py --dynamics fignet            # the shipped push model
    python examples/cem_push_rollout.py --dynamics mujoco --planner mppi

Every few environment steps the planner samples ``--population`` tip-velocity sequences over
``--horizon`` steps, rolls all of them out in one batched ``Dynamics.rollout`` call of the planning
dynamics (MuJoCo's threaded ``mujoco.rollout``, or one batched FIGNet graph per step), scores them
with the environment's own task (``env.unwrapped.task``: the reward ``env.step`` returns), refits
and plays the best plan's first actions in a MuJoCo environment: planning with the learned model,
acting in "reality". Defaults are the benchmark's (``fignet_gym.agents.PRESETS["push"]``) and the
episode length is the env's own (Push-v1: 75 steps).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import torch

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents import make_planner, run_episode
from fignet_gym.dynamics import MujocoDynamics, make_dynamics


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--env", default="fignet_gym/Push-v1")
    p.add_argument("--dynamics", default="fignet", choices=["mujoco", "fignet"],
                   help="the planner's model")
    p.add_argument("--checkpoint", help="learned push checkpoint (fignet; default: shipped)")
    p.add_argument("--planner", default="cem", choices=["cem", "mppi"])
    p.add_argument("--population", type=int, help="candidates per iteration (preset: 20)")
    p.add_argument("--horizon", type=int, help="planned steps (preset: 20)")
    p.add_argument("--iterations", type=int, help="refits per plan (preset: 2)")
    p.add_argument("--episodes", type=int, default=3)
    p.add_argument("--steps", type=int, help="stop episodes after this many steps "
                   "(default: the env's own time limit)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=1, help="torch threads (1: best on few shared cores)")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)

    env = gym.make(args.env, dynamics="mujoco")  # acting: MuJoCo, with the registered limit
    dyn = (MujocoDynamics(nthread=args.threads) if args.dynamics == "mujoco"
           else make_dynamics("fignet", args.checkpoint, "push"))
    planner = make_planner(args.planner, dyn, "push", horizon=args.horizon,
                           population=args.population, iterations=args.iterations)
    results = []
    for ep in range(args.episodes):
        out = run_episode(env, planner, seed=args.seed + ep, max_steps=args.steps)
        results.append(out)
        print(
            f"episode {ep}: success {out['is_success']}, "
            f"position error {out['position_error'] * 1000:.1f} mm, "
            f"heading error {out['orientation_error']:.3f} rad, {out['length']} steps, "
            f"{out['plan_cpu_seconds']:.2f} CPU-s per action"
        )
    return results


if __name__ == "__main__":
    main()
