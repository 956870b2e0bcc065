"""Swap MuJoCo for the learned simulator in your own MJCF scene, with the same calls.

    MUJOCO_GL=egl python examples/swap_dynamics.py --out push_swap.mp4

Part 1, your own scene: an MJCF string (a 6 x 4 cm box, not one of the training objects, and a
mocap pusher) is loaded with ``mujoco.MjModel.from_xml_string``; a straight push is rolled out
from the same whole state (``mj_getState(..., STATE_SPEC)``: physics and mocap poses) with
``MujocoDynamics`` and with ``FIGNetDynamics`` (the shipped push model), each in one
``Dynamics.rollout`` call, and the object's displacement printed for both. Any scene works if its
objects are free bodies, its pusher a mocap body and its timestep divides the model's 0.02 s.

Part 2, an environment: the same seeded ``Push-v1`` episodes with ``dynamics="mujoco"`` and
``dynamics="fignet"`` and the same actions of a scripted pusher that pushes the object towards
its goal from behind (``env.unwrapped.task.pushing_point``); it prints how far the learned pose
drifts from MuJoCo's and writes a side-by-side video (MuJoCo left, FIGNet right).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import imageio
import mujoco
import numpy as np
import torch

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.dynamics import STATE_SPEC, FIGNetDynamics, MujocoDynamics

MY_SCENE = """
<mujoco model="my_push">
  <option timestep="0.002"/>
  <worldbody>
    <geom name="floor" type="plane" size="0.5 0.5 0.05" friction="0.25 0.005 0.0001"/>
    <body name="box" pos="0 0 0.0065">
      <freejoint/>
      <geom type="box" size="0.03 0.02 0.0065" mass="0.4" friction="0.25 0.005 0.0001"/>
    </body>
    <body name="pusher" mocap="true" pos="-0.04 0 0.021">
      <geom type="cylinder" size="0.00475 0.02" friction="0.25 0.005 0.0001"/>
    </body>
  </worldbody>
</mujoco>
"""


def own_scene(checkpoint: str | None, steps: int) -> dict[str, np.ndarray]:
    """A straight 0.1 m/s push of the box in ``MY_SCENE`` by both dynamics: final box xy."""
    model = mujoco.MjModel.from_xml_string(MY_SCENE)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, data, state, STATE_SPEC)
    # One control row per 0.02 s step: the pusher's mocap pose (x advances 2 mm per step).
    control = np.tile(np.r_[data.mocap_pos[0], data.mocap_quat[0]], (1, steps, 1))
    control[0, :, 0] += 0.002 * np.arange(1, steps + 1)
    dyns = {"mujoco": MujocoDynamics(nthread=1), "fignet": FIGNetDynamics(checkpoint or "push")}
    final = {}
    for name, dyn in dyns.items():
        out = dyn.rollout(model, state[None], control, frame_skip=10)  # [1, steps, nstate]
        final[name] = out[0, -1, 1:3]  # qpos[0:2]: the box's xy
        print(f"my scene, {name:6s}: box moved {np.linalg.norm(final[name]) * 1000:5.1f} mm "
              f"to ({final[name][0] * 1000:.1f}, {final[name][1] * 1000:.1f}) mm")
    return final


def scripted_action(env: gym.Env) -> np.ndarray:
    """Line up behind the object (seen from the goal), then push it towards the goal."""
    u = env.unwrapped
    s = u.get_state()
    obj, tip = u.task.object_pose(s)[:2], u.task.tip_xy(s)
    to_goal = u.goal[:2] - obj
    unit = to_goal / max(np.linalg.norm(to_goal), 1e-9)
    side = np.array([-unit[1], unit[0]])
    contact = u.task.pushing_point(s, u.goal)
    lateral = np.dot(tip - contact, side)
    if np.dot(tip - obj, unit) > 0:  # on the goal's side of the object: go round it
        target = contact - 0.02 * unit + 0.08 * (np.sign(lateral) or 1.0) * side
    elif abs(lateral) > 0.003:  # behind, but off the line through the object: line up
        target = contact - 0.004 * unit
    else:  # in line: push, steering back onto the line
        return np.clip(unit - 30.0 * lateral * side, -1, 1)
    step_len = u.max_speed * u.dt  # how far the tip moves per step at |action| = 1
    return np.clip((target - tip) / step_len, -1, 1)  # arrive without overshooting


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--checkpoint", help="learned push checkpoint (default: the shipped one)")
    p.add_argument("--episodes", type=int, default=2)
    p.add_argument("--push-steps", type=int, default=25, help="steps of the push in part 1")
    p.add_argument("--max-steps", type=int, help="cut part 2's episodes (default: the env's limit)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="push_swap.mp4")
    p.add_argument("--size", type=int, default=320, help="video frame size (px)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (1: best on few shared cores)")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)

    result: dict = {"own_scene": own_scene(args.checkpoint, args.push_steps)}
    kw = {"render_mode": "rgb_array", "width": args.size, "height": args.size}
    envs = {
        "mujoco": gym.make("fignet_gym/Push-v1", dynamics="mujoco", **kw),
        "fignet": gym.make("fignet_gym/Push-v1", dynamics="fignet", checkpoint=args.checkpoint, **kw),
    }
    frames, result["episodes"] = [], []
    for ep in range(args.episodes):
        for e in envs.values():
            e.reset(seed=args.seed + ep)
        start_error = envs["mujoco"].unwrapped.task.errors(
            envs["mujoco"].unwrapped.get_state(), envs["mujoco"].unwrapped.goal)[0]
        done, n = False, 0
        while not done and (args.max_steps is None or n < args.max_steps):
            action = scripted_action(envs["mujoco"])  # both get MuJoCo's pusher's actions
            results = {k: e.step(action) for k, e in envs.items()}
            done = any(r[2] or r[3] for r in results.values())
            frames.append(np.concatenate([envs[k].render() for k in envs], axis=1))
            n += 1
        lay = envs["mujoco"].unwrapped.observation_layout
        gap = np.linalg.norm(results["mujoco"][0][lay["object_xy"]]
                             - results["fignet"][0][lay["object_xy"]])
        errors = {k: results[k][4]["position_error"] for k in envs}
        result["episodes"].append({"start_error": float(start_error), "errors": errors,
                                   "gap": float(gap), "steps": n})
        print(f"episode {ep}: goal {start_error * 1000:.1f} mm away at the start; after {n} steps "
              + ", ".join(f"{k} {v * 1000:.1f} mm" for k, v in errors.items())
              + f"; MuJoCo and FIGNet objects {gap * 1000:.1f} mm apart")
    imageio.mimsave(args.out, frames, fps=envs["mujoco"].metadata["render_fps"])
    print(f"wrote {args.out} ({len(frames)} frames)")
    return result


if __name__ == "__main__":
    main()
