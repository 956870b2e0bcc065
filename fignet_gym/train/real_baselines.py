"""Two more reference points of ``sim2real`` on real data: the limit-surface pushing model fitted
on the training split, and the noise floor of the data's own tracking noise.

* :func:`limit_surface_stage` (pushes only): :class:`~fignet_gym.dynamics.limit_surface.
  LimitSurfaceDynamics` replaying the trajectories through the same
  :class:`~fignet_gym.train.analytic.Replay` path as MuJoCo, its two parameters (pusher friction,
  pressure-radius scale) chosen on a grid by the fit loss on the training split
  (:func:`~fignet_gym.train.sysid.replay_loss`), scored on test.
* :func:`tracking_noise` estimates the tracker's noise from the data: for white noise of standard
  deviation ``s`` on a smooth track, the second difference of consecutive poses has standard
  deviation ``sqrt(6) s``; a robust (median absolute deviation) estimate ignores the few impacts.
* :func:`noise_floor`: the fitted MuJoCo replayed from starts whose given poses carry that noise,
  scored against its own unperturbed replay. No deterministic predictor given noisy poses can be
  expected to beat it: it is how far the same simulator drifts from itself because of the noise.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fignet_gym.atomic import write_text
from fignet_gym.data.format import Trajectory
from fignet_gym.dynamics.limit_surface import LimitSurfaceDynamics, fit_limit_surface
from fignet_gym.simulator.scene import ObjectKind
from fignet_gym.train.analytic import ContactParams, _axis_angle, _conj, _quat_mul
from fignet_gym.train.metrics import predictor_metrics
from fignet_gym.train.stats import paired_ratios

#: The limit-surface grid: pusher-object friction and factor on the uniform-pressure radius.
LS_FRICTIONS = (0.05, 0.1, 0.2, 0.3, 0.45, 0.65, 0.9, 1.3, 2.0, 3.0, 5.0)
LS_SCALES = (0.6, 0.8, 1.0, 1.25, 1.5)
#: The limit surface is quasi-static: one MuJoCo timestep per data step (the length does not matter).
LS_STEP = ContactParams(substeps=1)
#: Median absolute deviation to standard deviation for Gaussian noise.
MAD_TO_STD = 1.4826
#: Perturbed replays per test trajectory in :func:`noise_floor`.
FLOOR_SAMPLES = 4


def _yaw_about_z(q: np.ndarray) -> np.ndarray:
    return 2.0 * np.arctan2(q[..., 3], q[..., 0])


def _rotation_vectors(q: np.ndarray) -> np.ndarray:
    """Rotation vectors ``float[T-1, 3]`` between consecutive unit quaternions ``float[T, 4]``."""
    return np.array([_axis_angle(_quat_mul(q[k + 1], _conj(q[k]))) for k in range(len(q) - 1)])


def tracking_noise(trajs: Sequence[Trajectory]) -> dict[str, float]:
    """Tracking noise of the dynamic objects: ``{"position_m": s_p, "rotation_deg": s_r}``,
    per axis, from robust second differences of positions and of rotation vectors (module
    docstring); ``planar`` says whether every object turned about z only."""
    dpos, drot, planar = [], [], True
    for t in trajs:
        for o in np.nonzero(t.kinds == int(ObjectKind.DYNAMIC))[0]:
            p = np.asarray(t.poses[:, o], float)
            if len(p) < 4:
                continue
            d2 = np.diff(p[:, :3], 2, axis=0)
            dpos.append(d2 - np.median(d2, axis=0))
            w = np.diff(_rotation_vectors(p[:, 3:]), axis=0)
            drot.append(w - np.median(w, axis=0))
            planar &= bool(np.abs(p[:, 4:6]).max() < 1e-6)
    if not dpos:
        raise ValueError("no dynamic object with 4 or more poses to estimate tracking noise from")
    pos, rot = np.concatenate(dpos), np.concatenate(drot)
    axes = slice(0, 2) if planar else slice(0, 3)
    rot_axes = slice(2, 3) if planar else slice(0, 3)
    s_p = MAD_TO_STD * float(np.median(np.abs(pos[:, axes]))) / math.sqrt(6)
    s_r = MAD_TO_STD * float(np.median(np.abs(rot[:, rot_axes]))) / math.sqrt(6)
    return {"position_m": s_p, "rotation_deg": math.degrees(s_r), "planar": planar}


def perturb_start(traj: Trajectory, given: int, position: float, rotation_deg: float,
                  rng: np.random.Generator, planar: bool) -> Trajectory:
    """A copy of ``traj`` whose first ``given`` poses of dynamic objects carry independent
    Gaussian noise (``position`` m per axis, ``rotation_deg`` per axis; about z only if
    ``planar``, and no vertical noise then)."""
    poses = np.array(traj.poses, float)
    for o in np.nonzero(traj.kinds == int(ObjectKind.DYNAMIC))[0]:
        for k in range(min(given, len(poses))):
            dp = rng.normal(0.0, position, 3)
            w = np.radians(rotation_deg) * rng.normal(0.0, 1.0, 3)
            if planar:
                dp[2], w[:2] = 0.0, 0.0
            angle = float(np.linalg.norm(w))
            axis = w / angle if angle > 0 else np.array([0.0, 0.0, 1.0])
            dq = np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])
            poses[k, o, :3] += dp
            poses[k, o, 3:] = _quat_mul(dq, poses[k, o, 3:])
    return dataclasses.replace(traj, poses=poses)


def noise_floor(trajs: Sequence[Trajectory], params: Any, noise: dict[str, float], given: int = 3,
                horizon: int = 50, samples: int = FLOOR_SAMPLES, seed: int = 0) -> dict[str, Any]:
    """The fitted MuJoCo (``params``, a ``ContactParams``) replayed from ``samples`` perturbed
    starts per trajectory (:func:`perturb_start` at ``noise``, from :func:`tracking_noise`),
    scored against its unperturbed replay (:func:`~fignet_gym.train.evaluation.predictor_metrics`
    keys; medians over all perturbed replays), except that the ``*_ratio_still`` divide them by
    the real data's no-motion errors (the unit of every other row of the table)."""
    # deferred: sysid loads CMA-ES and Matplotlib (~0.9 s); evaluation imports LS_STEP from here
    from fignet_gym.train.sysid import ReplaySet

    t0 = time.process_time()
    rng = np.random.default_rng(seed)
    clean = ReplaySet(trajs, given, horizon).predict(params)
    truths, noisy = [], []
    for t, c in zip(trajs, clean, strict=True):
        truth = dataclasses.replace(t, poses=c)
        for _ in range(samples):
            truths.append(truth)
            noisy.append(perturb_start(truth, given, noise["position_m"], noise["rotation_deg"],
                                       rng, bool(noise.get("planar", False))))
    preds = ReplaySet(noisy, given, horizon).predict(params)
    for p, n in zip(preds, noisy, strict=True):
        p[:given] = np.asarray(n.poses[:given])  # scored from the (noisy) poses it was given
    out = predictor_metrics(truths, preds, given, horizon)
    data = predictor_metrics(list(trajs), [np.asarray(t.poses, float) for t in trajs], given, horizon)
    for q in ("translation_rmse", "rotation_deg"):
        for suffix, at in (("", "final"), ("_last", "last")):
            still = data[f"still_{q}_{at}"]
            out[f"{q}{suffix}_ratio_still"] = out[f"{q}_{at}"] / still if still > 0 else math.nan
    out.update(noise=noise, samples=samples, cpu_seconds=time.process_time() - t0)
    return out


