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

The two ways round differently, so the choice is made per scene of a batch (``edges > nodes`` of
that scene), never from batch totals: a scene's result must not depend on the scenes batched with
it (a vector env reproduces single envs, and a contact at the collision radius turns one ulp into
centimetres). For the same reason every matmul gets at least :data:`MIN_ROWS` rows: BLAS computes
narrower products with another kernel, which rounds differently from the same rows inside a larger
product.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from fignet_gym.simulator.graph import Graph

#: Fewest rows a matmul is given (padded with zeros): BLAS computes narrow products with other
#: kernels, whose rounding differs from the same rows inside a larger product, which would make a
#: scene's result depend on its batch. How narrow depends on the CPU: 1-3 rows on an AVX-512 Xeon,
#: up to 15 on an AMX one (experiments/README.md, "Speed": "Batched equals single");
#: tests/test_batching.py checks the margin on the machine it runs on.
MIN_ROWS = 32


#: oneDNN's fused linear runs on products of at least this many rows (below, its per-call cost
#: exceeds the saving), at most this many input columns and a multiple of 16 output columns:
#: there it rounds exactly like MKL's (checked by tests/test_batching.py; it does not for 256
#: inputs or 3 outputs), so a batch that crosses the threshold still reproduces its scenes alone.
FUSED_MIN_ROWS, FUSED_MAX_IN = 4096, 192


def _fused_ok(x: Tensor, w: Tensor) -> bool:
    """Whether oneDNN's fused linear (+ReLU) kernel applies: large float32 or bfloat16 CPU
    inference."""
    return (_ONEDNN and x.shape[0] >= FUSED_MIN_ROWS and x.shape[-1] <= FUSED_MAX_IN
            and w.shape[0] % 16 == 0 and x.device.type == "cpu"
            and x.dtype == w.dtype and x.dtype in _FUSED_DTYPES
            and x.dim() == 2 and not torch.is_grad_enabled()
            and not torch.is_autocast_enabled("cpu"))


_ONEDNN = torch.backends.mkldnn.is_available() and hasattr(torch.ops.mkldnn, "_linear_pointwise")
# oneDNN has no bfloat16 kernel on CPUs without AVX-512 BF16 / AMX (it fails to build one, where
# plain F.linear falls back): the fused path takes bfloat16 only where the CPU has it.
_FUSED_DTYPES = ((torch.float32, torch.bfloat16) if _ONEDNN and torch.ops.mkldnn._is_mkldnn_bf16_supported()
                 else (torch.float32,))


def linear(x: Tensor, w: Tensor, b: Tensor | None = None, relu: bool = False) -> Tensor:
    """``F.linear`` (then ReLU if ``relu``) whose rows round as they would inside any larger batch.

    ``float[M, in] -> float[M, out]``; fewer than :data:`MIN_ROWS` rows are zero-padded. In float32
    CPU inference on many rows it runs oneDNN's linear with the bias and ReLU fused into the matmul
    (the kernel inductor uses): up to twice MKL's rate on these narrow layers, because the output is
    written once instead of three times (bias broadcast, product, ReLU).
    """
    m = x.shape[0]
    pad = 0 < m < MIN_ROWS
    if pad:
        x = F.pad(x, (0, 0, 0, MIN_ROWS - m))
    if _fused_ok(x, w):
        out = torch.ops.mkldnn._linear_pointwise(x.contiguous(), w.contiguous(), b,
                                                 "relu" if relu else "none", [], "")
    else:
        out = F.linear(x, w, b)
        if relu:
            out = out.relu_()
    return out[:m] if pad else out


def addmm(c: Tensor, a: Tensor, b: Tensor) -> Tensor:
    """``c + a @ b`` (``float[M, n]``) with :func:`linear`'s row padding."""
    m = a.shape[0]
    if 0 < m < MIN_ROWS:
        pad = MIN_ROWS - m
        return torch.addmm(F.pad(c, (0, 0, 0, pad)), F.pad(a, (0, 0, 0, pad)), b)[:m]
    return torch.addmm(c, a, b)


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
        return self.forward_pre(linear(x, self.first.weight, self.first.bias))

    def forward_pre(self, pre: Tensor) -> Tensor:
        """Finish the MLP from a first-layer pre-activation ``float[..., hidden]``.

        ``pre`` is consumed: the ReLUs run in place (no extra allocation per layer; autograd is
        unaffected because no linear layer saves its output for backward). Layers are applied
        through the functional API: module calls cost as much as a small layer's arithmetic.
        """
        x = pre
        layers = list(self.rest)
        for i, layer in enumerate(layers):
            if isinstance(layer, nn.Linear):
                relu = i + 1 < len(layers) and isinstance(layers[i + 1], nn.ReLU)
                x = linear(x, layer.weight, layer.bias, relu)
            elif isinstance(layer, nn.LayerNorm):
                x = F.layer_norm(x, layer.normalized_shape, layer.weight, layer.bias, layer.eps)
            elif i == 0 or not isinstance(layers[i - 1], nn.Linear):  # else fused into the linear
                x = x.relu_()
        return x


