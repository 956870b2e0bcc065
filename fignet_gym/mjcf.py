"""MJCF builders for the push and toss scenes (MIT Pushing objects, MOVi-like tossed shapes).

Every builder returns an XML string for ``mujoco.MjModel.from_xml_string``. The world body holds
a finite floor plane (object 0 of :meth:`fignet_gym.simulator.scene.Scene.from_mjmodel`); then come the
bodies in document order, so a scene's object order is: floor, then the bodies as listed here.

Geometry choices (why):

* Every moving object is a **mesh geom**, also the simple shapes (cube, sphere, cylinder). FIGNet
  sees the triangle mesh, and MuJoCo then collides the same geometry (its convex hull): with
  primitives MuJoCo would collide an exact sphere while the learned model sees a 42-node
  polyhedron.
* MuJoCo collides a mesh by its convex hull. For convex shapes that is exact; for the non-convex
  procedural shapes (torus, torus knot, gear, star, hourglass) contacts with the floor are still
  exact (a plane only ever touches hull points), but one object cannot enter another's hole or the
  gap between gear teeth.
* Restitution follows the project convention (``docs/architecture.md``): a geom's
  ``solref = (timeconst, dampratio)`` with ``dampratio = restitution_to_dampratio(e)``.
  MuJoCo combines two geoms' ``solref`` by their mean and friction by the maximum (PyBullet, which
  made Kubric's data, multiplies both): the per-object properties are the same as Kubric's, the pair
  values differ.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from fignet_gym.simulator.scene import MeshOptions, restitution_to_dampratio

# --------------------------------------------------------------------------- MIT Pushing objects

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


def prism_mesh(outline: np.ndarray, thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """Closed prism over a star-shaped CCW outline, from ``z = -t/2`` to ``t/2``.

    Returns ``float[2K(+2), 3]`` vertices and ``int[F, 3]`` outward faces. Convex outlines are
    fanned from their first corner (no extra node); others from an added centre node per cap.
    """
    k = len(outline)
    h = thickness / 2
    bottom = np.column_stack([outline, np.full(k, -h)])
    top = np.column_stack([outline, np.full(k, h)])
    verts = [bottom, top]
    i = np.arange(k)
    j = (i + 1) % k
    faces = [np.stack([i, j, k + j], 1), np.stack([i, k + j, k + i], 1)]  # sides
    if _is_convex(outline):
        m = np.arange(1, k - 1)
        faces += [np.stack([np.zeros_like(m), m + 1, m], 1),  # bottom, normal -z
                  np.stack([np.full_like(m, k), k + m, k + m + 1], 1)]  # top, normal +z
    else:
        c = outline.mean(0)
        verts.append(np.array([[c[0], c[1], -h], [c[0], c[1], h]]))
        faces += [np.stack([np.full(k, 2 * k), j, i], 1),
                  np.stack([np.full(k, 2 * k + 1), k + i, k + j], 1)]
    return np.concatenate(verts), np.concatenate(faces).astype(np.int64)


def _is_convex(outline: np.ndarray) -> bool:
    d = np.roll(outline, -1, 0) - outline
    cross = d[:, 0] * np.roll(d[:, 1], -1) - d[:, 1] * np.roll(d[:, 0], -1)
    return bool(np.all(cross > -1e-12))


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


def _fmt(values: np.ndarray | Sequence[float]) -> str:
    return " ".join(f"{float(v):.9g}" for v in np.asarray(values).ravel())


def _mesh_asset(name: str, verts: np.ndarray, faces: np.ndarray) -> str:
    face = " ".join(map(str, faces.ravel()))
    return f'<mesh name="{name}" vertex="{_fmt(verts)}" face="{face}"/>'


def yaw_quat(yaw: float) -> np.ndarray:
    """``float[4]`` quaternion (w, x, y, z) of a rotation by ``yaw`` about +z."""
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


#: Contact time constant (s) of the toss scenes' geoms (MuJoCo's default). Measured with timestep
#: 0.002 (a 0.7 m sphere dropped at 5 m/s): 0.02 gives bounces of 0.37 / 0.53 / 0.72 for restitution
#: 0.3 / 0.5 / 0.7 with 1-2 cm penetration, while 0.01 and 0.005 gain energy (0.7 -> 1.1, 6.7).
CONTACT_TIMECONST = 0.02


_GRID_TEXTURE = ('<texture name="grid" type="2d" builtin="checker" rgb1=".85 .85 .82" '
                 'rgb2=".7 .7 .68" width="256" height="256"/>')


def _visual_header(offsize: int = 640) -> str:
    return (f'<visual><global offwidth="{offsize}" offheight="{offsize}"/>'
            '<quality shadowsize="2048"/></visual>')


def push_scene_xml(
    shape: str = "rect1", friction: float = 0.25, tip_radius: float = 0.00475,
    timestep: float = 0.002, floor_half_size: float = 0.5, *, tip_friction: float | None = None,
    object_pose: Sequence[float] = (0.0, 0.0, 0.0), tip_xy: Sequence[float] = (-0.15, 0.0),
    tip_half_height: float = 0.02, contact_timeconst: float = 0.005, tip_dampratio: float = 0.5,
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
    """
    obj = push_object(shape)
    tip_friction = friction if tip_friction is None else tip_friction
    verts, faces = prism_mesh(obj.outline, obj.thickness)
    com, inertia = _push_inertia(obj)
    x, y, yaw = (float(v) for v in object_pose)
    solref = f'{contact_timeconst} 1'
    tip_z = 0.001 + tip_half_height
    return f"""<mujoco model="push_{shape}">
  <compiler angle="radian"/>
  <option timestep="{timestep}" gravity="0 0 -9.81"/>
  {_visual_header()}
  <asset>
    {_GRID_TEXTURE}
    <material name="grid" texture="grid" texrepeat="40 40" texuniform="false"/>
    {_mesh_asset("object", verts, faces)}
  </asset>
  <worldbody>
    <light pos="0 0 2" dir="0 0 -1" directional="true"/>
    <camera name="top" pos="0 0 0.45" xyaxes="1 0 0 0 1 0"/>
    <geom name="floor" type="plane" size="{floor_half_size} {floor_half_size} 0.05" material="grid"
          friction="{friction} 0.005 0.0001" priority="1" solref="{solref}"/>
    <body name="object" pos="{x} {y} {obj.thickness / 2}" quat="{_fmt(yaw_quat(yaw))}">
      <freejoint name="object"/>
      <inertial pos="{_fmt(com)}" mass="{obj.mass}" fullinertia="{_fmt(inertia)}"/>
      <geom name="object" type="mesh" mesh="object" friction="{friction} 0.005 0.0001"
            solref="{solref}" rgba=".75 .35 .2 1"/>
    </body>
    <body name="tip" mocap="true" pos="{float(tip_xy[0])} {float(tip_xy[1])} {tip_z}">
      <geom name="tip" type="cylinder" size="{tip_radius} {tip_half_height}" priority="1"
            friction="{tip_friction} 0.005 0.0001" solref="{contact_timeconst} {tip_dampratio}"
            rgba=".2 .3 .8 1"/>
    </body>
  </worldbody>
</mujoco>
"""


