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
from fignet_gym.simulator.scene import Scene


def _common_steps(trajs: list[Trajectory], H: int) -> int:
    """Steps every trajectory has after its first ``H`` poses (rollouts are cut to the shortest)."""
    steps = min(t.num_steps for t in trajs) - H
    if steps < 1:
        raise ValueError(f"trajectories need more than {H} poses to evaluate")
    return steps


def _stack(trajs: list[Trajectory], scenes: list[Scene], steps: int, H: int
           ) -> tuple[Scene, Tensor]:
    """Batch scene and true poses ``float[H + steps, O_total, 7]`` of equal-length prefixes."""
    poses = torch.cat([torch.as_tensor(t.poses[:H + steps], dtype=torch.float32) for t in trajs], 1)
    return Scene.batch(scenes), poses


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


@torch.no_grad()
def one_step_errors(sim: LearnedSimulator, scene: Scene, true: Tensor) -> dict[str, float]:
    """Teacher-forced one-step errors over ``true float[H + T, O, 7]`` (a batched scene).

    Each step starts from the true history. Errors of dynamic objects' next poses, summed over
    objects and steps, are divided by the motion over the step: ``one_step_translation`` is
    ``sum |c_pred - c_true| / sum |c_true - c_prev|`` (centres of mass) and ``one_step_rotation``
    the same with geodesic angles; ``one_step_constvel_*`` are those of the constant-velocity
    model, the bar a useful simulator must clear.

    ``one_step_spin_gain`` is the least-squares slope of the predicted change of angular
    velocity (per step, as a rotation vector) on the true one: 1 when the model's torques are
    right in size on average, below 1 when it turns objects too little. It moves long before
    rollout rotation errors do (a model that gets half of a push's initial spin and then keeps it
    scores 0.5 here).

    ``one_step_free_flight`` is the RMS error of the predicted centre-of-mass acceleration of
    objects in free flight (whose true acceleration over the history and the step is the
    simulator's gravity prior), as a fraction of ``|g| dt^2``; NaN without a gravity prior or free
    objects. Free flight is the easy part of a toss, and its errors grow over every flight.
    """
    H = sim.config.history + 1
    dev = sim.device
    scene = scene.to(dev)
    true = true.to(dev)
    dyn = scene.dynamic_mask
    g = sim.gravity_step()
    g_norm = float(g.norm())
    com = scene.com_positions(true)  # float[T, O, 3]
    # Free where the true acceleration is the gravity prior; 2% absorbs float32 storage of poses.
    free = ((com[2:] - 2 * com[1:-1] + com[:-2] - g).norm(dim=-1) < 0.02 * g_norm) & dyn  # [T-2, O]
    sums = torch.zeros(10, dtype=torch.float64)
    for t in range(H, true.shape[0]):
        poses = (sim.step(scene, true[t - H:t], true[t]),
                 constant_velocity(true[t - 2:t + 1], 2)[0], true[t], true[t - 1])
        coms = [scene.com_positions(x) for x in poses[:2]] + [com[t], com[t - 1]]
        c = [x[dyn] for x in coms]
        pred, cv, nxt, cur = (x[dyn] for x in poses)
        # [model, constant velocity, true motion] for translation, then for rotation.
        terms = ([(c[i] - c[2]).norm(dim=-1).sum() for i in (0, 1, 3)]
                 + [quat_angle(x[:, 3:], nxt[:, 3:]).sum() for x in (pred, cv, cur)])
        prev = true[t - 2][dyn, 3:]
        d_pred, d_true = (spin_change(prev, cur[:, 3:], x[:, 3:]) for x in (pred, nxt))
        terms += [(d_pred * d_true).sum(), (d_true * d_true).sum()]
        # Steps t-2 -> t-1 -> t (the history) and t-1 -> t -> t+1 (the predicted one) are free.
        fly = free[t - 2] & free[max(t - 3, 0)] if g_norm > 0 else torch.zeros_like(dyn)
        acc = coms[0] - 2 * com[t - 1] + com[t - 2]
        terms += [((acc[fly] - g) ** 2).sum(), fly.sum()]
        sums += torch.stack(terms).double().cpu()
    out = {}
    for i, kind in ((0, "translation"), (3, "rotation")):
        total = float(sums[i + 2])
        out[f"one_step_{kind}"] = float(sums[i]) / total if total > 0 else math.nan
        out[f"one_step_constvel_{kind}"] = float(sums[i + 1]) / total if total > 0 else math.nan
    out["one_step_spin_gain"] = float(sums[6] / sums[7]) if sums[7] > 0 else math.nan
    out["one_step_free_flight"] = (math.sqrt(float(sums[8] / sums[9])) / g_norm if sums[9] > 0
                                   else math.nan)
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


