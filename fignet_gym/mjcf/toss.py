"""MJCF of the toss scenes: MOVi-like shapes (Kubric's materials and floor) over a floor plane."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from fignet_gym.mjcf.assets import (
    CONTACT_TIMECONST,
    DEFAULT_CONE,
    GRID_TEXTURE,
    check_cone,
    fmt_numbers,
    friction_attr,
    mesh_asset,
    prism_mesh,
    visual_header,
)
from fignet_gym.simulator.scene import MeshOptions, restitution_to_dampratio

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
#: Default start of a scene without poses: objects in a row along x, ``ROW_SPACING`` sizes apart
#: (a unit shape spans two sizes), their centres ``ROW_HEIGHT`` sizes plus ``ROW_CLEARANCE`` (m)
#: above the floor (clear of it in any orientation: the half-diagonal of a unit cube is 1.73).
ROW_SPACING, ROW_HEIGHT, ROW_CLEARANCE = 2.2, 1.8, 0.01


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
    velocities: np.ndarray | None = None, gravity: float = -10.0, cone: str = DEFAULT_CONE,
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
        cone: MuJoCo friction cone (:data:`fignet_gym.mjcf.assets.CONES`); ``"elliptic"`` (the
            default) lands an object the same way at every world heading, ``"pyramidal"`` is the
            scene of Toss-v0 and the first toss data.
    """
    k = len(objects)
    if k == 0:
        raise ValueError("toss_scene_xml needs at least one object")
    if poses is None:
        x = np.cumsum([0.0] + [o.size * ROW_SPACING for o in objects[:-1]])
        poses = np.array([[xi, 0.0, o.size * ROW_HEIGHT + ROW_CLEARANCE, 1, 0, 0, 0]
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
        assets.append(mesh_asset(f"obj{i}", v * obj.size, f))
        fr, rest, dens = MATERIALS[obj.material]
        rgba = ".7 .72 .75 1" if obj.material == "metal" else ".8 .25 .2 1"
        bodies.append(
            f'    <body name="obj{i}" pos="{fmt_numbers(pose[:3])}" quat="{fmt_numbers(pose[3:])}">\n'
            f'      <freejoint name="obj{i}"/>\n'
            f'      <geom name="obj{i}" type="mesh" mesh="obj{i}" density="{dens}" '
            f'friction="{friction_attr(fr)}" solref="{tc} {restitution_to_dampratio(rest):.9g}" '
            f'rgba="{rgba}"/>\n    </body>')
    key = ""
    if velocities is not None:
        velocities = np.asarray(velocities, dtype=float)
        if velocities.shape != (k, 6):
            raise ValueError(f"velocities must be float[{k}, 6], got shape {velocities.shape}")
        key = (f'  <keyframe><key name="start" qpos="{fmt_numbers(poses)}" '
               f'qvel="{fmt_numbers(velocities)}"/></keyframe>\n')
    fl = floor_half_size
    floor_damp = restitution_to_dampratio(FLOOR_RESTITUTION)
    newline = "\n    "
    return f"""<mujoco model="toss">
  <compiler angle="radian"/>
  <option timestep="{timestep}" gravity="0 0 {gravity}" cone="{check_cone(cone)}"/>
  {visual_header()}
  <asset>
    {GRID_TEXTURE}
    <material name="grid" texture="grid" texrepeat="{max(1, round(fl))} {max(1, round(fl))}"/>
    {newline.join(assets)}
  </asset>
  <worldbody>
    <light pos="0 0 {4 * fl}" dir="0 0 -1" directional="true"/>
    <geom name="floor" type="plane" size="{fl} {fl} 0.5" material="grid"
          friction="{friction_attr(FLOOR_FRICTION)}" solref="{tc} {floor_damp:.9g}"/>
{chr(10).join(bodies)}
  </worldbody>
{key}</mujoco>
"""


# --------------------------------------------------------------------------- a real tossed cube
