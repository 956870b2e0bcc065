"""Rollout evaluation of a learned simulator on a trajectory file (``fignet-gym evaluate``).

:func:`rollout_metrics` rolls a model out over every trajectory and adds to the paper's rollout
errors (:mod:`fignet_gym.train.metrics`) the teacher-forced one-step metrics
(:mod:`fignet_gym.train.one_step`), collision edges per step and milliseconds per learned step.
:func:`evaluate` is the command: checks, metrics, the comparison with a second checkpoint
(:mod:`fignet_gym.train.stats`) and the report (:mod:`fignet_gym.train.report`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import torch

from fignet_gym.data.format import Trajectory, build_scene, load_trajectories
from fignet_gym.data.split import group_members, trajectory_groups
from fignet_gym.dynamics.contact_params import SHIPPED_PREFIX, ContactParams, fit_path
from fignet_gym.dynamics.limit_surface import LS_PREFIX, load_limit_surface
from fignet_gym.dynamics.mujoco import MujocoDynamics, collect_warnings, unstable_summary
from fignet_gym.pretrained import load_pretrained
from fignet_gym.simulator.model import LearnedSimulator
from fignet_gym.simulator.scene import Scene
from fignet_gym.train.analytic import Replay, replay_all
from fignet_gym.train.data_checks import check_data_matches, check_dt
from fignet_gym.train.metrics import (
    HORIZON,
    penetration_summary,
    predictor_metrics,
    rotation_gain,
    score_rollouts,
    yaw_change,
    yaw_fit,
)
from fignet_gym.train.one_step import one_step_errors
from fignet_gym.train.real_baselines import LS_STEP
from fignet_gym.train.report import plot_curves, print_table, write_comparison_video
from fignet_gym.train.rollouts import ROLLOUT_BATCH, learned_rollouts, length_groups, pad_poses
from fignet_gym.train.stats import paired_ratios, per_recording

#: Side-by-side videos ``evaluate`` writes by default.
DEFAULT_VIDEOS = 2


def rollout_metrics(sim: LearnedSimulator, trajs: list[Trajectory], scenes: list[Scene] | None = None,
                    horizon: int = HORIZON, batch: int = ROLLOUT_BATCH) -> dict[str, Any]:
    """Roll out every trajectory over its own length and summarise (:func:`score_rollouts`).

    Checks each trajectory's ``dt`` against the model's. Adds the teacher-forced one-step errors,
    the rotation gain at the horizon, floor penetration, collision edges and timings.
    """
    check_dt(trajs, sim.config.dt)
    H = sim.config.history + 1
    scenes = scenes or [build_scene(t, sim.config.mesh_options) for t in trajs]
    preds, edges, secs = learned_rollouts(sim, trajs, scenes, batch)
    trues = [torch.as_tensor(t.poses, dtype=torch.float32) for t in trajs]
    out = score_rollouts(scenes, trues, preds, H, horizon, [t.name for t in trajs],
                         trajectory_groups(trajs))
    out.update(seconds=horizon * sim.config.dt, dt=sim.config.dt, ms_per_step_batched=1000 * secs,
               collision_edges_per_step=float(np.mean(edges)) if edges else math.nan)
    one: dict[str, Any] = {}
    sums: dict[str, list[tuple[float, float]]] = {}
    for idx in length_groups([t.num_steps for t in trajs], batch):
        T = max(trajs[i].num_steps for i in idx)
        scene = Scene.batch([scenes[i] for i in idx])
        true = torch.cat([pad_poses(trajs[i].poses, T) for i in idx], 1)
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
    yaw_p, yaw_t = [], []
    for i in reach:
        dyn = scenes[i].dynamic_mask
        yaw_t += yaw_change(trues[i][H - 1], trues[i][horizon])[dyn].tolist()
        yaw_p += yaw_change(trues[i][H - 1], preds[i][horizon])[dyn].tolist()
    out["yaw_slope"], out["yaw_correlation"] = yaw_fit(yaw_p, yaw_t)
    out.update(penetration_summary(scenes, preds, trues, H))
    return out


#: ``--against`` for MuJoCo exactly as each trajectory's stored MJCF says (no parameter changed).
NOMINAL = "mujoco:nominal"


def is_limit_surface_spec(against: str) -> bool:
    """Whether ``--against`` names a limit-surface fit (``limit-surface:<name or path>``)."""
    return against.startswith(LS_PREFIX)


def is_mujoco_spec(against: str) -> bool:
    """Whether ``--against`` names a fitted MuJoCo (``mujoco:<name>`` or a ``.json`` file) rather
    than a checkpoint."""
    return against.startswith(SHIPPED_PREFIX) or against.endswith(".json")


def evaluate(checkpoint: str, data: str, out: str, num: int | None = None,
             horizon: int | None = None, videos: int = DEFAULT_VIDEOS,
             against: str | None = None) -> dict[str, Any]:
    """Evaluate a checkpoint on a trajectory file: print a table, write JSON, plots and videos.

    ``num``: the first ``num`` trajectories (default: all). ``horizon``: frame of the headline
    errors, counted from frame 0 of each trajectory (default ``HORIZON``, or the last frame of
    the longest trajectory where that is shorter; a horizon no trajectory reaches is refused
    before any rollout); the last frame of each is scored too.

    ``against``: a second checkpoint rolled out on the same trajectories, or an analytic model
    replaying them from the same given poses: ``mujoco:nominal`` (each trajectory's own MJCF),
    a shipped fit such as ``mujoco:cube-real``, a path to a parameters JSON
    (:mod:`fignet_gym.dynamics.contact_params`), or the quasi-static pushing model
    ``limit-surface:push-real`` (a shipped fit) or ``limit-surface:<path.json>``;
    the ratios of the two models' median errors, with bootstrap intervals, are printed and stored
    under ``"against"``. Where several trajectories come from one recording (the windows of a
    real push), ``"per_recording"`` (and ``"against"["per_recording"]``) holds the same medians
    over recordings, each recording's windows averaged (:func:`~fignet_gym.train.stats.
    per_recording`). MuJoCo's instability warnings are counted in one line, not printed.
    """
    if (num is not None and num < 1) or (horizon is not None and horizon < 1) or videos < 0:
        raise ValueError(f"evaluate: num and horizon must be >= 1 and videos >= 0, got "
                         f"{num}, {horizon}, {videos}")
    sim = load_pretrained(checkpoint)
    trajs = load_trajectories(data)[:num]
    longest = max(t.num_steps for t in trajs) - 1  # the last frame any trajectory reaches
    if horizon is None:
        horizon = min(HORIZON, longest)
    elif horizon > longest:
        raise ValueError(f"{data}: no trajectory reaches frame {horizon} (the longest has "
                         f"{longest + 1} poses): pass --horizon {longest} or less")
    check_data_matches(sim, trajs, data)
    check_dt(trajs, sim.config.dt)
    other, params, dynamics = None, None, None
    if against is not None and is_limit_surface_spec(against):
        dynamics = load_limit_surface(against)
        params = LS_STEP
        replays = [Replay(t) for t in trajs]
        for r in replays:  # not a push scene: refused up front, in one line
            try:
                dynamics.validate(r.base, 1)
            except ValueError as err:
                raise ValueError(f"{data}: trajectory {r.traj.name!r}: {err}") from None
    elif against is not None and is_mujoco_spec(against):
        params = (ContactParams(source="nominal: the data's own MJCF") if against == NOMINAL
                  else ContactParams.load(fit_path(against), trajs[0].dt))
        replays = [Replay(t) for t in trajs]  # refuses trajectories without an MJCF, up front
    elif against is not None:
        other = load_pretrained(against)
        check_data_matches(other, trajs, data)
    outdir = Path(out)
    outdir.mkdir(parents=True, exist_ok=True)
    res = rollout_metrics(sim, trajs, horizon=horizon)
    res.update(checkpoint=str(checkpoint), data=str(data))
    if against is not None:
        given = sim.config.history + 1
        if dynamics is not None:
            preds = replay_all(trajs, params, dynamics, given=given, replays=replays)
            ref = predictor_metrics(trajs, preds, given, horizon)
            who = {"limit_surface": str(against), "params": {
                "tip_friction": dynamics.tip_friction, "pressure_scale": dynamics.pressure_scale}}
        elif params is not None:
            with collect_warnings() as warned:
                preds = []
                unstable = 0
                for r in replays:
                    before = len(warned)
                    preds.append(r.rollout(params, MujocoDynamics(nthread=1), given))
                    unstable += len(warned) > before
            if unstable:
                print(unstable_summary(f"--against {against} replays", unstable, len(replays)))
            ref = predictor_metrics(trajs, preds, given, horizon)
            who = {"mujoco": str(against), "params": params.to_json(), "unstable_replays": unstable}
        else:
            ref = rollout_metrics(other, trajs, horizon=horizon)
            who = {"checkpoint": str(against)}
        res["against"] = {**who, "ratios": paired_ratios(res, ref),
                          **{k: ref[k] for k in ("translation_rmse_final", "rotation_deg_final",
                                                 "translation_rmse_last", "rotation_deg_last")}}
    groups = trajectory_groups(trajs)
    if len(group_members(len(trajs), groups)) < len(trajs):  # None: a recording of its own
        res["per_recording"] = per_recording(res, ref if against is not None else None)
        if against is not None:
            res["against"]["per_recording"] = per_recording(ref)
    (outdir / "metrics.json").write_text(json.dumps(res, indent=2))
    print_table(res)
    plot_curves(res, outdir / "errors.png")
    for i in range(min(videos, len(trajs))):
        write_comparison_video(sim, trajs[i], outdir / f"rollout_{i}.mp4")
    print(f"wrote {outdir}/metrics.json, errors.png and {min(videos, len(trajs))} videos")
    return res
