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
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import mujoco
import numpy as np

from fignet_gym.data.format import Trajectory, TrajectoryWriter
from fignet_gym.mjcf import (
    MATERIALS,
    MIT_OBJECTS,
    SIMPLE_SHAPES,
    TOSS_SHAPES,
    PushObject,
    TossObject,
    push_scene_xml,
    toss_scene_xml,
    unit_shape_mesh,
)
from fignet_gym.simulator.scene import MeshOptions, Scene

GENERATOR_VERSION = "1"
KINDS = ("push", "toss-simple", "toss-complex")


class GenerationError(RuntimeError):
    """A trajectory could not be generated (named by kind, seed and index)."""


# --------------------------------------------------------------------------- configurations


@dataclass(frozen=True)
class PushConfig:
    """MIT-Pushing-like pushes (units: m, s, rad unless named otherwise).

    Attributes:
        shapes: objects drawn uniformly (keys of ``MIT_OBJECTS``).
        speeds_mm_s: tip speeds of the real dataset, drawn uniformly.
        angles_deg: push angles from the side normal (the real grid: 9 values in [-80, 80]).
        friction_range: object-surface friction, uniform (the real per-surface values are unknown;
            a range around steel on plastic).
        tip_friction_range: tip-object friction, uniform.
        approach: distance the tip travels before contact (0.04 m in the real data), shortened to
            ``speed * max_approach_time`` for slow pushes so that contact happens early in the
            trajectory.
        travel_past: distance the tip travels past the contact point, then it stops (0.05 m), or
            the trajectory ends first (slow pushes).
        duration: seconds per trajectory. timestep, substeps: MuJoCo step and steps per pose.
        tip_radius: m.
    """

    shapes: tuple[str, ...] = tuple(MIT_OBJECTS)
    speeds_mm_s: tuple[float, ...] = (10, 20, 50, 75, 100, 150, 200, 300, 400, 500)
    angles_deg: tuple[float, ...] = tuple(float(a) for a in np.linspace(-80, 80, 9))
    friction_range: tuple[float, float] = (0.15, 0.35)
    tip_friction_range: tuple[float, float] = (0.15, 0.35)
    approach: float = 0.04
    max_approach_time: float = 0.2
    travel_past: float = 0.05
    duration: float = 1.0
    timestep: float = 0.002
    substeps: int = 10
    tip_radius: float = 0.00475

    @property
    def dt(self) -> float:
        return self.timestep * self.substeps


@dataclass(frozen=True)
class TossConfig:
    """Kubric-MOVi-like tosses (MOVi-A with the simple shapes, MOVi-B-like with all).

    Attributes:
        shapes: drawn uniformly (default: cube, sphere, cylinder; all of ``TOSS_SHAPES`` when
            ``complex``).
        complex: sizes uniform in ``size_range`` instead of the two ``sizes`` (MOVi-B).
        num_objects: inclusive range of the object count.
        spawn_low, spawn_high: box of initial positions (MOVi: [-5,-5,1] to [5,5,5]).
        max_speed: horizontal velocity U(-v, v) minus (x, y): tossed toward the centre.
        duration: seconds per trajectory; timestep, substeps: MuJoCo step and steps per pose.
        floor_half_size: m. Rolling spheres and cylinders travel up to ~18 m in 2 s, so the
            floor (a finite mesh for the learned simulator) is 40 x 40 m; draws where an object
            still leaves it are redrawn.
        mesh_options: resolution of the simple shapes (default 8-node cube, 42-node sphere,
            26-node cylinder; the paper's MOVi-A meshes have 51 and 64 nodes).
    """

    shapes: tuple[str, ...] | None = None
    complex: bool = False
    sizes: tuple[float, ...] = (0.7, 1.4)
    size_range: tuple[float, float] = (0.7, 1.4)
    materials: tuple[str, ...] = tuple(MATERIALS)
    num_objects: tuple[int, int] = (3, 10)
    spawn_low: tuple[float, float, float] = (-5.0, -5.0, 1.0)
    spawn_high: tuple[float, float, float] = (5.0, 5.0, 5.0)
    max_speed: float = 4.0
    gravity: float = -10.0
    floor_half_size: float = 20.0
    duration: float = 2.0
    timestep: float = 0.002
    substeps: int = 10
    mesh_options: MeshOptions = field(default_factory=MeshOptions)

    @property
    def dt(self) -> float:
        return self.timestep * self.substeps

    @property
    def shape_set(self) -> tuple[str, ...]:
        if self.shapes is not None:
            return self.shapes
        return TOSS_SHAPES if self.complex else SIMPLE_SHAPES


