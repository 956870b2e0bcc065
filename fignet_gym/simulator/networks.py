"""MLPs and typed encode-process-decode message passing (FIGNet's graph network).

This module knows no physics: it maps a :class:`~fignet_gym.simulator.graph.Graph` of feature tensors to one
output vector per mesh node.

Edge updates are written for speed on CPU without changing the parameters (checkpoints keep
loading) or the function computed (up to float rounding). The first layer of an edge MLP is linear
in its concatenated input ``[edge, node_1, ..., node_k]``, so it can be evaluated in either of two
ways, whichever needs fewer multiply-adds (:func:`edge_first_layer`):

* gather the ``k`` node latents of every edge, concatenate and apply the layer (``M`` edges cost
  ``M * k`` rows of node input), or
* project every node once through all ``k`` weight blocks as one matmul, then sum the ``k``
  projected rows of each edge with one ``embedding_bag`` (``N * k`` rows): better once there are
  more edges than nodes (mesh edges), never materialising the per-edge concatenation.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from fignet_gym.simulator.graph import Graph


class MLP(nn.Module):
    """``num_hidden`` hidden layers of ReLU, a linear output and optionally a LayerNorm.

    ``float[..., in_size] -> float[..., out_size]``.
    """

    def __init__(self, in_size: int, hidden: int, out_size: int, num_hidden: int = 2,
                 layer_norm: bool = True) -> None:
        super().__init__()
        sizes = [in_size] + [hidden] * num_hidden
        self.first = nn.Linear(sizes[0], sizes[1])
        rest: list[nn.Module] = [nn.ReLU()]
        for a, b in zip(sizes[1:-1], sizes[2:], strict=True):
            rest += [nn.Linear(a, b), nn.ReLU()]
        rest.append(nn.Linear(sizes[-1], out_size))
        if layer_norm:
            rest.append(nn.LayerNorm(out_size))
        self.rest = nn.Sequential(*rest)

    def forward(self, x: Tensor) -> Tensor:
        return self.forward_pre(F.linear(x, self.first.weight, self.first.bias))

    def forward_pre(self, pre: Tensor) -> Tensor:
        """Finish the MLP from a first-layer pre-activation ``float[..., hidden]``.

        ``pre`` is consumed: the ReLUs run in place (no extra allocation per layer; autograd is
        unaffected because no linear layer saves its output for backward). Layers are applied
        through the functional API: module calls cost as much as a small layer's arithmetic.
        The LayerNorm runs in the parameters' precision even under bfloat16 autocast, so that
        latents and their residual sums stay float32 and only matmul inputs are rounded.
        """
        x = pre
        for layer in self.rest:
            if isinstance(layer, nn.Linear):
                x = F.linear(x, layer.weight, layer.bias)
            elif isinstance(layer, nn.LayerNorm):
                x = F.layer_norm(x.to(layer.weight.dtype), layer.normalized_shape, layer.weight,
                                 layer.bias, layer.eps)
            else:
                x = x.relu_()
        return x


@dataclass(frozen=True)
class EdgeIndex:
    """How one edge type gathers node latents, derived once per graph for all processor blocks.

    Attributes:
        nodes: ``int64[M, k]`` node of each of the ``k`` node slots of every edge, in the order of
            the MLP input blocks after the edge latent.
        table_rows: ``int64[M, k]`` rows ``k * node + slot`` of a ``[N * k, hidden]`` table of
            node projections, or ``None`` when gathering latents is cheaper (``M <= N``).
    """

    nodes: Tensor
    table_rows: Tensor | None

    @staticmethod
    def build(nodes: Tensor, num_nodes: int) -> EdgeIndex:
        """``nodes int64[M, k]``; projecting all ``N`` nodes pays off only with more edges than nodes."""
        k = nodes.shape[1]
        if nodes.shape[0] <= num_nodes:
            return EdgeIndex(nodes, None)
        return EdgeIndex(nodes, nodes * k + torch.arange(k, device=nodes.device))


def edge_first_layer(first: nn.Linear, e: Tensor, v: Tensor, index: EdgeIndex) -> Tensor:
    """First layer of an edge MLP on ``[e, v[nodes[:, 0]], ..., v[nodes[:, k-1]]]``.

    Args:
        first: the layer, ``weight float[hidden, D + k * L]``.
        e: ``float[M, D]`` edge latents.
        v: ``float[N, L]`` node latents.
        index: the edges' node slots.

    Returns:
        ``float[M, hidden]`` pre-activations.
    """
    m, k = index.nodes.shape
    w, b = first.weight, first.bias
    d = e.shape[1]
    if index.table_rows is None:
        gathered = v.index_select(0, index.nodes.reshape(-1)).view(m, k * v.shape[1])
        return F.linear(torch.cat((e, gathered), dim=1), w, b)
    h, n, lat = w.shape[0], v.shape[0], v.shape[1]
    # Weight blocks of the k node slots stacked as rows ([k * hidden, L]), so that one matmul
    # projects every node through all of them; the bias rides on slot 0, which each edge
    # gathers exactly once.
    w_nodes = w[:, d:].reshape(h, k, lat).transpose(0, 1).reshape(k * h, lat)
    b_nodes = torch.cat((b, b.new_zeros((k - 1) * h)))
    table = F.linear(v, w_nodes, b_nodes).view(n * k, h)
    gathered = F.embedding_bag(index.table_rows, table, mode="sum")
    return torch.addmm(gathered, e, w[:, :d].T)


@dataclass(frozen=True)
class Topology:
    """Index tensors of a graph shared by every processor block (built once per forward).

    Attributes:
        num_nodes: ``N``.
        node_object: ``int64[N]`` object of each mesh node.
        mesh: mesh edges ``[sender, receiver]``; ``mesh_receivers int64[E]``.
        world: node-node collision edges, likewise.
        face: face-face hyper-edges ``[s_1, s_2, s_3, r_1, r_2, r_3]``; ``face_receivers int64[3C]``
            the receiver node of each of the ``3C`` output vectors.
    """

    num_nodes: int
    node_object: Tensor
    mesh: EdgeIndex
    mesh_receivers: Tensor
    world: EdgeIndex
    world_receivers: Tensor
    face: EdgeIndex
    face_receivers: Tensor

    @staticmethod
    def of(g: Graph) -> Topology:
        """The index tensors of ``g``."""
        n = g.node_features.shape[0]
        me, we, fe = g.mesh_edges, g.node_edges, g.face_edges
        return Topology(
            num_nodes=n, node_object=g.node_object,
            mesh=EdgeIndex.build(torch.stack((me.senders, me.receivers), dim=1), n),
            mesh_receivers=me.receivers,
            world=EdgeIndex.build(torch.stack((we.senders, we.receivers), dim=1), n),
            world_receivers=we.receivers,
            face=EdgeIndex.build(torch.cat((fe.senders, fe.receivers), dim=1), n),
            face_receivers=fe.receivers.reshape(-1),
        )


def _sum_into(n: int, receivers: Tensor, messages: Tensor) -> Tensor:
    """Sum ``messages float[M, L]`` per receiver: ``float[n, L]`` in the messages' dtype."""
    return messages.new_zeros(n, messages.shape[1]).index_add_(0, receivers, messages)