def rollout_metrics(sim: LearnedSimulator, trajs: list[Trajectory], scenes: list[Scene] | None = None,
                    horizon: int = 50) -> dict[str, Any]:
    """Rollout all trajectories in one batch (cut to the shortest) and summarise.

    ``*_final`` values are at step ``min(horizon, T)``; ``*_curve`` are per-step medians over
    trajectories; ``*_ratio_*`` divide the model's median error by a reference model's.
    """
    H = sim.config.history + 1
    scenes = scenes or [build_scene(t, sim.config.mesh_options) for t in trajs]
    steps = _common_steps(trajs, H)
    scene, true = _stack(trajs, scenes, steps, H)
    pred, edges, secs = batched_rollout(sim, scene, true)
    gt = true[H:]
    k = min(horizon, steps) - 1
    out: dict[str, Any] = {"steps": steps, "horizon_step": k + 1, "seconds": (k + 1) * sim.config.dt,
                           "trajectories": len(trajs), "ms_per_step_batched": 1000 * secs,
                           "collision_edges_per_step": float(np.mean(edges)) / len(trajs)}
    out.update(final_errors(scene, pred, true, H, k))
    out.update(one_step_errors(sim, scene, true))
    out["rotation_gain"] = rotation_gain(scene.dynamic_mask, true[H - 1], pred[k], gt[k])
    pen_p, pen_t = floor_penetration(scene, pred).mean(), floor_penetration(scene, gt).mean()
    out["penetration_ratio"] = float(pen_p / pen_t) if pen_t > 0 else math.nan
    out["penetration_m"] = float(pen_p)
    return out


def final_errors(scene: Scene, pred: Tensor, true: Tensor, H: int, k: int) -> dict[str, Any]:
    """Errors of a rollout and of the reference models, ``k`` steps after the ``H`` given poses.

    ``pred float[T, O, 7]`` follows ``true float[H + T, O, 7]`` (a batch of scenes). Medians over
    scenes (``*_final``), per-step median curves, each scene's error, and ratios to the
    reference models with a bootstrap interval for the ratio to no motion.
    """
    gt = true[H:]
    still = true[H - 1][None].expand_as(gt)
    out: dict[str, Any] = {}
    per_model = {}
    for name, p in (("", pred), ("still_", still), ("constvel_", constant_velocity(true, H))):
        tr, rot = errors(scene, p, gt)
        per_model[name] = (tr, rot)
        out[f"{name}translation_rmse_final"] = float(tr[k].median())
        out[f"{name}rotation_deg_final"] = float(rot[k].median())
        if not name:
            out["translation_rmse_curve"] = tr.median(1).values.tolist()
            out["rotation_deg_curve"] = rot.median(1).values.tolist()
    for ref in ("still", "constvel"):
        for q in ("translation_rmse", "rotation_deg"):
            denom = out[f"{ref}_{q}_final"]
            out[f"{q}_ratio_{ref}"] = out[f"{q}_final"] / denom if denom > 0 else math.nan
    for i, q in enumerate(("translation_rmse", "rotation_deg")):
        out[f"{q}_ratio_still_ci95"] = median_ratio_interval(per_model[""][i][k].numpy(),
                                                             per_model["still_"][i][k].numpy())
        out[f"{q}_per_trajectory"] = per_model[""][i][k].tolist()
    return out


def perturbation_floor(trajs: list[Trajectory], position_noise: float, history: int = 2,
                       horizon: int = 50, seed: int = 0) -> dict[str, Any]:
    """The rollout errors of MuJoCo itself when its start is off by ``position_noise`` (m).

    Each generated trajectory is re-simulated (:func:`~fignet_gym.data.generate.resimulate`)
    with every free body moved horizontally by ``position_noise`` at the last of the
    ``history + 1`` poses a learned rollout starts from, and scored as :func:`rollout_metrics`
    scores a model (same keys). On chaotic data (tosses) this is a floor: a learned simulator
    whose state is off by ``position_noise`` after one step is at best a perfect simulator
    started that far off, so its rollouts are not expected to beat these errors.
    """
    from fignet_gym.data.generate import resimulate

    H = history + 1
    steps = _common_steps(trajs, H)
    scene, true = _stack(trajs, [build_scene(t) for t in trajs], steps, H)
    pred = torch.cat([torch.as_tensor(resimulate(t, position_noise, H - 1, seed + i)[H:H + steps],
                                      dtype=torch.float32) for i, t in enumerate(trajs)], 1)
    k = min(horizon, steps) - 1
    out: dict[str, Any] = {"position_noise": position_noise, "steps": steps, "horizon_step": k + 1,
                           "trajectories": len(trajs)}
    out.update(final_errors(scene, pred, true, H, k))
    return out


