"""``sim2real --pretrain``'s data: the analytic models fitted on the smallest size's real
trajectories and the synthetic trajectories they simulate (``pretrain/`` of a run; resumable).

Tosses vary their releases in the fitted MuJoCo (:mod:`fignet_gym.train.synthetic`); pushes
draw new pushes of the same objects (:mod:`fignet_gym.train.synthetic_push`) from the fitted
MuJoCo, the fitted limit surface, or half from each.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from fignet_gym.atomic import write_text
from fignet_gym.data.format import write_trajectories
from fignet_gym.train.analytic import ContactParams
from fignet_gym.train.real_baselines import fit_limit_surface_on
from fignet_gym.train.synthetic import synthetic_tosses
from fignet_gym.train.synthetic_push import PushSource, synthetic_pushes
from fignet_gym.train.sysid import fit_contact_params


def synthetic_prior(train: list, valid: list, out: Path, num: int, *, prior: str, push: bool,
                    fit_evaluations: int, fit_trajectories: int, given: int, horizon: int,
                    seed: int, space: Any = None
                    ) -> tuple[Path, dict[str, Any], dict[str, float], float]:
    """Fit ``prior`` (``"mujoco"``, ``"limit-surface"`` or ``"both"``) on the real ``train``
    (MuJoCo selected on ``valid``, over ``space``) and write ``num`` synthetic trajectories to
    ``out / "synthetic.h5"``; returns that path, the MuJoCo fit (``{}`` if none), the
    limit-surface parameters (``{}`` if none) and the CPU seconds spent. Each finished part is
    kept in ``out`` and read back on a resume."""
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.process_time()
    fit: dict[str, Any] = {}
    ls: dict[str, float] = {}
    if prior in ("mujoco", "both"):
        print(f"pretraining: MuJoCo fitted on {len(train)} training trajectories ...")
        fit = fit_contact_params(train, valid, out / "fit.json", evaluations=fit_evaluations,
                                 fit_trajectories=min(fit_trajectories, len(train)), given=given,
                                 horizon=horizon, seed=seed, space=space)
    if prior in ("limit-surface", "both"):
        ls_path = out / "limit_surface_fit.json"
        if ls_path.is_file():
            ls = json.loads(ls_path.read_text())
        else:
            print(f"pretraining: limit surface fitted on {len(train)} training trajectories ...")
            mu, scale, _ = fit_limit_surface_on(train, given, horizon, fit_trajectories, seed)
            ls = {"tip_friction": mu, "pressure_scale": scale}
            write_text(ls_path, json.dumps(ls, indent=1))
    synth = out / "synthetic.h5"
    if not synth.is_file():
        if push:
            sources = []
            if fit:
                sources.append(PushSource.mujoco(ContactParams.from_json(fit["params"])))
            if ls:
                sources.append(PushSource.limit_surface(ls["tip_friction"], ls["pressure_scale"]))
            trajs = []
            for k, src in enumerate(sources):
                share = num // len(sources) + (1 if k < num % len(sources) else 0)
                trajs += synthetic_pushes(train, src, share, seed + k, name=f"synthetic-{src.name}")
        else:
            trajs = synthetic_tosses(train, ContactParams.from_json(fit["params"]), num, seed)
        write_trajectories(synth, trajs)
    return synth, fit, ls, time.process_time() - t0


__all__ = ["synthetic_prior"]
