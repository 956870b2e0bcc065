"""Teacher-forced one-step metrics of a learned simulator: each step starts from the true history.

They move long before rollout errors do: the size of the predicted spin change (a model that
turns objects too little) and the free-flight acceleration (a model that gets gravity wrong).
"""

from __future__ import annotations

import math
from typing import Any

import torch
from torch import Tensor

from fignet_gym.simulator.geometry import quat_angle, quat_conj, quat_mul, quat_to_axis_angle
from fignet_gym.simulator.model import LearnedSimulator
from fignet_gym.simulator.scene import ObjectKind, Scene
from fignet_gym.train.metrics import constant_velocity

#: A static object whose nodes are all within this (m) of ``z = 0`` is the floor plane.
FLOOR_PLANE_TOL = 1e-6
#: Smallest clearance (m) that counts as free flight, for models with a zero collision radius.
MIN_FREE_MARGIN = 1e-3


def free_flight_mask(scene: Scene, true: Tensor, margin: float) -> Tensor:
    """Where each dynamic object is clear of everything by more than ``margin`` (m).

    ``true float[T, O, 7]`` (a batched scene) -> ``bool[T, O]``. Clear means: its lowest node is
    above ``z = margin`` (the floor plane of every scene here is ``z = 0``) and its bounding
    sphere (about the centre of mass, through its farthest node) is more than ``margin`` from
    the bounding sphere of every other non-floor object of its scene. Geometry only, so it holds
    on tracked data, where noisy second differences never match gravity.
    """
    nodes = scene.node_positions(true)  # [T, N, 3]
    T, n_obj = true.shape[0], scene.num_objects
    idx = scene.node_object[None].expand(T, -1)
    low = torch.full((T, n_obj), math.inf).scatter_reduce_(1, idx, nodes[..., 2], "amin")
    com = scene.com_positions(true)  # [T, O, 3]
    ref_nodes = scene.node_positions(scene.static_poses[None].to(true))[0]
    ref_com = scene.com_positions(scene.static_poses[None].to(true))[0]
    d = (ref_nodes - ref_com[scene.node_object]).norm(dim=-1)
    radius = torch.zeros(n_obj).scatter_reduce_(0, scene.node_object, d, "amax", include_self=False)
    # floors: static objects whose nodes are all on z = 0 (the ground plane)
    high = torch.full((n_obj,), -math.inf).scatter_reduce_(0, scene.node_object,
                                                          nodes[0, :, 2].abs(), "amax")
    floor = (scene.object_kind == ObjectKind.STATIC) & (high < FLOOR_PLANE_TOL)
    free = (low > margin) & scene.dynamic_mask
    same = scene.object_scene[:, None] == scene.object_scene[None]
    others = same & ~torch.eye(n_obj, dtype=torch.bool) & ~floor[None]
    if others.any():
        gap = (com[:, :, None] - com[:, None]).norm(dim=-1) - radius[:, None] - radius[None]
        free &= ~((gap <= margin) & others).any(-1)
    return free


