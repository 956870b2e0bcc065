"""Quasi-static planar pushing: the ellipsoidal limit surface and the motion cone (Lynch 1992).

The analytic model of the pushing literature, as Kloss et al. (2022) ran it on the MIT Pushing
data: an object sliding on a floor under uniform pressure moves so slowly that its twist is set
by the pusher's wrench alone. The limit surface (every frictional wrench the floor can resist) is
approximated by the ellipsoid ``fx^2 / fmax^2 + fy^2 / fmax^2 + m^2 / mmax^2 = 1`` with
``mmax / fmax = c``, the mean distance of the support area from the centre of mass. A wrench on
it moves the object along the surface's normal, the twist ``V = (fx, fy, m / c^2)`` (up to
scale). A point pusher with friction ``mu`` at contact point ``p`` (inward normal ``n``) applies
forces in the cone between ``n + mu t`` and ``n - mu t``; their twists give the contact point
velocities bounding the *motion cone*. A pusher velocity inside the cone sticks (the contact point
moves with the pusher), outside it slides along the nearer edge, the object's contact point
matching only the pusher's normal velocity. Floor friction and mass scale the forces, never the
motion, so the model has two parameters: ``tip_friction`` (``mu``) and ``pressure_scale`` (a factor
on ``c``, for pressure that is not uniform).

:class:`LimitSurfaceDynamics` is a :class:`~fignet_gym.dynamics.base.Dynamics` on MuJoCo push
scenes (one free-joint object on a floor, one mocap pusher with a cylinder or sphere geom): it
reads the object's outline (the convex hull of its geom, as MuJoCo collides it) and the pusher's
radius from the model, and moves the object quasi-statically as the pusher moves between its
current pose and its mocap target. Velocities in ``qvel`` are the last step's displacement over
its duration (the model has no momentum).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from fignet_gym.dynamics.base import DivergenceError, DynamicsBase
from fignet_gym.pretrained import pretrained_dir

#: Longest pusher displacement (m) integrated in one piece: the contact normal and point are
#: re-read after each piece (a 5 cm push is integrated in 200 pieces).
MAX_PIECE = 2.5e-4
#: A motion cone whose edges span less than this (sine of their angle) is one ray.
DEGENERATE_CONE = 1e-9
#: Grid cells per side of the outline's bounding box for the pressure radius ``c``.
PRESSURE_GRID = 64


@dataclass(frozen=True)
class PlanarGeometry:
    """What the model needs of a push scene (all in the object's body frame, metres).

    Attributes:
        hull: ``float[K, 2]`` convex outline, counter-clockwise, relative to the centre of mass.
        com: ``float[3]`` centre of mass in the body frame.
        pressure_radius: ``c`` = mean distance of the support area from the centre of mass.
        tip_radius: the pusher's radius.
        body, joint_qpos, joint_dof, tip_body: MuJoCo ids / addresses.
    """

    hull: np.ndarray
    com: np.ndarray
    pressure_radius: float
    tip_radius: float
    body: int
    joint_qpos: int
    joint_dof: int
    tip_body: int


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull ``float[K, 2]`` of ``float[N, 2]`` points (monotone chain)."""
    pts = np.unique(np.round(np.asarray(points, float), 12), axis=0)
    if len(pts) < 3:
        raise ValueError("the outline needs at least 3 distinct points")

    def half(seq: np.ndarray) -> list[np.ndarray]:
        out: list[np.ndarray] = []
        for q in seq:
            while len(out) >= 2 and _cross(out[-1] - out[-2], q - out[-2]) <= 0:
                out.pop()
            out.append(q)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def pressure_radius(hull: np.ndarray, cells: int = PRESSURE_GRID) -> float:
    """Mean distance from the origin of a uniform pressure over the convex ``hull float[K, 2]``."""
    lo, hi = hull.min(0), hull.max(0)
    u = (np.arange(cells) + 0.5) / cells
    gx, gy = np.meshgrid(lo[0] + u * (hi[0] - lo[0]), lo[1] + u * (hi[1] - lo[1]))
    pts = np.column_stack([gx.ravel(), gy.ravel()])
    inside = np.ones(len(pts), bool)
    for a, b in zip(hull, np.roll(hull, -1, 0), strict=True):
        inside &= (b[0] - a[0]) * (pts[:, 1] - a[1]) - (b[1] - a[1]) * (pts[:, 0] - a[0]) >= 0
    return float(np.linalg.norm(pts[inside], axis=1).mean())


def closest_on_hull(hull: np.ndarray, q: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Signed distance of ``q float[2]`` to the convex ``hull`` (negative inside), the closest
    boundary point ``float[2]`` and the outward unit normal ``float[2]`` there."""
    a, b = hull, np.roll(hull, -1, 0)
    ab = b - a
    t = np.clip(((q - a) * ab).sum(1) / (ab * ab).sum(1), 0.0, 1.0)
    near = a + t[:, None] * ab
    dist = np.linalg.norm(near - q, axis=1)
    i = int(np.argmin(dist))
    edge_out = np.array([ab[i, 1], -ab[i, 0]]) / np.linalg.norm(ab[i])  # CCW: outward is right
    inside = bool(np.all(ab[:, 0] * (q[1] - a[:, 1]) - ab[:, 1] * (q[0] - a[:, 0]) >= 0))
    if inside:
        return -float(dist[i]), near[i], edge_out
    normal = (q - near[i]) / max(dist[i], 1e-12)
    return float(dist[i]), near[i], normal


def pusher_twist(p: np.ndarray, n: np.ndarray, v_push: np.ndarray, mu: float, c: float
                 ) -> tuple[np.ndarray, bool]:
    """Object twist ``(vx, vy, omega) float[3]`` (frame at the centre of mass) under a point
    pusher at ``p float[2]`` with inward unit normal ``n float[2]`` moving by ``v_push float[2]``;
    ``mu``: pusher-object friction, ``c``: the limit surface's ``mmax / fmax``. Returns the twist
    and whether the contact sticks. No push (``v_push . n <= 0``): zero twist."""
    vn = float(v_push @ n)
    if vn <= 0.0:
        return np.zeros(3), False
    t = np.array([-n[1], n[0]])
    c2 = c * c

    def twist(f: np.ndarray) -> np.ndarray:
        return np.array([f[0], f[1], _cross(p, f) / c2])

    def contact_velocity(v: np.ndarray) -> np.ndarray:
        return np.array([v[0] - v[2] * p[1], v[1] + v[2] * p[0]])

    tw_l, tw_r = twist(n + mu * t), twist(n - mu * t)
    v_l, v_r = contact_velocity(tw_l), contact_velocity(tw_r)
    cone = np.column_stack([v_l, v_r])
    if abs(np.linalg.det(cone)) <= DEGENERATE_CONE * float(v_l @ v_l):
        # A frictionless pusher: the cone is one ray, the force is along the normal.
        return tw_l * (vn / float(v_l @ n)), False
    a, b = np.linalg.solve(cone, v_push)
    if a >= 0.0 and b >= 0.0:
        return a * tw_l + b * tw_r, True
    edge, v_edge = (tw_l, v_l) if b < 0.0 else (tw_r, v_r)
    return edge * (vn / float(v_edge @ n)), False


def planar_geometry(model: mujoco.MjModel) -> PlanarGeometry:
    """The object's convex outline and pressure radius and the pusher's radius from a push scene
    (one free joint, one mocap body); ``ValueError`` naming what is missing otherwise."""
    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    mocap = np.nonzero(model.body_mocapid >= 0)[0]
    if len(free) != 1 or len(mocap) != 1:
        raise ValueError(f"the limit-surface model pushes one free object with one mocap pusher; "
                         f"this model has {len(free)} free joints and {len(mocap)} mocap bodies")
    body = int(model.jnt_bodyid[free[0]])
    pts = []
    for g in np.nonzero(model.geom_bodyid == body)[0]:
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, model.geom_quat[g])
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
            m = model.geom_dataid[g]
            v = model.mesh_vert[model.mesh_vertadr[m]:model.mesh_vertadr[m] + model.mesh_vertnum[m]]
        elif model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
            v = np.array([[sx, sy, 0.0] for sx in (-1, 1) for sy in (-1, 1)]) * model.geom_size[g]
        else:
            raise ValueError(f"geom {g} of the pushed object: only mesh and box outlines")
        pts.append(v @ rot.reshape(3, 3).T + model.geom_pos[g])
    com = np.array(model.body_ipos[body], float)
    hull = convex_hull(np.concatenate(pts)[:, :2] - com[:2])
    tip_geoms = np.nonzero(model.geom_bodyid == mocap[0])[0]
    if len(tip_geoms) != 1 or int(model.geom_type[tip_geoms[0]]) not in (
            int(mujoco.mjtGeom.mjGEOM_CYLINDER), int(mujoco.mjtGeom.mjGEOM_SPHERE)):
        raise ValueError("the pusher must be one cylinder or sphere geom")
    return PlanarGeometry(hull=hull, com=com, pressure_radius=pressure_radius(hull),
                          tip_radius=float(model.geom_size[tip_geoms[0], 0]), body=body,
                          joint_qpos=int(model.jnt_qposadr[free[0]]),
                          joint_dof=int(model.jnt_dofadr[free[0]]), tip_body=int(mocap[0]))


class LimitSurfaceDynamics(DynamicsBase):
    """Quasi-static pushing (module docstring) behind the ``Dynamics`` protocol.

    Args:
        tip_friction: pusher-object friction coefficient ``mu``.
        pressure_scale: factor on the uniform-pressure radius ``c`` (1: uniform pressure).
    """

    def __init__(self, tip_friction: float = 0.25, pressure_scale: float = 1.0) -> None:
        if not (tip_friction >= 0.0 and pressure_scale > 0.0):
            raise ValueError(f"tip_friction must be >= 0 and pressure_scale > 0, got "
                             f"{tip_friction}, {pressure_scale}")
        self.tip_friction, self.pressure_scale = float(tip_friction), float(pressure_scale)
        self._geometry: tuple[mujoco.MjModel, PlanarGeometry] | None = None

    def geometry(self, model: mujoco.MjModel) -> PlanarGeometry:
        """:func:`planar_geometry` of ``model`` (cached for the last model)."""
        if self._geometry is None or self._geometry[0] is not model:
            self._geometry = (model, planar_geometry(model))
        return self._geometry[1]

    def validate(self, model: mujoco.MjModel, nstep: int, scene_type: str = "") -> None:
        """``ValueError`` unless ``model`` is a push scene this model can move."""
        if scene_type not in ("", "push"):
            raise ValueError(f"the limit-surface model simulates pushes, not {scene_type!r} scenes")
        planar_geometry(model)

    def step(self, model: mujoco.MjModel, data: mujoco.MjData, nstep: int = 1) -> None:
        """Move the pusher from its current pose to its mocap target over ``nstep`` timesteps and
        the object quasi-statically with it; see :meth:`Dynamics.step`."""
        geo = self.geometry(model)
        start = np.array(data.xpos[geo.tip_body, :2])
        target = np.array(data.mocap_pos[0, :2])
        q = geo.joint_qpos
        qpos = data.qpos[q:q + 7]
        yaw = 2.0 * math.atan2(qpos[6], qpos[3])
        rot = _rot(yaw)
        com = qpos[:2] + rot @ geo.com[:2]
        com0, yaw0 = com.copy(), yaw
        pieces = max(1, int(math.ceil(np.linalg.norm(target - start) / MAX_PIECE)))
        c = geo.pressure_radius * self.pressure_scale
        for k in range(pieces):
            a = start + (target - start) * (k / pieces)
            b = start + (target - start) * ((k + 1) / pieces)
            rot = _rot(yaw)
            local_b = rot.T @ (b - com)
            dist, near, out_n = closest_on_hull(geo.hull, local_b)
            depth = geo.tip_radius - dist
            if depth <= 0.0:
                continue
            n = -out_n
            v = rot.T @ (b - a)
            vn = float(v @ n)
            if vn <= 0.0:
                continue
            v = v * min(1.0, depth / vn)  # only the part of the move that enters the object
            tw, _ = pusher_twist(near, n, v, self.tip_friction, c)
            com = com + rot @ tw[:2]
            yaw += float(tw[2])
        if not (np.isfinite(com).all() and math.isfinite(yaw)):
            raise DivergenceError(f"limit-surface step gave a non-finite pose at t={data.time:.3f}s")
        rot = _rot(yaw)
        qpos[:2] = com - rot @ geo.com[:2]
        qpos[3:] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        duration = nstep * model.opt.timestep
        dof = geo.joint_dof
        data.qvel[dof:dof + 6] = 0.0
        data.qvel[dof:dof + 2] = (com - com0) / duration
        data.qvel[dof + 5] = (yaw - yaw0) / duration
        data.time += duration
        mujoco.mj_kinematics(model, data)  # the pusher's xpos is now its target


def _rot(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s], [s, c]])


def fit_limit_surface(loss: Callable[[LimitSurfaceDynamics], float], frictions: Sequence[float],
                      scales: Sequence[float]) -> tuple[float, float, dict[str, float]]:
    """Grid search of ``(tip_friction, pressure_scale)``: ``loss(dynamics) -> float`` for each
    pair (e.g. a replay loss on the training split); returns the best pair and every loss
    (keyed ``"mu,scale"``)."""
    grid: dict[str, float] = {}
    for mu in frictions:
        for s in scales:
            grid[f"{mu:g},{s:g}"] = float(loss(LimitSurfaceDynamics(mu, s)))
    best = min(grid, key=lambda k: grid[k])
    mu, s = (float(x) for x in best.split(","))
    return mu, s, grid


#: ``--against limit-surface:<name>`` (a shipped fit, ``pretrained/<name>.limit_surface.json``)
#: or ``limit-surface:<path>`` (a JSON file, such as ``sim2real``'s ``limit_surface.json``).
LS_PREFIX = "limit-surface:"
LS_SUFFIX = ".limit_surface.json"


def available_limit_surfaces() -> list[str]:
    """Names of the shipped limit-surface fits (``pretrained/<name>.limit_surface.json``)."""
    return sorted(p.name[: -len(LS_SUFFIX)] for p in pretrained_dir().glob(f"*{LS_SUFFIX}"))


def load_limit_surface(spec: str | os.PathLike) -> LimitSurfaceDynamics:
    """The model a ``limit-surface:<name or path>`` spec names: a JSON object with
    ``tip_friction`` and ``pressure_scale``, at its top level or under ``params`` (as
    ``sim2real`` writes ``limit_surface.json``); ``ValueError`` in one line otherwise."""
    text = str(spec)
    body = text[len(LS_PREFIX):] if text.startswith(LS_PREFIX) else text
    path = pretrained_dir() / f"{body}{LS_SUFFIX}"
    if not path.is_file():
        path = Path(body)
    if not path.is_file():
        names = ", ".join(LS_PREFIX + n for n in available_limit_surfaces()) or "none"
        raise ValueError(f"{text}: neither a shipped limit-surface fit ({names}) nor a JSON file")
    try:
        raw = json.loads(path.read_text())
        raw = raw.get("params", raw)
        return LimitSurfaceDynamics(float(raw["tip_friction"]), float(raw["pressure_scale"]))
    except (json.JSONDecodeError, AttributeError, KeyError, TypeError) as err:
        raise ValueError(f"{path}: not a limit-surface fit (needs tip_friction and "
                         f"pressure_scale; {type(err).__name__}: {err})") from None


__all__ = ["LS_PREFIX", "LS_SUFFIX", "MAX_PIECE", "available_limit_surfaces", "closest_on_hull",
           "convex_hull", "fit_limit_surface", "LimitSurfaceDynamics", "load_limit_surface",
           "planar_geometry", "PlanarGeometry", "pressure_radius", "pusher_twist"]