# --------------------------------------------------------------------------- toss scenes

#: Materials of Kubric MOVi (friction, restitution, density). Density is used as given, in kg/m^3,
#: like Kubric (which hands these numbers to PyBullet with metre units).
MATERIALS: dict[str, tuple[float, float, float]] = {
    "metal": (0.4, 0.3, 2.7),
    "rubber": (0.8, 0.7, 1.1),
}
#: Floor of Kubric MOVi: friction, restitution.
FLOOR_FRICTION, FLOOR_RESTITUTION = 0.3, 0.5
SIMPLE_SHAPES = ("cube", "sphere", "cylinder")
COMPLEX_SHAPES = ("cone", "torus", "torus_knot", "gear", "capsule", "star", "hourglass")
TOSS_SHAPES = SIMPLE_SHAPES + COMPLEX_SHAPES


@dataclass(frozen=True)
class TossObject:
    """One tossed object.

    Attributes:
        shape: one of :data:`TOSS_SHAPES`.
        size: scale (m), Kubric's: the unit shape spans ``[-1, 1]`` along its largest axis, so a
            cube of size 0.7 has half side 0.7 and a sphere radius 0.7.
        material: ``"metal"`` or ``"rubber"`` (:data:`MATERIALS`).
    """

    shape: str
    size: float
    material: str = "metal"

    def __post_init__(self) -> None:
        if self.shape not in TOSS_SHAPES:
            raise ValueError(f"unknown toss shape {self.shape!r}; valid: {', '.join(TOSS_SHAPES)}")
        if self.material not in MATERIALS:
            raise ValueError(f"unknown material {self.material!r}; valid: {', '.join(MATERIALS)}")
        if not self.size > 0:
            raise ValueError(f"size must be positive, got {self.size}")


