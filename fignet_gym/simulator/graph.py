"""Typed graph containers and FIGNet's input features (paper Sec. 3.1.1 and App. C.1.1).

Every feature is relative (differences of positions, never positions), so the model is
translation-equivariant. Each spatial vector ``d`` is followed by its norm ``|d|`` (App. C.2).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from fignet_gym.simulator.collision import FaceContacts
from fignet_gym.simulator.scene import ObjectKind, Scene


@dataclass(frozen=True)
class EdgeSet:
    """Directed edges of one type: ``senders``/``receivers`` ``int64[E]``, ``features`` ``float[E, D]``."""

    senders: Tensor
    receivers: Tensor
    features: Tensor


@dataclass(frozen=True)
class FaceEdgeSet:
    """Face-face hyper-edges: ``senders``/``receivers`` ``int64[C, 3]`` node indices, each face's
    nodes sorted by distance to its closest point; ``features`` ``float[C, D]``."""

    senders: Tensor
    receivers: Tensor
    features: Tensor


@dataclass(frozen=True)
class Graph:
    """One (possibly batched) FIGNet input graph.

    Attributes:
        node_features: ``float[N, Dn]`` mesh nodes.
        object_features: ``float[O, Do]`` object nodes (at the centre of mass).
        node_object: ``int64[N]`` object of each mesh node (object-mesh and mesh-object edges).
        obj_mesh_features: ``float[N, De]`` object->mesh edge features (one per mesh node).
        mesh_obj_features: ``float[N, De]`` mesh->object edge features (one per mesh node).
        mesh_edges: mesh edges within objects.
        face_edges: face-face collision hyper-edges.
        node_edges: node-node collision edges (MeshGraphNets baseline), else empty.
        node_pos: ``float[N, 3]`` current node positions: not a feature (the network sees only
            relative ones), the basis of the optional rigid projection of its output.
        node_scene: ``int64[N]`` scene of each node in a batch (sorted), or ``None`` for one
            scene: the network makes its per-scene choices from it, so that a scene's result does
            not depend on the scenes batched with it.
    """

    node_features: Tensor
    object_features: Tensor
    node_object: Tensor
    obj_mesh_features: Tensor
    mesh_obj_features: Tensor
    mesh_edges: EdgeSet
    face_edges: FaceEdgeSet
    node_edges: EdgeSet
    node_pos: Tensor
    node_scene: Tensor | None = None

    @property
    def num_objects(self) -> int:
        """``O``, the number of objects (object nodes, whether or not the network uses them)."""
        return int(self.object_features.shape[0])

    def edge_features(self, name: str) -> Tensor:
        """Features of the edge type ``name`` (mesh, obj_mesh, mesh_obj, face, world)."""
        return {
            "mesh": lambda: self.mesh_edges.features,
            "obj_mesh": lambda: self.obj_mesh_features,
            "mesh_obj": lambda: self.mesh_obj_features,
            "face": lambda: self.face_edges.features,
            "world": lambda: self.node_edges.features,
        }[name]()

    def map_features(self, fn: Callable[[str, Tensor], Tensor]) -> Graph:
        """The same topology with every feature tensor ``x`` of kind ``name`` (node, object,
        obj_mesh, mesh_obj, mesh, face, world) replaced by ``fn(name, x)``; positions and indices
        are kept."""
        return self.with_features(
            node_features=fn("node", self.node_features),
            object_features=fn("object", self.object_features),
            obj_mesh_features=fn("obj_mesh", self.obj_mesh_features),
            mesh_obj_features=fn("mesh_obj", self.mesh_obj_features),
            mesh=fn("mesh", self.mesh_edges.features),
            face=fn("face", self.face_edges.features),
            world=fn("world", self.node_edges.features))

    def with_features(self, **feats: Tensor) -> Graph:
        """The same topology with some feature tensors replaced (used for normalisation)."""
        fields = dict(self.__dict__)
        for key, val in feats.items():
            if key in ("mesh", "face", "world"):
                name = {"mesh": "mesh_edges", "face": "face_edges", "world": "node_edges"}[key]
                fields[name] = type(fields[name])(fields[name].senders, fields[name].receivers, val)
            else:
                fields[key] = val
        return Graph(**fields)


def with_norm(d: Tensor) -> Tensor:
    """Append the norm of each 3-vector: ``float[..., k*3] -> float[..., k*4]`` as ``[d, |d|]`` blocks."""
    d3 = d.reshape(*d.shape[:-1], d.shape[-1] // 3, 3)
    out = torch.cat((d3, d3.norm(dim=-1, keepdim=True)), dim=-1)
    return out.reshape(*d.shape[:-1], d3.shape[-2] * 4)


def clip_length(d: Tensor, max_len: float) -> Tensor:
    """Shorten 3-vectors longer than ``max_len`` to that length (``max_len <= 0``: unchanged).

    ``float[..., 3] -> float[..., 3]``. A floor of two 20 m triangles makes spanning vectors of
    metres next to the centimetre ones of objects; normalised together, the small ones (the
    geometry that matters) would be squashed to nothing. Direction is kept.
    """
    if max_len <= 0:
        return d
    n = d.norm(dim=-1, keepdim=True)
    return d * (max_len / n.clamp_min(max_len))


# The paper's 34 face-edge columns: [d_rs, |d_rs|], the sender's and the receiver's three spans
# with norms, and the two face normals.
FACE_BASE = 4 * 7 + 6


@dataclass(frozen=True)
class FaceEdgeContext:
    """What an optional face-edge feature group is built from (``C`` edges, ``N`` nodes).

    Attributes:
        d_rs: ``float[C, 3]`` receiver closest point minus sender closest point.
        sender_nodes: ``int64[C, 3]`` sender face nodes, sorted by distance to its closest point.
        kin_disp: ``float[N, 3]`` next-step displacement of kinematic nodes (0 for the others).
    """

    d_rs: Tensor
    sender_nodes: Tensor
    kin_disp: Tensor


def _next_separation(ctx: FaceEdgeContext) -> Tensor:
    """``[d_rs_next, |d_rs_next|] float[C, 4]``: ``d_rs`` with the sender moved by its face's mean
    next displacement, i.e. the separation a pusher will leave (or the overlap it will make) if
    the receiver stays. The network could combine ``d_rs`` with the nodes' displacement features
    itself, but a contact onset hinges on the sign of this millimetre-scale difference, and one
    feature makes it explicit."""
    c = ctx.d_rs.shape[0]
    shift = ctx.kin_disp.index_select(0, ctx.sender_nodes.reshape(-1)).view(c, 3, 3).mean(1)
    return with_norm(ctx.d_rs - shift)


@dataclass(frozen=True)
class FaceGroup:
    """An optional group of face-edge feature columns beyond the paper's.

    Attributes:
        name: the group's name, also the boolean ``SimulatorConfig`` field that switches it on.
        size: columns it appends.
        stats_from: first base column whose normaliser statistics the group's columns start from
            when a warm start adds the group (a column of the same scale).
        description: what it is, for model cards.
        build: ``FaceEdgeContext -> float[C, size]``.
    """

    name: str
    size: int
    stats_from: int
    description: str
    build: Callable[[FaceEdgeContext], Tensor]


# Every optional face-edge group, in layout order: the enabled ones follow the base columns.
# Graph building, feature sizes, warm starts and model cards all read this table.
FACE_GROUPS: tuple[FaceGroup, ...] = (
    FaceGroup("next_separation", 4, 0, "next-step separation from kinematic faces", _next_separation),
)


def enabled_face_groups(config: object) -> tuple[FaceGroup, ...]:
    """The groups of :data:`FACE_GROUPS` whose flag is set on ``config`` (a ``SimulatorConfig``)."""
    return tuple(g for g in FACE_GROUPS if getattr(config, g.name))


def feature_sizes(history: int, num_props: int = 3,
                  face_groups: Sequence[FaceGroup] = ()) -> dict[str, int]:
    """Input feature sizes of each graph element for ``history`` velocities."""
    node = 4 * history + num_props + 1 + 4
    face = FACE_BASE + sum(g.size for g in face_groups)
    return {"node": node, "object": node, "mesh": 8, "obj_mesh": 8, "face": face, "world": 4}


def _node_features(pos_hist: Tensor, kin: Tensor, kin_disp: Tensor, props: Tensor) -> Tensor:
    """``[velocities (+norms), props, kinematic flag, next kinematic displacement (+norm)]``.

    ``pos_hist float[H, X, 3]``, ``kin float[X]``, ``kin_disp float[X, 3]`` (zero for dynamic
    points), ``props float[X, P]``.
    """
    vel = pos_hist[1:] - pos_hist[:-1]  # [H-1, X, 3], oldest first
    vel = vel.flip(0).permute(1, 0, 2).reshape(pos_hist.shape[1], -1)  # newest first
    return torch.cat((with_norm(vel), props, kin[:, None], with_norm(kin_disp)), dim=-1)


#: Distances within this fraction of the largest one count as equal in :func:`tie_stable_order`.
TIE_TOLERANCE = 1e-5


def tie_stable_order(dist: Tensor) -> Tensor:
    """``int64[C, 3]`` order of each row of ``dist float[C, 3]`` by increasing distance, with
    distances equal to :data:`TIE_TOLERANCE` (relative) kept in column order. Unlike a plain
    sort, the order of exact geometric ties does not depend on float rounding."""
    tol = TIE_TOLERANCE * dist.amax(dim=1, keepdim=True)[..., None] + 1e-12
    diff = dist[:, None, :] - dist[:, :, None]  # [C, i, j] = d_j - d_i
    idx = torch.arange(dist.shape[1], device=dist.device)
    before = (diff > tol) | ((diff.abs() <= tol) & (idx[:, None] < idx[None, :]))  # i before j
    rank = before.sum(dim=1)  # how many come before j
    return rank.argsort(dim=1, stable=True)


def face_edge_features(pos: Tensor, faces: Tensor, contacts: FaceContacts, kin_disp: Tensor,
                       clip: float = 0.0, face_groups: Sequence[FaceGroup] = (),
                       sort_unclipped: bool = False) -> tuple[Tensor, Tensor, Tensor]:
    """Face-face hyper-edge features (paper eq. 1) with each face's nodes sorted by distance.

    Args:
        pos: ``float[N, 3]`` current node positions.
        faces: ``int64[F, 3]``.
        contacts: ``C`` directed face pairs with closest points.
        kin_disp: ``float[N, 3]`` next-step displacement of kinematic nodes (0 for the others).
        clip: spanning vectors longer than this are shortened (:func:`clip_length`; 0: off).
        face_groups: optional groups (:data:`FACE_GROUPS`) appended after the paper's columns.
        sort_unclipped: sort each face's nodes by their true distance, equal distances (to a
            relative 1e-5) in mesh order (:func:`tie_stable_order`). The clipped spans of a
            large floor triangle all have the clip's length, and regular meshes (a pusher's
            polygon) have nodes at equal distances, so the default sort (kept for the
            checkpoints trained on it) orders them by float rounding, which a turn or a shift
            of the scene changes.

    Returns:
        ``(senders int64[C, 3], receivers int64[C, 3], features float[C, 34 + group sizes])`` with
        features ``[d_rs, |d_rs|, (d_sj, |d_sj|)_j, (d_rj, |d_rj|)_j, n_s, n_r, groups...]``.
    """
    c = contacts.sender_face.shape[0]
    # Sender and receiver faces as one batch of 2C rows: [senders; receivers].
    nodes = faces.index_select(0, torch.cat((contacts.sender_face, contacts.receiver_face)))
    point = torch.cat((contacts.sender_point, contacts.receiver_point))
    x = pos.index_select(0, nodes.reshape(-1)).view(-1, 3, 3)  # [2C, vertex, 3]
    # Normal from the original vertex order (outward by the mesh's winding), before sorting.
    n = torch.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], dim=-1)
    n = n / n.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    raw = x - point[:, None, :]
    span = clip_length(raw, clip)
    if sort_unclipped:
        order = tie_stable_order(raw.norm(dim=-1))
    else:
        order = span.norm(dim=-1).argsort(dim=1, stable=True)
    nodes = torch.gather(nodes, 1, order)
    span = torch.gather(span, 1, order[..., None].expand(-1, -1, 3))
    d_rs = contacts.receiver_point - contacts.sender_point
    # [d_rs, sender spans, receiver spans]: with_norm appends each 3-vector's norm in one pass.
    vecs = with_norm(torch.cat((d_rs, span[:c].reshape(c, 9), span[c:].reshape(c, 9)), dim=-1))
    ctx = FaceEdgeContext(d_rs=d_rs, sender_nodes=nodes[:c], kin_disp=kin_disp)
    out = [vecs, n[:c], n[c:], *(g.build(ctx) for g in face_groups)]
    return nodes[:c], nodes[c:], torch.cat(out, dim=-1)


def _static_features(scene: Scene, clip: float) -> dict[str, Tensor]:
    """Pose-independent parts of the features, memoised on the scene (they never change).

    Keys: ``kin float[N + O]`` kinematic flags of mesh nodes then objects, ``props float[N + O, P]``,
    ``mesh_ref float[E, 4]`` reference mesh edge vectors with norms, ``rel_ref float[N, 4]``
    reference (clipped) node offsets from the centre of mass with norms.
    """

    def build() -> dict[str, Tensor]:
        kin_obj = (scene.object_kind != ObjectKind.DYNAMIC).to(scene.ref_vertices.dtype)
        s, r = scene.mesh_edges
        ref = scene.ref_vertices
        return {
            "kin": torch.cat((kin_obj[scene.node_object], kin_obj)),
            "props": torch.cat((scene.object_props[scene.node_object], scene.object_props)),
            "mesh_ref": with_norm(ref[s] - ref[r]),
            "rel_ref": with_norm(clip_length(ref - scene.object_com[scene.node_object], clip)),
        }

    return scene.cached(("graph_static", clip), build)


def build_graph(scene: Scene, node_hist: Tensor, com_hist: Tensor, node_next: Tensor,
                com_next: Tensor, contacts: FaceContacts, node_edges: tuple[Tensor, Tensor],
                clip: float = 0.0, face_groups: Sequence[FaceGroup] = (),
                sort_unclipped: bool = False) -> Graph:
    """Assemble all un-normalised input features.

    Args:
        scene: static topology (``N`` nodes, ``O`` objects).
        node_hist: ``float[H, N, 3]`` node positions, oldest first (last = current).
        com_hist: ``float[H, O, 3]`` centre-of-mass positions, oldest first.
        node_next: ``float[N, 3]`` next positions (used for kinematic nodes only).
        com_next: ``float[O, 3]`` next centre-of-mass positions (kinematic objects only).
        contacts: face-face contacts at the current positions (none for the node baseline).
        node_edges: MeshGraphNets-style node-node collision edges ``(senders int64[W], receivers
            int64[W])`` (none for FIGNet's face edges).
        clip: length (m) above which face spanning vectors and object-mesh offsets are shortened
            (0: the paper's unclipped features).
        face_groups: optional face-edge feature groups (:data:`FACE_GROUPS`) to append.
        sort_unclipped: see :func:`face_edge_features`.
    """
    static = _static_features(scene, clip)
    n = node_hist.shape[1]
    cur, cur_com = node_hist[-1], com_hist[-1]
    # Mesh and object nodes share one feature layout: one pass over the N + O points.
    hist = torch.cat((node_hist, com_hist), dim=1)
    kin_disp = (torch.cat((node_next, com_next)) - hist[-1]) * static["kin"][:, None]
    all_f = _node_features(hist, static["kin"], kin_disp, static["props"])
    node_f, obj_f = all_f[:n], all_f[n:]

    s, r = scene.mesh_edges
    mesh_f = torch.cat((with_norm(cur.index_select(0, s) - cur.index_select(0, r)), static["mesh_ref"]),
                       dim=-1)
    node_com = cur_com.index_select(0, scene.node_object)
    rel = with_norm(clip_length(cur - node_com, clip))
    # Object->mesh: d = x_sender(object) - x_receiver(node); mesh->object is its negation (the
    # norms stay).
    flip = rel.new_tensor([-1.0, -1.0, -1.0, 1.0])
    om_f = torch.cat((rel * flip, static["rel_ref"] * flip), dim=-1)
    mo_f = torch.cat((rel, static["rel_ref"]), dim=-1)

    fs, fr, ff = face_edge_features(cur, scene.faces, contacts, kin_disp[:n], clip, face_groups,
                                    sort_unclipped)
    ns, nr = node_edges
    nf = with_norm(cur[ns] - cur[nr])
    return Graph(
        node_features=node_f, object_features=obj_f, node_object=scene.node_object,
        obj_mesh_features=om_f, mesh_obj_features=mo_f,
        mesh_edges=EdgeSet(s, r, mesh_f), face_edges=FaceEdgeSet(fs, fr, ff),
        node_edges=EdgeSet(ns, nr, nf), node_pos=cur,
        node_scene=scene.object_scene.index_select(0, scene.node_object) if scene.num_scenes > 1 else None,
    )