def default_config(kind: str) -> PushConfig | TossConfig:
    """The configuration of a generator kind (``push``, ``toss-simple``, ``toss-complex``)."""
    if kind == "push":
        return PushConfig()
    if kind == "toss-simple":
        return TossConfig()
    if kind == "toss-complex":
        return TossConfig(complex=True)
    raise ValueError(f"unknown generator kind {kind!r}; valid: {', '.join(KINDS)}")


# --------------------------------------------------------------------------- simulation


def _num_poses(duration: float, dt: float) -> int:
    return int(round(duration / dt)) + 1


def _contact_on_outline(obj: PushObject, rng: np.random.Generator,
                        ) -> tuple[int, float, np.ndarray, np.ndarray]:
    """A contact point on the outline: (side index, position, point ``float[2]``, normal).

    Polygons: a side uniformly and a position uniform in [0.1, 0.9] along it. Ellipses (and the
    butter): side 0 and an angle fraction in [0, 1), as in the real file names; the point is where
    the ray at that angle from the centroid meets the outline.
    """
    outline = obj.outline
    k = len(outline)
    if obj.name.startswith("ellip") or obj.name == "butter":
        s = float(rng.uniform(0.0, 1.0))
        ang = 2 * np.pi * s
        ray = np.array([math.cos(ang), math.sin(ang)])
        c = obj.centroid()
        for i in range(k):  # the edge the ray leaves through
            a, b = outline[i] - c, outline[(i + 1) % k] - c
            m = np.array([[ray[0], a[0] - b[0]], [ray[1], a[1] - b[1]]])
            lam, mu = np.linalg.solve(m, a)
            if lam > 0 and -1e-9 <= mu <= 1 + 1e-9:
                side, point = i, c + lam * ray
                break
        else:  # pragma: no cover - a star-shaped outline always has a hit
            raise GenerationError(f"{obj.name}: no outline edge at angle {ang}")
        return 0, s, point, _edge_normal(outline, side)
    side = int(rng.integers(k))
    s = float(rng.uniform(0.1, 0.9))
    point = outline[side] * (1 - s) + outline[(side + 1) % k] * s
    return side, s, point, _edge_normal(outline, side)


def _edge_normal(outline: np.ndarray, i: int) -> np.ndarray:
    d = outline[(i + 1) % len(outline)] - outline[i]
    n = np.array([d[1], -d[0]])  # outward for a counter-clockwise outline
    return n / np.linalg.norm(n)


def _rot2(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s], [s, c]])


def tip_position(meta: dict[str, Any], t: float) -> np.ndarray:
    """``float[2]`` tip position at time ``t`` of a generated push (from its metadata)."""
    start, vel = np.asarray(meta["tip_start"]), np.asarray(meta["tip_velocity"])
    return start + vel * min(t, meta["tip_stop_time"])


#: Called before pose ``k`` is recorded; may change the state (see :func:`resimulate`).
PoseHook = Callable[[int, mujoco.MjModel, mujoco.MjData], None]


def simulate_push(mjcf: str, meta: dict[str, Any], num_poses: int, substeps: int,
                  hook: PoseHook | None = None) -> tuple[np.ndarray, Scene]:
    """Poses ``float[T, O, 7]`` of a push scene, the tip following :func:`tip_position`."""
    model = mujoco.MjModel.from_xml_string(mjcf)
    data = mujoco.MjData(model)
    scene = Scene.from_mjmodel(model)
    h = model.opt.timestep
    poses = np.empty((num_poses, scene.num_objects, 7))
    mujoco.mj_forward(model, data)
    step = 0
    for k in range(num_poses):
        for _ in range(substeps if k else 0):  # pose 0 is the initial state
            step += 1
            # the tip is where it should be at the end of the step (an implicit position drive)
            data.mocap_pos[0, :2] = tip_position(meta, step * h)
            mujoco.mj_step(model, data)
        if hook is not None:
            hook(k, model, data)
        poses[k] = scene.poses_from_data(data)
    return poses, scene


