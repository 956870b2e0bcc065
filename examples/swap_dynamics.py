"""Run the same pushes on MuJoCo and on a learned FIGNet simulator, side by side.

    MUJOCO_GL=egl python examples/swap_dynamics.py --checkpoint push.pt --out push_swap.mp4

Both environments get the same seed and the same actions; the script prints how far the learned
object pose drifts from MuJoCo's and writes a side-by-side video (MuJoCo left, FIGNet right). The
only difference between the two environments is the ``dynamics=`` argument.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import imageio
import numpy as np
import torch

import fignet_gym.envs  # noqa: F401  (registers the environments)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--checkpoint", help="learned push checkpoint (default: the pretrained one)")
    p.add_argument("--episodes", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="push_swap.mp4")
    p.add_argument(
        "--threads", type=int, default=1, help="torch threads (1: best on few shared cores)"
    )
    args = p.parse_args()
    torch.set_num_threads(args.threads)

    envs = {
        "mujoco": gym.make("fignet_gym/Push-v0", dynamics="mujoco", render_mode="rgb_array"),
        "fignet": gym.make(
            "fignet_gym/Push-v0",
            dynamics="fignet",
            checkpoint=args.checkpoint,
            render_mode="rgb_array",
        ),
    }
    lay = envs["mujoco"].unwrapped.observation_layout
    frames = []
    for ep in range(args.episodes):
        obs = {k: e.reset(seed=args.seed + ep)[0] for k, e in envs.items()}
        done = False
        while not done:
            # A simple scripted pusher: drive the tip through the object towards the goal.
            o = obs["mujoco"]
            push_dir = o[lay["goal_xy"]] - o[lay["object_xy"]]
            aim = o[lay["object_xy"]] - 0.06 * push_dir / (np.linalg.norm(push_dir) + 1e-9)
            to_aim = aim - o[lay["tip_xy"]]
            action = to_aim / max(np.linalg.norm(to_aim), 1e-3)
            if np.linalg.norm(to_aim) < 0.01:
                action = push_dir / (np.linalg.norm(push_dir) + 1e-9)
            results = {k: e.step(action) for k, e in envs.items()}
            obs = {k: r[0] for k, r in results.items()}
            done = any(r[2] or r[3] for r in results.values())
            frames.append(np.concatenate([envs[k].render() for k in envs], axis=1))
        gap = np.linalg.norm(obs["mujoco"][lay["object_xy"]] - obs["fignet"][lay["object_xy"]])
        print(
            f"episode {ep}: object position MuJoCo vs FIGNet differs by {gap * 1000:.1f} mm; "
            f"final position error to goal: "
            + ", ".join(f"{k} {results[k][4]['position_error'] * 1000:.1f} mm" for k in envs)
        )
    imageio.mimsave(args.out, frames, fps=envs["mujoco"].metadata["render_fps"])
    print(f"wrote {args.out} ({len(frames)} frames)")


if __name__ == "__main__":
    main()