def _oriented(m: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    faces = np.asarray(m.faces, dtype=np.int64)
    if m.volume < 0:  # inward winding: flip so normals point out (MuJoCo needs a positive volume)
        faces = faces[:, ::-1].copy()
    return np.asarray(m.vertices, dtype=float), faces


def _tube(path: np.ndarray, radius: float, sides: int) -> trimesh.Trimesh:
    """Closed tube of ``radius`` around the closed curve ``float[M, 3]`` (parallel transport)."""
    n = len(path)
    tangent = np.roll(path, -1, 0) - np.roll(path, 1, 0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.cross(tangent[0], [0.0, 0.0, 1.0] if abs(tangent[0, 2]) < 0.9 else [1.0, 0, 0])
    normals = []
    for t in tangent:  # transport the normal along the curve (no twist)
        normal = normal - t * (normal @ t)
        normal /= np.linalg.norm(normal)
        normals.append(normal)
    normals = np.array(normals)
    binormals = np.cross(tangent, normals)
    a = 2 * np.pi * np.arange(sides) / sides
    ring = (np.cos(a)[None, :, None] * normals[:, None]
            + np.sin(a)[None, :, None] * binormals[:, None])
    verts = (path[:, None] + radius * ring).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n), np.arange(sides), indexing="ij")
    i2, j2 = (i + 1) % n, (j + 1) % sides
    q = lambda a, b: (a * sides + b).ravel()  # noqa: E731
    faces = np.concatenate([np.stack([q(i, j), q(i2, j), q(i2, j2)], 1),
                            np.stack([q(i, j), q(i2, j2), q(i, j2)], 1)])
    # The transported frame may not close up exactly; the seam is a small twist, harmless here.
    return trimesh.Trimesh(verts, faces, process=False)


def _star_outline(points: int, outer: float, inner: float, per_edge: int) -> np.ndarray:
    corners = []
    for k in range(2 * points):
        r = outer if k % 2 == 0 else inner
        a = np.pi * k / points
        corners.append([r * math.cos(a), r * math.sin(a)])
    corners = np.array(corners)
    nxt = np.roll(corners, -1, 0)
    s = np.arange(per_edge)[None, :, None] / per_edge
    return (corners[:, None] * (1 - s) + nxt[:, None] * s).reshape(-1, 2)


def _gear_outline(teeth: int, outer: float, root: float, per_arc: int) -> np.ndarray:
    pts = []
    for k in range(teeth):
        base = 2 * np.pi * k / teeth
        step = 2 * np.pi / teeth
        # root arc, flank up, tip arc, flank down: a trapezoidal tooth
        for f, r in ((0.0, root), (0.3, root), (0.4, outer), (0.8, outer), (0.9, root)):
            pts.append((base + f * step, r))
        for s in np.linspace(0.4, 0.8, per_arc + 2)[1:-1]:
            pts.append((base + s * step, outer))
    pts.sort()
    return np.array([[r * math.cos(a), r * math.sin(a)] for a, r in pts])