class ProcessorBlock(nn.Module):
    """One round of typed message passing with residual connections (paper App. C.1.2)."""

    def __init__(self, latent: int, hidden: int, mesh_edges: bool, object_nodes: bool,
                 face_edges: bool, node_edges: bool, final: bool = False) -> None:
        super().__init__()
        L = latent
        self.use_mesh, self.use_obj, self.final = mesh_edges, object_nodes, final
        self.use_face, self.use_world = face_edges, node_edges
        n_in = L
        if mesh_edges:
            self.mesh_edge = MLP(3 * L, hidden, L)
            n_in += L
        if object_nodes:
            self.obj_mesh = MLP(3 * L, hidden, L)
            if not final:  # the last block's object nodes would never reach the decoder
                self.mesh_obj = MLP(3 * L, hidden, L)
                self.obj_node = MLP(2 * L, hidden, L)
            n_in += L
        if face_edges:
            # All nine input latents [q_j, v_sj, v_rj]_{j=1..3} feed all three outputs (eq. 4).
            self.face_edge = MLP(9 * L, hidden, 3 * L)
            n_in += L
        if node_edges:
            self.world_edge = MLP(3 * L, hidden, L)
            n_in += L
        self.mesh_node = MLP(n_in, hidden, L)

    def _object_pre(self, v: Tensor, o: Tensor, e_om: Tensor, e_mo: Tensor | None, node_obj: Tensor
                    ) -> list[Tensor]:
        """First-layer pre-activations ``float[N, hidden]`` of the object->mesh MLP on
        ``[e_om, o[node_obj], v]`` and (unless ``e_mo`` is ``None``) of the mesh->object MLP on
        ``[e_mo, v, o[node_obj]]``.

        The node blocks of both MLPs take two matmuls: mesh nodes through the stacked mesh-node
        weights, objects (``O`` rows, few) through the stacked object weights, then gathered.
        """
        L = v.shape[1]
        # (MLP, edge latents, column of its mesh-node block, column of its object block)
        parts = [(self.obj_mesh, e_om, 2 * L, L)]
        if e_mo is not None:
            parts.append((self.mesh_obj, e_mo, L, 2 * L))
        w_v = torch.cat([m.first.weight[:, a:a + L] for m, _, a, _ in parts])  # [k * hidden, L]
        w_o = torch.cat([m.first.weight[:, b:b + L] for m, _, _, b in parts])
        b_o = torch.cat([m.first.bias for m, _, _, _ in parts])
        nodes = F.linear(v, w_v).add_(F.linear(o, w_o, b_o).index_select(0, node_obj))
        return [torch.addmm(pre, e, m.first.weight[:, :L].T)
                for pre, (m, e, _, _) in zip(nodes.chunk(len(parts), dim=1), parts, strict=True)]

    def forward(self, t: Topology, v: Tensor, o: Tensor, e: dict[str, Tensor]
                ) -> tuple[Tensor, Tensor, dict[str, Tensor]]:
        """Update latents: ``v float[N, L]`` mesh nodes, ``o float[O, L]`` object nodes, ``e`` edge
        latents by type (``float[E, L]``; faces ``float[C, 3, L]``).

        In the ``final`` block only the new ``v`` is used (the decoder reads mesh nodes only), so
        edge latents are not updated (an empty dict is returned), nor are object nodes (``o`` is
        returned), which also skips the mesh->object messages; that block has no weights for them.
        """
        n, final = t.num_nodes, self.final
        new_e: dict[str, Tensor] = {}
        agg = [v]
        if self.use_mesh:
            m = self.mesh_edge.forward_pre(edge_first_layer(self.mesh_edge.first, e["mesh"], v, t.mesh))
            if not final:
                new_e["mesh"] = e["mesh"] + m
            agg.append(_sum_into(n, t.mesh_receivers, m))
        if self.use_world:
            m = self.world_edge.forward_pre(edge_first_layer(self.world_edge.first, e["world"], v, t.world))
            if not final:
                new_e["world"] = e["world"] + m
            agg.append(_sum_into(n, t.world_receivers, m))
        o_new = o
        if self.use_obj:
            pre = self._object_pre(v, o, e["obj_mesh"], None if final else e["mesh_obj"], t.node_object)
            om = self.obj_mesh.forward_pre(pre[0])
            # Exactly one object->mesh edge per mesh node, so its "sum" is the edge itself.
            agg.append(om)
            if not final:
                mo = self.mesh_obj.forward_pre(pre[1])
                new_e["obj_mesh"] = e["obj_mesh"] + om
                new_e["mesh_obj"] = e["mesh_obj"] + mo
                o_agg = _sum_into(o.shape[0], t.node_object, mo)
                o_new = o + self.obj_node(torch.cat((o, o_agg), dim=-1))
        if self.use_face:
            q = e["face"]  # float[C, 3, L]
            c, L = q.shape[0], q.shape[2]
            # Input layout per edge: [q_1, q_2, q_3, v_s1, v_s2, v_s3, v_r1, v_r2, v_r3].
            pre_f = edge_first_layer(self.face_edge.first, q.reshape(c, 3 * L), v, t.face)
            m = self.face_edge.forward_pre(pre_f).view(c, 3, L)
            if not final:
                new_e["face"] = q + m
            # Each of the three output vectors goes to its own receiver node.
            agg.append(_sum_into(n, t.face_receivers, m.view(3 * c, L)))
        v_new = v + self.mesh_node(torch.cat(agg, dim=-1))
        return v_new, o_new, new_e