def generate_push(rng: np.random.Generator, cfg: PushConfig) -> Trajectory:
    """One push: a random object, friction, speed, contact point and angle."""
    shape = str(rng.choice(cfg.shapes))
    obj = MIT_OBJECTS[shape]
    friction = float(rng.uniform(*cfg.friction_range))
    tip_friction = float(rng.uniform(*cfg.tip_friction_range))
    speed = float(rng.choice(cfg.speeds_mm_s)) / 1000.0
    angle_deg = float(rng.choice(cfg.angles_deg))
    yaw0 = float(rng.uniform(-np.pi, np.pi))
    side, s, point, normal = _contact_on_outline(obj, rng)
    rot = _rot2(yaw0)
    point, normal = rot @ point, rot @ normal
    direction = _rot2(math.radians(angle_deg)) @ -normal
    contact_tip = point + normal * cfg.tip_radius
    # Starting on the far side of the tangent line at the contact point, a convex object can only
    # be touched first at that point: the approach line never crosses the object.
    approach = min(cfg.approach, speed * cfg.max_approach_time)
    start = contact_tip - direction * approach
    meta: dict[str, Any] = {
        "source": "fignet_gym.generate", "kind": "push", "generator_version": GENERATOR_VERSION,
        "shape": shape, "friction": friction, "tip_friction": tip_friction,
        "speed_mm_s": speed * 1000, "angle_deg": angle_deg, "side": side, "position": s,
        "object_yaw0": yaw0, "tip_start": start.tolist(),
        "tip_velocity": (direction * speed).tolist(),
        "tip_contact_time": approach / speed,
        "tip_stop_time": (approach + cfg.travel_past) / speed,
        "timestep": cfg.timestep, "substeps": cfg.substeps,
    }
    mjcf = push_scene_xml(shape, friction, cfg.tip_radius, cfg.timestep,
                          tip_friction=tip_friction, object_pose=(0.0, 0.0, yaw0),
                          tip_xy=start)
    poses, scene = simulate_push(mjcf, meta, _num_poses(cfg.duration, cfg.dt), cfg.substeps)
    if not np.isfinite(poses).all():
        raise GenerationError(f"push {shape}: simulation diverged")
    return Trajectory(poses=poses, dt=cfg.dt, kinds=scene.object_kind.numpy(),
                      props=scene.object_props.double().numpy(), names=scene.object_names,
                      mjcf=mjcf, metadata=meta)


@lru_cache(maxsize=64)
def _unit_mesh(shape: str, mesh_options: MeshOptions) -> tuple[np.ndarray, np.ndarray]:
    return unit_shape_mesh(shape, mesh_options)


def random_quaternion(rng: np.random.Generator) -> np.ndarray:
    """Uniformly random unit quaternion (w, x, y, z) with w >= 0."""
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def _quat_to_mat(q: np.ndarray) -> np.ndarray:
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, q)
    return mat.reshape(3, 3)


def _place(objects: list[TossObject], rng: np.random.Generator, cfg: TossConfig,
           rounds: int = 20, tries: int = 100) -> np.ndarray | None:
    """Non-overlapping initial poses ``float[K, 7]`` above the floor, or None after many tries.

    Objects are placed one by one: random orientation, position uniform in the spawn box,
    rejected if the rotated mesh's bounding box meets the floor or an earlier object's box. When
    an object finds no room, the whole placement starts again (up to ``rounds`` times).
    """
    low, high = np.array(cfg.spawn_low), np.array(cfg.spawn_high)
    verts = [_unit_mesh(o.shape, cfg.mesh_options)[0] * o.size for o in objects]
    for _ in range(rounds):
        poses: list[np.ndarray] = []
        boxes: list[tuple[np.ndarray, np.ndarray]] = []
        for v in verts:
            for _ in range(tries):
                q = random_quaternion(rng)
                pos = rng.uniform(low, high)
                world = v @ _quat_to_mat(q).T + pos
                lo, hi = world.min(0), world.max(0)
                if lo[2] < 0.01:
                    continue
                if any(np.all(lo < bhi) and np.all(blo < hi) for blo, bhi in boxes):
                    continue
                poses.append(np.concatenate([pos, q]))
                boxes.append((lo, hi))
                break
            else:
                break
        if len(poses) == len(objects):
            return np.array(poses)
    return None


