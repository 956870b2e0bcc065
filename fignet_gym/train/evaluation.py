"""Rollout evaluation with the paper's metrics (``fignet-gym evaluate``).

Metrics, over dynamic objects, for rollouts started from the first ``H`` true poses of each
trajectory with kinematic and static objects following their true poses:

* translation error: RMSE (m) of centre-of-mass positions over objects, at each step;
* rotation error: geodesic angle (degrees) between predicted and true orientations,
  ``2 acos(|<q_pred, q_true>|)``, averaged over objects, at each step;
* penetration: mean depth (m) of dynamic nodes below the floor plane ``z = 0`` per step, as a ratio
  of the prediction's to the ground truth's (MuJoCo's soft contacts penetrate a little too);
* collision edges per step (face-face, or node-node for the MGN baselines) and milliseconds per
  learned step;
* rotation gain: median over objects of predicted / true turning angle at the horizon (below 1:
  the model turns objects too little).

Two reference models give the errors a scale: *no motion* (every object keeps its initial pose; the
unit of the paper's Fig. 7c) and *constant velocity* (each object keeps its last observed velocity).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from fignet_gym.data.format import Trajectory, build_scene
from fignet_gym.simulator.geometry import (
    axis_angle_to_quat,
    quat_angle,
    quat_conj,
    quat_mul,
    quat_normalize,
    quat_to_axis_angle,
)
from fignet_gym.simulator.model import LearnedSimulator
from fignet_gym.simulator.scene import ObjectKind, Scene

#: Relative tolerance of the data-dt vs model-dt check.
DT_RTOL = 1e-4


def check_dt(trajs: list[Trajectory], dt: float) -> None:
    """Raise ``ValueError`` naming the file and trajectory whose ``dt`` is not the model's ``dt``.

    A learned simulator predicts one step of its training ``dt``; scoring a 12 fps file with a
    50 Hz model would compare it with poses four steps away.
    """
    for t in trajs:
        if abs(t.dt - dt) > DT_RTOL * dt:
            where = f"{t.source}: " if t.source else ""
            raise ValueError(f"{where}trajectory {t.name!r}: field 'dt' is {t.dt:.6g} s, the model "
                             f"steps {dt:.6g} s (resample or import the data at the model's dt, or "
                             "train a model at the data's dt)")


def _pad(poses: np.ndarray, length: int) -> Tensor:
    """``float[T, O, 7]`` padded to ``length`` rows by repeating the last pose: ``float32``."""
    x = torch.as_tensor(np.asarray(poses), dtype=torch.float32)
    if x.shape[0] < length:
        x = torch.cat((x, x[-1:].expand(length - x.shape[0], -1, -1)))
    return x


def _chunks(lengths: list[int], size: int) -> list[list[int]]:
    """Indices grouped by similar length (sorted), ``size`` per group: little padding."""
    order = sorted(range(len(lengths)), key=lambda i: lengths[i])
    return [order[i:i + size] for i in range(0, len(order), size)]


def learned_rollouts(sim: LearnedSimulator, trajs: list[Trajectory], scenes: list[Scene],
                     batch: int = 32) -> tuple[list[Tensor], list[float], float]:
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
    for idx in _chunks(lengths, batch):
        T = max(lengths[i] for i in idx)
        scene = Scene.batch([scenes[i] for i in idx])
        true = torch.cat([_pad(trajs[i].poses, T) for i in idx], 1)
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
    floor = (scene.object_kind == ObjectKind.STATIC) & (high < 1e-6)
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
    margin = max(float(sim.config.collision_radius), 1e-3)
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


def constant_velocity(true: Tensor, H: int) -> Tensor:
    """Baseline: each object keeps the velocity of its last two observed poses. ``-> float[T, O, 7]``."""
    p0, p1 = true[H - 2], true[H - 1]
    steps = true.shape[0] - H
    k = torch.arange(1, steps + 1, dtype=true.dtype, device=true.device)[:, None, None]
    pos = p1[None, :, :3] + k * (p1[:, :3] - p0[:, :3])[None]
    dq = quat_to_axis_angle(quat_mul(p1[:, 3:], quat_conj(p0[:, 3:])))
    quat = quat_normalize(quat_mul(axis_angle_to_quat(k * dq[None]), p1[None, :, 3:].expand(steps, -1, -1)))
    return torch.cat((pos, quat), -1)


def errors(scene: Scene, pred: Tensor, true: Tensor) -> tuple[Tensor, Tensor]:
    """Per-step translation RMSE (m) and mean rotation error (deg) over dynamic objects.

    ``pred, true float[T, O, 7]`` for one scene (or a batch, then per scene ``float[T, B]``).
    """
    dyn = scene.dynamic_mask
    com_p, com_t = scene.com_positions(pred), scene.com_positions(true)
    sq = ((com_p - com_t) ** 2).sum(-1)[:, dyn]  # [T, O_dyn]
    ang = torch.rad2deg(quat_angle(pred[..., 3:], true[..., 3:]))[:, dyn]
    sid = scene.object_scene[dyn]
    B = scene.num_scenes
    cnt = torch.zeros(B).index_add_(0, sid, torch.ones(sid.shape[0]))
    trans = (torch.zeros(sq.shape[0], B).index_add_(1, sid, sq) / cnt).sqrt()
    rot = torch.zeros(sq.shape[0], B).index_add_(1, sid, ang) / cnt
    return trans, rot


def rotation_gain(dynamic: Tensor, start: Tensor, pred: Tensor, true: Tensor, min_deg: float = 1.0
                  ) -> float:
    """Median of predicted over true turning angle since ``start`` (geodesic, magnitudes only).

    ``dynamic bool[O]``; ``start, pred, true float[O, 7]``. Only dynamic objects that truly turn
    by more than ``min_deg`` count (NaN if none does). 1 is right on average in size; a model that
    turns pushed objects the right way but too little (a common failure) scores below 1, which
    the rotation error alone does not show.
    """
    turn_t = torch.rad2deg(quat_angle(start[:, 3:], true[:, 3:]))
    turn_p = torch.rad2deg(quat_angle(start[:, 3:], pred[:, 3:]))
    keep = dynamic & (turn_t > min_deg)
    if not keep.any():
        return math.nan
    return float((turn_p[keep] / turn_t[keep]).median())


def floor_penetration(scene: Scene, poses: Tensor) -> Tensor:
    """Mean depth (m) of dynamic nodes below ``z = 0`` per step: ``float[T, O, 7] -> float[T]``."""
    z = scene.node_positions(poses)[..., 2][:, scene.dynamic_mask[scene.node_object]]
    return (-z).clamp_min(0).mean(-1)


def _median(x: list[float]) -> float:
    return float(np.median(x)) if len(x) else math.nan


def _errors_one(scene: Scene, pred: Tensor, true: Tensor) -> tuple[np.ndarray, np.ndarray]:
    tr, rot = errors(scene, pred, true)
    return tr[:, 0].numpy(), rot[:, 0].numpy()


def score_rollouts(scenes: list[Scene], trues: list[Tensor], preds: list[Tensor], given: int,
                   horizon: int = 50, names: list[str] | None = None) -> dict[str, Any]:
    """The paper's rollout errors of any predictor, each trajectory over its own length.

    Args:
        scenes: one scene per trajectory. trues, preds: ``float[T_i, O_i, 7]`` full-length true
            and predicted poses (the first ``given`` predicted rows are the given true poses).
        given: poses the predictor was given (``history + 1``); they are not scored.
        horizon: frame (counted from frame 0 of each trajectory) of the ``*_final`` errors.
            Trajectories without that frame are left out of them (counted in
            ``horizon_trajectories``); every trajectory's last frame gives the ``*_last`` errors.

    Returns medians over trajectories at the horizon (``*_final``) and at the last frame
    (``*_last``), per-frame median curves (frames ``given`` .. over the trajectories that have
    them), per-trajectory errors, ratios to no motion (every object keeps its last given pose)
    and constant velocity, and bootstrap intervals of the ratios to no motion.
    """
    if horizon < given:
        raise ValueError(f"horizon {horizon} is inside the {given} given poses (frames 0 .. "
                         f"{given - 1}): errors are counted from frame 0, so use {given} or more")
    lengths = [int(t.shape[0]) for t in trues]
    reach = [i for i, n in enumerate(lengths) if n > horizon]
    if not reach:
        raise ValueError(f"no trajectory reaches frame {horizon} (the longest has {max(lengths)} "
                         "poses): lower the horizon")
    per: dict[str, dict[str, list[float]]] = {}
    curves: dict[str, list[list[float]]] = {"translation_rmse": [], "rotation_deg": []}
    for i, (scene, true, pred) in enumerate(zip(scenes, trues, preds, strict=True)):
        true, pred = true.float(), pred.float()
        gt = true[given:]
        models = {"": pred[given:], "still_": true[given - 1][None].expand_as(gt),
                  "constvel_": constant_velocity(true, given)}
        for name, p in models.items():
            tr, rot = _errors_one(scene, p, gt)
            for q, e in (("translation_rmse", tr), ("rotation_deg", rot)):
                d = per.setdefault(f"{name}{q}", {"final": [], "last": []})
                if i in reach:
                    d["final"].append(float(e[horizon - given]))
                d["last"].append(float(e[-1]))
                if not name:
                    curves[q].append(e.tolist())
    out: dict[str, Any] = {"horizon_step": horizon, "horizon_trajectories": len(reach),
                           "trajectories": len(trues), "given_poses": given,
                           "steps": max(lengths) - given,
                           "lengths": [min(lengths), int(np.median(lengths)), max(lengths)]}
    for key, d in per.items():
        out[f"{key}_final"] = _median(d["final"])
        out[f"{key}_last"] = _median(d["last"])
    for q in ("translation_rmse", "rotation_deg"):
        longest = max(len(c) for c in curves[q])
        out[f"{q}_curve"] = [_median([c[k] for c in curves[q] if len(c) > k]) for k in range(longest)]
        for at in ("final", "last"):
            suffix = "" if at == "final" else "_last"
            for ref in ("still", "constvel"):
                denom = out[f"{ref}_{q}_{at}"]
                out[f"{q}{suffix}_ratio_{ref}"] = out[f"{q}_{at}"] / denom if denom > 0 else math.nan
            model, still = np.array(per[q][at]), np.array(per[f"still_{q}"][at])
            out[f"{q}{suffix}_ratio_still_ci95"] = median_ratio_interval(model, still)
            out[f"{q}{suffix}_per_trajectory"] = per[q][at]
            out[f"still_{q}{suffix}_per_trajectory"] = per[f"still_{q}"][at]
    if names is not None:
        out["names"] = list(names)
        out["horizon_names"] = [names[i] for i in reach]
    return out


def rollout_metrics(sim: LearnedSimulator, trajs: list[Trajectory], scenes: list[Scene] | None = None,
                    horizon: int = 50, batch: int = 32) -> dict[str, Any]:
    """Roll out every trajectory over its own length and summarise (:func:`score_rollouts`).

    Checks each trajectory's ``dt`` against the model's. Adds the teacher-forced one-step errors,
    the rotation gain at the horizon, floor penetration, collision edges and timings.
    """
    check_dt(trajs, sim.config.dt)
    H = sim.config.history + 1
    scenes = scenes or [build_scene(t, sim.config.mesh_options) for t in trajs]
    preds, edges, secs = learned_rollouts(sim, trajs, scenes, batch)
    trues = [torch.as_tensor(t.poses, dtype=torch.float32) for t in trajs]
    out = score_rollouts(scenes, trues, preds, H, horizon, [t.name for t in trajs])
    out.update(seconds=horizon * sim.config.dt, dt=sim.config.dt, ms_per_step_batched=1000 * secs,
               collision_edges_per_step=float(np.mean(edges)) if edges else math.nan)
    one: dict[str, Any] = {}
    sums: dict[str, list[tuple[float, float]]] = {}
    for idx in _chunks([t.num_steps for t in trajs], batch):
        T = max(trajs[i].num_steps for i in idx)
        scene = Scene.batch([scenes[i] for i in idx])
        true = torch.cat([_pad(trajs[i].poses, T) for i in idx], 1)
        res = one_step_errors(sim, scene, true, torch.tensor([trajs[i].num_steps for i in idx]))
        weight = float(sum(trajs[i].num_steps - H for i in idx))
        for k, v in res.items():
            if isinstance(v, str):
                one.setdefault(k, v)
            else:
                w = float(res["free_flight_steps"]) if "free_flight" in k else weight
                sums.setdefault(k, []).append((float(v), w))
    for k, vals in sums.items():
        if k == "free_flight_steps":
            one[k] = int(sum(v for v, _ in vals))
            continue
        good = [(v, w) for v, w in vals if math.isfinite(v) and w > 0]
        one[k] = sum(v * w for v, w in good) / sum(w for _, w in good) if good else math.nan
    if one.get("free_flight_steps", 0) > 0:
        one.pop("one_step_free_flight_absent", None)
    out.update(one)
    reach = [i for i, t in enumerate(trajs) if t.num_steps > horizon]
    gains = [rotation_gain(scenes[i].dynamic_mask, trues[i][H - 1], preds[i][horizon],
                           trues[i][horizon]) for i in reach]
    gains = [x for x in gains if math.isfinite(x)]
    out["rotation_gain"] = float(np.median(gains)) if gains else math.nan
    out.update(_penetration(scenes, preds, trues, H))
    return out


def predictor_metrics(trajs: list[Trajectory], preds: list[np.ndarray], given: int = 3,
                      horizon: int = 50) -> dict[str, Any]:
    """:func:`score_rollouts` of predicted poses ``float[T_i, O_i, 7]`` (an analytic simulator,
    say) on trajectories, with the same keys as :func:`rollout_metrics`'s rollout errors."""
    scenes = [build_scene(t) for t in trajs]
    trues = [torch.as_tensor(t.poses, dtype=torch.float32) for t in trajs]
    pred_t = [torch.as_tensor(np.asarray(p), dtype=torch.float32) for p in preds]
    out = score_rollouts(scenes, trues, pred_t, given, horizon, [t.name for t in trajs])
    out.update(seconds=horizon * trajs[0].dt, dt=trajs[0].dt)
    out.update(_penetration(scenes, pred_t, trues, given))
    return out


