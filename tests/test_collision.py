"""Tests of face-face collision detection against an independent oracle, FCL and brute force."""

from __future__ import annotations

import itertools

import fcl
import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation
from torch import Tensor

from fignet_gym.simulator.collision import FaceContacts, find_face_contacts, triangle_closest_points

# Faces of a triangle as vertex subsets: 3 vertices, 3 edges, the interior.
_SUBSETS = [(0,), (1,), (2,), (0, 1), (1, 2), (0, 2), (0, 1, 2)]


def oracle_distance(a: np.ndarray, b: np.ndarray, tol: float = 1e-10) -> np.ndarray:
    """Triangle distances ``float64[P]`` by enumerating face pairs (vertex, edge, interior of each).

    Independent of the implementation: for every pair of faces, the least-squares (pseudo-inverse)
    closest points of their affine hulls are kept when their barycentric coordinates are feasible.
    At a vertex of the (convex) set of optimal pairs that restricted problem has a unique solution,
    so the minimum over feasible face pairs is the exact distance, degenerate triangles included.
    """
    best = np.full(a.shape[0], np.inf)
    for sa, sb in itertools.product(_SUBSETS, _SUBSETS):
        da = a[:, sa[1:]] - a[:, sa[:1]]  # [P, ka, 3]
        db = b[:, sb[1:]] - b[:, sb[:1]]
        mat = np.concatenate((da, -db), 1).transpose(0, 2, 1)  # [P, 3, ka + kb]
        rhs = b[:, sb[0]] - a[:, sa[0]]
        if mat.shape[2]:
            x = (np.linalg.pinv(mat) @ rhs[:, :, None])[:, :, 0]
            resid = mat @ x[:, :, None] - rhs[:, :, None]
        else:
            x, resid = np.zeros((a.shape[0], 0)), -rhs[:, :, None]
        xa, xb = x[:, : len(sa) - 1], x[:, len(sa) - 1:]
        ok = ((xa >= -tol).all(1) & (xa.sum(1) <= 1 + tol) & (xb >= -tol).all(1)
              & (xb.sum(1) <= 1 + tol))
        best = np.where(ok, np.minimum(best, np.linalg.norm(resid[:, :, 0], axis=1)), best)
    return best