def fit_limit_surface_on(train: Sequence[Trajectory], given: int = 3, horizon: int = 50,
                         fit_trajectories: int = 64, seed: int = 0
                         ) -> tuple[float, float, dict[str, float]]:
    """Fit :class:`LimitSurfaceDynamics` on ``train``: grid :data:`LS_FRICTIONS` x
    :data:`LS_SCALES`, loss :func:`~fignet_gym.train.sysid.replay_loss` on a seeded sample of
    ``fit_trajectories``; returns ``(tip_friction, pressure_scale, grid)``."""
    # deferred: sysid loads CMA-ES and Matplotlib (~0.9 s); evaluation imports LS_STEP from here
    from fignet_gym.train.sysid import ReplaySet, replay_loss

    rng = np.random.default_rng(seed)
    pick = (rng.choice(len(train), fit_trajectories, replace=False).tolist()
            if len(train) > fit_trajectories else list(range(len(train))))
    fit_set = ReplaySet([train[i] for i in pick], given, horizon)

    def loss(dyn: LimitSurfaceDynamics) -> float:
        fit_set.dynamics = dyn
        return replay_loss(fit_set.frame_errors(fit_set.predict(LS_STEP)), given)

    return fit_limit_surface(loss, LS_FRICTIONS, LS_SCALES)


