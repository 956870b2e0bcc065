"""MJCF of the push scene: one MIT Pushing object (a prism over its outline) and a kinematic tip."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fignet_gym.mjcf.assets import (
    DEFAULT_CONE,
    GRID_TEXTURE,
    check_cone,
    fmt_numbers,
    friction_attr,
    mesh_asset,
    prism_mesh,
    visual_header,
    yaw_quat,
)

#: Sides of the polygon approximating an ellipse outline (vertices on the ellipse).
ELLIPSE_SIDES = 16
#: Thickness (m) of every MIT Pushing object.
MIT_THICKNESS = 0.013


@dataclass(frozen=True)
class PushObject:
    """One MIT Pushing object: a prism of ``thickness`` over a planar outline.

    Attributes:
        name: shape name of the dataset (``rect1`` ...).
        outline: ``float[K, 2]`` convex polygon (m) in the object frame, counter-clockwise.
        mass: kg. inertia_z: kg m^2 about the vertical axis through the centroid (the dataset's).
        thickness: m.
    """

    name: str
    outline: np.ndarray
    mass: float
    inertia_z: float
    thickness: float = MIT_THICKNESS

    def centroid(self) -> np.ndarray:
        """``float[2]`` area centroid of the outline in the object frame."""
        return _polygon_moments(self.outline)[1]


def _rect(width: float, height: float) -> np.ndarray:
    a, b = width / 2, height / 2
    return np.array([[a, b], [-a, b], [-a, -b], [a, -b]])


def _right_triangle(leg_a: float, leg_b: float, d: float = 0.045) -> np.ndarray:
    # datasets.md: vertices [[d,d],[d-b,d],[d,d-a]]; b runs along x, a along y.
    return np.array([[d, d], [d - leg_b, d], [d, d - leg_a]])


def ellipse_outline(a: float, b: float, sides: int = ELLIPSE_SIDES) -> np.ndarray:
    """``float[sides, 2]`` polygon inscribed in the ellipse with semi-axes ``a`` (x), ``b`` (y)."""
    t = 2 * np.pi * np.arange(sides) / sides
    return np.stack([a * np.cos(t), b * np.sin(t)], axis=1)


def _hexagon(circumradius: float) -> np.ndarray:
    # Orientation unknown in the sources: a corner on +x.
    t = np.pi / 3 * np.arange(6)
    return circumradius * np.stack([np.cos(t), np.sin(t)], axis=1)


def _polygon_moments(outline: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Area, centroid ``float[2]`` and ``[<x^2>, <y^2>, <xy>]`` per unit area about the centroid."""
    x, y = outline[:, 0], outline[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = cross.sum() / 2
    cx = ((x + xn) * cross).sum() / (6 * area)
    cy = ((y + yn) * cross).sum() / (6 * area)
    ixx = ((x**2 + x * xn + xn**2) * cross).sum() / (12 * area)  # <x^2> about the origin
    iyy = ((y**2 + y * yn + yn**2) * cross).sum() / (12 * area)
    ixy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * cross).sum() / (24 * area)
    return float(area), np.array([cx, cy]), np.array([ixx - cx**2, iyy - cy**2, ixy - cx * cy])


def _butter_outline() -> np.ndarray:
    # The real outline is not available: an ellipse with the butter's area (mass / (density t),
    # density of the other ten objects) and its Iz (an ellipse has Iz / m = (a^2 + b^2) / 4).
    known = [o for o in _KNOWN.values()]
    density = np.mean([o.mass / (_polygon_moments(o.outline)[0] * o.thickness) for o in known])
    mass, iz = _BUTTER_MASS_IZ
    ab = mass / (density * MIT_THICKNESS) / np.pi
    s2 = 4 * iz / mass  # a^2 + b^2
    a = (math.sqrt(s2 + 2 * ab) + math.sqrt(max(s2 - 2 * ab, 0.0))) / 2
    return ellipse_outline(a, ab / a)


_KNOWN: dict[str, PushObject] = {
    "rect1": PushObject("rect1", _rect(0.090, 0.090), 0.8374, 0.001131),
    "rect2": PushObject("rect2", _rect(0.08991, 0.11258), 1.045, 0.001808),
    "rect3": PushObject("rect3", _rect(0.13501, 0.08994), 1.2508, 0.002744),
    "tri1": PushObject("tri1", _right_triangle(0.12587, 0.12590), 0.8028, 0.001414),
    "tri2": PushObject("tri2", _right_triangle(0.12587, 0.15100), 0.9826, 0.002108),
    "tri3": PushObject("tri3", _right_triangle(0.12561, 0.17650), 1.1326, 0.002957),
    "ellip1": PushObject("ellip1", ellipse_outline(0.0525, 0.0525), 0.8937, 0.001231),
    "ellip2": PushObject("ellip2", ellipse_outline(0.0525, 0.065445), 1.1104, 0.001953),
    "ellip3": PushObject("ellip3", ellipse_outline(0.0525, 0.0785), 1.3338, 0.002973),
    "hex": PushObject("hex", _hexagon(0.0605), 0.9827, 0.001497),
}
_BUTTER_MASS_IZ = (1.1974, 0.002954)

#: The eleven MIT Pushing objects. ``butter`` is an ellipse fitted to its mass and Iz (its real
#: free-form outline is not available here).
MIT_OBJECTS: dict[str, PushObject] = {
    **_KNOWN, "butter": PushObject("butter", _butter_outline(), *_BUTTER_MASS_IZ)}


def push_object(shape: str) -> PushObject:
    """The MIT object called ``shape``; ``ValueError`` listing the valid names otherwise."""
    if shape not in MIT_OBJECTS:
        raise ValueError(f"unknown push shape {shape!r}; valid: {', '.join(MIT_OBJECTS)}")
    return MIT_OBJECTS[shape]


def _push_inertia(obj: PushObject) -> tuple[np.ndarray, np.ndarray]:
    """Centroid ``float[3]`` and full inertia ``[ixx, iyy, izz, ixy, ixz, iyz]`` of the prism.

    Izz is the dataset's; the in-plane second moments of the outline are scaled to match it, so
    that ``ixx + iyy >= izz`` always holds, and ``t^2 / 12`` is added for the thickness.
    """
    _, c, (sxx, syy, sxy) = _polygon_moments(obj.outline)
    s = obj.inertia_z / (obj.mass * (sxx + syy))
    m, tt = obj.mass, obj.thickness**2 / 12
    full = np.array([m * (s * syy + tt), m * (s * sxx + tt), obj.inertia_z, -m * s * sxy, 0, 0])
    return np.array([c[0], c[1], 0.0]), full


def push_scene_xml(
    shape: str = "rect1", friction: float = 0.25, tip_radius: float = 0.00475,
    timestep: float = 0.002, floor_half_size: float = 0.5, *, tip_friction: float | None = None,
    object_pose: Sequence[float] = (0.0, 0.0, 0.0), tip_xy: Sequence[float] = (-0.15, 0.0),
    tip_half_height: float = 0.02, contact_timeconst: float = 0.005, tip_dampratio: float = 0.5,
    cone: str = DEFAULT_CONE,
) -> str:
    """MJCF of one MIT Pushing object on a floor, with a cylindrical mocap pusher ("tip").

    Bodies: world (floor plane, object 0), ``object`` (free joint, the outline extruded to a 13 mm
    prism whose body frame is the dataset's object frame at mid-height, so it rests at
    ``z = thickness / 2``), ``tip`` (mocap, vertical cylinder of ``tip_radius``, bottom 1 mm above
    the floor so it never touches it).

    Args:
        shape: key of :data:`MIT_OBJECTS`.
        friction: object-surface sliding friction (floor and object geoms).
        tip_friction: tip-object friction (default: ``friction``). Floor and tip have geom priority
            1, so each of their contacts with the object uses their own friction exactly.
        object_pose: initial (x, y, yaw) of the object. tip_xy: initial tip position.
        contact_timeconst, tip_dampratio: contact softness. A mocap body has no velocity for
            MuJoCo, so the contact damping brakes the pushed object as if the tip stood still and
            the tip sinks in by about ``2 v timeconst dampratio^2``. Stiff contacts (0.005 s, 2.5
            timesteps) and an under-damped tip (0.5) keep that to 1.3 mm at 500 mm/s (0.14 mm at
            50 mm/s) without bounces; MuJoCo's default 0.02 s sinks the tip 9 mm and tilts the
            object by 5 degrees at 400 mm/s.
        cone: MuJoCo friction cone (:data:`fignet_gym.mjcf.assets.CONES`). ``"elliptic"`` makes
            friction isotropic, so a push gives the same motion in the object's frame at every
            world heading; ``"pyramidal"`` is the scene of Push-v1 and the first push data.
    """
    obj = push_object(shape)
    tip_friction = friction if tip_friction is None else tip_friction
    verts, faces = prism_mesh(obj.outline, obj.thickness)
    com, inertia = _push_inertia(obj)
    x, y, yaw = (float(v) for v in object_pose)
    solref = f'{contact_timeconst} 1'
    tip_z = 0.001 + tip_half_height
    geom = (f'<geom name="object" type="mesh" mesh="object" friction="{friction_attr(friction)}"\n'
            f'            solref="{solref}" rgba=".75 .35 .2 1"/>')
    return push_scene_text(
        f"push_{shape}", timestep=timestep, meshes=mesh_asset("object", verts, faces), geoms=geom,
        mass=obj.mass, com=com, inertia=inertia, thickness=obj.thickness, object_pose=(x, y, yaw),
        tip_xy=tip_xy, tip_z=tip_z, tip_radius=tip_radius, tip_half_height=tip_half_height,
        floor_half_size=floor_half_size, friction=friction, tip_friction=tip_friction,
        contact_timeconst=contact_timeconst, tip_dampratio=tip_dampratio, cone=cone)


def push_scene_text(
    name: str, *, timestep: float, meshes: str, geoms: str, mass: float | None,
    com: np.ndarray | None, inertia: np.ndarray | None, thickness: float,
    object_pose: Sequence[float], tip_xy: Sequence[float],
    tip_z: float, tip_radius: float, tip_half_height: float, floor_half_size: float,
    friction: float, tip_friction: float, contact_timeconst: float, tip_dampratio: float,
    cone: str,
) -> str:
    """MJCF text of a pushing scene: floor, a free ``object`` body holding ``geoms`` (MJCF text of
    its geoms over the ``meshes`` assets), with ``com float[3]`` and ``inertia float[6]``
    (full inertia; ``mass=None``: MuJoCo's own from the geoms), and the mocap ``tip`` cylinder,
    under friction ``cone``. Shared by :func:`push_scene_xml`, :func:`~fignet_gym.mjcf.pusht_scene_xml`
    and the real-outline scenes of :mod:`fignet_gym.data.mit_scene`."""
    x, y, yaw = (float(v) for v in object_pose)
    solref = f'{contact_timeconst} 1'
    # mass None: MuJoCo computes mass and inertia from the geoms (their density).
    inertial = "" if mass is None else (f'<inertial pos="{fmt_numbers(com)}" mass="{mass}" '
                                        f'fullinertia="{fmt_numbers(inertia)}"/>')
    return f"""<mujoco model="{name}">
  <compiler angle="radian"/>
  <option timestep="{timestep}" gravity="0 0 -9.81" cone="{check_cone(cone)}"/>
  {visual_header()}
  <asset>
    {GRID_TEXTURE}
    <material name="grid" texture="grid" texrepeat="40 40" texuniform="false"/>
    {meshes}
  </asset>
  <worldbody>
    <light pos="0 0 2" dir="0 0 -1" directional="true"/>
    <camera name="top" pos="0 0 0.45" xyaxes="1 0 0 0 1 0"/>
    <geom name="floor" type="plane" size="{floor_half_size} {floor_half_size} 0.05" material="grid"
          friction="{friction_attr(friction)}" priority="1" solref="{solref}"/>
    <body name="object" pos="{x} {y} {thickness / 2}" quat="{fmt_numbers(yaw_quat(yaw))}">
      <freejoint name="object"/>
      {inertial}
      {geoms}
    </body>
    <body name="tip" mocap="true" pos="{float(tip_xy[0])} {float(tip_xy[1])} {tip_z}">
      <geom name="tip" type="cylinder" size="{tip_radius} {tip_half_height}" priority="1"
            friction="{friction_attr(tip_friction)}" solref="{contact_timeconst} {tip_dampratio}"
            rgba=".2 .3 .8 1"/>
    </body>
  </worldbody>
</mujoco>
"""