def simulate_toss(mjcf: str, num_poses: int, substeps: int, hook: PoseHook | None = None,
                  ) -> tuple[np.ndarray, Scene]:
    """Poses ``float[T, O, 7]`` of a toss scene, from its keyframe ``start``."""
    model = mujoco.MjModel.from_xml_string(mjcf)
    data = mujoco.MjData(model)
    scene = Scene.from_mjmodel(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_forward(model, data)
    poses = np.empty((num_poses, scene.num_objects, 7))
    for k in range(num_poses):
        if k:
            mujoco.mj_step(model, data, nstep=substeps)
        if hook is not None:
            hook(k, model, data)
        poses[k] = scene.poses_from_data(data)
    return poses, scene


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
    if kind not in KINDS or traj.metadata.get("source") != "fignet_gym.generate":
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
    else:
        poses, _ = simulate_toss(traj.mjcf, traj.num_steps, substeps, nudge)
    return poses


def generate_toss(rng: np.random.Generator, cfg: TossConfig, max_attempts: int = 20) -> Trajectory:
    """One toss: 3-10 objects tossed toward the centre of the floor.

    A draw is redrawn (from the same random stream, so still deterministic) when the objects do not
    fit in the spawn box, the simulation diverges, or an object leaves the floor, whose mesh is
    finite for the learned simulator while MuJoCo's plane is infinite.
    """
    shapes = cfg.shape_set
    for attempt in range(max_attempts):
        n = int(rng.integers(cfg.num_objects[0], cfg.num_objects[1] + 1))
        objects = []
        for _ in range(n):
            size = (float(rng.uniform(*cfg.size_range)) if cfg.complex
                    else float(rng.choice(cfg.sizes)))
            material = str(rng.choice(cfg.materials))
            objects.append(TossObject(str(rng.choice(shapes)), size, material))
        poses0 = _place(objects, rng, cfg)
        if poses0 is None:
            continue
        vel = np.zeros((n, 6))
        vel[:, :2] = rng.uniform(-cfg.max_speed, cfg.max_speed, size=(n, 2)) - poses0[:, :2]
        mjcf = toss_scene_xml(objects, cfg.timestep, cfg.floor_half_size, cfg.mesh_options,
                              poses=poses0, velocities=vel, gravity=cfg.gravity)
        poses, scene = simulate_toss(mjcf, _num_poses(cfg.duration, cfg.dt), cfg.substeps)
        dyn = scene.dynamic_mask.numpy()
        if not np.isfinite(poses).all():
            continue
        if np.abs(poses[:, dyn, :2]).max() > cfg.floor_half_size - 0.5:
            continue
        meta = {
            "source": "fignet_gym.generate",
            "kind": "toss-complex" if cfg.complex else "toss-simple",
            "generator_version": GENERATOR_VERSION, "attempt": attempt,
            "shapes": [o.shape for o in objects], "sizes": [o.size for o in objects],
            "materials": [o.material for o in objects], "init_qvel": vel.tolist(),
            "timestep": cfg.timestep, "substeps": cfg.substeps,
        }
        return Trajectory(poses=poses, dt=cfg.dt, kinds=scene.object_kind.numpy(),
                          props=scene.object_props.double().numpy(), names=scene.object_names,
                          mjcf=mjcf, metadata=meta)
    raise GenerationError(f"no valid toss after {max_attempts} draws")


# --------------------------------------------------------------------------- driver


def _one(task: tuple[str, PushConfig | TossConfig, int, int]) -> Trajectory:
    kind, cfg, seed, index = task
    # hash(seed, index): the stream of trajectory `index` does not depend on the others
    rng = np.random.default_rng(np.random.SeedSequence([seed, index]))
    try:
        traj = generate_push(rng, cfg) if kind == "push" else generate_toss(rng, cfg)
    except GenerationError as err:
        raise GenerationError(f"{kind} seed {seed} index {index}: {err}") from None
    traj.name = f"{kind}-s{seed}-{index:06d}"
    traj.metadata.update(seed=seed, index=index)
    return traj


def _init_worker() -> None:
    import torch

    torch.set_num_threads(1)


_THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def iter_trajectories(kind: str, num: int, seed: int, workers: int = 1,
                      config: PushConfig | TossConfig | None = None) -> Iterator[Trajectory]:
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
             config: PushConfig | TossConfig | None = None, progress: bool = True,
             ) -> dict[str, float]:
    """Generate ``num`` trajectories of ``kind`` into ``out`` (atomic); returns timing stats."""
    from tqdm import tqdm

    if isinstance(num, bool) or not isinstance(num, int) or num < 1:
        raise ValueError(f"num must be an integer >= 1, got {num!r}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    cfg = config or default_config(kind)
    if not (math.isfinite(cfg.duration) and cfg.duration > 0):
        raise ValueError(f"duration must be a finite number of seconds > 0, got {cfg.duration!r}")
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
    "GENERATOR_VERSION", "KINDS", "GenerationError", "PushConfig", "TossConfig", "default_config",
    "generate", "generate_push", "generate_toss", "iter_trajectories", "resimulate", "simulate_push",
    "simulate_toss", "tip_position",
]
