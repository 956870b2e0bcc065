"""Typed graph containers and FIGNet's input features (paper Sec. 3.1.1 and App. C.1.1).

Every feature is relative (differences of positions, never positions), so the model is
translation-equivariant. Each spatial vector ``d`` is followed by its norm ``|d|`` (App. C.2).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from fignet_gym.simulator.collision import FaceContacts
from fignet_gym.simulator.geometry import barycentric
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

    def edge_features(self, name: str) -> Tensor:
        """Features of the edge type ``name`` (mesh, obj_mesh, mesh_obj, face, world)."""
        return {
            "mesh": lambda: self.mesh_edges.features,
            "obj_mesh": lambda: self.obj_mesh_features,
            "mesh_obj": lambda: self.mesh_obj_features,
            "face": lambda: self.face_edges.features,
            "world": lambda: self.node_edges.features,
        }[name]()

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


# Face-edge feature layout: the paper's 34 columns, then each optional group that is switched on
# (4 columns each: a vector and its norm), in this order.
FACE_BASE = 4 * 7 + 6
FACE_EXTRAS = ("next_separation", "contact_lever", "ballistic_separation")


def feature_sizes(history: int, num_props: int = 3, next_separation: bool = False,
                  contact_lever: bool = False, ballistic_separation: bool = False) -> dict[str, int]:
    """Input feature sizes of each graph element for ``history`` velocities."""
    node = 4 * history + num_props + 1 + 4
    face = FACE_BASE + 4 * (int(next_separation) + int(contact_lever) + int(ballistic_separation))
    return {"node": node, "object": node, "mesh": 8, "obj_mesh": 8, "face": face, "world": 4}


def _node_features(pos_hist: Tensor, kin: Tensor, kin_disp: Tensor, props: Tensor) -> Tensor:
    """``[velocities (+norms), props, kinematic flag, next kinematic displacement (+norm)]``.

    ``pos_hist float[H, X, 3]``, ``kin float[X]``, ``kin_disp float[X, 3]`` (zero for dynamic
    points), ``props float[X, P]``.
    """
    vel = pos_hist[1:] - pos_hist[:-1]  # [H-1, X, 3], oldest first
    vel = vel.flip(0).permute(1, 0, 2).reshape(pos_hist.shape[1], -1)  # newest first
    return torch.cat((with_norm(vel), props, kin[:, None], with_norm(kin_disp)), dim=-1)


def face_edge_features(pos: Tensor, faces: Tensor, contacts: FaceContacts, clip: float = 0.0,
                       kin_disp: Tensor | None = None, node_com: Tensor | None = None,
                       node_step: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
    """Face-face hyper-edge features (paper eq. 1) with each face's nodes sorted by distance.

    Args:
        pos: ``float[N, 3]`` current node positions.
        faces: ``int64[F, 3]``.
        contacts: ``C`` directed face pairs with closest points.
        clip: spanning vectors longer than this are shortened (:func:`clip_length`; 0: off).
        kin_disp: ``float[N, 3]`` next-step displacement of kinematic nodes (0 for the others).
            When given, ``[d_rs_next, |d_rs_next|]`` is appended: ``d_rs`` with the sender moved
            by its face's mean next displacement, i.e. the separation a pusher will leave (or the
            overlap it will make) if the receiver stays. The network could combine ``d_rs`` with
            the nodes' displacement features itself, but a contact onset hinges on the sign of
            this millimetre-scale difference, and one feature makes it explicit.
        node_com: ``float[N, 3]`` centre of mass of each node's object. When given,
            ``[l_r, |l_r|]`` is appended: the receiver's closest point relative to its object's
            centre of mass (clipped like the spans), the lever arm of the contact force. The
            torque it makes is one cross product of two features of the same edge, where without
            it the network must assemble the lever from the face spans and the nodes' offsets to
            the centre of mass over several message-passing steps.
        node_step: ``float[N, 3]`` each node's expected displacement over the next step (its
            last velocity plus the gravity prior if dynamic, its known displacement if not).
            When given, ``[d_rs_ball, |d_rs_ball|]`` is appended: ``d_rs`` after both closest
            points move by ``node_step`` interpolated at them (barycentric weights). Whether two
            faces within ``d_c`` touch within the step (an impact) or pass (a near miss) hinges
            on this difference of a separation and a relative velocity at the contact point.

    Returns:
        ``(senders int64[C, 3], receivers int64[C, 3], features float[C, 34 to 46])`` with features
        ``[d_rs, |d_rs|, (d_sj, |d_sj|)_j, (d_rj, |d_rj|)_j, n_s, n_r (, d_rs_next, |d_rs_next|)
        (, l_r, |l_r|) (, d_rs_ball, |d_rs_ball|)]``.
    """
    c = contacts.sender_face.shape[0]
    # Sender and receiver faces as one batch of 2C rows: [senders; receivers].
    nodes = faces.index_select(0, torch.cat((contacts.sender_face, contacts.receiver_face)))
    point = torch.cat((contacts.sender_point, contacts.receiver_point))
    x = pos.index_select(0, nodes.reshape(-1)).view(-1, 3, 3)  # [2C, vertex, 3]
    if node_step is not None:  # interpolated in the original vertex order, before sorting
        moved = (barycentric(x, point)[..., None]
                 * node_step.index_select(0, nodes.reshape(-1)).view(-1, 3, 3)).sum(1)  # [2C, 3]
    # Normal from the original vertex order (outward by the mesh's winding), before sorting.
    n = torch.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], dim=-1)
    n = n / n.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    span = clip_length(x - point[:, None, :], clip)
    order = span.norm(dim=-1).argsort(dim=1, stable=True)
    nodes = torch.gather(nodes, 1, order)
    span = torch.gather(span, 1, order[..., None].expand(-1, -1, 3))
    d_rs = contacts.receiver_point - contacts.sender_point
    # [d_rs, sender spans, receiver spans]: with_norm appends each 3-vector's norm in one pass.
    vecs = with_norm(torch.cat((d_rs, span[:c].reshape(c, 9), span[c:].reshape(c, 9)), dim=-1))
    out = [vecs, n[:c], n[c:]]
    if kin_disp is not None:
        shift = kin_disp.index_select(0, nodes[:c].reshape(-1)).view(c, 3, 3).mean(1)
        out.append(with_norm(d_rs - shift))
    if node_com is not None:
        com_r = node_com.index_select(0, faces[contacts.receiver_face, 0])
        out.append(with_norm(clip_length(contacts.receiver_point - com_r, clip)))
    if node_step is not None:
        out.append(with_norm(d_rs + moved[c:] - moved[:c]))
    return nodes[:c], nodes[c:], torch.cat(out, dim=-1)


def _static_features(scene: Scene, clip: float) -> dict[str, Tensor]:
    """Pose-independent parts of the features, cached in the scene (they never change).

    Keys: ``kin float[N + O]`` kinematic flags of mesh nodes then objects, ``props float[N + O, P]``,
    ``mesh_ref float[E, 4]`` reference mesh edge vectors with norms, ``rel_ref float[N, 4]``
    reference (clipped) node offsets from the centre of mass with norms.
    """
    key = ("graph_static", clip)
    if key not in scene._cache:
        kin_obj = (scene.object_kind != ObjectKind.DYNAMIC).to(scene.ref_vertices.dtype)
        s, r = scene.mesh_edges
        ref = scene.ref_vertices
        scene._cache[key] = {
            "kin": torch.cat((kin_obj[scene.node_object], kin_obj)),
            "props": torch.cat((scene.object_props[scene.node_object], scene.object_props)),
            "mesh_ref": with_norm(ref[s] - ref[r]),
            "rel_ref": with_norm(clip_length(ref - scene.object_com[scene.node_object], clip)),
        }
    return scene._cache[key]


def build_graph(scene: Scene, node_hist: Tensor, com_hist: Tensor, node_next: Tensor,
                com_next: Tensor, contacts: FaceContacts | None,
                node_edges: tuple[Tensor, Tensor] | None = None, clip: float = 0.0,
                next_separation: bool = False, contact_lever: bool = False,
                gravity_step: Tensor | None = None) -> Graph:
    """Assemble all un-normalised input features.

    Args:
        scene: static topology (``N`` nodes, ``O`` objects).
        node_hist: ``float[H, N, 3]`` node positions, oldest first (last = current).
        com_hist: ``float[H, O, 3]`` centre-of-mass positions, oldest first.
        node_next: ``float[N, 3]`` next positions (used for kinematic nodes only).
        com_next: ``float[O, 3]`` next centre-of-mass positions (kinematic objects only).
        contacts: face-face contacts at the current positions (``None``: no face edges).
        node_edges: optional MeshGraphNets-style node-node collision edges ``(senders, receivers)``.
        clip: length (m) above which face spanning vectors and object-mesh offsets are shortened
            (0: the paper's unclipped features).
        next_separation: append the next-step separation to face features
            (:func:`face_edge_features`); contact_lever: the receiver's lever arm, likewise.
        gravity_step: ``float[3]`` gravity prior (m per step^2); when given, the separation after
            a ballistic step is appended to face features likewise (``ballistic_separation``).
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

    empty_i = torch.zeros(0, dtype=torch.long, device=cur.device)
    if contacts is not None:
        step = None
        if gravity_step is not None:
            vel = node_hist[-1] - node_hist[-2] + gravity_step
            step = torch.where(static["kin"][:n, None] > 0, kin_disp[:n], vel)
        fs, fr, ff = face_edge_features(cur, scene.faces, contacts, clip,
                                        kin_disp[:n] if next_separation else None,
                                        node_com if contact_lever else None, step)
    else:
        fs = fr = empty_i.reshape(0, 3)
        ff = cur.new_zeros(0, feature_sizes(1, next_separation=next_separation, contact_lever=contact_lever,
                                            ballistic_separation=gravity_step is not None)["face"])
    if node_edges is not None:
        ns, nr = node_edges
        nf = with_norm(cur[ns] - cur[nr])
    else:
        ns = nr = empty_i
        nf = cur.new_zeros(0, 4)
    return Graph(
        node_features=node_f, object_features=obj_f, node_object=scene.node_object,
        obj_mesh_features=om_f, mesh_obj_features=mo_f,
        mesh_edges=EdgeSet(s, r, mesh_f), face_edges=FaceEdgeSet(fs, fr, ff),
        node_edges=EdgeSet(ns, nr, nf), node_pos=cur,
        node_scene=scene.object_scene.index_select(0, scene.node_object) if scene.num_scenes > 1 else None,
    )
