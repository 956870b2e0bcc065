"""Kubric-MOVi-like tosses in MuJoCo: objects thrown onto a floor, and re-runs of generated ones."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import mujoco
import numpy as np

from fignet_gym.data.format import Trajectory
from fignet_gym.data.generator_base import (
    GENERATED_SOURCE,
    GENERATOR_VERSION,
    GenerationError,
    PoseHook,
    num_poses,
)
from fignet_gym.mjcf import (
    DEFAULT_CONE,
    MATERIALS,
    SIMPLE_SHAPES,
    TOSS_SHAPES,
    TossObject,
    toss_scene_xml,
    unit_shape_mesh,
)
from fignet_gym.simulator.scene import MeshOptions, Scene

#: Lowest point (m) of a placed object above the floor at the start.
START_CLEARANCE = 0.01
#: A toss whose objects come within this (m) of the floor's edge is drawn again.
FLOOR_EDGE_MARGIN = 0.5
#: Draws of a whole toss before :class:`GenerationError`.
MAX_ATTEMPTS = 20


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
        cone: MuJoCo friction cone (``"elliptic"``: isotropic, a toss turned about the vertical
            lands turned; ``"pyramidal"``: the first toss data).
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
    cone: str = DEFAULT_CONE

    @property
    def dt(self) -> float:
        return self.timestep * self.substeps

    @property
    def shape_set(self) -> tuple[str, ...]:
        if self.shapes is not None:
            return self.shapes
        return TOSS_SHAPES if self.complex else SIMPLE_SHAPES


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
                if lo[2] < START_CLEARANCE:
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


def generate_toss(rng: np.random.Generator, cfg: TossConfig, max_attempts: int = MAX_ATTEMPTS) -> Trajectory:
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
                              poses=poses0, velocities=vel, gravity=cfg.gravity,
                              cone=cfg.cone)
        poses, scene = simulate_toss(mjcf, num_poses(cfg.duration, cfg.dt), cfg.substeps)
        dyn = scene.dynamic_mask.numpy()
        if not np.isfinite(poses).all():
            continue
        if np.abs(poses[:, dyn, :2]).max() > cfg.floor_half_size - FLOOR_EDGE_MARGIN:
            continue
        meta = {
            "source": GENERATED_SOURCE,
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