def random_pairs(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` triangle pairs of each hard kind: ``float64[P, 3, 3]`` twice."""
    def rand(*shape: int) -> np.ndarray:
        return rng.uniform(-1, 1, size=shape)

    def in_plane(tri: np.ndarray, count: int) -> np.ndarray:  # random points in each tri's plane
        w = rng.uniform(-1, 2, size=(tri.shape[0], count, 3))
        w[..., 2] = 1 - w[..., :2].sum(-1)  # affine weights, bounded
        return np.einsum("pkv,pvc->pkc", w, tri)

    def normal(tri: np.ndarray) -> np.ndarray:
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        return nrm / np.linalg.norm(nrm, axis=1, keepdims=True)

    kinds = []
    a = rand(n, 3, 3)
    kinds.append((a, rand(n, 3, 3)))  # general: about half intersect
    kinds.append((a, rand(n, 3, 3) + rand(n, 1, 3) * 2.5))  # mostly separated
    h = rng.uniform(0, 0.3, size=(n, 1, 1))
    kinds.append((a, in_plane(a, 3) + h * normal(a)[:, None]))  # parallel (h = 0: coplanar)
    kinds.append((a, in_plane(a, 3)))  # coplanar
    b = rand(n, 3, 3)
    b[:, 0] = a[np.arange(n), rng.integers(0, 3, n)]
    kinds.append((a, b))  # shared vertex
    b = rand(n, 3, 3)
    b[:, :2] = a[:, [1, 0]]
    kinds.append((a, b))  # shared edge
    b = rand(n, 3, 3)
    b[:, 0] = np.einsum("pv,pvc->pc", rng.dirichlet(np.ones(3), n), a)
    kinds.append((a, b))  # a vertex of b touches a's face
    centre = np.einsum("pv,pvc->pc", rng.dirichlet(np.ones(3), n), a)
    c = rand(n, 3, 3)
    c -= c.mean(1, keepdims=True)
    kinds.append((a, centre[:, None] + c))  # intersecting: b's centroid lies on a
    rot = Rotation.from_rotvec(rand(n, 3) * 1e-4).as_matrix()
    kinds.append((a, a @ rot.transpose(0, 2, 1) + rand(n, 1, 3) * 0.05))  # nearly parallel edges
    deg = rand(n, 3, 3)
    lam = rng.uniform(-1, 2, size=(n, 1))
    deg[: n // 3, 2] = deg[: n // 3, 0] + lam[: n // 3] * (deg[: n // 3, 1] - deg[: n // 3, 0])
    deg[n // 3: 2 * n // 3, 1:] = deg[n // 3: 2 * n // 3, :1]  # points
    deg[2 * n // 3:, 1] = deg[2 * n // 3:, 0]  # two equal vertices
    kinds.append((a, deg))
    kinds.append((deg, deg[rng.permutation(n)] * 0.5))  # degenerate against degenerate
    return np.concatenate([k[0] for k in kinds]), np.concatenate([k[1] for k in kinds])


def point_to_triangle(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    return oracle_distance(np.repeat(p[:, None], 3, 1), tri)


@pytest.fixture(scope="module")
def pairs() -> tuple[np.ndarray, np.ndarray]:
    """The hard kinds at random scales (1 mm to 10 m) and offsets (to 5 m): ``float64[P, 3, 3]``."""
    rng = np.random.default_rng(0)
    a, b = random_pairs(rng, 400)
    scale = 10 ** rng.uniform(-3, 1, size=(len(a), 1, 1))
    offset = rng.uniform(-5, 5, size=(len(a), 1, 3))
    return a * scale + offset, b * scale + offset


def coordinate_scale(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.maximum(np.abs(a).max((1, 2)), np.abs(b).max((1, 2)))


def test_triangle_closest_points_matches_oracle_float64(pairs):
    a, b = pairs
    dist, pa, pb = (x.numpy() for x in triangle_closest_points(torch.tensor(a), torch.tensor(b)))
    ref, tol = oracle_distance(a, b), 1e-12 * coordinate_scale(a, b)  # measured: 2e-14
    assert np.isfinite(dist).all() and np.isfinite(pa).all() and np.isfinite(pb).all()
    assert (np.abs(dist - ref) < tol).all()
    assert (np.abs(np.linalg.norm(pa - pb, axis=1) - dist) < tol).all()
    assert (point_to_triangle(pa, a) < tol).all() and (point_to_triangle(pb, b) < tol).all()
    assert (dist == 0).sum() > 1000  # the intersecting, touching and coplanar kinds were exercised


def test_triangle_closest_points_float32(pairs):
    a, b = (torch.tensor(x, dtype=torch.float32) for x in pairs)
    dist, pa, pb = triangle_closest_points(a, b)
    assert dist.dtype == pa.dtype == torch.float32
    a, b = a.double().numpy(), b.double().numpy()  # the same rounded inputs for the oracle
    ref, tol = oracle_distance(a, b), 2e-6 * coordinate_scale(a, b)  # measured: 6e-7
    assert (np.abs(dist.numpy() - ref) < tol).all()
    assert (point_to_triangle(pa.double().numpy(), a) < tol).all()
    assert (point_to_triangle(pb.double().numpy(), b) < tol).all()


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_mm_features_in_metre_scene(dtype):
    """Faces of a 4.75 mm tip near a 13 mm thick object and a 40 m floor, 0.5 m from the origin."""
    rng = np.random.default_rng(1)
    n = 2000
    offset = np.array([0.45, -0.3, 0.0065])
    small = offset + rng.uniform(-0.005, 0.005, size=(n, 3, 3))
    other = offset + rng.uniform(-0.005, 0.005, size=(n, 3, 3)) + rng.uniform(0, 0.004, (n, 1, 3))
    floor = np.array([[-20.0, -20.0, 0.0], [20.0, -20.0, 0.0], [20.0, 20.0, 0.0]])
    tilted = np.broadcast_to(floor, (n, 3, 3)) @ Rotation.from_rotvec(
        rng.normal(size=(n, 3)) * 1e-3).as_matrix()
    # A 1 cm edge nearly parallel to (1e-7 to 1e-2 rad) and just above the floor's diagonal,
    # crossing it, its third vertex off the floor: only edge-edge candidates find the distance.
    angle = 10 ** rng.uniform(-7, -2, n) * rng.choice([-1, 1], n)
    centre = np.stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(0, 0.002, n)], 1)
    centre[:, 1] = centre[:, 0]  # on the diagonal x = y
    half = np.stack([np.cos(angle + np.pi / 4), np.sin(angle + np.pi / 4), np.zeros(n)], 1) * 0.005
    off_floor = centre + np.array([-0.004, 0.004, 0.001])  # on the side of the missing triangle
    crossing = np.stack([centre - half, centre + half, off_floor], 1)
    a = np.concatenate((small, small, crossing))
    b = np.concatenate((other, tilted, np.broadcast_to(floor, (n, 3, 3))))
    ta, tb = torch.tensor(a, dtype=dtype), torch.tensor(b, dtype=dtype)
    dist, pa, pb = triangle_closest_points(ta, tb)
    ref = oracle_distance(ta.double().numpy(), tb.double().numpy())  # same rounded inputs
    # float32: a few ulps of the floor's 20 m coordinates (1 ulp = 1.9 um); float64: sqrt(eps)
    # times the 1 cm edge for nearly parallel crossing edges (see triangle_closest_points).
    tol = 3e-6 if dtype == torch.float32 else 1e-9
    np.testing.assert_allclose(dist.double().numpy(), ref, atol=tol)
    assert np.abs(dist.double().numpy() - ref)[:n].max() < tol / 10  # small vs small: no floor
    assert point_to_triangle(pa.double().numpy(), ta.double().numpy()).max() < tol
    assert point_to_triangle(pb.double().numpy(), tb.double().numpy()).max() < tol


def test_hand_computed_cases():
    tri = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=torch.float64)
    cases = torch.stack([
        tri + torch.tensor([0.1, 0.1, 0.1], dtype=torch.float64),  # parallel, 0.1 above
        torch.tensor([[0.2, 0.2, -0.5], [0.2, 0.2, 0.5], [0.9, 0.9, 0.5]]),  # pierces at (.2,.2,0)
        torch.tensor([[0.5, -1, 0.3], [0.5, 1, 0.3], [0.5, 0, 2]]),  # edge crosses above edge
        torch.tensor([[2.0, 2, 0], [3, 2, 0], [2, 3, 0]]),  # coplanar, vertex vs edge
        torch.tensor([[0.3, 0.3, 0.0], [0.3, 0.3, 0.0], [0.3, 0.3, 0.0]]),  # point on the face
    ]).double()
    dist, pa, pb = triangle_closest_points(tri.expand(5, 3, 3), cases)
    expect_d = torch.tensor([0.1, 0.0, 0.3, 1.5 * 2**0.5, 0.0], dtype=torch.float64)
    torch.testing.assert_close(dist, expect_d)
    torch.testing.assert_close(pb[0] - pa[0], torch.tensor([0, 0, 0.1], dtype=torch.float64))
    assert 0 <= pa[0, 0] and 0 <= pa[0, 1] and pa[0, 0] + pa[0, 1] <= 0.9 + 1e-12
    torch.testing.assert_close(pa[1], torch.tensor([0.2, 0.2, 0.0], dtype=torch.float64))
    torch.testing.assert_close(pb[1], pa[1], rtol=0, atol=0)
    torch.testing.assert_close(pa[2], torch.tensor([0.5, 0.0, 0.0], dtype=torch.float64))
    torch.testing.assert_close(pb[2], torch.tensor([0.5, 0.0, 0.3], dtype=torch.float64))
    torch.testing.assert_close(pa[3], torch.tensor([0.5, 0.5, 0.0], dtype=torch.float64))
    torch.testing.assert_close(pb[3], torch.tensor([2.0, 2.0, 0.0], dtype=torch.float64))


# ----------------------------------------------------------------------- whole meshes


def random_meshes(rng: np.random.Generator) -> list[trimesh.Trimesh]:
    hull = trimesh.convex.convex_hull(rng.normal(size=(20, 3)) * [0.3, 0.2, 0.1])
    return [trimesh.creation.icosphere(1, radius=0.2), trimesh.creation.box((0.3, 0.2, 0.1)),
            trimesh.creation.cylinder(0.05, 0.3, sections=12), hull]


def posed(mesh: trimesh.Trimesh, rng: np.random.Generator, spread: float) -> np.ndarray:
    return mesh.vertices @ Rotation.random(random_state=rng).as_matrix().T + rng.uniform(
        -spread, spread, 3)


def scene_tensors(verts: list[np.ndarray], faces: list[np.ndarray], dtype=torch.float64):
    offs = np.cumsum([0] + [len(v) for v in verts[:-1]])
    node_pos = torch.tensor(np.concatenate(verts), dtype=dtype)
    tri_idx = torch.tensor(np.concatenate([f + o for f, o in zip(faces, offs, strict=True)]))
    face_obj = torch.cat([torch.full((len(f),), i, dtype=torch.long) for i, f in enumerate(faces)])
    return node_pos, tri_idx, face_obj


def fcl_distance(va: np.ndarray, fa: np.ndarray, vb: np.ndarray, fb: np.ndarray) -> float:
    objs = []
    for v, f in ((va, fa), (vb, fb)):
        bvh = fcl.BVHModel()
        bvh.beginModel(len(v), len(f))
        bvh.addSubModel(v, f)
        bvh.endModel()
        objs.append(fcl.CollisionObject(bvh, fcl.Transform()))
    return fcl.distance(objs[0], objs[1], fcl.DistanceRequest(enable_nearest_points=True),
                        fcl.DistanceResult())


def test_mesh_distance_matches_fcl():
    rng = np.random.default_rng(2)
    radius, checked_near, checked_far = 0.05, 0, 0
    for trial in range(80):
        meshes = random_meshes(rng)
        ma, mb = meshes[trial % 4], meshes[(trial // 4) % 4]
        va, vb = posed(ma, rng, 0.0), posed(mb, rng, 0.0)
        # Slide b along a random direction until it is just around the radius from a.
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        vb = vb + direction * (np.ptp(va, 0).max() + np.ptp(vb, 0).max())
        gap = fcl_distance(va, ma.faces, vb, mb.faces)
        vb = vb - direction * (gap - rng.uniform(-0.02, 0.08))
        d_fcl = max(fcl_distance(va, ma.faces, vb, mb.faces), 0.0)
        pos, tri, obj = scene_tensors([va, vb], [ma.faces, mb.faces])
        got = find_face_contacts(pos, tri, obj, torch.tensor([[0, 1]]), radius)
        if d_fcl < radius - 1e-9:
            assert got.num_contacts > 0
            assert abs(got.distance.min().item() - d_fcl) < 1e-9
            checked_near += 1
        elif d_fcl > radius + 1e-9:
            assert got.num_contacts == 0
            checked_far += 1
    assert checked_near > 20 and checked_far > 10


def brute_force(pos: Tensor, tri: Tensor, obj: Tensor, obj_pairs: Tensor, radius: float) -> set:
    fa, fb = torch.meshgrid(torch.arange(len(tri)), torch.arange(len(tri)), indexing="ij")
    fa, fb = fa.flatten(), fb.flatten()
    allowed = torch.zeros(int(obj.max()) + 1, int(obj.max()) + 1, dtype=torch.bool)
    allowed[obj_pairs[:, 0], obj_pairs[:, 1]] = True
    allowed |= allowed.clone().T
    fa, fb = fa[allowed[obj[fa], obj[fb]]], fb[allowed[obj[fa], obj[fb]]]
    dist, _, _ = triangle_closest_points(pos[tri[fa]], pos[tri[fb]])
    keep = dist < radius
    return set(zip(fa[keep].tolist(), fb[keep].tolist(), strict=True))


def random_scene(rng: np.random.Generator, dtype=torch.float64):
    meshes = random_meshes(rng)
    picks = [meshes[k] for k in rng.integers(0, 4, 6)]
    verts = [posed(m, rng, 0.25) for m in picks]
    floor = trimesh.Trimesh([[-20, -20, -0.2], [20, -20, -0.2], [20, 20, -0.2], [-20, 20, -0.2]],
                            [[0, 1, 2], [0, 2, 3]], process=False)
    pos, tri, obj = scene_tensors(verts + [floor.vertices], [m.faces for m in picks]
                                  + [floor.faces], dtype)
    perm = torch.tensor(rng.permutation(len(tri)))  # faces need not be grouped by object
    pairs = torch.triu_indices(7, 7, 1).T
    pairs = pairs[torch.tensor(rng.random(len(pairs)) < 0.8)]  # only some pairs are candidates
    return pos, tri[perm], obj[perm], pairs


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_complete_and_well_formed(dtype):
    rng = np.random.default_rng(3)
    total = 0
    for _ in range(4):
        pos, tri, obj, obj_pairs = random_scene(rng, dtype)
        radius = 0.05
        got = find_face_contacts(pos, tri, obj, obj_pairs, radius)
        assert isinstance(got, FaceContacts)
        assert got.sender_point.dtype == got.distance.dtype == dtype
        found = list(zip(got.sender_face.tolist(), got.receiver_face.tolist(), strict=True))
        assert len(found) == len(set(found))
        assert set(found) == brute_force(pos, tri, obj, obj_pairs, radius)
        total += len(found)
        # Both directions, with points and distances swapped consistently.
        half = got.num_contacts // 2
        assert torch.equal(got.sender_face[:half], got.receiver_face[half:])
        assert torch.equal(got.sender_point[:half], got.receiver_point[half:])
        assert torch.equal(got.distance[:half], got.distance[half:])
        # Only candidate object pairs, never one object with itself.
        os_, or_ = obj[got.sender_face], obj[got.receiver_face]
        assert (os_ != or_).all()
        lo, hi = torch.minimum(os_, or_), torch.maximum(os_, or_)
        allowed = set(map(tuple, obj_pairs.tolist()))
        assert set(zip(lo.tolist(), hi.tolist(), strict=True)) <= allowed
        # Reported distances are those of the reported points, below the radius.
        gap = (got.sender_point - got.receiver_point).norm(dim=1)
        torch.testing.assert_close(gap, got.distance)
        assert (got.distance < radius).all()
    assert total > 200


def test_penetrating_meshes_produce_contacts():
    box = trimesh.creation.box((0.2, 0.2, 0.2))
    pos, tri, obj = scene_tensors([box.vertices, box.vertices + [0.15, 0.05, 0.02]],
                                  [box.faces, box.faces])
    got = find_face_contacts(pos, tri, obj, torch.tensor([[0, 1]]), 0.001)
    assert got.num_contacts > 0 and (got.distance == 0).any()
    inter = got.distance == 0
    torch.testing.assert_close(got.sender_point[inter], got.receiver_point[inter])


def test_empty_and_far_inputs():
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    pos, tri, obj = scene_tensors([box.vertices, box.vertices + 1.0], [box.faces, box.faces],
                                  torch.float32)
    # An L-shaped object whose box holds a small cube that no face comes near.
    bar_x, bar_y = trimesh.creation.box((1, 0.1, 0.1)), trimesh.creation.box((0.1, 1, 0.1))
    shifted = [bar_x.vertices + [0.45, 0, 0], bar_y.vertices + [0, 0.45, 0],
               box.vertices + [0.6, 0.6, 0]]
    l_pos, l_tri, l_obj = scene_tensors(shifted, [bar_x.faces, bar_y.faces, box.faces],
                                        torch.float32)
    l_obj = torch.where(l_obj == 2, 1, 0)
    cases = [(pos, tri, obj, torch.zeros(0, 2, dtype=torch.long)),
             (pos, tri, obj, torch.tensor([[0, 1]])), (l_pos, l_tri, l_obj, torch.tensor([[0, 1]]))]
    for args in cases:
        got = find_face_contacts(*args, 0.05)
        assert got.num_contacts == 0
        assert got.sender_point.shape == (0, 3) and got.sender_point.dtype == torch.float32
        assert got.sender_face.dtype == torch.long and got.distance.shape == (0,)


def test_node_collision_edges_match_brute_force() -> None:
    from fignet_gym.simulator.collision import node_collision_edges

    gen = torch.Generator().manual_seed(3)
    counts = [5, 7, 4, 6]
    node_object = torch.repeat_interleave(torch.arange(4), torch.tensor(counts))
    pos = torch.rand(sum(counts), 3, generator=gen, dtype=torch.float64)
    pairs = torch.tensor([[0, 1], [0, 3], [2, 3]])  # objects 1 and 2 may not collide
    radius = 0.35
    s, r = node_collision_edges(pos, node_object, pairs, radius)
    got = sorted(zip(s.tolist(), r.tolist(), strict=True))
    allowed = {tuple(p) for p in pairs.tolist()}
    expect = sorted((a, b) for a in range(len(pos)) for b in range(len(pos))
                    if tuple(sorted((int(node_object[a]), int(node_object[b])))) in allowed
                    and float((pos[a] - pos[b]).norm()) < radius)
    assert got == expect and len(expect) > 4
    empty = node_collision_edges(pos, node_object, pairs[:0], radius)
    assert empty[0].numel() == 0 and empty[1].numel() == 0
