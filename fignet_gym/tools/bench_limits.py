"""How far the learned step is from the machine's own limit, and rollout throughput as users meet it.

Used by ``fignet-gym bench shipped`` and ``bench rollout``:

* :func:`network_flops` counts the graph network's multiply-adds analytically, block by block (each
  MLP's matmuls over the rows it runs on, with the first-layer route each edge type takes);
* :func:`matmul_rate` times plain ``torch.mm`` on exactly those shapes, the rate this machine
  reaches on them (the limit the network is measured against);
* :func:`time_rollouts` times ``Dynamics.rollout`` of the learned dynamics against
  ``mujoco.rollout`` (one thread and all threads), in scene-steps per second.
"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Iterator
from typing import Any

import mujoco
import numpy as np
import torch
from torch import nn

from fignet_gym.dynamics import STATE_SPEC, FIGNetDynamics, MujocoDynamics
from fignet_gym.simulator.model import LearnedSimulator
from fignet_gym.simulator.networks import MIN_ROWS, MLP, EdgeIndex, EncodeProcessDecode, Topology
from fignet_gym.simulator.scene import Scene

Shape = tuple[int, int, int]  # (rows, in, out) of one matmul


def _mlp_shapes(mlp: MLP, rows: int, first: bool = True) -> Iterator[Shape]:
    """Matmuls of ``mlp`` over ``rows`` rows (``first=False``: its first layer is counted apart)."""
    layers = [mlp.first] if first else []
    layers += [m for m in mlp.rest if isinstance(m, nn.Linear)]
    for lin in layers:
        yield rows, lin.in_features, lin.out_features


def _edge_first(mlp: MLP, index: EdgeIndex, edge_in: int, latent: int) -> Iterator[Shape]:
    """First layer of an edge MLP by the route :func:`networks.edge_first_layer` takes."""
    m, k = index.nodes.shape
    h = mlp.first.out_features
    if index.table_rows is None:
        yield m, edge_in + k * latent, h
        return
    mt = index.table_rows.shape[0]
    u = index.table_nodes.shape[0] if index.table_nodes is not None else None
    if index.gather_edges is not None:
        yield index.gather_edges.shape[0], edge_in + k * latent, h
    yield (u if u is not None else -1), latent, k * h  # -1: all nodes (filled in by caller)
    yield mt, edge_in, h


def network_flops(sim: LearnedSimulator, scene: Scene, history: torch.Tensor
                  ) -> tuple[dict[str, float], list[Shape]]:
    """Analytic FLOPs (2 per multiply-add) of the graph network in one step of ``scene``.

    ``history float[H, O, 7]``. Returns ``({block: FLOPs}, [(rows, in, out) of every matmul]})``;
    blocks are ``encoders``, ``block 0`` .. ``block P-1`` and ``decoder``. Elementwise work
    (LayerNorm, ReLU, residual sums, gathers, scatters) is not counted.
    """
    net: EncodeProcessDecode = sim.net
    inputs = sim.build_inputs(scene, history, history[-1])
    g = inputs.graph
    t = Topology.of(g)
    n, o, L = g.node_features.shape[0], g.object_features.shape[0], net.latent
    rows = {"mesh": g.mesh_edges.features.shape[0], "obj_mesh": n, "mesh_obj": n,
            "face": g.face_edges.features.shape[0], "world": g.node_edges.features.shape[0]}
    blocks: dict[str, list[Shape]] = {"encoders": list(_mlp_shapes(net.enc_node, n))}
    if net.object_nodes:
        blocks["encoders"] += list(_mlp_shapes(net.enc_obj, o))
    for name, mlp in net.enc.items():
        blocks["encoders"] += list(_mlp_shapes(mlp, rows[name]))
    for i, blk in enumerate(net.blocks):
        shapes: list[Shape] = []
        edges = [("mesh", blk.use_mesh, "mesh_edge", t.mesh, L),
                 ("world", blk.use_world, "world_edge", t.world, L),
                 ("face", blk.use_face, "face_edge", t.face, 3 * L)]
        for _, used, attr, index, edge_in in edges:
            if not used:
                continue
            mlp = getattr(blk, attr)
            shapes += [(n if r == -1 else r, a, b) for r, a, b in _edge_first(mlp, index, edge_in, L)]
            shapes += list(_mlp_shapes(mlp, index.nodes.shape[0], first=False))
        if blk.use_obj:
            pairs = [blk.obj_mesh] + ([] if blk.final else [blk.mesh_obj])
            h = blk.obj_mesh.first.out_features
            shapes += [(n, L, len(pairs) * h), (o, L, len(pairs) * h)]  # node and object blocks
            for mlp in pairs:
                shapes.append((n, L, h))  # edge block
                shapes += list(_mlp_shapes(mlp, n, first=False))
            if not blk.final:
                shapes += list(_mlp_shapes(blk.obj_node, o))
        shapes += list(_mlp_shapes(blk.mesh_node, n))
        blocks[f"block {i}"] = shapes
    blocks["decoder"] = list(_mlp_shapes(net.decoder, n))
    # Products narrower than MIN_ROWS run padded (networks.linear): count what is executed.
    blocks = {k: [(max(r, MIN_ROWS) if r > 0 else 0, a, b) for r, a, b in v] for k, v in blocks.items()}
    flops = {k: float(sum(2 * r * a * b for r, a, b in v)) for k, v in blocks.items()}
    return flops, [s for v in blocks.values() for s in v if s[0] > 0]


def matmul_rate(shapes: list[Shape], repeats: int = 5, dtype: torch.dtype = torch.float32) -> float:
    """GFLOP/s of plain ``torch.mm`` in ``dtype`` on exactly these ``(rows, in, out)`` shapes (the
    median of ``repeats`` timings of all of them, CPU seconds of this process)."""
    gen = torch.Generator().manual_seed(0)
    ops = [(torch.randn(r, a, generator=gen).to(dtype), torch.randn(a, b, generator=gen).to(dtype))
           for r, a, b in shapes]
    total = sum(2.0 * r * a * b for r, a, b in shapes)
    times = []
    with torch.inference_mode():
        for x, w in ops[:4]:
            torch.mm(x, w)  # warm up
        for _ in range(repeats):
            t0 = time.process_time()
            for x, w in ops:
                torch.mm(x, w)
            times.append(time.process_time() - t0)
    return total / max(statistics.median(times), 1e-9) / 1e9


def _rollout_inputs(model: mujoco.MjModel, data: mujoco.MjData, batch: int, steps: int,
                    mocap_velocity: np.ndarray | None, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``batch`` copies of ``data``'s state (``float64[B, nstate]``) and mocap controls
    ``float64[B, steps, 7 * nmocap]`` moving at ``mocap_velocity`` (m/s), slightly varied per row."""
    state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, data, state, STATE_SPEC)
    nm = model.nmocap
    control = np.zeros((batch, steps, 7 * nm))
    if nm:
        rng = np.random.default_rng(0)
        vel = np.zeros((batch, nm, 3))
        if mocap_velocity is not None:
            vel[:] = mocap_velocity
            vel[..., :2] += rng.normal(scale=0.02, size=(batch, nm, 2))
        t = dt * np.arange(1, steps + 1)
        pos = data.mocap_pos[None, None] + t[None, :, None, None] * vel[:, None]
        control[..., :3 * nm] = pos.reshape(batch, steps, 3 * nm)
        control[..., 3 * nm:] = np.tile(data.mocap_quat.reshape(-1), (batch, steps, 1))
    return np.tile(state, (batch, 1)), control


