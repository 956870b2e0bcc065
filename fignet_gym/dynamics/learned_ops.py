"""Tensor operations of the learned dynamics: many scenes stepped as one graph, and the pose
history's constant-velocity back-extrapolation and mocap blends (torch, on the simulator's
device)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

from fignet_gym.simulator.geometry import axis_angle_to_quat, quat_mul, quat_normalize
from fignet_gym.simulator.model import LearnedSimulator
from fignet_gym.simulator.scene import Scene

#: Nodes per learned step at most: larger batches are stepped in chunks of whole scenes. Per-scene
#: cost is lowest around 8k to 17k nodes (experiments/README.md, Speed); beyond, every latent
#: outgrows the caches and each new tensor is fresh memory to fault in.
CHUNK_NODES = 16384


def batched_step(sim: LearnedSimulator, scene: Scene, count: int, hist: Tensor, target: Tensor
                 ) -> Tensor:
    """One learned step of ``count`` copies of ``scene``, in chunks of at most
    :data:`CHUNK_NODES` nodes (the scenes are disjoint, and a scene's result does not depend on
    its batch, so chunking changes no bit).

    ``hist float[H, count*O, 7]``, ``target float[count*O, 7]`` -> ``float[count*O, 7]``.
    """
    chunks = -(-count * scene.num_nodes // CHUNK_NODES)
    if chunks <= 1:
        return sim.step(scene.repeat(count), hist, target)
    n_obj, out, start = scene.num_objects, [], 0
    for i in range(chunks):
        c = count // chunks + (i < count % chunks)  # sizes differ by at most one
        rows = slice(start * n_obj, (start + c) * n_obj)
        out.append(sim.step(scene.repeat(c), hist[:, rows], target[rows]))
        start += c
    return torch.cat(out)


def integrate_back(poses: Tensor, lin: Tensor, ang_body: Tensor, k: int, dt: float) -> Tensor:
    """Poses ``k * dt`` earlier at constant velocity.

    ``poses float[D, 7]``, ``lin float[D, 3]`` (world), ``ang_body float[D, 3]`` -> ``float[D, 7]``.
    """
    p = poses[:, :3] - (k * dt) * lin
    q = quat_normalize(quat_mul(poses[:, 3:], axis_angle_to_quat(-(k * dt) * ang_body)))
    return torch.cat((p, q), dim=-1)


def kinematic_targets(pos: np.ndarray, quat: np.ndarray, device: torch.device) -> Tensor:
    """Kinematic targets of every step on ``device``: ``pos float[B, T, K, 3]``,
    ``quat float[B, T, K, 4]`` -> ``float[T, B*K, 7]`` (unit quaternions)."""
    tgt = torch.as_tensor(np.concatenate((pos, quat), -1), dtype=torch.float32, device=device)
    tgt = tgt.transpose(0, 1).reshape(pos.shape[1], -1, 7)
    return torch.cat((tgt[..., :3], quat_normalize(tgt[..., 3:])), -1)


def blend_targets(start: Tensor, target: Tensor, rows: Tensor, frac: float) -> Tensor:
    """``target float[N, 7]`` with ``rows bool[N]`` moved the fraction ``frac`` of the way from
    ``start float[N, 7]`` (positions linearly, quaternions as normalised linear blends: MuJoCo's
    mocap path, :func:`~fignet_gym.dynamics.mujoco.interpolate_mocap`)."""
    mid = start + (target - start) * frac
    mid = torch.cat((mid[:, :3], quat_normalize(mid[:, 3:])), -1)
    return torch.where(rows[:, None], mid, target)


def describe_divergence(nxt: Tensor, cur: Tensor, dyn: np.ndarray, names: Sequence[str],
                        floor_z: float, t: float, limits: Any) -> str:
    """Human-readable reason for the first sick dynamic object of one scene: its next and current
    poses ``float[O, 7]``, dynamic object indices ``int[D]``, object names, the floor height (m),
    the time (s) and ``limits`` (``max_distance``, ``fall_depth``, ``max_speed``, ``dt``)."""
    for o in dyn:
        p, c = nxt[o], cur[o]
        name = names[o]
        if not bool(torch.isfinite(p).all()):
            return f"learned dynamics diverged: object '{name}' is non-finite at t={t:.3f}s"
        pos = p[:3].tolist()
        where = f"object '{name}' at ({pos[0]:.3g}, {pos[1]:.3g}, {pos[2]:.3g}) m at t={t:.3f}s"
        if float(p[:3].norm()) > limits.max_distance:
            limit = f"max_distance={limits.max_distance:g} m"
            return f"learned dynamics diverged: {where} is beyond {limit}"
        if float(p[2]) < floor_z - limits.fall_depth:
            return f"learned dynamics diverged: {where} fell {limits.fall_depth:g} m below the floor"
        speed = float((p[:3] - c[:3]).norm()) / limits.dt
        if speed > limits.max_speed:
            return (f"learned dynamics diverged: {where} moves at {speed:.3g} m/s "
                    f"(max_speed={limits.max_speed:g})")
    return "learned dynamics diverged"