def _penetration(scenes: list[Scene], preds: list[Tensor], trues: list[Tensor],
                 start: int) -> dict[str, float]:
    """Mean floor penetration (m) of predicted poses ``float[T_i, O_i, 7]`` from step ``start``
    on, and its ratio to the ground truth's (NaN when the truth never penetrates)."""
    pen_p = float(np.mean([floor_penetration(s, p[start:]).mean()
                           for s, p in zip(scenes, preds, strict=True)]))
    pen_t = float(np.mean([floor_penetration(s, t[start:]).mean()
                           for s, t in zip(scenes, trues, strict=True)]))
    return {"penetration_ratio": pen_p / pen_t if pen_t > 0 else math.nan, "penetration_m": pen_p}


def perturbation_floor(trajs: list[Trajectory], position_noise: float, history: int = 2,
                       horizon: int = 50, seed: int = 0) -> dict[str, Any]:
    """The rollout errors of MuJoCo itself when its start is off by ``position_noise`` (m).

    Each generated trajectory is re-simulated (:func:`~fignet_gym.data.generate.resimulate`)
    with every free body moved horizontally by ``position_noise`` at the last of the
    ``history + 1`` poses a learned rollout starts from, and scored as :func:`rollout_metrics`
    scores a model (same keys; ``horizon`` counted from frame 0). On chaotic data (tosses) this
    is a floor: a learned simulator whose state is off by ``position_noise`` after one step is at
    best a perfect simulator started that far off, so its rollouts are not expected to beat
    these errors.
    """
    from fignet_gym.data.generate import resimulate

    H = history + 1
    preds = []
    for i, t in enumerate(trajs):
        p = resimulate(t, position_noise, H - 1, seed + i)
        p[:H] = t.poses[:H]  # the given poses are the true ones, as for a learned rollout
        preds.append(p)
    out: dict[str, Any] = {"position_noise": position_noise}
    out.update(predictor_metrics(trajs, preds, H, horizon))
    return out


