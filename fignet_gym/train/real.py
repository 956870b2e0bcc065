"""Training on small real data sets (tracked tosses): the gravity prior and one call per split.

:func:`free_flight_gravity` measures the acceleration of free flight from the data itself (real
rigs are not at 9.81 m/s^2 to the tracker: the ContactNets cube falls at 9.61 in its frame), and
:func:`train_on_split` trains the ``cube-real`` recipe on the first ``size`` trajectories of a
training file, selects its checkpoint on a validation file only, and resumes where a killed run
stopped. ``fignet-gym sim2real`` calls it once per training-set size.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from fignet_gym.data.format import Trajectory, build_scene, load_trajectories
from fignet_gym.train.config import TrainConfig, load_run_config
from fignet_gym.train.rundir import RunFolderError, check_resume_config
from fignet_gym.train.trainer import Trainer

#: Optimiser steps of ``cube-real`` by training-set size (the last entry for anything larger):
#: a few tosses are learned (and overfitted) sooner, so small sets get fewer steps. Selection on
#: validation picks the best checkpoint within them. Sized so that a whole ``sim2real`` sweep
#: (8 .. all of 240 tosses, with validations and MuJoCo's fit) stays within 2 CPU hours on one
#: core (experiments/README.md, real tosses, "Sweep budget").
DEFAULT_STEPS: tuple[tuple[int, int], ...] = ((8, 3000), (16, 4000), (32, 5000), (64, 8000),
                                              (128, 12000), (10**9, 20000))
#: Pushforward starts after this fraction of a run's steps (the ``cube-real`` preset's 5000 of
#: 40000): validation error kept falling only once it had started.
UNROLL_AFTER_FRACTION = 0.125
#: The rollout polish (``train_on_split(..., polish=True)``): after its base run, the selected
#: model is fine-tuned through 10-step rollouts (``training.rollout_steps``) for
#: :data:`POLISH_STEPS` steps, at the first 1000 steps' rates of the 1e-4 to 1e-5 schedule over
#: 3000 steps of the sixth round's fine-tunes (whose best checkpoints were at step 1000; 10
#: steps cost half of 20 and scored within validation noise of them). Selection still runs on
#: validation and the warm start is validated first, so the base model stays a candidate
#: (experiments/README.md, real tosses: the rollout-loss fine-tunes).
POLISH_STEPS = 1000
POLISH_OVERRIDES: dict[str, Any] = {"training.rollout_steps": 10, "training.lr": 1e-4,
                                    "training.lr_final": 4.64e-5, "training.unroll_after": 0}
#: ``sim2real`` polishes only training sets at least this large: with 16 tosses the rollout loss
#: fitted their particular landings (level on validation, a larger stop-short bias).
POLISH_MIN_SIZE = 64


class TrainingInterrupted(RuntimeError):
    """A :func:`train_on_split` run was stopped (SIGINT / SIGTERM) before its last step."""


def default_steps(size: int) -> int:
    """Optimiser steps :func:`train_on_split` takes for ``size`` training trajectories."""
    for limit, steps in DEFAULT_STEPS:
        if size <= limit:
            return steps
    return DEFAULT_STEPS[-1][1]


def finished_run(done: Path, best: Path, steps: int) -> Path:
    """``best`` of a finished run (``done`` its record), if it ran the ``steps`` asked for.

    Raises :class:`~fignet_gym.train.rundir.RunFolderError` otherwise: a budget changed between
    calls must not be answered with the old run's results.
    """
    ran = json.loads(done.read_text()).get("step")
    if ran != steps:
        raise RunFolderError(f"{done.parent}: holds a finished run of {ran} steps, asked for "
                             f"{steps}: use another run folder")
    return best


def free_flight_gravity(trajs: Sequence[Trajectory], clearance: float = 0.01, min_poses: int = 8
                        ) -> float:
    """Vertical acceleration (m/s^2, negative: down) of free flight, measured from poses.

    For each trajectory, the first poses in which every dynamic node is more than ``clearance``
    (m) above the floor plane ``z = 0`` (a toss before its first impact) are fitted with a
    parabola in time for the dynamic objects' mean centre-of-mass height; the result is the median
    over trajectories of ``2 a``. Trajectories with fewer than ``min_poses`` such poses are
    skipped; ``ValueError`` if none is left.
    """
    fits = []
    for traj in trajs:
        scene = build_scene(traj)
        dyn = scene.dynamic_mask
        poses = torch.as_tensor(traj.poses, dtype=torch.float32)
        low = scene.node_positions(poses)[:, dyn[scene.node_object], 2].amin(dim=1)  # [T]
        touching = (low <= clearance).nonzero()
        n = int(touching[0, 0]) if touching.numel() else poses.shape[0]
        if n < min_poses:
            continue
        z = scene.com_positions(poses[:n])[:, dyn, 2].mean(dim=1).double().numpy()
        t = np.arange(n) * traj.dt
        fits.append(2.0 * np.polyfit(t, z, 2)[0])
    if not fits:
        raise ValueError(f"no trajectory has {min_poses} poses of free flight (every dynamic node "
                         f"more than {clearance} m above z = 0) to measure gravity from")
    return float(np.median(fits))


def _trajectories(spec: str | os.PathLike | Sequence[Trajectory], what: str) -> list[Trajectory]:
    if isinstance(spec, (str, os.PathLike)):
        return load_trajectories(spec)
    trajs = list(spec)
    if not trajs or not all(isinstance(t, Trajectory) for t in trajs):
        raise TypeError(f"{what}: expected a trajectory file or a non-empty list of Trajectory")
    return trajs


def train_on_split(
    train: str | os.PathLike | Sequence[Trajectory],
    valid: str | os.PathLike | Sequence[Trajectory],
    size: int | None,
    out_dir: str | os.PathLike,
    budget: int | None = None,
    *,
    config: str = "cube-real",
    overrides: dict[str, Any] | None = None,
    seed: int = 0,
    init: str | None = None,
    polish: bool = False,
) -> Path:
    """Train a simulator on the first ``size`` training trajectories; return its best checkpoint.

    Args:
        train: training trajectories (a file or a list) in the split's order, so that size ``k``
            is the split's subset ``k`` (``fignet_gym.data.split.Split.subset``).
        valid: validation trajectories: checkpoints are selected on these only (never on test).
        size: how many training trajectories to use (``None``: all).
        out_dir: run folder (``best.pt``, ``last.pt``, ``curve.jsonl``, ``config.json``,
            ``split.json``). A run already there is resumed, a finished one returned as is.
        budget: optimiser steps (``None``: :func:`default_steps` of the size).
        config: preset or JSON config file (default ``cube-real``); ``overrides`` as for
            ``fignet-gym train --set``.
        seed: seed of initialisation, sampling and noise.
        init: fine-tune this checkpoint (a file or a pretrained name) instead of starting from
            scratch (a resumed run continues its own ``last.pt``).
        polish: then fine-tune the selected model through rollouts in ``out_dir / "polish"``
            (:data:`POLISH_OVERRIDES`, :data:`POLISH_STEPS` steps) and return that run's best.

    Raises :class:`TrainingInterrupted` if the run was stopped before its last step (its
    ``last.pt`` is written: calling again resumes it exactly).

    The gravity prior is measured on the training subset (:func:`free_flight_gravity`; for a
    fine-tune on the checkpoint's own data, its own prior) unless ``overrides`` sets
    ``simulator.gravity``. Returns
    ``out_dir / "best.pt"``.
    """
    trajs = _trajectories(train, "train")
    valid_trajs = _trajectories(valid, "valid")
    if size is not None:
        if not 1 <= size <= len(trajs):
            raise ValueError(f"train: a subset of {size} trajectories needs 1 to {len(trajs)}")
        trajs = trajs[:size]
    out = Path(out_dir)
    best = out / "best.pt"
    done = out / "done.json"
    sets: dict[str, Any] = dict(overrides or {})
    sets.setdefault("training.seed", seed)
    sets.setdefault("training.threads", 1)
    steps = int(budget) if budget is not None else default_steps(len(trajs))
    sets.setdefault("training.steps", steps)
    sets.setdefault("training.unroll_after", int(steps * UNROLL_AFTER_FRACTION))
    # Validate ~12 times per run whatever its length: early stopping needs points to choose
    # from, and a validation (80 full-length rollouts plus one-step errors) costs about as much
    # CPU as 500 training steps.
    sets.setdefault("training.valid_every", max(25, steps // 12))
    if "simulator.gravity" not in sets:
        # Fine-tunes too: on the data a checkpoint was trained on this is its own prior (its
        # accelerations are residuals of it; the preset's rounded -9.61 instead of a measured
        # -9.612 already moves the rollouts), on other data the data's gravity.
        sets["simulator.gravity"] = (0.0, 0.0, free_flight_gravity(trajs))
    sim_cfg, cfg = load_run_config(config, sets)
    # A run left in ``out`` (finished or not) is only reused when it is the run asked for: a
    # changed budget or recipe must not return stale results.
    check_resume_config(out, sim_cfg, asdict(cfg))
    if done.is_file() and best.is_file():
        finished_run(done, best, cfg.steps)  # refuses a finished run of another budget
    else:
        _train(out, sim_cfg, cfg, trajs, valid_trajs, init)
    if not polish:
        return best
    # The base run's schedule keys must not carry over; its gravity prior and recipe do.
    base = {k: v for k, v in sets.items()
            if k not in ("training.steps", "training.unroll_after", "training.valid_every")}
    return train_on_split(trajs, valid_trajs, None, out / "polish", POLISH_STEPS, config=config,
                          overrides={**base, **POLISH_OVERRIDES}, seed=seed, init=str(best))


def _train(out: Path, sim_cfg: dict[str, Any], cfg: TrainConfig, trajs: list[Trajectory],
           valid: list[Trajectory], init: str | None) -> None:
    """The training of :func:`train_on_split` into ``out`` (resumed if begun); writes
    ``done.json`` when it reaches its last step."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "split.json").write_text(json.dumps(
        {"train": [t.name for t in trajs], "valid": [t.name for t in valid],
         "gravity": list(sim_cfg["gravity"]), "steps": cfg.steps}, indent=1))
    # Resumed only when begun: a fresh size is no "--resume: no last.pt" line in the user's log.
    begun = (out / "last.pt").is_file()
    state = Trainer(sim_cfg, cfg, trajs, valid, out, resume=begun, init=init).run()
    if state.step < cfg.steps:  # SIGINT / SIGTERM: last.pt is written, a new call resumes
        raise TrainingInterrupted(f"{out}: training interrupted at step {state.step} of "
                                  f"{cfg.steps}; call again to resume")
    if not (out / "best.pt").is_file() or not math.isfinite(state.best_error):
        raise RuntimeError(f"{out}: no finite validation score: the run diverged")
    (out / "done.json").write_text(json.dumps(
        {"step": state.step, "cpu_hours": state.cpu_seconds / 3600, "best_score": state.best_error}))


def run_cpu_hours(out_dir: str | os.PathLike) -> float:
    """CPU hours of a finished :func:`train_on_split` run, its polish stage included (NaN if the
    run has not finished)."""
    done, polished = Path(out_dir) / "done.json", Path(out_dir) / "polish" / "done.json"
    if not done.is_file():
        return math.nan
    return sum(json.loads(f.read_text())["cpu_hours"] for f in (done, polished) if f.is_file())
