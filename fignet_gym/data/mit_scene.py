"""MJCF of one real MIT Pushing object (its measured outline) on a floor, with the tip.

The same scene as :func:`fignet_gym.mjcf.push_scene_xml` (floor, a free prism, a mocap cylinder
tip; the same contact defaults, so fitted parameters mean the same), but the prism is the
dataset's own outline, already expressed in the **recorded** object frame (the measured offset
applied by the caller), so the tracked poses are used as they are.

MuJoCo collides a mesh by its convex hull, and the butter's hull is 16% larger than its outline:
a tip in one of its two waists would sit 12 mm inside the hull. A non-convex outline is therefore
cut into convex pieces (:func:`convex_pieces`, a fan from the centroid), one mesh geom each, so
MuJoCo collides the real outline; FIGNet meshes the union of the pieces (the same solid).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fignet_gym.data.mit_geometry import REAL_THICKNESS, TIP_RADIUS, polygon_area
from fignet_gym.mjcf import prism_mesh
from fignet_gym.mjcf.assets import friction_attr, mesh_asset
from fignet_gym.mjcf.push import push_scene_text

#: Height (m) of the tip body's centre above the floor (bottom 1 mm up, half height 0.02 m).
TIP_Z = 0.021
_TIP_HALF_HEIGHT = 0.02
#: Turn (m^2, a cross product) below which three outline points count as collinear.
_CONVEX_EPS = 1e-12


def prism_inertia(outline: np.ndarray, mass: float, inertia_z: float,
                  thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """Centroid ``float[3]`` and inertia ``[ixx, iyy, izz, ixy, ixz, iyz]`` of a uniform prism
    over ``outline float[K, 2]`` (CCW), with the dataset's ``inertia_z`` about the centroid (the
    outline's in-plane moments are scaled to it; ``t^2 / 12`` added for the thickness)."""
    x, y = outline[:, 0], outline[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = cross.sum() / 2
    cx, cy = ((x + xn) * cross).sum() / (6 * area), ((y + yn) * cross).sum() / (6 * area)
    sxx = ((x**2 + x * xn + xn**2) * cross).sum() / (12 * area) - cx**2
    syy = ((y**2 + y * yn + yn**2) * cross).sum() / (12 * area) - cy**2
    sxy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * cross).sum() / (24 * area) - cx * cy
    s = inertia_z / (mass * (sxx + syy))
    tt = thickness**2 / 12
    full = np.array([mass * (s * syy + tt), mass * (s * sxx + tt), inertia_z, -mass * s * sxy, 0, 0])
    return np.array([cx, cy, 0.0]), full


def _turns_left(poly: np.ndarray) -> bool:
    d = np.roll(poly, -1, axis=0) - poly
    cross = d[:, 0] * np.roll(d[:, 1], -1) - d[:, 1] * np.roll(d[:, 0], -1)
    return bool(np.all(cross > -_CONVEX_EPS))


def convex_pieces(outline: np.ndarray) -> list[np.ndarray]:
    """Convex CCW polygons ``float[K_i, 2]`` whose union is the CCW ``outline float[K, 2]``.

    A convex outline is its own piece. Otherwise the outline must be star-shaped about its
    vertex mean (``ValueError`` if not): fan wedges ``(centre, v_i, v_i+1)`` are merged greedily,
    in order, while the merged piece stays convex, starting after a reflex vertex.
    """
    if _turns_left(outline):
        return [outline]
    c = outline.mean(axis=0)
    rel = outline - c
    nxt = np.roll(rel, -1, axis=0)
    if not np.all(rel[:, 0] * nxt[:, 1] - rel[:, 1] * nxt[:, 0] > 0):
        raise ValueError("outline is neither convex nor star-shaped about its vertex mean")
    k = len(outline)
    d = np.roll(outline, -1, axis=0) - outline
    turn = d[:, 0] * np.roll(d[:, 1], -1) - d[:, 1] * np.roll(d[:, 0], -1)
    first = (int(np.flatnonzero(turn < 0)[0]) + 1) % k  # a reflex vertex ends the last piece
    order = [(first + i) % k for i in range(k + 1)]
    pieces, chain = [], [order[0]]
    for v in order[1:]:
        trial = np.vstack([c, outline[chain + [v]]])
        if len(chain) >= 2 and not _turns_left(trial):
            pieces.append(np.vstack([c, outline[chain]]))
            chain = [chain[-1]]
        chain.append(v)
    pieces.append(np.vstack([c, outline[chain]]))
    return pieces


#: Cone of the imported scenes' nominal MuJoCo: the scene every published sim2real figure of the
#: nominal baseline was measured on. The fitted models (``push-real.mujoco.json``) set their own.
NOMINAL_CONE = "pyramidal"


def real_push_scene_xml(
    name: str, outline: np.ndarray, mass: float, inertia_z: float, friction: float = 0.25, *,
    thickness: float = REAL_THICKNESS, tip_radius: float = TIP_RADIUS, timestep: float = 0.002,
    floor_half_size: float = 0.5, object_pose: Sequence[float] = (0.0, 0.0, 0.0),
    tip_xy: Sequence[float] = (-0.15, 0.0), contact_timeconst: float = 0.005,
    tip_dampratio: float = 0.5,
) -> str:
    """MJCF text: floor (object 0), ``object`` (free prism over ``outline float[K, 2]`` in its
    body frame, resting at ``z = thickness / 2``; geoms ``object0``, ... one per convex piece),
    ``tip`` (mocap cylinder). Arguments as
    :func:`fignet_gym.mjcf.push_scene_xml`; ``name`` only names the model."""
    poly = np.asarray(outline, float)
    if polygon_area(poly) < 0:
        poly = poly[::-1]
    pieces = [prism_mesh(p, thickness) for p in convex_pieces(poly)]
    com, inertia = prism_inertia(poly, mass, inertia_z, thickness)
    meshes = "\n    ".join(mesh_asset(f"object{i}", v, f) for i, (v, f) in enumerate(pieces))
    geoms = "\n      ".join(f'<geom name="object{i}" type="mesh" mesh="object{i}" friction='
                            f'"{friction_attr(friction)}" solref="{contact_timeconst} 1" '
                            'rgba=".75 .35 .2 1"/>' for i in range(len(pieces)))
    return push_scene_text(
        f"push_{name}_real", timestep=timestep, meshes=meshes, geoms=geoms, mass=mass, com=com,
        inertia=inertia, thickness=thickness, object_pose=object_pose, tip_xy=tip_xy, tip_z=TIP_Z,
        tip_radius=tip_radius, tip_half_height=_TIP_HALF_HEIGHT, floor_half_size=floor_half_size,
        friction=friction, tip_friction=friction, contact_timeconst=contact_timeconst,
        tip_dampratio=tip_dampratio, cone=NOMINAL_CONE)
