"""``fignet-gym collect``: record a planner's episodes, acted in MuJoCo, as training trajectories.

    fignet-gym collect --env fignet_gym/Push-v2 --planner cem --episodes 200 --seed 100000 \\
        --action-noise 0.3 --epsilon 0.1 --out data/push_plan.h5

Model-based RL's usual remedy for a model that is wrong where the planner goes: train it on the
states the planner visits. Each episode is reset with ``seed + k``, planned with ``--dynamics``
(MuJoCo by default, cheap) and acted in MuJoCo; the executed action is the plan's, plus Gaussian
noise of std ``--action-noise`` (clipped to the action box), or with probability ``--epsilon`` a
uniformly random action, so the data also cover the planner's mistakes. After the reset and after
every env step (one learned step, ``env.dt``) every object's body-frame pose is recorded, in the
order of ``Scene.from_mjmodel`` (the format of ``fignet-gym generate``, ``docs/data.md``). The tip
(a mocap body) moves linearly within a step, as in the generated pushes, so replaying the recorded
tip poses from the first pose in the stored MJCF reproduces the recorded object poses.

Keep the seeds disjoint from those a benchmark is scored on: the episodes' goals and starts are
drawn from them.
"""

from __future__ import annotations

import argparse
import inspect
import json
import math
import time
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch
from tqdm import tqdm

from fignet_gym.atomic import output_lock
from fignet_gym.data.format import Trajectory, TrajectoryWriter
from fignet_gym.simulator.scene import Scene
from fignet_gym.tools.plan import parse_env_kwargs, planning_agent, unknown_env

#: ``metadata["source"]`` of recorded planner episodes (MuJoCo poses, not re-simulable by
#: ``resimulate``: the tip follows the planner, not a generator's draw).
COLLECTED_SOURCE = "fignet_gym.collect"
PLANNERS = ("cem", "mppi")
#: Model fields that must equal those of the env's MJCF (else the stored MJCF would not be the
#: scene the poses were simulated in, e.g. an env that edits its compiled model).
_MODEL_FIELDS = ("body_mass", "body_inertia", "geom_friction", "geom_solref", "geom_solimp",
                 "geom_size", "geom_priority")


class CollectError(ValueError):
    """A user error in the ``collect`` arguments (reported as one ``error:`` line)."""


def check_arguments(args: argparse.Namespace) -> None:
    """:class:`CollectError` for values out of range, before anything is built or written."""
    if not (math.isfinite(args.action_noise) and args.action_noise >= 0):
        raise CollectError(f"--action-noise must be a finite number >= 0, got {args.action_noise}")
    if not (math.isfinite(args.epsilon) and 0 <= args.epsilon <= 1):
        raise CollectError(f"--epsilon must be a number in [0, 1], got {args.epsilon}")
    if args.checkpoint and args.dynamics != "fignet":
        raise CollectError("--checkpoint only applies to --dynamics fignet")
    env_kwargs(args.env_kwargs)
    out = Path(args.out)
    if out.is_dir():
        raise CollectError(f"--out {out}: is a directory; --out must be a file")
    if out.exists() and not args.force:
        raise CollectError(f"--out {out}: already exists; pass --force to replace it")


#: Env arguments ``--env-kwargs`` may not set: the episodes are acted in MuJoCo, unrendered.
_FIXED_ENV_ARGS = ("dynamics", "checkpoint", "dynamics_kwargs", "render_mode", "width", "height")


def env_kwargs(text: str) -> dict[str, Any]:
    """``--env-kwargs``' JSON object as a dict; :class:`CollectError` if it is not one, or sets an
    argument the episodes fix (:data:`_FIXED_ENV_ARGS`)."""
    return parse_env_kwargs(text, _FIXED_ENV_ARGS, "collect acts in MuJoCo, unrendered",
                            CollectError)


def _make_env(env_id: str, kwargs: dict[str, Any]) -> Any:
    """``gym.make(env_id, dynamics="mujoco", **kwargs)``; :class:`CollectError` for an argument
    the env's constructor does not take or a value it refuses (the ids are registered as soon as
    Gymnasium is imported: :mod:`fignet_gym.registration`)."""
    # deferred: Gymnasium; `fignet-gym --help` imports this module for its parser, not the RL stack
    import gymnasium as gym

    cls = gym.spec(env_id).entry_point
    if isinstance(cls, str):
        cls = gym.envs.registration.load_env_creator(cls)
    params = inspect.signature(cls).parameters
    if not any(p.kind is p.VAR_KEYWORD for p in params.values()):
        unknown = sorted(set(kwargs) - set(params))
        if unknown:
            allowed = sorted(set(params) - set(_FIXED_ENV_ARGS) - {"self"})
            raise CollectError(f"--env-kwargs: {env_id} takes no argument {', '.join(unknown)}; "
                               f"its arguments: {', '.join(allowed)}")
    try:
        return gym.make(env_id, dynamics="mujoco", **kwargs)
    except (TypeError, ValueError) as err:
        raise CollectError(f"--env-kwargs: {env_id} refuses {json.dumps(kwargs)}: {err}") from None