@dataclass(frozen=True)
class EdgeIndex:
    """How one edge type gathers node latents, derived once per graph for all processor blocks.

    Attributes:
        nodes: ``int64[M, k]`` node of each of the ``k`` node slots of every edge, in the order of
            the MLP input blocks after the edge latent.
        table_rows: ``int64[Mt, k]`` rows ``k * position + slot`` of a ``[U * k, hidden]`` table of
            node projections for the edges of scenes with more edges than nodes, or ``None`` when
            no scene has (every edge gathers latents).
        table_nodes: ``int64[U]`` nodes projected into the table (``None``: all nodes).
        table_edges: ``int64[Mt]`` the edges of ``table_rows`` and ``gather_edges int64[Mg]`` the
            others, when both kinds occur in one batch (``None`` otherwise).
    """

    nodes: Tensor
    table_rows: Tensor | None
    table_nodes: Tensor | None = None
    table_edges: Tensor | None = None
    gather_edges: Tensor | None = None

    @staticmethod
    def build(nodes: Tensor, node_scene: Tensor | None = None, num_scenes: int = 1,
              num_nodes: int | None = None) -> EdgeIndex:
        """``nodes int64[M, k]``, ``node_scene int64[N]`` (sorted; ``None``: one scene of
        ``num_nodes`` nodes). Projecting a scene's nodes pays off only with more edges than nodes."""
        m, k = nodes.shape
        slots = torch.arange(k, device=nodes.device)
        if node_scene is None or num_scenes == 1:
            n = num_nodes if node_scene is None else node_scene.shape[0]
            if m <= n:
                return EdgeIndex(nodes, None)
            return EdgeIndex(nodes, nodes * k + slots)
        edge_scene = node_scene.index_select(0, nodes[:, 0])
        table = (torch.bincount(edge_scene, minlength=num_scenes)
                 > torch.bincount(node_scene, minlength=num_scenes))
        if not bool(table.any()):
            return EdgeIndex(nodes, None)
        if bool(table.all()):
            return EdgeIndex(nodes, nodes * k + slots)
        edge_t = table.index_select(0, edge_scene)
        table_edges, gather_edges = edge_t.nonzero().squeeze(1), (~edge_t).nonzero().squeeze(1)
        table_nodes = table.index_select(0, node_scene).nonzero().squeeze(1)
        position = torch.full_like(node_scene, -1).index_copy_(
            0, table_nodes, torch.arange(table_nodes.shape[0], device=nodes.device))
        rows = position[nodes.index_select(0, table_edges)] * k + slots
        return EdgeIndex(nodes, rows, table_nodes, table_edges, gather_edges)


def _gathered_first_layer(first: nn.Linear, e: Tensor, v: Tensor, nodes: Tensor) -> Tensor:
    """First layer on the concatenation ``[e, v[nodes[:, 0]], ...]``: ``float[M, hidden]``."""
    m, k = nodes.shape
    gathered = v.index_select(0, nodes.reshape(-1)).view(m, k * v.shape[1])
    return linear(torch.cat((e, gathered), dim=1), first.weight, first.bias)