@torch.no_grad()
def one_step_errors(sim: LearnedSimulator, scene: Scene, true: Tensor,
                    lengths: Tensor | None = None) -> dict[str, Any]:
    """Teacher-forced one-step errors over ``true float[H + T, O, 7]`` (a batched scene).

    ``lengths int[B]``: poses of each scene of the batch (the rows after them are padding and
    are skipped; default: all rows). Each step starts from the true history. Errors of dynamic
    objects' next poses, summed over objects and steps, are divided by the motion over the step:
    ``one_step_translation`` is ``sum |c_pred - c_true| / sum |c_true - c_prev|`` (centres of
    mass) and ``one_step_rotation`` the same with geodesic angles; ``one_step_constvel_*`` are
    those of the constant-velocity model, the bar a useful simulator must clear.

    ``one_step_spin_gain`` is the least-squares slope of the predicted change of angular
    velocity (per step, as a rotation vector) on the true one: 1 when the model's torques are
    right in size on average, below 1 when it turns objects too little. It moves long before
    rollout rotation errors do (a model that gets half of a push's initial spin and then keeps it
    scores 0.5 here).

    ``one_step_free_flight`` is the RMS error of the predicted centre-of-mass acceleration of
    objects in free flight (clear of everything by the collision radius over the history and the
    step, :func:`free_flight_mask`), as a fraction of ``|a| dt^2``, against ``a``, the data's own
    mean free-flight acceleration (``free_flight_acceleration``, m/s^2: gravity on generated data,
    about 9.6 m/s^2 on the real cube tosses). Tracking noise averages out of ``a``; it still
    enters the predicted acceleration through the given history. NaN, with the reason in
    ``one_step_free_flight_absent``, without a gravity prior or free-flying objects.
    """
    H = sim.config.history + 1
    dev = sim.device
    scene = scene.to(dev)
    true = true.to(dev)
    dyn = scene.dynamic_mask
    g = sim.gravity_step()
    g_norm = float(g.norm())
    com = scene.com_positions(true)  # float[T, O, 3]
    steps = true.shape[0]
    if lengths is None:
        valid = torch.ones(steps, scene.num_objects, dtype=torch.bool, device=dev)
    else:
        valid = torch.arange(steps, device=dev)[:, None] < lengths.to(dev)[scene.object_scene]
    margin = max(float(sim.config.collision_radius), MIN_FREE_MARGIN)
    free = free_flight_mask(scene, true, margin) & valid
    # The prediction of pose t is a free-flight step if poses t-H .. t (its history and itself)
    # are all free; the data's acceleration there is centred on pose t-1.
    win = torch.zeros_like(free)
    for t in range(H, steps):
        win[t] = free[t - H:t + 1].all(0)
    acc_true = torch.zeros_like(com)
    acc_true[2:] = com[2:] - 2 * com[1:-1] + com[:-2]
    n_free = int(win.sum())
    a_data = acc_true[win].mean(0) if n_free else g
    # Running sums: 3 of translation, 3 of rotation, 2 of spin, 2 of free flight (see `terms`).
    sums = torch.zeros(10, dtype=torch.float64)
    for t in range(H, steps):
        ok = dyn & valid[t]
        if not ok.any():
            continue
        poses = (sim.step(scene, true[t - H:t], true[t]),
                 constant_velocity(true[t - 2:t + 1], 2)[0], true[t], true[t - 1])
        coms = [scene.com_positions(x) for x in poses[:2]] + [com[t], com[t - 1]]
        c = [x[ok] for x in coms]
        pred, cv, nxt, cur = (x[ok] for x in poses)
        # [model, constant velocity, true motion] for translation, then for rotation.
        terms = ([(c[i] - c[2]).norm(dim=-1).sum() for i in (0, 1, 3)]
                 + [quat_angle(x[:, 3:], nxt[:, 3:]).sum() for x in (pred, cv, cur)])
        prev = true[t - 2][ok, 3:]
        d_pred, d_true = (spin_change(prev, cur[:, 3:], x[:, 3:]) for x in (pred, nxt))
        terms += [(d_pred * d_true).sum(), (d_true * d_true).sum()]
        fly = win[t] & ok if g_norm > 0 else torch.zeros_like(ok)
        acc = coms[0] - 2 * com[t - 1] + com[t - 2]
        terms += [((acc[fly] - a_data) ** 2).sum(), fly.sum()]
        sums += torch.stack(terms).double().cpu()
    out: dict[str, Any] = {}
    for i, kind in ((0, "translation"), (3, "rotation")):
        total = float(sums[i + 2])
        out[f"one_step_{kind}"] = float(sums[i]) / total if total > 0 else math.nan
        out[f"one_step_constvel_{kind}"] = float(sums[i + 1]) / total if total > 0 else math.nan
    out["one_step_spin_gain"] = float(sums[6] / sums[7]) if sums[7] > 0 else math.nan
    a_norm = float(a_data.norm())
    out["one_step_free_flight"] = (math.sqrt(float(sums[8] / sums[9])) / a_norm
                                   if sums[9] > 0 and a_norm > 0 else math.nan)
    out["free_flight_steps"] = int(sums[9])
    out["free_flight_acceleration"] = (float(a_data[2]) / sim.config.dt**2 if n_free else math.nan)
    if g_norm == 0:
        out["one_step_free_flight_absent"] = "the simulator has no gravity prior"
    elif sums[9] == 0:
        out["one_step_free_flight_absent"] = (
            f"no dynamic object is clear of everything by the collision radius ({margin} m) over "
            f"{H + 1} consecutive poses")
    return out


def spin_change(q_prev: Tensor, q_cur: Tensor, q_next: Tensor) -> Tensor:
    """Change of per-step rotation (world-frame rotation vectors, rad) between the steps
    ``prev -> cur`` and ``cur -> next``: ``float[O, 4]`` quaternions each -> ``float[O, 3]``."""
    spin = quat_to_axis_angle(quat_mul(q_cur, quat_conj(q_prev)))
    return quat_to_axis_angle(quat_mul(q_next, quat_conj(q_cur))) - spin
