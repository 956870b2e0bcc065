"""Exact symmetry about gravity: a canonical frame per scene, taken equivariantly from its poses.

Physics on a level floor under vertical gravity does not change when the scene is turned about
the vertical or shifted horizontally. A model that sees every scene in a frame that turns and
shifts with it is therefore equivariant by construction, to float rounding, and never has to learn
the symmetry from augmented data. The frame of a scene is its reference object's (the first
dynamic one, else the first object that is not a floor): the origin below that object's position,
and the heading of one of its body axes projected onto the floor (x, or y when x is within 60 deg
of the vertical, or z), so it is defined for tilted and tumbling objects too.

Level horizontal planes among the static objects (floors) are invariant themselves, so their
world yaw and position say nothing about the scene: in the canonical frame a floor is upright and
shifted so that the centroid of its first triangle lies under the frame origin. Its far corners
(which the clipped face spans see) are then the same for every turn and shift of the scene, and
the reference object sits inside one triangle, away from the diagonal of a two-triangle floor,
where contacts near it would otherwise switch triangles with float rounding.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from fignet_gym.simulator.geometry import quat_mul, quat_to_matrix
from fignet_gym.simulator.scene import ObjectKind, Scene

#: A body axis is used for the heading when its horizontal part is at least this long (a unit
#: axis within 60 deg of the vertical has less). Of three orthonormal axes one always qualifies.
MIN_HORIZONTAL = 0.5
#: A floor whose quaternion's x and y parts are below this is level (turned about z only).
LEVEL_TOLERANCE = 1e-6
#: A static object whose vertices span less than this height (m) in its body frame is a plane.
PLANE_THICKNESS = 1e-9


@dataclass(frozen=True)
class CanonicalFrame:
    """One frame per scene of a (batched) scene, as the rotation and shift that map world
    coordinates into it: ``x_c = Rz(-yaw) (x - origin)``.

    Attributes:
        origin: ``float[S, 3]`` (z = 0) world point of each scene's frame origin.
        cos, sin: ``float[S]`` of each scene's heading ``yaw``.
    """

    origin: Tensor
    cos: Tensor
    sin: Tensor


def _static_info(scene: Scene) -> tuple[Tensor, Tensor, Tensor, bool]:
    """``(reference int64[S], plane bool[O], anchor float[O, 3], any plane)``: each scene's
    reference object, the floors, the centroid of each floor's first triangle in its body frame
    (else 0), and whether the batch has a floor at all. Built once per scene on its host tensors."""
    def build() -> tuple[Tensor, Tensor, Tensor, bool]:
        o = scene.num_objects
        z = scene.ref_vertices[:, 2]
        big = torch.finfo(z.dtype).max
        zmin = torch.full((o,), big, dtype=z.dtype).scatter_reduce(0, scene.node_object, z, "amin")
        zmax = torch.full((o,), -big, dtype=z.dtype).scatter_reduce(0, scene.node_object, z, "amax")
        has_nodes = torch.zeros(o, dtype=torch.bool).index_fill(0, scene.node_object, True)
        plane = ((scene.object_kind == ObjectKind.STATIC) & has_nodes
                 & (zmax - zmin <= PLANE_THICKNESS))
        # Lowest score first: dynamic objects, then the other non-floors, in object order.
        idx = torch.arange(o)
        score = idx + o * (scene.object_kind != ObjectKind.DYNAMIC).long() + 2 * o * plane.long()
        s = scene.num_scenes
        ref = torch.full((s,), 3 * o, dtype=torch.long).scatter_reduce(
            0, scene.object_scene, score, "amin") % o
        nf = scene.faces.shape[0]
        first = torch.full((o,), nf, dtype=torch.long).scatter_reduce(
            0, scene.face_object, torch.arange(nf), "amin")
        anchor = torch.zeros(o, 3, dtype=scene.ref_vertices.dtype)
        rows = (plane & (first < nf)).nonzero().squeeze(1)
        anchor[rows] = scene.ref_vertices[scene.faces[first[rows]]].mean(1)
        # A Python bool, once per scene: a tensor test per step would sync a GPU with the host.
        return ref, plane, anchor, bool(plane.any())
    return scene.cached("canonical_static", build)


def canonical_frame(scene: Scene, poses: Tensor) -> CanonicalFrame:
    """The frame of each scene from its current poses ``float[O, 7]`` (``[x, y, z, qw, qx, qy,
    qz]``). Turning the scene by ``a`` about the vertical turns every frame by ``a``; shifting it
    horizontally shifts every origin: so :func:`to_frame` gives the same poses for both."""
    ref, _, _, _ = _static_info(scene)
    pose = poses.index_select(0, ref.to(poses.device))
    axes = quat_to_matrix(pose[:, 3:]).transpose(-1, -2)[..., :2]  # [S, axis, xy]
    long_enough = axes.norm(dim=-1) >= MIN_HORIZONTAL  # [S, 3]
    first = torch.where(long_enough[:, 0], 0, torch.where(long_enough[:, 1], 1, 2))
    h = axes.gather(1, first[:, None, None].expand(-1, 1, 2))[:, 0]  # [S, 2]
    h = h / h.norm(dim=-1, keepdim=True)
    origin = torch.cat((pose[:, :2], torch.zeros_like(pose[:, 2:3])), dim=-1)
    return CanonicalFrame(origin, h[:, 0], h[:, 1])


def _apply(scene: Scene, poses: Tensor, frame: CanonicalFrame, inverse: bool) -> Tensor:
    _, plane, anchor, any_plane = _static_info(scene)
    sc = scene.object_scene.to(poses.device)
    c, s = frame.cos.index_select(0, sc), frame.sin.index_select(0, sc)  # [O]
    if not inverse:
        s = -s
    o = frame.origin.index_select(0, sc)
    p = poses[..., :3] - o if not inverse else poses[..., :3]
    x = c * p[..., 0] - s * p[..., 1]
    y = s * p[..., 0] + c * p[..., 1]
    pos = torch.stack((x, y, p[..., 2]), dim=-1)
    if inverse:
        pos = pos + o
    # Half angles from atan2: sqrt((1 +- c) / 2) loses half its digits near c = -1 or 1.
    half = torch.atan2(s, c) / 2
    zero = torch.zeros_like(c)
    qz = torch.stack((half.cos(), zero, zero, half.sin()), dim=-1).expand_as(poses[..., 3:])
    quat = quat_mul(qz, poses[..., 3:])
    out = torch.cat((pos, quat), dim=-1)
    if not any_plane:
        return out
    # Level floors: their world yaw and position say nothing (the plane is the same set), so in
    # the frame they are upright with the first triangle's centroid under the origin. Inverse:
    # kept as given (a floor's world pose is never asked back).
    level = plane.to(poses.device) & (poses[..., 4:6].abs().amax(-1) < LEVEL_TOLERANCE)
    if inverse:
        return torch.where(level[..., None], poses, out)
    a = anchor.to(poses.device)
    floor = torch.cat((-a[:, :2].expand_as(poses[..., :2]), poses[..., 2:3],
                       torch.ones_like(poses[..., 3:4]), torch.zeros_like(poses[..., 4:])), dim=-1)
    return torch.where(level[..., None], floor, out)


def to_frame(scene: Scene, poses: Tensor, frame: CanonicalFrame) -> Tensor:
    """World poses ``float[..., O, 7]`` in the canonical ``frame`` (floors keep theirs)."""
    return _apply(scene, poses, frame, inverse=False)


def from_frame(scene: Scene, poses: Tensor, frame: CanonicalFrame) -> Tensor:
    """Inverse of :func:`to_frame`: canonical poses ``float[..., O, 7]`` back in the world."""
    return _apply(scene, poses, frame, inverse=True)
