"""Collision edges: directed face pairs of different objects within ``d_c`` (FIGNet), and node
pairs (the MeshGraphNets baseline, :func:`node_collision_edges`).

FIGNet (Sec. 3.1, App. C) connects two faces of different objects by a face-face edge when any
point of one is within the collision radius ``d_c`` of any point of the other, and builds the edge
features from the closest points of the two triangles. This module finds those pairs, with their
closest points, for a whole batch of scenes at once:

* broad phase: per-object boxes (AABBs) prune the candidate object pairs, per-face boxes prune each
  object's faces to those near the partner object, and the face pairs of all surviving object pairs
  are enumerated together with index arithmetic and box-tested;
* narrow phase (:func:`triangle_closest_points`): exact closest points between triangle pairs.

Everything is vectorised torch on the input device: no Python loop over objects, pairs, faces or
contacts, no numpy round trip. Dimension letters are in ``docs/architecture.md``; ``P`` counts
triangle pairs. Meshes are treated as surfaces: a small object wholly inside a large one, farther
than ``d_c`` from all of its faces, has no contact.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

#: Closest-point candidates whose distances differ by less than this many times the rounding of
#: their coordinates (``eps`` times the largest) are ties.
TIE_ROUNDING = 2


@dataclass(frozen=True)
class FaceContacts:
    """Directed face-face contacts (each close unordered pair appears once in each direction).

    Attributes:
        sender_face: ``int64[C]`` index of the sender face.
        receiver_face: ``int64[C]`` index of the receiver face.
        sender_point: ``float[C, 3]`` closest point on the sender face.
        receiver_point: ``float[C, 3]`` closest point on the receiver face.
        distance: ``float[C]`` distance between the two points (0 for intersecting triangles).
    """

    sender_face: Tensor
    receiver_face: Tensor
    sender_point: Tensor
    receiver_point: Tensor
    distance: Tensor

    @property
    def num_contacts(self) -> int:
        return int(self.sender_face.shape[0])


def _candidate_table() -> list[list[int]]:
    """Where the 21 candidates of :func:`triangle_closest_points` put their two points.

    Rows: base vertex and direction of the point on A, then on B; a point is
    ``vertex[base] + coef * direction[dir]`` with vertices ``(A0, A1, A2, B0, B1, B2)`` and
    directions ``(A's edges, B's edges, A's normal, B's normal)``; ``coef`` is 0 for a vertex.
    """
    cols = []
    for s in (0, 1):  # piercing: edge i of the other triangle crosses triangle s
        cols += [(3 * (1 - s) + i,) * 4 for i in range(3)]
    for s in (0, 1):  # vertex v of the other triangle projected on triangle s
        for v in range(3):
            q = 3 * (1 - s) + v
            cols.append((q, 6, q, 0) if s == 0 else (q, 0, q, 7))
    cols += [(i, i, 3 + j, 3 + j) for i in range(3) for j in range(3)]  # edge i of A, j of B
    return [list(row) for row in zip(*cols, strict=True)]


_TABLES: dict[torch.device, Tensor] = {}  # _candidate_table() per device, built once


def _cross(a: Tensor, b: Tensor) -> Tensor:
    """Cross product over dim 0 (coordinates first), broadcasting the other dims."""
    (ax, ay, az), (bx, by, bz) = a.unbind(0), b.unbind(0)
    return torch.stack((ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx))


def _dot(a: Tensor, b: Tensor) -> Tensor:
    """Dot product over dim 0 (coordinates first), broadcasting the other dims."""
    return (a * b).sum(0)


def _dot_outer(a: Tensor, b: Tensor) -> Tensor:
    """Unrolled :func:`_dot` for operands broadcast against each other: no 3x larger temporary."""
    (ax, ay, az), (bx, by, bz) = a.unbind(0), b.unbind(0)
    return (ax * bx).addcmul_(ay, by).addcmul_(az, bz)


@torch.no_grad()
def triangle_closest_points(tri_a: Tensor, tri_b: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Exact closest points between triangle pairs (no autograd graph is recorded).

    Args:
        tri_a: ``float[P, 3, 3]`` vertices of the first triangle of each pair.
        tri_b: ``float[P, 3, 3]`` vertices of the second triangle.

    Returns:
        ``(distance float[P], point_a float[P, 3], point_b float[P, 3])`` with ``point_a`` on
        ``tri_a``, ``point_b`` on ``tri_b`` and ``distance = |point_a - point_b|``. Intersecting
        triangles have distance 0 and ``point_a == point_b``, a point where an edge of one triangle
        pierces the other. Degenerate (segment or point) triangles are handled.

    The result is the best of 21 candidate point pairs, each a pair of points on the two triangles
    (up to rounding), so their minimum is the distance as soon as one is an optimal pair, and one
    always is:

    * 9 edge-edge candidates: the exact closest points of each pair of edges (segments), which
      include the vertex-edge and vertex-vertex cases, and the vertex-face case whenever the face
      point is on the face's boundary (the edge and vertex Voronoi regions of the face);
    * 6 vertex-face candidates for the face's interior region: a vertex projected on the other
      triangle's plane, kept if the projection falls inside;
    * 6 piercing candidates: where an edge crosses the other triangle's plane, kept if inside,
      with distance 0. Disjoint triangles are closest at a vertex-face or an edge-edge pair;
      intersecting ones have an edge piercing the other, or (coplanar, touching) a zero
      edge-edge or vertex-face distance.

    Inside tests need no tolerance: a point that fails one by rounding is on the boundary, where an
    edge candidate reproduces it. Triangles with ``sin`` of an angle below ``16 eps`` skip the face
    candidates: up to rounding they are their edges. Accuracy is about ``eps`` times the triangles'
    coordinates, with two exceptions: for nearly parallel edges (angle below ``sqrt(eps)``) crossing
    inside both, the error is up to ``sqrt(eps)`` times the shorter edge; the plane of a sliver
    (smallest angle ``a``) is only known to about ``eps / sin(a)`` radians.
    """
    dist, point_a, point_b = _closest_points(tri_a.permute(2, 1, 0), tri_b.permute(2, 1, 0))
    return dist, point_a.T.contiguous(), point_b.T.contiguous()


