"""From your own MJCF file to a learned simulator of it, its errors against MuJoCo and a planned push.

    python examples/own_scene.py                                # the built-in crate scene
    python examples/own_scene.py --mjcf my_scene.xml --object crate --pusher finger \\
        --num 400 --steps 3000 --out outputs/my_scene           # your scene, a larger budget

Four steps, each a library call that the command line also offers:

1. ``generate("scene", ...)``: seeded pushes of ``--object`` by the mocap body ``--pusher``,
   simulated by MuJoCo as the file says (``fignet-gym generate scene --mjcf FILE``), training
   and validation files;
2. ``train_from_files(..., "push-cpu")``: FIGNet trained on them for ``--steps`` optimiser steps
   (``fignet-gym train``);
3. ``evaluate(...)``: rollouts of the trained model on the validation pushes, which MuJoCo
   simulated: its errors against MuJoCo, beside no motion (``fignet-gym evaluate``);
4. one episode of ``fignet_gym/ScenePush-v0`` on the same file, acting in MuJoCo, planned by CEM
   on the trained model (``fignet-gym plan``).

``--num`` and ``--steps`` are the budget. The defaults (1000 pushes, 5000 steps) took 368 CPU-s
on one core for the built-in crate: after 1 s of a validation push the learned crate is 9.7 mm
from MuJoCo's (no motion: 25.4 mm; 38%, rotation 78% of no motion), and the planned episode
succeeded in 26 steps. At 200 pushes and 1000 steps (118 CPU-s): 12.6 mm (54%), rotation 123%,
and the episode failed (31.7 mm). The paper's budgets are far larger (docs/training.md).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

#: A 10 x 6 x 6 cm, 0.5 kg crate on a floor and a cylindrical finger, isotropic friction.
CRATE = """<mujoco model="crate">
  <option timestep="0.002" cone="elliptic"/>
  <worldbody>
    <geom name="ground" type="plane" size="1 1 0.1" friction="0.3 0.005 0.0001"/>
    <body name="crate" pos="0 0 0.03">
      <freejoint/>
      <geom type="box" size="0.05 0.03 0.03" mass="0.5" friction="0.3 0.005 0.0001"/>
    </body>
    <body name="finger" mocap="true" pos="-0.2 0 0.03">
      <geom type="cylinder" size="0.006 0.03"/>
    </body>
  </worldbody>
</mujoco>
"""


def main(argv: list[str] | None = None) -> dict[str, object]:
    """Run the four steps; returns the evaluation's metrics and the episode's result."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mjcf", help="your scene (default: the built-in crate scene)")
    p.add_argument("--object", default="crate", help="the free body to push")
    p.add_argument("--pusher", default="finger", help="the mocap body that pushes")
    p.add_argument("--num", type=int, default=1000, help="training pushes (budget)")
    p.add_argument("--steps", type=int, default=5000, help="optimiser steps (budget)")
    p.add_argument("--episode-steps", type=int, default=75, help="steps of the planned episode")
    p.add_argument("--planner-budget", default="preset", choices=("preset", "tiny"),
                   help="CEM's push preset, or a tiny one for a smoke run")
    p.add_argument("--out", default="outputs/own_scene", help="folder for data, run and plots")
    args = p.parse_args(argv)
    if args.num < 2 or args.steps < 1:
        p.error("--num must be >= 2 and --steps >= 1")

    from fignet_gym.data.generate import generate
    from fignet_gym.data.scene_generator import SceneConfig
    from fignet_gym.train.evaluation import evaluate
    from fignet_gym.train.trainer import train_from_files

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    mjcf = Path(args.mjcf) if args.mjcf else out / "crate.xml"
    if not args.mjcf:
        mjcf.write_text(CRATE)
    cfg = SceneConfig.from_file(mjcf, target=args.object, speed=(0.05, 0.15),
                                offset=(-0.03, 0.03))
    n_valid = max(1, args.num // 10)
    generate("scene", args.num, 0, out / "train.h5", config=cfg)
    generate("scene", n_valid, 1, out / "valid.h5", config=cfg)

    tiny = args.steps < 50
    overrides = {"training.steps": args.steps,
                 "training.valid_every": max(1, min(250, args.steps // 4))}
    if tiny:  # a smoke run: no pushforward unroll, small batches
        overrides.update({"training.batch_size": 2, "training.unroll_after": args.steps + 1,
                          "training.valid_trajectories": 1})
    train_from_files(str(out / "train.h5"), str(out / "valid.h5"), "push-cpu", str(out / "run"),
                     overrides=overrides, force=True)
    checkpoint = out / "run" / "best.pt"
    # The validation pushes are MuJoCo's own: the errors are the learned model's against MuJoCo.
    metrics = evaluate(str(checkpoint), str(out / "valid.h5"), str(out / "eval"), videos=0)

    episode = plan_episode(mjcf, args.object, args.pusher, checkpoint, args.episode_steps,
                           args.planner_budget == "tiny")
    print(f"planned on the learned model, acting in MuJoCo: success {episode['success']}, "
          f"final error {1e3 * episode['position_error']:.1f} mm / "
          f"{episode['orientation_error']:.3f} rad after {episode['steps']} steps")
    return {"metrics": metrics, "episode": episode}


def plan_episode(mjcf: Path, obj: str, pusher: str, checkpoint: Path, max_steps: int,
                 tiny: bool) -> dict[str, float | bool | int]:
    """One seeded ``ScenePush-v0`` episode acting in MuJoCo, planned by CEM on ``checkpoint``."""
    import gymnasium as gym

    import fignet_gym.envs  # noqa: F401  (registers the environments)
    from fignet_gym.agents import make_planner
    from fignet_gym.dynamics import make_dynamics

    env = gym.make("fignet_gym/ScenePush-v0", mjcf=str(mjcf), object=obj, pusher=pusher,
                   max_episode_steps=max_steps)
    budget = {"horizon": 3, "population": 8, "iterations": 1} if tiny else {}
    planner = make_planner("cem", make_dynamics("fignet", str(checkpoint), "push"), "push",
                           env=env, **budget)
    obs, _ = env.reset(seed=0)
    info: dict = {}
    steps, done = 0, False
    while not done:
        action, _ = planner.predict(obs, deterministic=True)
        obs, _, terminated, truncated, info = env.step(action)
        steps, done = steps + 1, terminated or truncated  # the time limit truncates
    return {"success": bool(info.get("is_success", False)), "steps": steps,
            "position_error": float(info["position_error"]),
            "orientation_error": float(info["orientation_error"])}


if __name__ == "__main__":
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    np.set_printoptions(precision=4)
    main()