def limit_surface_stage(train: Sequence[Trajectory], test: Sequence[Trajectory], given: int = 3,
                        horizon: int = 50, fit_trajectories: int = 64, seed: int = 0
                        ) -> dict[str, Any]:
    """:func:`fit_limit_surface_on` ``train``, scored on ``test`` (``predictor_metrics`` keys,
    ``params``, ``grid``, ``cpu_seconds``)."""
    # deferred: sysid loads CMA-ES and Matplotlib (~0.9 s); evaluation imports LS_STEP from here
    from fignet_gym.train.sysid import ReplaySet

    t0 = time.process_time()
    mu, scale, grid = fit_limit_surface_on(train, given, horizon, fit_trajectories, seed)
    test_set = ReplaySet(test, given, horizon)
    test_set.dynamics = LimitSurfaceDynamics(mu, scale)
    out = predictor_metrics(list(test), test_set.predict(LS_STEP), given, horizon)
    out.update(params={"tip_friction": mu, "pressure_scale": scale}, grid=grid,
               cpu_seconds=time.process_time() - t0)
    return out


def run_stages(out: Any, train: Sequence[Trajectory], test: Sequence[Trajectory], fitted_params: Any,
               fitted: dict[str, Any], push: bool, given: int, horizon: int, fit_trajectories: int,
               seed: int) -> dict[str, dict[str, Any]]:
    """``sim2real``'s extra stages, each kept in ``out`` once done (resumable):
    ``limit_surface.json`` (pushes only: :func:`limit_surface_stage`, with paired ratios to the
    fitted MuJoCo metrics ``fitted``) and ``noise_floor.json`` (:func:`noise_floor` of the
    fitted MuJoCo at the training split's :func:`tracking_noise`)."""
    out = Path(out)
    res: dict[str, dict[str, Any]] = {}
    stages = [("noise_floor", lambda: noise_floor(test, fitted_params, tracking_noise(train), given,
                                                  horizon, seed=seed))]
    if push:
        stages.insert(0, ("limit_surface", lambda: limit_surface_stage(
            train, test, given, horizon, fit_trajectories, seed)))
    for name, run in stages:
        path = out / f"{name}.json"
        if path.is_file():
            res[name] = json.loads(path.read_text())
            continue
        print(f"{name.replace('_', ' ')} on the test split ...")
        r = run()
        if name == "limit_surface":
            r["vs_fitted_mujoco"] = paired_ratios(r, fitted)
        write_text(path, json.dumps(r, indent=1, default=float))
        res[name] = r
    return res


__all__ = ["FLOOR_SAMPLES", "LS_FRICTIONS", "LS_SCALES", "LS_STEP", "fit_limit_surface_on",
           "limit_surface_stage", "noise_floor", "perturb_start", "run_stages", "tracking_noise"]