def floor_table(data: str, noises: list[float], out: str | None = None, num: int | None = None,
                horizon: int = 50, history: int = 2) -> list[dict[str, Any]]:
    """Print (and write as JSON to ``out``) :func:`perturbation_floor` at several noise levels."""
    from fignet_gym.data.format import load_trajectories

    trajs = load_trajectories(data)[:num]
    if not trajs:
        raise ValueError(f"{data}: holds no trajectories")
    rows = [perturbation_floor(trajs, n, history=history, horizon=horizon) for n in noises]
    print(f"MuJoCo re-run from a start nudged by the noise: {len(trajs)} trajectories of {data}, "
          f"error at step {rows[0]['horizon_step']} (median; % of no motion)")
    print(f"{'noise (m)':>10s} {'transl. RMSE (m)':>17s} {'% still':>8s} "
          f"{'rotation (deg)':>15s} {'% still':>8s}")
    for r in rows:
        print(f"{r['position_noise']:10.2g} {r['translation_rmse_final']:17.4f} "
              f"{100 * r['translation_rmse_ratio_still']:8.1f} {r['rotation_deg_final']:15.2f} "
              f"{100 * r['rotation_deg_ratio_still']:8.1f}")
    if out:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        Path(out).write_text(json.dumps({"data": data, "rows": rows}, indent=2))
        plot_floor(rows, Path(out).with_suffix(".png"), title=Path(data).name)
        print(f"wrote {out} and {Path(out).with_suffix('.png')}")
    return rows