class EncodeProcessDecode(nn.Module):
    """FIGNet's graph network: typed encoders, ``steps`` unshared processor blocks, a node decoder."""

    def __init__(self, feature_sizes: dict[str, int], latent: int = 128, hidden: int = 128,
                 steps: int = 10, out_size: int = 3, mesh_edges: bool = True,
                 object_nodes: bool = True, face_edges: bool = True, node_edges: bool = False) -> None:
        super().__init__()
        L = latent
        self.latent = L
        self.enc_node = MLP(feature_sizes["node"], hidden, L)
        self.enc = nn.ModuleDict()
        if mesh_edges:
            self.enc["mesh"] = MLP(feature_sizes["mesh"], hidden, L)
        if object_nodes:
            self.enc_obj = MLP(feature_sizes["object"], hidden, L)
            self.enc["obj_mesh"] = MLP(feature_sizes["obj_mesh"], hidden, L)
            self.enc["mesh_obj"] = MLP(feature_sizes["obj_mesh"], hidden, L)
        if face_edges:
            self.enc["face"] = MLP(feature_sizes["face"], hidden, 3 * L)
        if node_edges:
            self.enc["world"] = MLP(feature_sizes["world"], hidden, L)
        self.object_nodes = object_nodes
        self.blocks = nn.ModuleList(
            ProcessorBlock(L, hidden, mesh_edges, object_nodes, face_edges, node_edges,
                           final=i == steps - 1)
            for i in range(steps))
        self.decoder = MLP(L, hidden, out_size, layer_norm=False)

    def forward(self, g: Graph) -> Tensor:
        """Per-node outputs ``float[N, out_size]`` for a graph of normalised features."""
        v = self.enc_node(g.node_features)
        o = self.enc_obj(g.object_features) if self.object_nodes else v.new_zeros(0, self.latent)
        e: dict[str, Tensor] = {}
        for name, mlp in self.enc.items():
            out = mlp(g.edge_features(name))
            e[name] = out.view(-1, 3, self.latent) if name == "face" else out
        topology = Topology.of(g)
        for block in self.blocks:
            v, o, e = block(topology, v, o, e)
        return self.decoder(v)
