"""The Push-T scene: a T block on a floor and a cylindrical mocap tip (``PushT-v0``).

The T has the proportions of Push-T (Chi et al. 2023; LeRobot's ``gym-pusht``): a bar 4 units
wide and 1 deep, and a stem 1 unit wide and 3 long below it, here with a unit of 2.5 cm (a
10 x 10 cm T) and the MIT Pushing objects' 13 mm thickness, mass density and contact settings,
so the shipped ``push`` model is a close warm start. The body frame sits at the T's area
centroid (its centre of mass) with the stem along +y. Each bar is a convex mesh geom of its own:
MuJoCo collides a mesh by its convex hull, and two convex pieces keep the T's inner corners.
"""

from __future__ import annotations

import numpy as np

from fignet_gym.mjcf.assets import DEFAULT_CONE, friction_attr, mesh_asset, prism_mesh
from fignet_gym.mjcf.push import MIT_THICKNESS, push_scene_text

#: Push-T's unit (m): the bar is 4 x 1 units, the stem 1 x 3.
PUSHT_UNIT = 0.025
#: Mass density (kg / m^3) of the MIT Pushing steel objects (rect1: 0.837 kg over 90 x 90 x 13 mm).
PUSHT_DENSITY = 0.8374 / (0.090 * 0.090 * MIT_THICKNESS)


def pusht_rectangles(unit: float = PUSHT_UNIT) -> np.ndarray:
    """``float[2, 4, 2]`` the bar's and the stem's counter-clockwise corners (m) in the T's body
    frame (origin at the area centroid, stem along +y)."""
    bar = np.array([[-2.0, 0.0], [2.0, 0.0], [2.0, 1.0], [-2.0, 1.0]])
    stem = np.array([[-0.5, 1.0], [0.5, 1.0], [0.5, 4.0], [-0.5, 4.0]])
    centroid_y = (4.0 * 0.5 + 3.0 * 2.5) / 7.0  # area-weighted centres of bar (4) and stem (3)
    return (np.stack([bar, stem]) - (0.0, centroid_y)) * unit


def pusht_outline(unit: float = PUSHT_UNIT) -> np.ndarray:
    """``float[8, 2]`` the T's counter-clockwise (non-convex) outline (m) in its body frame."""
    bar, stem = pusht_rectangles(unit)
    return np.array([bar[0], bar[1], bar[2], stem[1], stem[2], stem[3], stem[0], bar[3]])


def _inertia(rects: np.ndarray, density: float, thickness: float) -> tuple[float, np.ndarray]:
    """Mass (kg) and full inertia ``[ixx, iyy, izz, ixy, ixz, iyz]`` about the body origin of
    the axis-aligned boxes ``rects float[R, 4, 2]`` extruded by ``thickness``."""
    mass, full = 0.0, np.zeros(6)
    for r in rects:
        (x0, y0), (x1, y1) = r.min(0), r.max(0)
        w, d = x1 - x0, y1 - y0
        m = density * w * d * thickness
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        # The box's own moments, then the parallel-axis shift to the body origin.
        ixx = m * (d**2 + thickness**2) / 12 + m * cy**2
        iyy = m * (w**2 + thickness**2) / 12 + m * cx**2
        izz = m * (w**2 + d**2) / 12 + m * (cx**2 + cy**2)
        full += (ixx, iyy, izz, -m * cx * cy, 0.0, 0.0)
        mass += m
    return mass, full


def pusht_scene_xml(friction: float = 0.25, tip_radius: float = 0.00475,
                    unit: float = PUSHT_UNIT, cone: str = DEFAULT_CONE) -> str:
    """MJCF of the Push-T scene: floor, the free body ``object`` (the T: two mesh geoms ``bar``
    and ``stem``), the mocap ``tip`` cylinder and the ``top`` camera; isotropic friction by
    default. Contact settings are :func:`~fignet_gym.mjcf.push_scene_xml`'s."""
    rects = pusht_rectangles(unit)
    mass, inertia = _inertia(rects, PUSHT_DENSITY, MIT_THICKNESS)
    meshes, geoms = [], []
    for name, rect in zip(("bar", "stem"), rects, strict=True):
        verts, faces = prism_mesh(rect, MIT_THICKNESS)
        meshes.append(mesh_asset(name, verts, faces))
        geoms.append(f'<geom name="{name}" type="mesh" mesh="{name}" '
                     f'friction="{friction_attr(friction)}" solref="0.005 1" rgba=".75 .35 .2 1"/>')
    return push_scene_text(
        "push_t", timestep=0.002, meshes="\n    ".join(meshes), geoms="\n      ".join(geoms),
        mass=mass, com=np.zeros(3), inertia=inertia, thickness=MIT_THICKNESS,
        object_pose=(0.0, 0.0, 0.0), tip_xy=(-0.15, 0.0), tip_z=0.021, tip_radius=tip_radius,
        tip_half_height=0.02, floor_half_size=0.5, friction=friction, tip_friction=friction,
        contact_timeconst=0.005, tip_dampratio=0.5, cone=cone)


__all__ = ["PUSHT_DENSITY", "PUSHT_UNIT", "pusht_outline", "pusht_rectangles", "pusht_scene_xml"]
