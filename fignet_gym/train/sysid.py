"""System identification: MuJoCo's contact parameters fitted to trajectories by CMA-ES (``cma``).

The search space (:data:`DEFAULT_SPACE`, each parameter scaled to [0, 1], log scales for the
positive ones): sliding and torsional friction, ``solref`` time constant and damping ratio,
gravity along z and, for the elliptic cone, ``impratio``. The friction cone is categorical: one
CMA-ES run per cone. Each candidate is scored by :func:`replay_loss` on the training trajectories
(MuJoCo replaying them from their first poses, :mod:`fignet_gym.train.analytic`); the best point
of each run and each run's final mean are then scored on the validation trajectories, which pick
the fit (the test split is never looked at here). The number of substeps per data step is chosen
on validation too, among :data:`SUBSTEPS`.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cma
import mujoco
import numpy as np
import torch
from tqdm import tqdm

from fignet_gym.data.format import Trajectory
from fignet_gym.dynamics.contact_params import CONES, ContactParams
from fignet_gym.dynamics.mujoco import MujocoDynamics, collect_warnings, unstable_summary
from fignet_gym.simulator.geometry import transform_points
from fignet_gym.train.analytic import GIVEN_POSES, Replay

#: Loss scales: 1 cm of translation RMSE weighs as much as 10 degrees of rotation error.
TRANSLATION_SCALE, ROTATION_SCALE = 0.01, 10.0
#: Per-frame errors are clipped at this many scales, so a few tosses that land on another face
#: (90+ degrees) do not decide the fit alone.
CLIP = 10.0
#: Candidate substeps (MuJoCo timesteps per data step) as multiples of the MJCF's own, chosen on
#: validation.
SUBSTEP_FACTORS = (0.5, 1.0, 2.0)
#: A start of the search is kept this far (in unit coordinates) inside the bounds, so that CMA-ES
#: can step both ways.
UNIT_MARGIN = 0.02
#: CMA-ES initial step size, in unit coordinates.
CMA_SIGMA0 = 0.25
#: Start of a pusher's friction when the MJCF has no kinematic geom to read it from.
KINEMATIC_FRICTION_START = 0.2
#: Frames of each trajectory the loss averages over, and the weight of its last frame.
FIT_FRAMES, LAST_FRAME_WEIGHT = 100, 0.5
#: MuJoCo needs a contact time constant of at least this many timesteps to stay stable.
MIN_TIMECONST_STEPS = 2
#: Default frame (from 0) of the reported errors.
HORIZON = 50


@dataclass(frozen=True)
class Dimension:
    """One searched parameter: ``name`` of :class:`ContactParams`, bounds, log scale or not."""

    name: str
    low: float
    high: float
    log: bool = True

    def value(self, u: float) -> float:
        u = float(np.clip(u, 0.0, 1.0))
        if self.log:
            return float(math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low))))
        return float(self.low + u * (self.high - self.low))

    def unit(self, v: float) -> float:
        if self.log:
            u = (math.log(v) - math.log(self.low)) / (math.log(self.high) - math.log(self.low))
        else:
            u = (v - self.low) / (self.high - self.low)
        return float(np.clip(u, UNIT_MARGIN, 1.0 - UNIT_MARGIN))


#: The searched family (bounds wide around the nominal values; the time constant stays above
#: two timesteps of the finest substep choice at the cube data's 1/148 s).
DEFAULT_SPACE: tuple[Dimension, ...] = (
    Dimension("friction", 0.02, 1.5),
    Dimension("torsional", 1e-5, 0.05),
    Dimension("timeconst", 0.002, 0.1),
    Dimension("dampratio", 0.05, 3.0),
    Dimension("gravity", -10.3, -9.3, log=False),
)
#: Searched with the elliptic cone only (it has no effect on the pyramidal one's solution).
ELLIPTIC_ONLY: tuple[Dimension, ...] = (Dimension("impratio", 1.0, 30.0),)
#: Searched when the scenes have kinematic objects (a pusher's own friction).
KINEMATIC_ONLY: tuple[Dimension, ...] = (Dimension("friction_kinematic", 0.02, 1.5),)


def _angle_deg(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Geodesic angle (deg) between unit quaternions ``float[..., 4]``."""
    d = np.abs(np.sum(q1 * q2, axis=-1))
    return np.rad2deg(2.0 * np.arccos(np.clip(d, 0.0, 1.0)))