def _table_first_layer(first: nn.Linear, e: Tensor, v: Tensor, rows: Tensor) -> Tensor:
    """First layer from node projections: ``v float[U, L]`` projected through each slot's weight
    block, rows ``int64[M, k]`` of that table summed per edge, plus the edge block on ``e``."""
    w, b = first.weight, first.bias
    k, d = rows.shape[1], e.shape[1]
    h, n, lat = w.shape[0], v.shape[0], v.shape[1]
    # Weight blocks of the k node slots stacked as rows ([k * hidden, L]), so that one matmul
    # projects every node through all of them; the bias rides on slot 0, which each edge
    # gathers exactly once.
    w_nodes = w[:, d:].reshape(h, k, lat).transpose(0, 1).reshape(k * h, lat)
    b_nodes = torch.cat((b, b.new_zeros((k - 1) * h)))
    table = linear(v, w_nodes, b_nodes).view(n * k, h)
    gathered = F.embedding_bag(rows, table, mode="sum")
    return addmm(gathered, e, w[:, :d].T)


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
    if index.table_rows is None:
        return _gathered_first_layer(first, e, v, index.nodes)
    v_t = v if index.table_nodes is None else v.index_select(0, index.table_nodes)
    if index.table_edges is None:
        return _table_first_layer(first, e, v_t, index.table_rows)
    g, t = index.gather_edges, index.table_edges
    pre_g = _gathered_first_layer(first, e.index_select(0, g), v, index.nodes.index_select(0, g))
    pre_t = _table_first_layer(first, e.index_select(0, t), v_t, index.table_rows)
    out = pre_g.new_empty(e.shape[0], first.weight.shape[0])
    return out.index_copy_(0, g, pre_g).index_copy_(0, t, pre_t)


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
        ns = g.node_scene
        s = 1 if ns is None or n == 0 else int(ns[-1]) + 1

        def index(nodes: Tensor) -> EdgeIndex:
            return EdgeIndex.build(nodes, ns, s, n)

        return Topology(
            num_nodes=n, node_object=g.node_object,
            mesh=index(torch.stack((me.senders, me.receivers), dim=1)),
            mesh_receivers=me.receivers,
            world=index(torch.stack((we.senders, we.receivers), dim=1)),
            world_receivers=we.receivers,
            face=index(torch.cat((fe.senders, fe.receivers), dim=1)),
            face_receivers=fe.receivers.reshape(-1),
        )


def _residual(x: Tensor, update: Tensor) -> Tensor:
    """``x + update`` (same shape); in place on ``x`` when no graph is recorded.

    Each block's old latents are dead once its new ones exist, and writing the sum into them
    saves allocating (and faulting in) a fresh buffer the size of every edge set per block.
    Under autograd the old latent is an input that backward still reads, so a new tensor is made.
    """
    if torch.is_grad_enabled() or x.dtype != update.dtype:
        return x + update
    return x.add_(update)


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
        nodes = linear(v, w_v).add_(linear(o, w_o, b_o).index_select(0, node_obj))
        return [addmm(pre, e, m.first.weight[:, :L].T)
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
                new_e["mesh"] = _residual(e["mesh"], m)
            agg.append(_sum_into(n, t.mesh_receivers, m))
        if self.use_world:
            m = self.world_edge.forward_pre(edge_first_layer(self.world_edge.first, e["world"], v, t.world))
            if not final:
                new_e["world"] = _residual(e["world"], m)
            agg.append(_sum_into(n, t.world_receivers, m))
        o_new = o
        if self.use_obj:
            pre = self._object_pre(v, o, e["obj_mesh"], None if final else e["mesh_obj"], t.node_object)
            om = self.obj_mesh.forward_pre(pre[0])
            # Exactly one object->mesh edge per mesh node, so its "sum" is the edge itself.
            agg.append(om)
            if not final:
                mo = self.mesh_obj.forward_pre(pre[1])
                new_e["obj_mesh"] = _residual(e["obj_mesh"], om)
                new_e["mesh_obj"] = _residual(e["mesh_obj"], mo)
                o_agg = _sum_into(o.shape[0], t.node_object, mo)
                o_new = o + self.obj_node(torch.cat((o, o_agg), dim=-1))
        if self.use_face:
            q = e["face"]  # float[C, 3, L]
            c, L = q.shape[0], q.shape[2]
            # Input layout per edge: [q_1, q_2, q_3, v_s1, v_s2, v_s3, v_r1, v_r2, v_r3].
            pre_f = edge_first_layer(self.face_edge.first, q.reshape(c, 3 * L), v, t.face)
            m = self.face_edge.forward_pre(pre_f).view(c, 3, L)
            if not final:
                new_e["face"] = _residual(q, m)
            # Each of the three output vectors goes to its own receiver node.
            agg.append(_sum_into(n, t.face_receivers, m.view(3 * c, L)))
        v_new = _residual(v, self.mesh_node(torch.cat(agg, dim=-1)))
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