def unit_shape_mesh(
    shape: str, mesh_options: MeshOptions | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Mesh of a toss shape at size 1 (largest half extent 1, centred).

    Returns vertices ``float[n, 3]`` and outward faces ``int[f, 3]``.

    Simple shapes follow ``mesh_options`` (the same triangulation ``Scene`` uses for primitives:
    a cube's 8 corners, a level-1 icosphere of 42 nodes, a 12-section cylinder of 26 nodes by
    default). Complex shapes have fixed resolutions of a few hundred to about a thousand nodes.
    """
    opts = mesh_options or MeshOptions()
    c = trimesh.creation
    if shape == "cube":
        m = c.box(extents=(2.0, 2.0, 2.0))
        for _ in range(opts.box_subdivisions):
            m = m.subdivide()
    elif shape == "sphere":
        m = c.icosphere(subdivisions=opts.sphere_subdivisions, radius=1.0)
    elif shape == "cylinder":
        m = c.cylinder(radius=1.0, height=2.0, sections=opts.cylinder_sections)
    elif shape == "cone":
        # revolved profile with rings along the slant: 8 rings x 48 sections (~340 nodes)
        h = np.linspace(0.0, 1.0, 9)[:-1]
        profile = np.concatenate([[[0.0, -1.0]], np.stack([1 - h, -1 + 2 * h], 1), [[0.0, 1.0]]])
        m = c.revolve(profile, sections=48)
    elif shape == "torus":
        m = c.torus(major_radius=0.7, minor_radius=0.3, major_sections=32, minor_sections=16)
    elif shape == "torus_knot":
        t = np.linspace(0, 2 * np.pi, 120, endpoint=False)
        p, q = 2, 3  # trefoil
        r = 2 + np.cos(q * t)
        path = np.stack([r * np.cos(p * t), r * np.sin(p * t), -np.sin(q * t)], 1)
        path *= 0.75 / np.abs(path[:, :2]).max()
        m = _tube(path, 0.22, 8)
    elif shape == "gear":
        m = trimesh.Trimesh(*prism_mesh(_gear_outline(16, 1.0, 0.8, 4), 0.5), process=False)
    elif shape == "capsule":
        m = c.capsule(height=1.0, radius=0.5, count=[24, 12])
    elif shape == "star":
        m = trimesh.Trimesh(*prism_mesh(_star_outline(5, 1.0, 0.45, 6), 0.4), process=False)
    elif shape == "hourglass":
        z = np.linspace(-1, 1, 13)
        profile = np.stack([0.35 + 0.55 * z**2, z], 1)
        profile = np.concatenate([[[0.0, -1.0]], profile, [[0.0, 1.0]]])
        m = c.revolve(profile, sections=32)
    else:
        raise ValueError(f"unknown toss shape {shape!r}; valid: {', '.join(TOSS_SHAPES)}")
    v, f = _oriented(m)
    lo, hi = v.min(0), v.max(0)
    v = v - (lo + hi) / 2
    return v / np.abs(v).max(), f


def toss_scene_xml(
    objects: Sequence[TossObject], timestep: float = 0.002, floor_half_size: float = 10.0,
    mesh_options: MeshOptions | None = None, *, poses: np.ndarray | None = None,
    velocities: np.ndarray | None = None, gravity: float = -10.0,
) -> str:
    """MJCF of objects ``obj0 .. objK-1`` (free joints, mesh geoms) above a Kubric-like floor.

    Args:
        objects: the K objects.
        mesh_options: triangulation of the simple shapes (see :func:`unit_shape_mesh`).
        poses: ``float[K, 7]`` initial body poses (default: in a row along x, resting above z=0).
        velocities: ``float[K, 6]`` initial free-joint velocities (linear world, angular local as
            MuJoCo's ``qvel``); stored with ``poses`` in a keyframe ``start``, so
            ``mj_resetDataKeyframe(model, data, 0)`` restores the exact initial state.
        gravity: along z (Kubric: -10).
    """
    k = len(objects)
    if k == 0:
        raise ValueError("toss_scene_xml needs at least one object")
    if poses is None:
        x = np.cumsum([0.0] + [o.size * 2.2 for o in objects[:-1]])
        poses = np.array([[xi, 0.0, o.size * 1.8 + 0.01, 1, 0, 0, 0]
                          for xi, o in zip(x, objects, strict=True)])
    poses = np.asarray(poses, dtype=float)
    if poses.shape != (k, 7):
        raise ValueError(f"poses must be float[{k}, 7], got shape {poses.shape}")
    tc = CONTACT_TIMECONST
    assets, bodies, meshes = [], [], {}
    for i, (obj, pose) in enumerate(zip(objects, poses, strict=True)):
        if obj.shape not in meshes:
            meshes[obj.shape] = unit_shape_mesh(obj.shape, mesh_options)
        v, f = meshes[obj.shape]
        assets.append(_mesh_asset(f"obj{i}", v * obj.size, f))
        fr, rest, dens = MATERIALS[obj.material]
        rgba = ".7 .72 .75 1" if obj.material == "metal" else ".8 .25 .2 1"
        bodies.append(
            f'    <body name="obj{i}" pos="{_fmt(pose[:3])}" quat="{_fmt(pose[3:])}">\n'
            f'      <freejoint name="obj{i}"/>\n'
            f'      <geom name="obj{i}" type="mesh" mesh="obj{i}" density="{dens}" '
            f'friction="{fr} 0.005 0.0001" solref="{tc} {restitution_to_dampratio(rest):.9g}" '
            f'rgba="{rgba}"/>\n    </body>')
    key = ""
    if velocities is not None:
        velocities = np.asarray(velocities, dtype=float)
        if velocities.shape != (k, 6):
            raise ValueError(f"velocities must be float[{k}, 6], got shape {velocities.shape}")
        key = (f'  <keyframe><key name="start" qpos="{_fmt(poses)}" '
               f'qvel="{_fmt(velocities)}"/></keyframe>\n')
    fl = floor_half_size
    floor_damp = restitution_to_dampratio(FLOOR_RESTITUTION)
    newline = "\n    "
    return f"""<mujoco model="toss">
  <compiler angle="radian"/>
  <option timestep="{timestep}" gravity="0 0 {gravity}"/>
  {_visual_header()}
  <asset>
    {_GRID_TEXTURE}
    <material name="grid" texture="grid" texrepeat="{max(1, round(fl))} {max(1, round(fl))}"/>
    {newline.join(assets)}
  </asset>
  <worldbody>
    <light pos="0 0 {4 * fl}" dir="0 0 -1" directional="true"/>
    <geom name="floor" type="plane" size="{fl} {fl} 0.5" material="grid"
          friction="{FLOOR_FRICTION} 0.005 0.0001" solref="{tc} {floor_damp:.9g}"/>
{chr(10).join(bodies)}
  </worldbody>
{key}</mujoco>
"""


# --------------------------------------------------------------------------- a real tossed cube


def cube_scene_xml(
    half_width: float, mass: float, inertia: float, friction: float | Sequence[float],
    restitution: float | None, *, timestep: float = 0.002, gravity: float = -9.81,
    floor_half_size: float = 2.0, contact_timeconst: float = CONTACT_TIMECONST, name: str = "cube",
    dampratio: float | None = None, cone: str = "pyramidal", impratio: float = 1.0,
) -> str:
    """MJCF of one cube (free joint, box geom) above a floor plane at ``z = 0`` (the world body).

    Objects of the scene: ``world`` (static floor), ``name`` (dynamic). A box primitive rather
    than a mesh: MuJoCo's box-plane collision is exact and the learned model's mesh follows
    :class:`~fignet_gym.simulator.scene.MeshOptions` (8 corners by default).

    Args:
        half_width: m. mass: kg. inertia: kg m^2 about each principal axis through the centre.
        friction: sliding friction of both geoms, or their (sliding, torsional, rolling)
            triple. restitution: as ``solref`` damping ratio
            (:func:`~fignet_gym.simulator.scene.restitution_to_dampratio`) with time constant
            ``contact_timeconst`` (s) on both geoms; ``dampratio`` gives the ratio directly
            instead (a fitted one may exceed 1, which no restitution maps to).
        cone, impratio: MuJoCo's friction cone and its impedance ratio.
    """
    if not (half_width > 0 and mass > 0 and inertia > 0):
        raise ValueError(f"cube needs positive half_width, mass and inertia, got {half_width}, "
                         f"{mass}, {inertia}")
    if dampratio is None:
        if restitution is None:
            raise ValueError("cube_scene_xml needs restitution or dampratio")
        dampratio = restitution_to_dampratio(restitution)
    solref = f"{contact_timeconst:.9g} {dampratio:.9g}"
    fr = _fmt(friction) if np.ndim(friction) else f"{friction:.9g} 0.005 0.0001"
    fl = floor_half_size
    return f"""<mujoco model="{name}_toss">
  <compiler angle="radian"/>
  <option timestep="{timestep:.9g}" gravity="0 0 {gravity:.9g}" cone="{cone}"
          impratio="{impratio:.9g}"/>
  {_visual_header()}
  <asset>
    {_GRID_TEXTURE}
    <material name="grid" texture="grid" texrepeat="{max(1, round(4 * fl))} {max(1, round(4 * fl))}"/>
  </asset>
  <worldbody>
    <light pos="0 0 {4 * fl:.9g}" dir="0 0 -1" directional="true"/>
    <geom name="floor" type="plane" size="{fl:.9g} {fl:.9g} 0.05" material="grid"
          friction="{fr}" solref="{solref}"/>
    <body name="{name}" pos="0 0 {2 * half_width:.9g}">
      <freejoint name="{name}"/>
      <inertial pos="0 0 0" mass="{mass:.9g}" diaginertia="{_fmt([inertia] * 3)}"/>
      <geom name="{name}" type="box" size="{_fmt([half_width] * 3)}"
            friction="{fr}" solref="{solref}" rgba=".8 .25 .2 1"/>
    </body>
  </worldbody>
</mujoco>
"""
