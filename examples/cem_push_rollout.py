"""Model-predictive pushing with the cross-entropy method on ``Dynamics.rollout``.

    python examples/cem_push_rollout.py --dynamics fignet --checkpoint push.pt

Every environment step, CEM samples ``--samples`` tip-velocity sequences over ``--horizon`` steps,
rolls all of them out in one batched call of the planning dynamics (MuJoCo's threaded
``mujoco.rollout``, or one batched FIGNet graph per step), keeps the best and refits. The first
action of the plan is executed in a MuJoCo environment: planning with the learned model, acting in
"reality".
"""

from __future__ import annotations

import argparse

import fignet_gym.envs  # noqa: F401  (registers the environments)
import gymnasium as gym
import mujoco
import numpy as np
import torch
from fignet_gym.envs.base import wrap_angle, yaw_of

from fignet_gym.dynamics import STATE_SPEC, make_dynamics


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dynamics", default="mujoco", help="planning dynamics: mujoco or fignet")
    p.add_argument("--checkpoint", help="learned push checkpoint (fignet; default: pretrained)")
    p.add_argument("--samples", type=int, default=32)
    p.add_argument("--horizon", type=int, default=8)
    p.add_argument("--iterations", type=int, default=3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--threads", type=int, default=1, help="torch threads (1: best on few shared cores)"
    )
    p.add_argument("--steps", type=int, default=100, help="environment steps (2 s)")
    args = p.parse_args()
    torch.set_num_threads(args.threads)

    env = gym.make("fignet_gym/Push-v0", dynamics="mujoco").unwrapped
    planner = make_dynamics(args.dynamics, args.checkpoint, "push")
    planner.validate(env.model, env.nstep, "push")
    model, rng = env.model, np.random.default_rng(args.seed)
    nstate = mujoco.mj_stateSize(model, STATE_SPEC)
    qadr = env._qadr  # the object's free joint: qpos[qadr:qadr+7] (state index 1 + qadr)
    obs, _ = env.reset(seed=args.seed)
    mean = np.zeros((args.horizon, 2))
    for t in range(args.steps):
        state = np.zeros(nstate)
        mujoco.mj_getState(model, env.data, state, STATE_SPEC)
        tip0 = env.data.mocap_pos[0].copy()
        std = np.full_like(mean, 0.6)
        for _ in range(args.iterations):
            actions = np.clip(mean + std * rng.standard_normal((args.samples, *mean.shape)), -1, 1)
            tips = tip0 + np.concatenate(
                [
                    np.cumsum(actions * env.max_speed * env.step_time, axis=1),
                    np.zeros((args.samples, args.horizon, 1)),
                ],
                axis=2,
            )
            quat = np.broadcast_to([1.0, 0, 0, 0], (args.samples, args.horizon, 4))
            control = np.concatenate([tips, quat], axis=2)  # mocap_pos, then mocap_quat
            states = planner.rollout(model, state[None], control, frame_skip=env.nstep)
            final = states[:, -1, 1 + qadr : 1 + qadr + 7]
            # Distance to the goal, plus a small pull of the tip towards the point behind the
            # object (seen from the goal), so that plans not reaching the object are ranked too.
            to_goal = env.goal[:2] - final[:, :2]
            cost = np.linalg.norm(to_goal, axis=1)
            behind = final[:, :2] - 0.07 * to_goal / (cost[:, None] + 1e-9)
            cost += 0.3 * np.linalg.norm(tips[:, -1, :2] - behind, axis=1)
            cost += 0.02 * np.abs(wrap_angle(env.goal[2] - yaw_of(final[:, 3:])))  # 2 cm per rad
            cost[~np.isfinite(cost)] = np.inf  # diverged learned rollouts
            elite = actions[np.argsort(cost)[: max(args.samples // 8, 2)]]
            mean, std = elite.mean(0), elite.std(0) + 0.05
        obs, _, terminated, truncated, info = env.step(mean[0])
        mean = np.concatenate([mean[1:], mean[-1:]])  # warm start: shift the plan
        if t % 20 == 0 or terminated or truncated:
            print(
                f"step {t}: position error {info['position_error'] * 1000:.1f} mm, "
                f"heading error {np.degrees(info['orientation_error']):.1f} deg"
            )
        if terminated or truncated:
            break


if __name__ == "__main__":
    main()