class ReplaySet:
    """Trajectories prepared for many replays: compiled models, centres of mass, dynamic objects.

    Args:
        trajs: trajectories with MJCFs. given: poses a rollout starts from (``history + 1``).
        horizon: frame (from 0) of the reported errors (``errors_at``).
    """

    def __init__(self, trajs: Sequence[Trajectory], given: int = GIVEN_POSES, horizon: int = HORIZON
                 ) -> None:
        self.trajs = list(trajs)
        self.given, self.horizon = given, horizon
        self.replays = [Replay(t) for t in self.trajs]
        self.dyn = [r.scene.dynamic_mask.numpy() for r in self.replays]
        self.com = [r.scene.object_com.double().numpy() for r in self.replays]
        self.dynamics = MujocoDynamics(nthread=1)
        self.rollouts = 0

    def predict(self, params: ContactParams) -> list[np.ndarray]:
        """Replayed poses ``float[T_i, O_i, 7]`` of every trajectory."""
        self.rollouts += len(self.replays)
        return [r.rollout(params, self.dynamics, self.given) for r in self.replays]

    def frame_errors(self, preds: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per-frame translation RMSE (m) and mean rotation error (deg) over dynamic objects."""
        out = []
        for t, p, dyn, com in zip(self.trajs, preds, self.dyn, self.com, strict=True):
            true = np.asarray(t.poses, float)
            c_p = _com(p, com)[:, dyn]
            c_t = _com(true, com)[:, dyn]
            tr = np.sqrt(((c_p - c_t) ** 2).sum(-1).mean(-1))
            rot = _angle_deg(p[:, dyn, 3:], true[:, dyn, 3:]).mean(-1)
            out.append((tr, rot))
        return out


def _com(poses: np.ndarray, com: np.ndarray) -> np.ndarray:
    """World centre-of-mass positions ``float[T, O, 3]`` of body poses ``float[T, O, 7]``."""
    return transform_points(torch.as_tensor(poses), torch.as_tensor(com)).numpy()


def replay_loss(errs: list[tuple[np.ndarray, np.ndarray]], given: int, fit_frames: int = FIT_FRAMES,
                last_weight: float = LAST_FRAME_WEIGHT) -> float:
    """Fit loss: mean over trajectories of the mean over frames ``given .. fit_frames - 1`` of
    ``min(e / 1 cm, 10) + min(r / 10 deg, 10)``, plus ``last_weight`` times the same at each
    trajectory's last frame."""
    total = 0.0
    for tr, rot in errs:
        s = np.minimum(tr / TRANSLATION_SCALE, CLIP) + np.minimum(rot / ROTATION_SCALE, CLIP)
        total += float(s[given:fit_frames].mean()) + last_weight * float(s[-1])
    return total / max(len(errs), 1)


def summary(errs: list[tuple[np.ndarray, np.ndarray]], horizon: int) -> dict[str, float]:
    """Median translation (m) and rotation (deg) errors at frame ``horizon`` and the last frame."""
    at = [(tr[horizon], rot[horizon]) for tr, rot in errs if len(tr) > horizon]
    last = [(tr[-1], rot[-1]) for tr, rot in errs]
    med = lambda xs, i: float(np.median([x[i] for x in xs])) if xs else math.nan  # noqa: E731
    return {"translation_m": med(at, 0), "rotation_deg": med(at, 1),
            "translation_last_m": med(last, 0), "rotation_last_deg": med(last, 1)}


def _params_at(base: ContactParams, space: Sequence[Dimension], u: np.ndarray, cone: str
               ) -> ContactParams:
    return replace(base, cone=cone, **{d.name: d.value(x) for d, x in zip(space, u, strict=True)})


def _nominal_value(base: ContactParams, d: Dimension, model_value: float) -> float:
    v = getattr(base, d.name)
    return float(model_value if v is None else v)


def fit_contact_params(
    train: Sequence[Trajectory], valid: Sequence[Trajectory], out: str | os.PathLike | None = None,
    *, base: ContactParams | None = None, space: Sequence[Dimension] | None = None,
    cones: Sequence[str] = CONES, evaluations: int = 240, fit_trajectories: int = 64,
    given: int = GIVEN_POSES, horizon: int = HORIZON, seed: int = 0, substeps: Sequence[int] | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Fit :class:`ContactParams` to ``train`` by CMA-ES, one run per friction cone; select on
    ``valid``.

    Args:
        base: fixed settings (substeps, integrator ...) and the start of the search (default:
            the MJCF's own values, i.e. the data's nominal friction and restitution).
        space: searched parameters (default :data:`DEFAULT_SPACE`, plus
            :data:`KINEMATIC_ONLY` when the scenes have kinematic objects).
        evaluations: CMA-ES candidates per cone (each replays ``fit_trajectories`` training
            trajectories, a seeded sample of ``train``), rounded up to whole generations. MuJoCo's
            instability warnings are counted (``unstable_candidates`` per cone, one summary
            line), not printed, and no ``MUJOCO_LOG.TXT`` is written.
        substeps: candidates chosen on validation (default: :data:`SUBSTEP_FACTORS` times the
            MJCF's own, i.e. ``base.substeps`` or ``dt / timestep``).
        out: JSON file of the result; a finished run there is returned as is (resumable per cone:
            each finished cone is kept in ``<out>.partial.json``).

    Returns ``{"params": ContactParams JSON, "cone_runs": [...], "valid": summary, ...}``.
    """
    with collect_warnings() as warned:  # the validation replays' (the search counts its own)
        result = _fit(train, valid, out, base=base, space=space, cones=cones,
                      evaluations=evaluations, fit_trajectories=fit_trajectories, given=given,
                      horizon=horizon, seed=seed, substeps=substeps, progress=progress)
    if warned and progress:
        print(f"fit MuJoCo, validation replays: MuJoCo warned {len(warned)} times ("
              f"{warned[0].split('.')[0]}); such replays hold their last finite poses and score "
              "as they are")
    return result


def _fit(train: Sequence[Trajectory], valid: Sequence[Trajectory], out: str | os.PathLike | None,
         *, base: ContactParams | None, space: Sequence[Dimension] | None, cones: Sequence[str],
         evaluations: int, fit_trajectories: int, given: int, horizon: int, seed: int,
         substeps: Sequence[int] | None, progress: bool) -> dict[str, Any]:
    """:func:`fit_contact_params` inside its warning collector."""
    out_path = Path(out) if out is not None else None
    if out_path is not None and out_path.is_file():
        return json.loads(out_path.read_text())
    partial_path = out_path.with_suffix(".partial.json") if out_path else None
    partial: dict[str, Any] = (json.loads(partial_path.read_text())
                               if partial_path is not None and partial_path.is_file() else {})
    base = base or ContactParams()
    for c in cones:
        if c not in CONES:
            raise ValueError(f"unknown cone {c!r}; valid: {CONES}")
    rng = np.random.default_rng(seed)
    pick = (rng.choice(len(train), fit_trajectories, replace=False).tolist()
            if len(train) > fit_trajectories else list(range(len(train))))
    fit_set = ReplaySet([train[i] for i in pick], given, horizon)
    valid_set = ReplaySet(valid, given, horizon)
    m0 = fit_set.replays[0].base
    if space is None:
        space = DEFAULT_SPACE + (KINEMATIC_ONLY if m0.nmocap else ())
    kin_geoms = [g for g in range(m0.ngeom) if m0.body_mocapid[m0.geom_bodyid[g]] >= 0]
    start = {"friction": float(m0.geom_friction[0, 0]), "torsional": float(m0.geom_friction[0, 1]),
             "timeconst": float(m0.geom_solref[0, 0]), "dampratio": float(m0.geom_solref[0, 1]),
             "gravity": float(m0.opt.gravity[2]), "impratio": float(m0.opt.impratio),
             "friction_kinematic": (float(m0.geom_friction[kin_geoms[0], 0]) if kin_geoms
                                    else KINEMATIC_FRICTION_START)}
    t0 = time.process_time()
    runs = partial.get("cone_runs", [])
    done = {r["cone"] for r in runs}
    for cone in cones:
        if cone in done:
            continue
        dims = list(space) + (list(ELLIPTIC_ONLY) if cone == "elliptic" else [])
        x0 = [d.unit(_nominal_value(base, d, start.get(d.name, (d.low + d.high) / 2))) for d in dims]
        es = cma.CMAEvolutionStrategy(x0, CMA_SIGMA0, {"bounds": [0, 1], "seed": seed + 1,
                                                  "maxfevals": evaluations, "verbose": -9})
        history = []
        bar = None
        if progress:
            # CMA-ES stops after the generation that reaches ``evaluations``: whole generations.
            total = -(-evaluations // es.popsize) * es.popsize
            bar = tqdm(total=total, desc=f"fit MuJoCo ({cone} cone)", unit="eval",
                       leave=False)
        unstable = 0
        with collect_warnings() as warned:
            while not es.stop():
                xs = es.ask()
                losses = []
                for x in xs:
                    p = _params_at(base, dims, np.asarray(x), cone)
                    before = len(warned)
                    losses.append(replay_loss(fit_set.frame_errors(fit_set.predict(p)), given))
                    unstable += len(warned) > before
                    if bar is not None:
                        bar.update(1)
                es.tell(xs, losses)
                history.append(float(min(losses)))
        if bar is not None:
            bar.total = bar.n  # a search that converged early ends where it stopped
            bar.close()
        if unstable and progress:
            print(unstable_summary(f"fit MuJoCo ({cone} cone) candidates", unstable,
                                   int(es.result.evaluations)))
        cands = {"best": np.asarray(es.result.xbest), "mean": np.asarray(es.result.xfavorite)}
        cand_res = {}
        for label, x in cands.items():
            p = _params_at(base, dims, x, cone)
            errs = valid_set.frame_errors(valid_set.predict(p))
            cand_res[label] = {"params": p.to_json(), "valid_loss": replay_loss(errs, given),
                               "valid": summary(errs, horizon)}
        runs.append({"cone": cone, "train_loss_best": float(es.result.fbest),
                     "evaluations": int(es.result.evaluations), "unstable_candidates": unstable,
                     "loss_per_iteration": history,
                     "candidates": cand_res})
        if partial_path is not None:
            partial_path.parent.mkdir(parents=True, exist_ok=True)
            partial_path.write_text(json.dumps({"cone_runs": runs}, indent=1))
    best = min(((r, c) for r in runs for c in r["candidates"].values()),
               key=lambda rc: rc[1]["valid_loss"])
    chosen = ContactParams.from_json(best[1]["params"])
    n0 = base.substeps_for(m0, valid[0].dt)
    if substeps is None:
        substeps = sorted({max(1, int(round(n0 * f))) for f in SUBSTEP_FACTORS})
    if chosen.substeps is None:
        chosen = replace(chosen, substeps=n0)
    sub_res = {}
    for n in substeps:  # the timestep, chosen on validation with the other parameters fixed
        p = replace(chosen, substeps=int(n))
        if p.timeconst is not None and p.timeconst < MIN_TIMECONST_STEPS * (valid[0].dt / n):
            continue  # MuJoCo needs timeconst >= 2 timesteps for a stable contact
        errs = valid_set.frame_errors(valid_set.predict(p))
        sub_res[int(n)] = {"valid_loss": replay_loss(errs, given), "valid": summary(errs, horizon)}
    if sub_res:
        n_best = min(sub_res, key=lambda n: sub_res[n]["valid_loss"])
        chosen = replace(chosen, substeps=n_best)
    result = {"params": chosen.to_json(), "valid": sub_res.get(chosen.substeps, best[1])["valid"],
              "valid_loss": sub_res.get(chosen.substeps, best[1])["valid_loss"],
              "cone_runs": runs, "substeps_on_valid": {str(k): v for k, v in sub_res.items()},
              "fit_trajectories": [t.name for t in fit_set.trajs],
              "valid_trajectories": len(valid), "given_poses": given, "horizon": horizon,
              "space": [d.__dict__ for d in space], "seed": seed,
              "rollouts": fit_set.rollouts + valid_set.rollouts,
              "cpu_seconds": time.process_time() - t0 + partial.get("cpu_seconds", 0.0),
              "mujoco_version": mujoco.__version__, "cma_version": cma.__version__}
    if out_path is not None:
        out_path.parent.mkdir(parents=True, exist_ok=True)
        out_path.write_text(json.dumps(result, indent=1))
        if partial_path is not None:
            partial_path.unlink(missing_ok=True)
    return result


def env_parameters(params: ContactParams, dt: float, source: str) -> dict[str, Any]:
    """The fitted parameters as shipped next to a model (``pretrained/<name>.mujoco.json``, read by
    the envs and ``evaluate --against mujoco:<name>``): :meth:`ContactParams.to_json` with
    ``source``. The fit must have chosen its substeps (``dt / substeps`` is the timestep)."""
    if params.substeps is None:
        raise ValueError(f"fitted parameters without substeps: the timestep for data steps of {dt} s "
                         "is undefined")
    return replace(params, source=source).to_json()
