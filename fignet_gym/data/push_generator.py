"""MIT-Pushing-like pushes in MuJoCo: a kinematic tip at constant speed against one object."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from fignet_gym.data.format import Trajectory
from fignet_gym.data.generator_base import (
    GENERATED_SOURCE,
    GENERATOR_VERSION,
    GenerationError,
    PoseHook,
    num_poses,
    simulate_driven,
)
from fignet_gym.mjcf import DEFAULT_CONE, MIT_OBJECTS, PushObject, push_scene_xml
from fignet_gym.simulator.scene import Scene

#: Contact points on a polygon side are drawn from this fraction of its length (corners excluded).
SIDE_FRACTION = (0.1, 0.9)
#: Tolerance (in units of the edge parameter) of a ray-edge intersection test.
EDGE_TOL = 1e-9
#: Millimetres per metre (speeds are configured in mm/s).
MM_PER_M = 1000.0


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
        cone: MuJoCo friction cone (``"elliptic"``: isotropic, the same push in the object's
            frame at every world heading; ``"pyramidal"``: the first push data).
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
    cone: str = DEFAULT_CONE

    @property
    def dt(self) -> float:
        return self.timestep * self.substeps


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
            if lam > 0 and -EDGE_TOL <= mu <= 1 + EDGE_TOL:
                side, point = i, c + lam * ray
                break
        else:  # pragma: no cover - a star-shaped outline always has a hit
            raise GenerationError(f"{obj.name}: no outline edge at angle {ang}")
        return 0, s, point, _edge_normal(outline, side)
    side = int(rng.integers(k))
    s = float(rng.uniform(*SIDE_FRACTION))
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


def simulate_push(mjcf: str, meta: dict[str, Any], num_poses: int, substeps: int,
                  hook: PoseHook | None = None) -> tuple[np.ndarray, Scene]:
    """Poses ``float[T, O, 7]`` of a push scene, the tip following :func:`tip_position`."""

    def drive(data: mujoco.MjData, t: float) -> None:
        data.mocap_pos[0, :2] = tip_position(meta, t)

    return simulate_driven(mjcf, num_poses, substeps, drive, hook=hook)


def generate_push(rng: np.random.Generator, cfg: PushConfig) -> Trajectory:
    """One push: a random object, friction, speed, contact point and angle."""
    shape = str(rng.choice(cfg.shapes))
    obj = MIT_OBJECTS[shape]
    friction = float(rng.uniform(*cfg.friction_range))
    tip_friction = float(rng.uniform(*cfg.tip_friction_range))
    speed = float(rng.choice(cfg.speeds_mm_s)) / MM_PER_M
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
        "source": GENERATED_SOURCE, "kind": "push", "generator_version": GENERATOR_VERSION,
        "shape": shape, "friction": friction, "tip_friction": tip_friction,
        "speed_mm_s": speed * 1000, "angle_deg": angle_deg, "side": side, "position": s,
        "object_yaw0": yaw0, "tip_start": start.tolist(),
        "tip_velocity": (direction * speed).tolist(),
        "tip_contact_time": approach / speed,
        "tip_stop_time": (approach + cfg.travel_past) / speed,
        "timestep": cfg.timestep, "substeps": cfg.substeps, "cone": cfg.cone,
    }
    mjcf = push_scene_xml(shape, friction, cfg.tip_radius, cfg.timestep,
                          tip_friction=tip_friction, object_pose=(0.0, 0.0, yaw0),
                          tip_xy=start, cone=cfg.cone)
    poses, scene = simulate_push(mjcf, meta, num_poses(cfg.duration, cfg.dt), cfg.substeps)
    if not np.isfinite(poses).all():
        raise GenerationError(f"push {shape}: simulation diverged")
    return Trajectory(poses=poses, dt=cfg.dt, kinds=scene.object_kind.numpy(),
                      props=scene.object_props.double().numpy(), names=scene.object_names,
                      mjcf=mjcf, metadata=meta)