def plot_floor(rows: list[dict[str, Any]], path: Path, title: str = "") -> None:
    """Errors of :func:`perturbation_floor` (% of no motion) against the start error (log axis)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in rows if r["position_noise"] > 0]
    noise = [1000 * r["position_noise"] for r in rows]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    for q, label in (("translation_rmse", "translation"), ("rotation_deg", "rotation")):
        ax.plot(noise, [100 * r[f"{q}_ratio_still"] for r in rows], "o-", label=label)
    ax.set(xscale="log", xlabel="start position error (mm)", ylabel="MuJoCo's error (% of no motion)",
           title=f"{title}, step {rows[0]['horizon_step']}" if rows else title)
    ax.grid(alpha=0.3, which="both")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def median_ratio_interval(model: np.ndarray, ref: np.ndarray, draws: int = 2000, seed: int = 0
                          ) -> list[float]:
    """Bootstrap 95% interval of ``median(model) / median(ref)`` over trajectories (``float[B]``
    each, resampled in pairs). With ~100 trajectories a median ratio of small errors (a pushed
    object's yaw) is uncertain by tens of percent; the interval says how much."""
    if model.shape[0] == 0:
        return [math.nan, math.nan]
    idx = np.random.default_rng(seed).integers(0, model.shape[0], (draws, model.shape[0]))
    den = np.median(ref[idx], axis=1)
    ratios = np.median(model[idx], axis=1) / np.where(den > 0, den, np.nan)
    lo, hi = np.nanpercentile(ratios, [2.5, 97.5])
    return [float(lo), float(hi)]


def paired_ratios(res: dict[str, Any], ref: dict[str, Any]) -> dict[str, Any]:
    """Ratios of two models' median errors on the same trajectories (of the ``*_final`` and
    ``*_last`` medians that :func:`score_rollouts` reports), with bootstrap 95% intervals
    (trajectories resampled in pairs): ``{"translation_rmse": [ratio, lo, hi], "rotation_deg":
    [...], "translation_rmse_last": [...], "rotation_deg_last": [...]}``.
    """
    out: dict[str, Any] = {}
    for q in ("translation_rmse", "rotation_deg"):
        for suffix, at in (("", "final"), ("_last", "last")):
            key = f"{q}{suffix}_per_trajectory"
            if key not in res or key not in ref:
                continue
            a, b = (np.asarray(r[key]) for r in (res, ref))
            if a.shape != b.shape:
                raise ValueError(f"paired ratios need the same trajectories ({a.shape} vs {b.shape})")
            den = ref[f"{q}_{at}"]
            out[f"{q}{suffix}"] = [res[f"{q}_{at}"] / den if den > 0 else math.nan,
                                   *median_ratio_interval(a, b)]
    return out


def data_scene_type(traj: Trajectory) -> str:
    """The scene type (``"push"``, ``"toss"``; ``""``: unknown) a trajectory's metadata implies."""
    kind, source = str(traj.metadata.get("kind", "")), str(traj.metadata.get("source", ""))
    if kind == "push" or source.startswith("mit_pushing"):
        return "push"
    if kind.startswith("toss") or source.startswith("kubric_movi"):
        return "toss"
    return ""


def check_data_matches(sim: LearnedSimulator, trajs: list[Trajectory], data: str | Path) -> None:
    """``ValueError`` naming ``data`` if it is empty or of another scene type than ``sim``'s."""
    if not trajs:
        raise ValueError(f"{data}: holds no trajectories")
    trained = sim.config.scene_type
    kinds = {data_scene_type(t) for t in trajs} - {""}
    if trained and kinds and kinds != {trained}:
        raise ValueError(f"{data}: holds {'/'.join(sorted(kinds))} trajectories, the checkpoint was "
                         f"trained on '{trained}' scenes")


def evaluate(checkpoint: str, data: str, out: str, num: int | None = None, horizon: int = 50,
             videos: int = 2, against: str | None = None) -> dict[str, Any]:
    """Evaluate a checkpoint on a trajectory file: print a table, write JSON, plots and videos.

    ``num``: the first ``num`` trajectories (default: all). ``horizon``: frame of the headline
    errors, counted from frame 0 of each trajectory; the last frame of each is scored too.

    ``against``: a second checkpoint rolled out on the same trajectories; the ratios of the two
    models' median errors, with bootstrap intervals, are printed and stored under ``"against"``.
    """
    from fignet_gym.data.format import load_trajectories
    from fignet_gym.pretrained import load_pretrained

    if (num is not None and num < 1) or horizon < 1 or videos < 0:
        raise ValueError(f"evaluate: num and horizon must be >= 1 and videos >= 0, got "
                         f"{num}, {horizon}, {videos}")
    sim = load_pretrained(checkpoint)
    trajs = load_trajectories(data)[:num]
    check_data_matches(sim, trajs, data)
    check_dt(trajs, sim.config.dt)
    outdir = Path(out)
    outdir.mkdir(parents=True, exist_ok=True)
    res = rollout_metrics(sim, trajs, horizon=horizon)
    res.update(checkpoint=str(checkpoint), data=str(data))
    if against is not None:
        other = load_pretrained(against)
        check_data_matches(other, trajs, data)
        ref = rollout_metrics(other, trajs, horizon=horizon)
        res["against"] = {"checkpoint": str(against), "ratios": paired_ratios(res, ref),
                          **{k: ref[k] for k in ("translation_rmse_final", "rotation_deg_final",
                                                 "translation_rmse_last", "rotation_deg_last")}}
    (outdir / "metrics.json").write_text(json.dumps(res, indent=2))
    print_table(res)
    plot_curves(res, outdir / "errors.png")
    for i in range(min(videos, len(trajs))):
        write_comparison_video(sim, trajs[i], outdir / f"rollout_{i}.mp4")
    print(f"wrote {outdir}/metrics.json, errors.png and {min(videos, len(trajs))} videos")
    return res


def print_table(res: dict[str, Any], label: str = "FIGNet") -> None:
    """Print the headline metrics against the reference models."""
    h = res["horizon_step"]
    print(f"{res['trajectories']} trajectories ({res['horizon_trajectories']} reach frame {h}); "
          f"errors at frame {h} from frame 0 ({res['seconds']:.2f} s) and at each one's last frame")
    print(f"{'model':16s} {'transl. (m)':>12s} {'rot. (deg)':>11s} {'last transl.':>13s} "
          f"{'last rot.':>10s}")
    for name, pre in ((label, ""), ("no motion", "still_"), ("const. velocity", "constvel_")):
        print(f"{name:16s} {res[pre + 'translation_rmse_final']:12.4f} "
              f"{res[pre + 'rotation_deg_final']:11.2f} {res[pre + 'translation_rmse_last']:13.4f} "
              f"{res[pre + 'rotation_deg_last']:10.2f}")
    ci_t, ci_r = res["translation_rmse_ratio_still_ci95"], res["rotation_deg_ratio_still_ci95"]
    print(f"ratio to no motion: translation {res['translation_rmse_ratio_still']:.1%} "
          f"(95% interval {ci_t[0]:.0%}-{ci_t[1]:.0%}), rotation {res['rotation_deg_ratio_still']:.1%} "
          f"({ci_r[0]:.0%}-{ci_r[1]:.0%}); last frame {res['translation_rmse_last_ratio_still']:.1%}"
          f" / {res['rotation_deg_last_ratio_still']:.1%}")
    if "collision_edges_per_step" in res:
        print(f"collision edges per scene-step {res['collision_edges_per_step']:.1f}, "
              f"{res['ms_per_step_batched']:.1f} ms per batched step, "
              f"floor penetration ratio {res['penetration_ratio']:.2f}")
    if "against" in res:
        ag = res["against"]
        print(f"against {ag['checkpoint']}: translation RMSE {ag['translation_rmse_final']:.4f} m, "
              f"rotation {ag['rotation_deg_final']:.2f} deg")
        for q, name in (("translation_rmse", "translation"), ("rotation_deg", "rotation"),
                        ("translation_rmse_last", "last-frame translation"),
                        ("rotation_deg_last", "last-frame rotation")):
            r, lo, hi = ag["ratios"][q]
            print(f"  ratio of medians (this / that), {name}: {r:.3f} (95% interval {lo:.3f}-{hi:.3f})")
    if "rotation_gain" in res:
        print(f"rotation gain (predicted / true turn of objects turning > 1 deg, median) "
              f"{res['rotation_gain']:.2f}; one-step spin gain (teacher-forced) "
              f"{res['one_step_spin_gain']:.2f}")
    if "one_step_free_flight" in res:
        if math.isfinite(res["one_step_free_flight"]):
            print(f"one-step free-flight acceleration error (RMS / |a| dt^2, {res['free_flight_steps']} "
                  f"steps, data's a = {res['free_flight_acceleration']:.2f} m/s^2) "
                  f"{res['one_step_free_flight']:.3f}")
        else:
            print(f"no free-flight metric: {res.get('one_step_free_flight_absent', 'undefined')}")


def plot_curves(res: dict[str, Any], path: Path) -> None:
    """Translation and rotation error against step (median over trajectories)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    given = int(res.get("given_poses", 1))
    t = np.arange(given, given + len(res["translation_rmse_curve"]))
    ax[0].plot(t, res["translation_rmse_curve"])
    ax[0].set(xlabel="frame (from 0)", ylabel="translation RMSE (m), median")
    ax[1].plot(t, res["rotation_deg_curve"])
    ax[1].set(xlabel="frame (from 0)", ylabel="rotation error (deg), median")
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_comparison_video(sim: LearnedSimulator, traj: Trajectory, path: Path) -> None:
    """Side-by-side video at real time: ground truth (left) and the learned rollout (right)."""
    from fignet_gym.data.viewer import (
        Camera,
        fit_camera,
        render_frames,
        side_by_side,
        trajectory_model,
        write_video,
    )

    H = sim.config.history + 1
    scene = build_scene(traj, sim.config.mesh_options)
    true = torch.as_tensor(traj.poses, dtype=torch.float32)
    pred, _, _ = batched_rollout(sim, scene, true)
    pred_full = torch.cat((true[:H], pred)).double().numpy()
    model, bodies = trajectory_model(traj)
    # One camera for both halves, framed on the ground truth, so the two are comparable.
    cam = fit_camera(model, bodies, traj.poses)
    fixed = Camera(lookat=tuple(cam.lookat), distance=float(cam.distance))
    left = render_frames(model, traj.poses, bodies, 360, 360, fixed)
    right = render_frames(model, pred_full, bodies, 360, 360, fixed)
    left = [_label(f, "MuJoCo (ground truth)") for f in left]
    right = [_label(f, "FIGNet rollout") for f in right]
    write_video(side_by_side(left, right), path, fps=1.0 / traj.dt)


def _label(frame: np.ndarray, text: str) -> np.ndarray:
    """The frame ``uint8[H, W, 3]`` with ``text`` written in its top-left corner."""
    from PIL import Image, ImageDraw

    img = Image.fromarray(frame)
    draw = ImageDraw.Draw(img)
    draw.rectangle((0, 0, 8 + 7 * len(text), 20), fill=(0, 0, 0))
    draw.text((4, 4), text, fill=(255, 255, 255))
    return np.asarray(img)
