"""Learned-simulator rollouts over trajectory files: similar lengths batched into one scene.

Each trajectory is rolled out over its own length from its first ``history + 1`` true poses;
kinematic and static objects follow their true poses.
"""

from __future__ import annotations

import time

import numpy as np
import torch
from torch import Tensor

from fignet_gym.data.format import Trajectory
from fignet_gym.simulator.model import LearnedSimulator
from fignet_gym.simulator.scene import Scene

#: Trajectories rolled out together as one batched scene.
ROLLOUT_BATCH = 32


def pad_poses(poses: np.ndarray, length: int) -> Tensor:
    """``float[T, O, 7]`` padded to ``length`` rows by repeating the last pose: ``float32``."""
    x = torch.as_tensor(np.asarray(poses), dtype=torch.float32)
    if x.shape[0] < length:
        x = torch.cat((x, x[-1:].expand(length - x.shape[0], -1, -1)))
    return x


def length_groups(lengths: list[int], size: int) -> list[list[int]]:
    """Indices grouped by similar length (sorted), ``size`` per group: little padding."""
    order = sorted(range(len(lengths)), key=lambda i: lengths[i])
    return [order[i:i + size] for i in range(0, len(order), size)]


def learned_rollouts(sim: LearnedSimulator, trajs: list[Trajectory], scenes: list[Scene],
                     batch: int = ROLLOUT_BATCH) -> tuple[list[Tensor], list[float], float]:
    """Each trajectory rolled out over its own length from its first ``history + 1`` poses.

    Trajectories of similar length run as one batch (padded with their last pose, the padding's
    predictions dropped). Returns full-length poses ``float[T_i, O_i, 7]`` per trajectory (the
    given poses first), collision edges per scene-step of each batch, and seconds per batched
    step.
    """
    H = sim.config.history + 1
    lengths = [t.num_steps for t in trajs]
    short = [t.name for t in trajs if t.num_steps <= H]
    if short:
        raise ValueError(f"trajectories {short[:3]} have at most {H} poses: nothing to predict")
    out: list[Tensor | None] = [None] * len(trajs)
    edges, secs, n_steps = [], 0.0, 0
    for idx in length_groups(lengths, batch):
        T = max(lengths[i] for i in idx)
        scene = Scene.batch([scenes[i] for i in idx])
        true = torch.cat([pad_poses(trajs[i].poses, T) for i in idx], 1)
        pred, e, s = batched_rollout(sim, scene, true)
        edges += [x / len(idx) for x in e]
        secs += s * pred.shape[0]
        n_steps += pred.shape[0]
        full = torch.cat((true[:H], pred))
        off = 0
        for i in idx:
            n = scenes[i].num_objects
            out[i] = full[:lengths[i], off:off + n]
            off += n
    return out, edges, secs / max(n_steps, 1)  # type: ignore[return-value]


@torch.no_grad()
def batched_rollout(sim: LearnedSimulator, scene: Scene, true: Tensor
                    ) -> tuple[Tensor, list[int], float]:
    """Roll out from the first ``H`` rows of ``true float[H + T, O, 7]``.

    Returns ``(pred float[T, O, 7], collision edges per step, seconds per step)``.
    """
    H = sim.config.history + 1
    dev = sim.device
    scene = scene.to(dev)
    hist = true[:H].to(dev)
    preds, edges = [], []
    t0 = time.perf_counter()
    for t in range(H, true.shape[0]):
        nxt, inputs, _ = sim.step_with_info(scene, hist, true[t].to(dev))
        preds.append(nxt)
        g = inputs.graph  # face-face edges for FIGNet, node-node edges for the MGN baselines
        edges.append(int(g.face_edges.senders.shape[0] + g.node_edges.senders.shape[0]))
        hist = torch.cat((hist[1:], nxt[None]), 0)
    secs = (time.perf_counter() - t0) / max(len(preds), 1)
    return torch.stack(preds).cpu(), edges, secs
