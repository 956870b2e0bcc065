"""MLPs and typed encode-process-decode message passing (FIGNet's graph network).

This module knows no physics: it maps a :class:`~fignet_gym.graph.Graph` of feature tensors to one
output vector per mesh node. Edge updates never materialise the concatenation
``[edge, sender, receiver]`` per edge: the first layer of each edge MLP is split by input block, node
latents are projected once per node and then gathered, which is the main saving when there are
many more edges than nodes.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from fignet_gym.graph import Graph


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
        for a, b in zip(sizes[1:-1], sizes[2:]):
            rest += [nn.Linear(a, b), nn.ReLU()]
        rest.append(nn.Linear(sizes[-1], out_size))
        if layer_norm:
            rest.append(nn.LayerNorm(out_size))
        self.rest = nn.Sequential(*rest)

    def forward(self, x: Tensor) -> Tensor:
        return self.rest(self.first(x))

    def forward_pre(self, pre: Tensor) -> Tensor:
        """Finish the MLP from a first-layer pre-activation ``float[..., hidden]``."""
        return self.rest(pre)

    def project(self, x: Tensor, start: int, stop: int, bias: bool = False) -> Tensor:
        """First-layer contribution of input block ``[start, stop)``: ``float[..., stop-start] -> [..., hidden]``."""
        out = x @ self.first.weight[:, start:stop].T
        return out + self.first.bias if bias else out


class ProcessorBlock(nn.Module):
    """One round of typed message passing with residual connections (paper App. C.1.2)."""

    def __init__(self, latent: int, hidden: int, mesh_edges: bool, object_nodes: bool,
                 face_edges: bool, node_edges: bool) -> None:
        super().__init__()
        L = latent
        self.use_mesh, self.use_obj = mesh_edges, object_nodes
        self.use_face, self.use_world = face_edges, node_edges
        n_in = L
        if mesh_edges:
            self.mesh_edge = MLP(3 * L, hidden, L)
            n_in += L
        if object_nodes:
            self.obj_mesh = MLP(3 * L, hidden, L)
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

    @staticmethod
    def _edge_pre(mlp: MLP, e: Tensor, vs: Tensor, vr: Tensor, s: Tensor, r: Tensor, L: int) -> Tensor:
        """First-layer pre-activation of ``[e, v_s, v_r]`` without concatenating per edge."""
        return (mlp.project(e, 0, L, bias=True) + mlp.project(vs, L, 2 * L)[s]
                + mlp.project(vr, 2 * L, 3 * L)[r])

    def forward(self, g: Graph, v: Tensor, o: Tensor, e: dict[str, Tensor]) -> tuple[Tensor, Tensor, dict[str, Tensor]]:
        """Update latents. ``v float[N, L]`` mesh nodes, ``o float[O, L]`` object nodes, ``e`` edge latents by type."""
        L = v.shape[1]
        n = v.shape[0]
        new_e: dict[str, Tensor] = {}
        agg = [v]
        if self.use_mesh:
            s, r = g.mesh_edges.senders, g.mesh_edges.receivers
            m = self.mesh_edge.forward_pre(self._edge_pre(self.mesh_edge, e["mesh"], v, v, s, r, L))
            new_e["mesh"] = e["mesh"] + m
            agg.append(v.new_zeros(n, L).index_add_(0, r, m))
        if self.use_world:
            s, r = g.node_edges.senders, g.node_edges.receivers
            m = self.world_edge.forward_pre(self._edge_pre(self.world_edge, e["world"], v, v, s, r, L))
            new_e["world"] = e["world"] + m
            agg.append(v.new_zeros(n, L).index_add_(0, r, m))
        if self.use_obj:
            node_obj = g.node_object
            # Exactly one object->mesh edge per mesh node, so its "sum" is the edge itself.
            om = self.obj_mesh.forward_pre(self._edge_pre(
                self.obj_mesh, e["obj_mesh"], o, v, node_obj, torch.arange(n, device=v.device), L))
            mo = self.mesh_obj.forward_pre(
                self.mesh_obj.project(e["mesh_obj"], 0, L, bias=True)
                + self.mesh_obj.project(v, L, 2 * L) + self.mesh_obj.project(o, 2 * L, 3 * L)[node_obj])
            new_e["obj_mesh"] = e["obj_mesh"] + om
            new_e["mesh_obj"] = e["mesh_obj"] + mo
            agg.append(om)
            o_agg = o.new_zeros(o.shape).index_add_(0, node_obj, mo)
            o_new = o + self.obj_node(torch.cat((o, o_agg), dim=-1))
        else:
            o_new = o
        if self.use_face:
            fs, fr = g.face_edges.senders, g.face_edges.receivers  # int64[C, 3]
            mlp = self.face_edge
            q = e["face"]  # float[C, 3, L]
            c = q.shape[0]
            # Input layout per edge: [q_1, q_2, q_3, v_s1, v_s2, v_s3, v_r1, v_r2, v_r3].
            pre = mlp.project(q.reshape(c, 3 * L), 0, 3 * L, bias=True)
            for j in range(3):
                pre = pre + mlp.project(v, (3 + j) * L, (4 + j) * L)[fs[:, j]]
                pre = pre + mlp.project(v, (6 + j) * L, (7 + j) * L)[fr[:, j]]
            m = mlp.forward_pre(pre).reshape(c, 3, L)
            new_e["face"] = q + m
            # Each of the three output vectors goes to its own receiver node.
            agg.append(v.new_zeros(n, L).index_add_(0, fr.reshape(-1), m.reshape(-1, L)))
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
            ProcessorBlock(L, hidden, mesh_edges, object_nodes, face_edges, node_edges)
            for _ in range(steps))
        self.decoder = MLP(L, hidden, out_size, layer_norm=False)

    def forward(self, g: Graph) -> Tensor:
        """Per-node outputs ``float[N, out_size]`` for a graph of normalised features."""
        v = self.enc_node(g.node_features)
        o = self.enc_obj(g.object_features) if self.object_nodes else v.new_zeros(0, self.latent)
        e: dict[str, Tensor] = {}
        for name, mlp in self.enc.items():
            feats = g.edge_features(name)
            out = mlp(feats)
            e[name] = out.reshape(-1, 3, self.latent) if name == "face" else out
        for block in self.blocks:
            v, o, e = block(g, v, o, e)
        return self.decoder(v)