def _recordable(env: Any, env_id: str) -> str:
    """The env's MJCF, checked to be the scene of its compiled model; :class:`CollectError` else."""
    u = env.unwrapped
    xml = getattr(u, "mjcf", None)
    if not isinstance(xml, str) or getattr(u, "scene_type", "") != "push":
        raise CollectError(f"--env: {env_id} exposes no push scene MJCF (env.mjcf) to record; "
                           "use fignet_gym/Push-v1 or Push-v2")
    plain = mujoco.MjModel.from_xml_string(xml)
    for name in _MODEL_FIELDS:
        if not np.array_equal(getattr(plain, name), getattr(u.model, name)):
            raise CollectError(f"--env: {env_id} edits its compiled model ({name} differs from "
                               "its MJCF), so its episodes cannot be stored with their scene")
    return xml


def noisy_action(planned: np.ndarray, rng: np.random.Generator, action_noise: float,
                 epsilon: float, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """The executed action ``float[A]``: with probability ``epsilon`` uniform in ``[low, high]``,
    else ``planned`` plus ``N(0, action_noise^2)`` per axis, clipped to the box."""
    if epsilon > 0 and rng.random() < epsilon:
        return rng.uniform(low, high).astype(planned.dtype)
    if action_noise > 0:
        planned = planned + rng.normal(0.0, action_noise, planned.shape)
    return np.clip(planned, low, high).astype(np.float32)


def record_episode(env: Any, planner: Any, seed: int, rng: np.random.Generator,
                   action_noise: float = 0.0, epsilon: float = 0.0) -> tuple[np.ndarray, dict[str, Any]]:
    """Act one episode and record it: ``(poses float[T, O, 7], summary)``.

    ``poses[0]`` is the state after ``env.reset(seed=seed)``, ``poses[t]`` the state after step
    ``t``; objects in ``Scene.from_mjmodel`` order. The summary holds the episode's length,
    return, success and final errors.
    """
    u = env.unwrapped
    scene = Scene.from_mjmodel(u.model)
    env.reset(seed=seed)
    planner.reset()
    planner.bind(env)
    poses = [scene.poses_from_data(u.data)]
    box = env.action_space
    total, info, done = 0.0, {}, False
    cpu = 0.0
    while not done:
        action = noisy_action(np.asarray(planner.plan(env), np.float32), rng, action_noise,
                              epsilon, box.low, box.high)
        cpu += planner.last.cpu_seconds
        _, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        poses.append(scene.poses_from_data(u.data))
        done = terminated or truncated
    length = len(poses) - 1
    summary = {"length": length, "return": total, "is_success": bool(info.get("is_success", False)),
               "position_error": float(info.get("position_error", np.nan)),
               "orientation_error": float(info.get("orientation_error", np.nan)),
               "diverged": "diverged" in info, "plan_cpu_seconds": cpu / max(length, 1)}
    return np.stack(poses), summary


def collect(args: argparse.Namespace) -> dict[str, Any]:
    """Record ``args.episodes`` episodes into ``args.out`` (atomic); returns the run's summary."""
    check_arguments(args)
    torch.set_num_threads(1)
    if unknown := unknown_env(args.env):
        raise CollectError(unknown)
    extra = env_kwargs(args.env_kwargs)
    env = _make_env(args.env, extra)
    xml = _recordable(env, args.env)
    u = env.unwrapped
    scene = Scene.from_mjmodel(u.model)
    try:
        planner = planning_agent(args.env, env, args.planner, args.dynamics, "mujoco",
                                 args.checkpoint, env_kwargs=extra, seed=args.seed)
    except ValueError as err:  # a checkpoint of another scene
        raise CollectError(str(err)) from None
    common = {"source": COLLECTED_SOURCE, "kind": u.scene_type, "env": args.env,
              "planner": args.planner, "dynamics": args.dynamics, "checkpoint": args.checkpoint,
              "action_noise": args.action_noise, "epsilon": args.epsilon,
              "shape": getattr(u, "shape", None), "env_kwargs": extra}
    file_meta = {**common, "seed": args.seed, "episodes": args.episodes,
                 "mujoco_version": mujoco.__version__}
    rows: list[dict[str, Any]] = []
    start = time.process_time()
    with output_lock(args.out), TrajectoryWriter(args.out, file_meta) as writer:
        seeds = range(args.seed, args.seed + args.episodes)
        for seed in tqdm(seeds, desc=f"collect {args.env}", unit="episode",
                         disable=args.no_progress):
            rng = np.random.default_rng(np.random.SeedSequence([args.seed, seed]))
            poses, row = record_episode(env, planner, seed, rng, args.action_noise, args.epsilon)
            meta = {**common, **row, "seed": seed, "goal": np.asarray(u.goal).tolist()}
            writer.add(Trajectory(poses=poses, dt=u.dt, kinds=scene.object_kind.numpy(),
                                  props=scene.object_props.double().numpy(),
                                  names=scene.object_names, mjcf=xml, metadata=meta,
                                  name=f"collect-{u.scene_type}-{seed}"))
            rows.append({"seed": seed, **row})
    steps = sum(r["length"] for r in rows)
    summary = {"episodes": len(rows), "poses": steps + len(rows),
               "success_rate": float(np.mean([r["is_success"] for r in rows])),
               "cpu_seconds": time.process_time() - start}
    print(f"wrote {len(rows)} episodes ({steps} steps) to {args.out}: success "
          f"{summary['success_rate']:.0%}, {summary['cpu_seconds']:.0f} CPU-s")
    return summary