def time_rollouts(model: mujoco.MjModel, data: mujoco.MjData, substeps: int,
                  checkpoint: str | LearnedSimulator, batches: list[int], steps: int = 25,
                  mocap_velocity: np.ndarray | None = None, repeats: int = 3,
                  precision: str = "float32") -> list[dict[str, Any]]:
    """Scene-steps per second of ``Dynamics.rollout`` over ``steps`` recorded steps of ``substeps``
    MuJoCo timesteps each, for each batch size: learned (network in ``precision``), ``mujoco.rollout``
    on one thread and on every CPU. Times are medians of ``repeats`` runs (learned: CPU seconds of
    this process; MuJoCo multi-threaded: wall seconds, its threads are not this process's CPU
    time)."""
    learned = FIGNetDynamics(checkpoint, precision=precision)
    mj1, mjn = MujocoDynamics(nthread=1), MujocoDynamics(nthread=os.cpu_count() or 1)
    out = []
    for b in batches:
        state, control = _rollout_inputs(model, data, b, steps, mocap_velocity,
                                         model.opt.timestep * substeps)
        row: dict[str, Any] = {"batch": b, "steps": steps}
        for name, dyn, clock in (("learned", learned, time.process_time),
                                 ("mujoco_1thread", mj1, time.process_time),
                                 (f"mujoco_{mjn.nthread}threads", mjn, time.perf_counter)):
            dyn.rollout(model, state[:1], control[:1], frame_skip=substeps)  # warm up / mesh once
            times = []
            for _ in range(repeats if b * steps < 20_000 or name != "learned" else 1):
                t0 = clock()
                res = dyn.rollout(model, state, control, frame_skip=substeps)
                times.append(clock() - t0)
            sec = statistics.median(times)
            row[name] = {"seconds": sec, "scene_steps_per_s": b * steps / sec,
                         "finite": bool(np.isfinite(res).all())}
        out.append(row)
    return out
