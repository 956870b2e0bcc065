"""Face-face collision detection: directed face pairs of different objects within ``d_c``.

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
    """Where the 39 candidates of :func:`triangle_closest_points` put their two points.

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
    for s in (0, 1):  # vertex v of the other triangle against edge k of triangle s
        for v in range(3):
            for k in range(3):
                q, e = 3 * (1 - s) + v, 3 * s + k
                cols.append((e, e, q, 0) if s == 0 else (q, 0, e, e))
    cols += [(i, i, 3 + j, 3 + j) for i in range(3) for j in range(3)]  # edge i of A, j of B
    return [list(row) for row in zip(*cols, strict=True)]


_TABLES: dict[torch.device, Tensor] = {}


def _cross(a: Tensor, b: Tensor) -> Tensor:
    """Cross product over dim 0 (coordinates first), broadcasting the other dims."""
    return torch.stack((a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                        a[0] * b[1] - a[1] * b[0]))


def _dot(a: Tensor, b: Tensor) -> Tensor:
    """Dot product over dim 0 (coordinates first)."""
    return (a * b).sum(0)


def triangle_closest_points(tri_a: Tensor, tri_b: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Exact closest points between triangle pairs.

    Args:
        tri_a: ``float[P, 3, 3]`` vertices of the first triangle of each pair.
        tri_b: ``float[P, 3, 3]`` vertices of the second triangle.

    Returns:
        ``(distance float[P], point_a float[P, 3], point_b float[P, 3])`` with ``point_a`` on
        ``tri_a``, ``point_b`` on ``tri_b`` and ``distance = |point_a - point_b|``. Intersecting
        triangles have distance 0 and ``point_a == point_b``, a point where an edge of one triangle
        pierces the other. Degenerate (segment or point) triangles are handled.

    The result is the best of 39 candidate point pairs, each a pair of points on the two triangles
    (up to rounding), so the minimum is the distance if one candidate is optimal, and one is:

    * 18 vertex-edge candidates (a vertex against an edge of the other triangle) and 9 edge-edge
      candidates (closest points of the two lines, clamped to the segments): together, the exact
      distance between every pair of edges. They also cover the vertex-face case whenever the face
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
    finfo, num, inf = torch.finfo(tri_a.dtype), tri_a.shape[0], float("inf")
    # Layout [coordinate, side, vertex, ..., P]: pairs last, so every op runs over contiguous
    # memory with only leading dims broadcast (about 20x faster on CPU than [P, ..., 3]). Side s
    # tests triangle s against the vertices and edges of the other one.
    tris = torch.stack((tri_a, tri_b)).permute(3, 0, 2, 1).contiguous()  # [3, 2, 3, P]
    pts = tris.flip(1)  # the other triangle's vertices
    edges = tris.roll(-1, 2) - tris  # edge k runs from vertex k to vertex k + 1
    len2 = _dot(edges, edges)  # [2, 3, P]

    # Vertex-edge: each vertex of the other triangle against each edge of this one.
    rel = pts[:, :, :, None] - tris[:, :, None]  # [3, 2, vertex, edge, P]
    t = (_dot(rel, edges[:, :, None]) / len2[:, None].clamp_min(finfo.tiny)).clamp_(0, 1)
    ve_gap = rel - t * edges[:, :, None]
    ve_d2 = _dot(ve_gap, ve_gap).reshape(18, num)

    # Vertex-face (interior) and piercing. side[.., k, :] = (x - v_k) . (n x e_k) is |n|^2 times
    # the barycentric weight of vertex k + 2 of x's projection on the plane.
    normal = _cross(edges[:, :, 0], edges[:, :, 1])  # [3, 2, P], unnormalised
    nn = _dot(normal, normal)
    usable = (nn > (16 * finfo.eps) ** 2 * len2[:, 0] * len2[:, 1])[:, None]  # [2, 1, P]
    side = _dot(rel, _cross(normal[:, :, None], edges)[:, :, None])  # [2, vertex, edge, P]
    height = _dot(rel[:, :, :, 0], normal[:, :, None])  # [2, vertex, P], signed, times |n|
    lift = -height / nn.clamp_min(finfo.tiny)[:, None]  # projection = vertex + lift * normal
    vf_d2 = torch.where((side.amin(2) >= 0) & usable, height * -lift, inf).reshape(6, num)
    h_next = height.roll(-1, 1)
    crosses = height * h_next < 0  # edge i of the other triangle (vertex i to i + 1) crosses
    frac = height / torch.where(crosses, height - h_next, torch.ones_like(height))
    side_q = side + frac[:, :, None] * (side.roll(-1, 1) - side)  # side is affine in x
    pi_ok = crosses & (side_q.amin(2) >= 0) & usable
    pi_d2 = torch.where(pi_ok, 0.0, inf).to(tri_a.dtype).reshape(6, num)

    # Edge-edge: closest points of the supporting lines (normal equations), clamped.
    d1, d2 = edges[:, 0, :, None], edges[:, 1, None]  # [3, 3, 1, P], [3, 1, 3, P]
    r = tris[:, 1, None] - tris[:, 0, :, None]  # [3, 3, 3, P], B_j - A_i
    a, e, b = len2[0, :, None], len2[1, None], _dot(d1, d2)
    c1, c2 = _dot(r, d1), _dot(r, d2)
    den = (a * e - b * b).clamp_min(finfo.tiny)
    s = ((c1 * e - b * c2) / den).clamp_(0, 1)  # [3, 3, P]
    u = ((b * c1 - a * c2) / den).clamp_(0, 1)
    ee_gap = s * d1 - u * d2 - r  # point on A minus point on B
    ee_d2 = _dot(ee_gap, ee_gap).reshape(9, num)

    # Best candidate (piercing first on ties), then rebuild its two points from the table.
    best = torch.cat((pi_d2, vf_d2, ve_d2, ee_d2)).min(0).indices  # [P]
    zero3, zero9 = height.new_zeros(3, num), height.new_zeros(9, num)
    frac, lift, t = frac.reshape(6, num), lift.reshape(6, num), t.reshape(18, num)
    coef_a = torch.cat((frac, lift[:3], zero3, t[:9], zero9, s.reshape(9, num)))  # [39, P]
    coef_b = torch.cat((frac, zero3, lift[3:], zero9, t[9:], u.reshape(9, num)))
    if tri_a.device not in _TABLES:
        _TABLES[tri_a.device] = torch.tensor(_candidate_table(), device=tri_a.device)
    where = _TABLES[tri_a.device][:, best]  # [4, P]
    vertex = tris.reshape(3, 6, num)
    direction = torch.cat((edges.reshape(3, 6, num), normal), 1)  # [3, 8, P]

    def point(row: int, coef: Tensor) -> Tensor:  # float[3, P]
        base = vertex.gather(1, where[row].expand(3, 1, num))[:, 0]
        step = direction.gather(1, where[row + 1].expand(3, 1, num))[:, 0]
        return base + coef.gather(0, best[None])[0] * step

    point_a, point_b = point(0, coef_a), point(2, coef_b)
    return (point_a - point_b).norm(dim=0), point_a.T, point_b.T


def _empty_contacts(like: Tensor) -> FaceContacts:
    idx = torch.zeros(0, dtype=torch.long, device=like.device)
    pts = like.new_zeros(0, 3)
    return FaceContacts(idx, idx.clone(), pts, pts.clone(), like.new_zeros(0))


def _segment_ranges(counts: Tensor) -> tuple[Tensor, Tensor]:
    """Expand ``int64[G]`` group sizes to ``(group int64[M], rank_in_group int64[M])``."""
    group = torch.repeat_interleave(counts)
    first = counts.cumsum(0) - counts
    return group, torch.arange(group.shape[0], device=counts.device) - first[group]


def find_face_contacts(
    node_pos: Tensor, faces: Tensor, face_object: Tensor, object_pairs: Tensor, radius: float,
) -> FaceContacts:
    """All directed face pairs of candidate object pairs whose triangles are closer than ``radius``.

    Args:
        node_pos: ``float[N, 3]`` world node positions.
        faces: ``int64[F, 3]`` node indices of each triangle.
        face_object: ``int64[F]`` object of each face.
        object_pairs: ``int64[K, 2]`` object pairs that may collide (the caller decides which:
            typically same scene, at least one dynamic). Only these pairs produce contacts.
        radius: the collision radius ``d_c`` (m); pairs with distance ``< radius`` are kept.

    Returns:
        :class:`FaceContacts`: each close face pair ``(a, b)`` appears as ``a -> b`` and ``b -> a``
        (the first ``C / 2`` contacts have their sender on ``object_pairs[:, 0]``'s side).
    """
    if object_pairs.shape[0] == 0 or faces.shape[0] == 0:
        return _empty_contacts(node_pos)
    tri = node_pos[faces]  # [F, 3, 3]
    lo, hi = tri.amin(1), tri.amax(1)  # [F, 3] face boxes
    # A hair of slack keeps the box tests conservative against rounding of the exact distance.
    reach = radius + 4 * torch.finfo(node_pos.dtype).eps * (radius + node_pos.abs().max())
    n_obj = int(torch.maximum(face_object.max(), object_pairs.max())) + 1

    # Object boxes in one reduction: [min corner, -max corner].
    face_box = torch.cat((lo, -hi), 1)  # [F, 6]
    obj_box = face_box.new_full((n_obj, 6), float("inf")).scatter_reduce_(
        0, face_object[:, None].expand(-1, 6), face_box, "amin")
    # A box b "reaches" box c if b.lo <= c.hi + reach and -b.hi <= -c.lo + reach on every axis.
    obj_reach = torch.cat((-obj_box[:, 3:], -obj_box[:, :3]), 1) + reach  # [hi + r, -lo + r]
    i, j = object_pairs[:, 0], object_pairs[:, 1]
    near = (obj_box[i] <= obj_reach[j]).all(1) & (obj_box[j] <= obj_reach[i]).all(1)
    pairs = object_pairs[near]  # [K', 2]
    n_pairs = pairs.shape[0]
    if n_pairs == 0:
        return _empty_contacts(node_pos)

    # Faces of each object, grouped; entry e < K' stands for (pair e, first object vs the second's
    # box), entry K' + e for the reverse.
    order = torch.argsort(face_object, stable=True)
    count = torch.bincount(face_object, minlength=n_obj)
    start = count.cumsum(0) - count
    own = torch.cat((pairs[:, 0], pairs[:, 1]))
    partner = torch.cat((pairs[:, 1], pairs[:, 0]))
    entry, rank = _segment_ranges(count[own])
    face = order[start[own][entry] + rank]
    hit = (face_box[face] <= obj_reach[partner[entry]]).all(1)
    entry, face = entry[hit], face[hit]  # still sorted by entry, so side 0 comes first
    n_first = int((entry < n_pairs).sum())
    pair_a, face_a = entry[:n_first], face[:n_first]
    pair_b, face_b = entry[n_first:] - n_pairs, face[n_first:]

    # Every face of side 0 against every face of side 1 of the same pair.
    count_b = torch.bincount(pair_b, minlength=n_pairs)
    start_b = count_b.cumsum(0) - count_b
    ia, rank = _segment_ranges(count_b[pair_a])
    fa = face_a[ia]
    fb = face_b[start_b[pair_a[ia]] + rank]
    face_reach = torch.cat((hi, -lo), 1) + reach
    close = (face_box[fa] <= face_reach[fb]).all(1)
    fa, fb = fa[close], fb[close]

    dist, pa, pb = triangle_closest_points(tri[fa], tri[fb])
    close = dist < radius
    fa, fb, dist, pa, pb = fa[close], fb[close], dist[close], pa[close], pb[close]
    return FaceContacts(
        sender_face=torch.cat((fa, fb)),
        receiver_face=torch.cat((fb, fa)),
        sender_point=torch.cat((pa, pb)),
        receiver_point=torch.cat((pb, pa)),
        distance=torch.cat((dist, dist)),
    )
