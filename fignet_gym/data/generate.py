"""MuJoCo data generators: MIT-Pushing-like pushes and Kubric-MOVi-like tosses.

Each trajectory is simulated from its own MJCF (kept in the record) with a random generator seeded
by ``SeedSequence([seed, index])``, so a file is identical for a seed whatever the number of worker
processes. Distributions and their sources are in ``docs/data.md``; a learned step is
``dt = substeps x timestep`` (0.02 s by default for both tasks).
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing as mp
import os
import time
from collections.abc import Callable, Iterator
from typing import Any

import mujoco
import numpy as np
import torch
from tqdm import tqdm

from fignet_gym.data.format import Trajectory, TrajectoryWriter
from fignet_gym.data.generator_base import GENERATED_SOURCE, GENERATOR_VERSION, GenerationError
from fignet_gym.data.push_generator import PushConfig, generate_push, simulate_push, tip_position
from fignet_gym.data.scene_generator import SceneConfig, check_scene, generate_scene, simulate_scene
from fignet_gym.data.toss_generator import TossConfig, generate_toss, random_quaternion, simulate_toss

KINDS = ("push", "toss-simple", "toss-complex", "scene")
#: A generator's configuration: the shipped kinds' or a user's scene (``SceneConfig.from_file``).
Config = PushConfig | TossConfig | SceneConfig


def default_config(kind: str) -> PushConfig | TossConfig:
    """The configuration of a generator kind (``push``, ``toss-simple``, ``toss-complex``)."""
    if kind == "push":
        return PushConfig()
    if kind == "toss-simple":
        return TossConfig()
    if kind == "toss-complex":
        return TossConfig(complex=True)
    if kind == "scene":
        raise ValueError("generate scene: pass the scene's MJCF (--mjcf FILE)")
    raise ValueError(f"unknown generator kind {kind!r}; valid: {', '.join(KINDS)}")


def resimulate(traj: Trajectory, position_noise: float = 0.0, at_pose: int = 0, seed: int = 0
               ) -> np.ndarray:
    """Re-run a generated trajectory in MuJoCo, optionally nudging its start: ``-> float[T, O, 7]``.

    Before pose ``at_pose`` is recorded, every free body is moved by ``position_noise`` (m) in its
    own random horizontal direction (horizontal: a body resting on the floor is not driven into
    it; velocities kept). With no noise this reproduces ``traj.poses`` (to float
    precision); with some, the spread of the outcomes is the error a perfect simulator makes from
    a slightly wrong state, a floor under any learned model's rollout error on chaotic data.
    Only trajectories made by :func:`generate` can be re-run (imported real data has no MJCF).
    """
    kind = traj.metadata.get("kind", "")
    if kind not in KINDS or traj.metadata.get("source") != GENERATED_SOURCE:
        raise ValueError(f"trajectory {traj.name!r} ({kind or 'no kind'}) was not made by "
                         "fignet_gym.generate, so it cannot be re-simulated")
    if position_noise < 0 or not 0 <= at_pose < traj.num_steps:
        raise ValueError(f"need position_noise >= 0 and 0 <= at_pose < {traj.num_steps}, "
                         f"got {position_noise} and {at_pose}")
    rng = np.random.default_rng(seed)

    def nudge(k: int, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        if k != at_pose or position_noise == 0:
            return
        for j in np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE):
            angle = rng.uniform(0.0, 2.0 * np.pi)
            adr = model.jnt_qposadr[j]
            data.qpos[adr:adr + 2] += position_noise * np.array([np.cos(angle), np.sin(angle)])
        mujoco.mj_forward(model, data)

    substeps = int(traj.metadata["substeps"])
    if kind == "push":
        poses, _ = simulate_push(traj.mjcf, traj.metadata, traj.num_steps, substeps, nudge)
    elif kind == "scene":
        poses, _ = simulate_scene(traj.mjcf, traj.metadata, traj.num_steps, substeps, nudge)
    else:
        poses, _ = simulate_toss(traj.mjcf, traj.num_steps, substeps, nudge)
    return poses


def _one(task: tuple[str, Config, int, int]) -> Trajectory:
    kind, cfg, seed, index = task
    # hash(seed, index): the stream of trajectory `index` does not depend on the others
    rng = np.random.default_rng(np.random.SeedSequence([seed, index]))
    try:
        if isinstance(cfg, SceneConfig):
            traj = generate_scene(rng, cfg)
        else:
            traj = generate_push(rng, cfg) if kind == "push" else generate_toss(rng, cfg)
    except GenerationError as err:
        raise GenerationError(f"{kind} seed {seed} index {index}: {err}") from None
    traj.name = f"{kind}-s{seed}-{index:06d}"
    traj.metadata.update(seed=seed, index=index)
    return traj


def _init_worker() -> None:
    torch.set_num_threads(1)


_THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def iter_trajectories(kind: str, num: int, seed: int, workers: int = 1,
                      config: Config | None = None) -> Iterator[Trajectory]:
    """Yield trajectories ``0 .. num-1`` in order (parallel over ``workers`` processes)."""
    if seed < 0:
        raise ValueError(f"seed must be non-negative, got {seed}")
    cfg = config or default_config(kind)
    tasks = [(kind, cfg, seed, i) for i in range(num)]
    if workers <= 1:
        yield from map(_one, tasks)
        return
    # spawned workers inherit the environment: one BLAS / OpenMP thread each
    saved = {v: os.environ.get(v) for v in _THREAD_VARS}
    os.environ.update({v: "1" for v in _THREAD_VARS})
    try:
        pool = mp.get_context("spawn").Pool(workers, initializer=_init_worker)
    finally:
        for v, old in saved.items():
            if old is None:
                os.environ.pop(v, None)
            else:
                os.environ[v] = old
    with pool:
        yield from pool.imap(_one, tasks, chunksize=1)  # ordered: same file for any worker count


def generate(kind: str, num: int, seed: int, out: str | os.PathLike, workers: int = 1,
             config: Config | None = None, progress: bool = True,
             ) -> dict[str, float]:
    """Generate ``num`` trajectories of ``kind`` into ``out`` (atomic); returns timing stats."""
    if isinstance(num, bool) or not isinstance(num, int) or num < 1:
        raise ValueError(f"num must be an integer >= 1, got {num!r}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    cfg = config or default_config(kind)
    if not (math.isfinite(cfg.duration) and cfg.duration > 0):
        raise ValueError(f"duration must be a finite number of seconds > 0, got {cfg.duration!r}")
    if isinstance(cfg, SceneConfig):
        check_scene(cfg)  # refusals and the cone warning once, before any worker starts
    meta = {"kind": kind, "seed": seed, "num": num, "generator_version": GENERATOR_VERSION,
            "mujoco_version": mujoco.__version__, "config": _jsonable(dataclasses.asdict(cfg))}
    start = time.perf_counter()
    with TrajectoryWriter(out, meta) as writer:
        bar: Callable[[Iterator[Trajectory]], Iterator[Trajectory]] = (
            (lambda it: tqdm(it, total=num, desc=f"generate {kind}", unit="traj"))
            if progress else (lambda it: it))
        for traj in bar(iter_trajectories(kind, num, seed, workers, cfg)):
            writer.add(traj)
    elapsed = time.perf_counter() - start
    return {"num": num, "seconds": elapsed, "traj_per_s": num / elapsed if elapsed > 0 else 0.0}


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x


__all__ = [
    "GENERATOR_VERSION", "KINDS", "Config", "GenerationError", "PushConfig", "SceneConfig", "TossConfig",
    "default_config",
    "generate", "generate_push", "generate_toss", "iter_trajectories", "resimulate", "simulate_push",
    "random_quaternion", "simulate_toss", "tip_position",
]