def floor_table(data: str, noises: list[float], out: str | None = None, num: int = 32,
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
    """Ratios of two models' median errors on the same trajectories (of the ``*_final`` medians
    that :func:`rollout_metrics` reports), with bootstrap 95% intervals (trajectories resampled
    in pairs): ``{"translation_rmse": [ratio, lo, hi], "rotation_deg": [...]}``.
    """
    out: dict[str, Any] = {}
    for q in ("translation_rmse", "rotation_deg"):
        a, b = (np.asarray(r[f"{q}_per_trajectory"]) for r in (res, ref))
        if a.shape != b.shape:
            raise ValueError(f"paired ratios need the same trajectories ({a.shape} vs {b.shape})")
        den = ref[f"{q}_final"]
        out[q] = [res[f"{q}_final"] / den if den > 0 else math.nan, *median_ratio_interval(a, b)]
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


def evaluate(checkpoint: str, data: str, out: str, num: int = 32, horizon: int = 50,
             videos: int = 2, against: str | None = None) -> dict[str, Any]:
    """Evaluate a checkpoint on a trajectory file: print a table, write JSON, plots and videos.

    ``against``: a second checkpoint rolled out on the same trajectories; the ratios of the two
    models' median errors, with bootstrap intervals, are printed and stored under ``"against"``.
    """
    from fignet_gym.data.format import load_trajectories
    from fignet_gym.pretrained import load_checkpoint

    if num < 1 or horizon < 1 or videos < 0:
        raise ValueError(f"evaluate: num and horizon must be >= 1 and videos >= 0, got "
                         f"{num}, {horizon}, {videos}")
    sim = load_checkpoint(checkpoint)
    trajs = load_trajectories(data)[:num]
    check_data_matches(sim, trajs, data)
    outdir = Path(out)
    outdir.mkdir(parents=True, exist_ok=True)
    res = rollout_metrics(sim, trajs, horizon=horizon)
    res.update(checkpoint=str(checkpoint), data=str(data))
    if against is not None:
        other = load_checkpoint(against)
        check_data_matches(other, trajs, data)
        ref = rollout_metrics(other, trajs, horizon=horizon)
        res["against"] = {"checkpoint": str(against), "translation_rmse_final": ref["translation_rmse_final"],
                          "rotation_deg_final": ref["rotation_deg_final"], "ratios": paired_ratios(res, ref)}
    (outdir / "metrics.json").write_text(json.dumps(res, indent=2))
    print_table(res)
    plot_curves(res, outdir / "errors.png")
    for i in range(min(videos, len(trajs))):
        write_comparison_video(sim, trajs[i], outdir / f"rollout_{i}.mp4")
    print(f"wrote {outdir}/metrics.json, errors.png and {min(videos, len(trajs))} videos")
    return res


def print_table(res: dict[str, Any]) -> None:
    """Print the headline metrics against the reference models."""
    h = res["horizon_step"]
    print(f"{res['trajectories']} trajectories, error at step {h} ({res['seconds']:.2f} s)")
    print(f"{'model':16s} {'transl. RMSE (m)':>17s} {'rotation (deg)':>15s}")
    for label, pre in (("FIGNet", ""), ("no motion", "still_"), ("const. velocity", "constvel_")):
        tr, rot = res[pre + "translation_rmse_final"], res[pre + "rotation_deg_final"]
        print(f"{label:16s} {tr:17.4f} {rot:15.2f}")
    ci_t, ci_r = res["translation_rmse_ratio_still_ci95"], res["rotation_deg_ratio_still_ci95"]
    print(f"ratio to no motion: translation {res['translation_rmse_ratio_still']:.1%} "
          f"(95% interval {ci_t[0]:.0%}-{ci_t[1]:.0%}), rotation {res['rotation_deg_ratio_still']:.1%} "
          f"({ci_r[0]:.0%}-{ci_r[1]:.0%})")
    print(f"collision edges per scene-step {res['collision_edges_per_step']:.1f}, "
          f"{res['ms_per_step_batched']:.1f} ms per batched step, "
          f"floor penetration ratio {res['penetration_ratio']:.2f}")
    if "against" in res:
        ag = res["against"]
        print(f"against {ag['checkpoint']}: translation RMSE {ag['translation_rmse_final']:.4f} m, "
              f"rotation {ag['rotation_deg_final']:.2f} deg")
        for q, name in (("translation_rmse", "translation"), ("rotation_deg", "rotation")):
            r, lo, hi = ag["ratios"][q]
            print(f"  ratio of medians (this / that), {name}: {r:.3f} (95% interval {lo:.3f}-{hi:.3f})")
    print(f"rotation gain (predicted / true turn of objects turning > 1 deg, median) "
          f"{res['rotation_gain']:.2f}; one-step spin gain (teacher-forced) "
          f"{res['one_step_spin_gain']:.2f}")
    if math.isfinite(res["one_step_free_flight"]):
        print(f"one-step free-flight acceleration error (RMS / |g| dt^2) {res['one_step_free_flight']:.3f}")


def plot_curves(res: dict[str, Any], path: Path) -> None:
    """Translation and rotation error against step (median over trajectories)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    t = np.arange(1, len(res["translation_rmse_curve"]) + 1)
    ax[0].plot(t, res["translation_rmse_curve"])
    ax[0].set(xlabel="step", ylabel="translation RMSE (m)")
    ax[1].plot(t, res["rotation_deg_curve"])
    ax[1].set(xlabel="step", ylabel="rotation error (deg)")
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
