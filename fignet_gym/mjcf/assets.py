"""Shared pieces of the MJCF builders: number formatting, mesh assets, prisms, the visual header."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: Turn of consecutive outline edges (a cross product, m^2) below which an outline is still convex:
#: collinear corners of a polygon approximating a curve.
CONVEX_TOL = 1e-12
#: MuJoCo's default torsional and rolling friction, written where only sliding friction is chosen.
TORSIONAL_FRICTION, ROLLING_FRICTION = 0.005, 0.0001
#: Offscreen render buffer (pixels per side) of every scene, enough for the viewer's videos.
OFFSCREEN_SIZE = 640
#: MuJoCo friction cones. The elliptic one is isotropic in the contact plane; the pyramidal one
#: (MuJoCo's default) approximates the friction disc by a polygon fixed in the contact frame, so a
#: push or a landing turns an object differently at each world heading (issue 38).
CONES = ("elliptic", "pyramidal")
#: The cone of every generated scene and of the current env versions (Push-v2, Toss-v1).
DEFAULT_CONE = "elliptic"


def check_cone(cone: str) -> str:
    """``cone`` if it is one of :data:`CONES`; ``ValueError`` naming the valid ones otherwise."""
    if cone not in CONES:
        raise ValueError(f"unknown friction cone {cone!r}; valid: {', '.join(CONES)}")
    return cone


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
    if is_convex(outline):
        m = np.arange(1, k - 1)
        faces += [np.stack([np.zeros_like(m), m + 1, m], 1),  # bottom, normal -z
                  np.stack([np.full_like(m, k), k + m, k + m + 1], 1)]  # top, normal +z
    else:
        c = outline.mean(0)
        verts.append(np.array([[c[0], c[1], -h], [c[0], c[1], h]]))
        faces += [np.stack([np.full(k, 2 * k), j, i], 1),
                  np.stack([np.full(k, 2 * k + 1), k + i, k + j], 1)]
    return np.concatenate(verts), np.concatenate(faces).astype(np.int64)


def is_convex(outline: np.ndarray) -> bool:
    d = np.roll(outline, -1, 0) - outline
    cross = d[:, 0] * np.roll(d[:, 1], -1) - d[:, 1] * np.roll(d[:, 0], -1)
    return bool(np.all(cross > -CONVEX_TOL))


def fmt_numbers(values: np.ndarray | Sequence[float]) -> str:
    return " ".join(f"{float(v):.9g}" for v in np.asarray(values).ravel())


def mesh_asset(name: str, verts: np.ndarray, faces: np.ndarray) -> str:
    face = " ".join(map(str, faces.ravel()))
    return f'<mesh name="{name}" vertex="{fmt_numbers(verts)}" face="{face}"/>'


def yaw_quat(yaw: float) -> np.ndarray:
    """``float[4]`` quaternion (w, x, y, z) of a rotation by ``yaw`` about +z."""
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


#: Contact time constant (s) of the toss scenes' geoms (MuJoCo's default). Measured with timestep
#: 0.002 (a 0.7 m sphere dropped at 5 m/s): 0.02 gives bounces of 0.37 / 0.53 / 0.72 for restitution
#: 0.3 / 0.5 / 0.7 with 1-2 cm penetration, while 0.01 and 0.005 gain energy (0.7 -> 1.1, 6.7).
CONTACT_TIMECONST = 0.02


GRID_TEXTURE = ('<texture name="grid" type="2d" builtin="checker" rgb1=".85 .85 .82" '
                 'rgb2=".7 .7 .68" width="256" height="256"/>')


def visual_header(offsize: int = OFFSCREEN_SIZE) -> str:
    return (f'<visual><global offwidth="{offsize}" offheight="{offsize}"/>'
            '<quality shadowsize="2048"/></visual>')


def friction_attr(sliding: float | str) -> str:
    """MJCF ``friction`` attribute text: ``sliding`` with MuJoCo's default torsional and rolling."""
    return f"{sliding} {TORSIONAL_FRICTION} {ROLLING_FRICTION}"
