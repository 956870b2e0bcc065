"""The paper's rollout metrics of any predictor of poses, and the reference models that scale them.

Metrics, over dynamic objects, for rollouts started from the first ``H`` true poses of each
trajectory with kinematic and static objects following their true poses:

* translation error: RMSE (m) of centre-of-mass positions over objects, at each step;
* rotation error: geodesic angle (degrees) between predicted and true orientations,
  ``2 acos(|<q_pred, q_true>|)``, averaged over objects, at each step;
* penetration: mean depth (m) of dynamic nodes below the floor plane ``z = 0`` per step, as a ratio
  of the prediction's to the ground truth's (MuJoCo's soft contacts penetrate a little too);
* rotation gain: median over objects of predicted / true turning angle at the horizon (below 1:
  the model turns objects too little).

Two reference models give the errors a scale: *no motion* (every object keeps its initial pose; the
unit of the paper's Fig. 7c) and *constant velocity* (each object keeps its last observed velocity).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from torch import Tensor

from fignet_gym.data.format import Trajectory, build_scene
from fignet_gym.data.split import trajectory_groups
from fignet_gym.simulator.geometry import (
    axis_angle_to_quat,
    quat_angle,
    quat_conj,
    quat_mul,
    quat_normalize,
    quat_to_axis_angle,
)
from fignet_gym.simulator.scene import Scene
from fignet_gym.train.stats import median_ratio_interval

#: Objects that truly turn by less than this (degrees) are left out of the rotation gain: the
#: ratio of two tiny angles is noise.
MIN_TURN_DEG = 1.0
#: Default frame of the headline errors, counted from frame 0 (the paper's 50 steps).
HORIZON = 50


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


def rotation_gain(dynamic: Tensor, start: Tensor, pred: Tensor, true: Tensor, min_deg: float = MIN_TURN_DEG
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


def yaw_change(start: Tensor, end: Tensor) -> Tensor:
    """Signed turn (rad) about the world vertical from ``start`` to ``end`` poses ``float[O, 7]``:
    ``float[O]`` in (-pi, pi], the twist about z of the relative rotation."""
    rel = quat_normalize(quat_mul(end[:, 3:], quat_conj(start[:, 3:])))  # w >= 0
    return 2 * torch.atan2(rel[:, 3], rel[:, 0])


def yaw_fit(pred: list[float], true: list[float]) -> tuple[float, float]:
    """``(slope, correlation)`` of predicted on true yaw changes (least squares with an
    intercept): 1 and 1 for a model that turns every object as much as the data does."""
    if len(true) < 3 or float(np.std(true)) == 0.0:
        return math.nan, math.nan
    p, t = np.asarray(pred), np.asarray(true)
    slope = float(np.polyfit(t, p, 1)[0])
    return slope, float(np.corrcoef(t, p)[0, 1])


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
                   horizon: int = HORIZON, names: list[str] | None = None,
                   groups: list[str | None] | None = None) -> dict[str, Any]:
    """The paper's rollout errors of any predictor, each trajectory over its own length.

    Args:
        scenes: one scene per trajectory. trues, preds: ``float[T_i, O_i, 7]`` full-length true
            and predicted poses (the first ``given`` predicted rows are the given true poses).
        given: poses the predictor was given (``history + 1``); they are not scored.
        horizon: frame (counted from frame 0 of each trajectory) of the ``*_final`` errors.
            Trajectories without that frame are left out of them (counted in
            ``horizon_trajectories``); every trajectory's last frame gives the ``*_last`` errors.
        groups: one recording key per trajectory (``data.split.trajectory_groups``): the
            bootstrap intervals resample whole recordings (windows of one push are correlated).
            The keys of the trajectories behind each median are returned as ``groups_final`` and
            ``groups_last``, so :func:`~fignet_gym.train.stats.paired_ratios` pairs them too.

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
    if groups is not None:
        out["groups_final"], out["groups_last"] = [groups[i] for i in reach], list(groups)
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
            out[f"{q}{suffix}_ratio_still_ci95"] = median_ratio_interval(
                model, still, groups=out.get(f"groups_{at}"))
            out[f"{q}{suffix}_per_trajectory"] = per[q][at]
            out[f"still_{q}{suffix}_per_trajectory"] = per[f"still_{q}"][at]
    if names is not None:
        out["names"] = list(names)
        out["horizon_names"] = [names[i] for i in reach]
    return out


def predictor_metrics(trajs: list[Trajectory], preds: list[np.ndarray], given: int = 3,
                      horizon: int = HORIZON) -> dict[str, Any]:
    """:func:`score_rollouts` of predicted poses ``float[T_i, O_i, 7]`` (an analytic simulator,
    say) on trajectories, with the same keys as :func:`rollout_metrics`'s rollout errors."""
    scenes = [build_scene(t) for t in trajs]
    trues = [torch.as_tensor(t.poses, dtype=torch.float32) for t in trajs]
    pred_t = [torch.as_tensor(np.asarray(p), dtype=torch.float32) for p in preds]
    out = score_rollouts(scenes, trues, pred_t, given, horizon, [t.name for t in trajs],
                         trajectory_groups(trajs))
    out.update(seconds=horizon * trajs[0].dt, dt=trajs[0].dt)
    out.update(penetration_summary(scenes, pred_t, trues, given))
    return out


def penetration_summary(scenes: list[Scene], preds: list[Tensor], trues: list[Tensor],
                        start: int) -> dict[str, float]:
    """Mean floor penetration (m) of predicted poses ``float[T_i, O_i, 7]`` from step ``start``
    on, and its ratio to the ground truth's (NaN when the truth never penetrates)."""
    pen_p = float(np.mean([floor_penetration(s, p[start:]).mean()
                           for s, p in zip(scenes, preds, strict=True)]))
    pen_t = float(np.mean([floor_penetration(s, t[start:]).mean()
                           for s, t in zip(scenes, trues, strict=True)]))
    return {"penetration_ratio": pen_p / pen_t if pen_t > 0 else math.nan, "penetration_m": pen_p}