def _closest_points(tri_a: Tensor, tri_b: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """:func:`triangle_closest_points` on ``float[3, 3, P]`` (coordinate, vertex, pair) inputs.

    Returns ``(distance float[P], point_a float[3, P], point_b float[3, P])``.
    """
    finfo, num, inf = torch.finfo(tri_a.dtype), tri_a.shape[2], float("inf")
    # Layout [coordinate, side, vertex, ..., P]: pairs last, so every op runs over contiguous
    # memory with only leading dims broadcast (about 20x faster on CPU than [P, ..., 3]). Side s
    # tests triangle s against the vertices of the other one.
    tris = torch.stack((tri_a, tri_b), 1)  # [3, 2, 3, P]
    edges = tris.roll(-1, 2) - tris  # edge k runs from vertex k to vertex k + 1
    len2 = _dot(edges, edges)  # [2, 3, P]

    # Vertex-face (interior) and piercing. side[., v, k] = (x_v - v_k) . (n x e_k) is |n|^2 times
    # the barycentric weight of vertex k + 2 for the projection of x_v on the plane. (Expanding
    # n x e_k into dot products is cheaper, but its rounding grows as 1/sin^2 of a sliver's angle
    # rather than 1/sin, enough to misplace points inside slivers.)
    pts = tris.flip(1)  # the other triangle's vertices
    rel = pts - tris[:, :, :1]  # [3, 2, vertex, P], from vertex 0 of this triangle
    normal = _cross(edges[:, :, 0], edges[:, :, 1])  # [3, 2, P], unnormalised
    nn = _dot(normal, normal)
    usable = (nn > (16 * finfo.eps) ** 2 * len2[:, 0] * len2[:, 1])[:, None]  # [2, 1, P]
    side = _dot_outer(rel[:, :, :, None], _cross(normal[:, :, None], edges)[:, :, None])
    side[:, :, 1] += nn[:, None]  # (v_0 - v_1) . (n x e_1) = |n|^2; the other two offsets are 0
    height = _dot(rel, normal[:, :, None])  # [2, vertex, P], signed, times |n|
    lift = -height / nn.clamp_min(finfo.tiny)[:, None]  # projection = vertex + lift * normal
    vf_d2 = (height * -lift).masked_fill_(~((side.amin(2) >= 0) & usable), inf)
    h_next = height.roll(-1, 1)
    crosses = height * h_next < 0  # edge i of the other triangle (vertex i to i + 1) crosses
    frac = height / torch.where(crosses, height - h_next, torch.ones_like(height))
    side_q = side + frac[:, :, None] * (side.roll(-1, 1) - side)  # side is affine in x
    pi_d2 = height.new_full((2, 3, num), inf).masked_fill_(
        crosses & (side_q.amin(2) >= 0) & usable, 0.0)

    # Edge-edge: segment closest points by clamped alternating minimisation (Ericson, RTCD 5.1.9).
    # The first parameter comes from the lines' normal equations; taking it on the shorter edge
    # bounds the error for nearly parallel edges, where those equations are ill-conditioned.
    d1, d2 = edges[:, 0, :, None], edges[:, 1, None]  # [3, 3, 1, P], [3, 1, 3, P]
    r = tris[:, 1, None] - tris[:, 0, :, None]  # [3, 3, 3, P], B_j - A_i
    a, e, b = len2[0, :, None], len2[1, None], _dot_outer(d1, d2)
    c1, c2 = _dot_outer(r, d1), _dot_outer(r, d2)
    den = (a * e - b * b).clamp_min(finfo.tiny)
    a, e = a.clamp_min(finfo.tiny), e.clamp_min(finfo.tiny)
    short_a = (a <= e).expand(3, 3, num)
    s = ((c1 * e).sub_(b * c2) / den).clamp_(0, 1)
    u = ((b * c1).sub_(a * c2) / den).clamp_(0, 1)
    u = torch.where(short_a, ((b * s - c2) / e).clamp_(0, 1), u)  # short A: u from s, s from u
    s = ((b * u + c1) / a).clamp_(0, 1)
    u = torch.where(short_a, u, ((b * s - c2) / e).clamp_(0, 1))  # short B: s from u, u from s
    gap = (s * d1).addcmul_(u, d2, value=-1).sub_(r)  # point on A minus point on B
    ee_d2 = gap.square_().sum(0).reshape(9, num)

    # Best candidate, then rebuild its two points from the table. Parallel faces tie many
    # candidates; the first in table order (piercing first) within rounding of the minimum wins
    # (a squared distance d^2 from coordinates of size c rounds by about 2 d c eps), so which one
    # is taken depends on the triangles, not on rounding (which a turned or shifted scene changes).
    all_d2 = torch.cat((pi_d2.reshape(6, num), vf_d2.reshape(6, num), ee_d2))
    low = all_d2.min(0).values
    scale = tris.abs().amax(dim=(0, 1, 2)) * (TIE_ROUNDING * finfo.eps)
    best = (all_d2 <= low + 2 * scale * low.sqrt() + scale.square()).to(torch.uint8).argmax(0)
    zero3 = height.new_zeros(3, num)
    frac, lift = frac.reshape(6, num), lift.reshape(6, num)
    coef_a = torch.cat((frac, lift[:3], zero3, s.reshape(9, num)))  # [21, P]
    coef_b = torch.cat((frac, zero3, lift[3:], u.reshape(9, num)))
    if tri_a.device not in _TABLES:
        _TABLES[tri_a.device] = torch.tensor(_candidate_table(), device=tri_a.device)
    where = _TABLES[tri_a.device].index_select(1, best)  # [4, P]
    vertex = tris.reshape(3, 6, num)
    direction = torch.cat((edges.reshape(3, 6, num), normal), 1)  # [3, 8, P]

    def point(row: int, coef: Tensor) -> Tensor:  # float[3, P]
        base = vertex.gather(1, where[row].expand(3, 1, num))[:, 0]
        step = direction.gather(1, where[row + 1].expand(3, 1, num))[:, 0]
        return base + coef.gather(0, best[None])[0] * step

    point_a, point_b = point(0, coef_a), point(2, coef_b)
    diff = point_a - point_b
    return _dot(diff, diff).sqrt(), point_a, point_b


def no_face_contacts(like: Tensor) -> FaceContacts:
    """Zero contacts, with the device and float dtype of ``like``."""
    idx = torch.zeros(0, dtype=torch.long, device=like.device)
    pts = like.new_zeros(0, 3)
    return FaceContacts(idx, idx.clone(), pts, pts.clone(), like.new_zeros(0))


def _segment_ranges(counts: Tensor) -> tuple[Tensor, Tensor]:
    """Expand ``int64[G]`` group sizes to ``(group int64[M], rank_in_group int64[M])``."""
    group = torch.repeat_interleave(counts)
    first = (counts.cumsum(0) - counts).index_select(0, group)
    return group, torch.arange(group.shape[0], device=counts.device) - first


def _reaches(reach: Tensor, box: Tensor) -> Tensor:
    """``bool[M]``: boxes ``float[6, M]`` (min corner, -max corner) within reach ``float[6, M]``."""
    return (reach - box).amin(0) >= 0


@torch.no_grad()
def find_face_contacts(
    node_pos: Tensor, faces: Tensor, face_object: Tensor, object_pairs: Tensor, radius: float,
) -> FaceContacts:
    """All directed face pairs of candidate object pairs whose triangles are closer than ``radius``.

    Contacts are graph inputs, not differentiable: no autograd graph is recorded. Work and memory
    grow with the number of face pairs whose boxes, grown by ``radius``, overlap.

    Args:
        node_pos: ``float[N, 3]`` world node positions.
        faces: ``int64[F, 3]`` node indices of each triangle.
        face_object: ``int64[F]`` object of each face (faces need not be grouped by object).
        object_pairs: ``int64[K, 2]`` object pairs ``(i, j)``, ``i < j``, that may collide (the
            caller decides which: typically same scene, at least one dynamic). Only these pairs
            produce contacts.
        radius: the collision radius ``d_c`` (m); pairs with distance ``< radius`` are kept.

    Returns:
        :class:`FaceContacts`: each close face pair ``(a, b)`` appears as ``a -> b`` and ``b -> a``
        (the first ``C / 2`` contacts have their sender on the side of ``object_pairs[:, 0]``).
    """
    if object_pairs.shape[0] == 0 or faces.shape[0] == 0:
        return no_face_contacts(node_pos)
    # Coordinates first (triangles [9, F], boxes [6, F]): gathers and reductions then run over
    # contiguous memory; 2-D index_select and amin beat fancy indexing, 3-D gathers and all()
    # several times on CPU.
    tri = node_pos.T.index_select(1, faces.T.flatten()).view(9, -1)  # [(coordinate, vertex), F]
    lo, hi = tri.view(3, 3, -1).amin(1), tri.view(3, 3, -1).amax(1)  # [3, F]
    box = torch.cat((lo, -hi))  # [6, F]: a box b reaches c if reach(c) - box(b) >= 0 everywhere
    reach = torch.cat((hi, -lo)) + radius
    n_obj = max(int(face_object.max()), int(object_pairs.max())) + 1
    obj_box = box.new_full((6, n_obj), float("inf")).scatter_reduce_(
        1, face_object.expand(6, -1), box, "amin")
    obj_reach = torch.cat((-obj_box[3:], -obj_box[:3])) + radius
    near = _reaches(obj_reach.index_select(1, object_pairs[:, 1]),
                    obj_box.index_select(1, object_pairs[:, 0]))
    pairs = object_pairs.index_select(0, near.nonzero().squeeze(1))  # [K', 2]
    n_pairs = pairs.shape[0]
    if n_pairs == 0:
        return no_face_contacts(node_pos)

    # Faces of each object near its partner's box. Entry e < K' stands for the first object of
    # pair e against the second's box, entry K' + e for the reverse.
    order = torch.argsort(face_object, stable=True)
    count = torch.bincount(face_object, minlength=n_obj)
    own, partner = pairs.T.reshape(-1), pairs.flip(1).T.reshape(-1)
    entry, rank = _segment_ranges(count.index_select(0, own))
    first = (count.cumsum(0) - count).index_select(0, own).index_select(0, entry)
    face = order.index_select(0, first + rank)
    hit = _reaches(obj_reach.index_select(1, partner.index_select(0, entry)),
                   box.index_select(1, face))
    entry, face = entry.masked_select(hit), face.masked_select(hit)  # still sorted by entry
    n_first = int((entry < n_pairs).sum())
    pair_a, face_a = entry[:n_first], face[:n_first]
    pair_b, face_b = entry[n_first:] - n_pairs, face[n_first:]

    # Every such face of the first object against every one of the second, box-tested.
    count_b = torch.bincount(pair_b, minlength=n_pairs)
    ia, rank = _segment_ranges(count_b.index_select(0, pair_a))
    fa = face_a.index_select(0, ia)
    first = (count_b.cumsum(0) - count_b).index_select(0, pair_a.index_select(0, ia))
    fb = face_b.index_select(0, first + rank)
    close = _reaches(reach.index_select(1, fb), box.index_select(1, fa)).nonzero().squeeze(1)
    fa, fb = fa.index_select(0, close), fb.index_select(0, close)

    dist, pa, pb = _closest_points(tri.index_select(1, fa).view(3, 3, -1),
                                   tri.index_select(1, fb).view(3, 3, -1))
    close = (dist < radius).nonzero().squeeze(1)
    fa, fb, dist = fa.index_select(0, close), fb.index_select(0, close), dist.index_select(0, close)
    pa, pb = pa.index_select(1, close), pb.index_select(1, close)
    return FaceContacts(
        sender_face=torch.cat((fa, fb)),
        receiver_face=torch.cat((fb, fa)),
        sender_point=torch.cat((pa, pb), 1).T.contiguous(),
        receiver_point=torch.cat((pb, pa), 1).T.contiguous(),
        distance=torch.cat((dist, dist)),
    )


@torch.no_grad()
def node_collision_edges(node_pos: Tensor, node_object: Tensor, object_pairs: Tensor, radius: float
                         ) -> tuple[Tensor, Tensor]:
    """MeshGraphNets "world edges": node pairs of candidate object pairs closer than ``radius``.

    The collision edges of the node-based baseline (``SimulatorConfig.collision = "node"``).
    Vectorised over all node pairs of every candidate object pair (fine for the baselines' scene
    sizes; no broad phase).

    Args:
        node_pos: ``float[N, 3]`` world node positions.
        node_object: ``int64[N]`` object of each node; nodes are contiguous per object.
        object_pairs: ``int64[K, 2]`` object pairs that may collide (as in :func:`find_face_contacts`).
        radius: pairs with distance ``< radius`` are kept.

    Returns:
        ``(senders int64[W], receivers int64[W])``, each close pair in both directions.
    """
    pairs = object_pairs
    if pairs.shape[0] == 0:
        return no_node_edges(node_pos)
    n_obj = max(int(node_object.max()), int(pairs.max())) + 1
    counts = torch.bincount(node_object, minlength=n_obj)
    starts = torch.cumsum(counts, 0) - counts
    ca, cb = counts[pairs[:, 0]], counts[pairs[:, 1]]
    per_pair = ca * cb
    pair_id = torch.repeat_interleave(torch.arange(pairs.shape[0], device=node_pos.device), per_pair)
    offset = torch.arange(int(per_pair.sum()), device=node_pos.device) - torch.repeat_interleave(
        torch.cumsum(per_pair, 0) - per_pair, per_pair)
    a = starts[pairs[pair_id, 0]] + offset // cb[pair_id]
    b = starts[pairs[pair_id, 1]] + offset % cb[pair_id]
    close = ((node_pos[a] - node_pos[b]) ** 2).sum(-1) < radius**2
    a, b = a[close], b[close]
    return torch.cat((a, b)), torch.cat((b, a))


def no_node_edges(like: Tensor) -> tuple[Tensor, Tensor]:
    """Zero node-node edges ``(int64[0], int64[0])`` on the device of ``like``."""
    empty = torch.zeros(0, dtype=torch.long, device=like.device)
    return empty, empty.clone()
