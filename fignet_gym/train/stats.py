"""Bootstrap statistics of rollout errors: intervals of median ratios over trajectories.

Trajectories are resampled with replacement (in pairs when two predictors are compared on the
same trajectories), so an interval says how much a median ratio moves with the sample of
trajectories, not with the randomness of one model. Trajectories cut from one recording (the
windows of one real push share ``metadata["file"]``) are not independent: given their groups,
whole recordings are resampled (a cluster bootstrap), else the interval is too narrow.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from typing import Any

import numpy as np

from fignet_gym.data.split import group_members

#: Bootstrap resamples per interval.
BOOTSTRAP_DRAWS = 2000
#: Percentiles of the resampled ratios that bound a 95% interval.
INTERVAL_PERCENTILES = (2.5, 97.5)


def median_ratio_interval(model: np.ndarray, ref: np.ndarray, draws: int = BOOTSTRAP_DRAWS, seed: int = 0,
                          groups: Sequence[Hashable | None] | None = None) -> list[float]:
    """Bootstrap 95% interval of ``median(model) / median(ref)`` over trajectories (``float[B]``
    each, resampled in pairs). With ~100 trajectories a median ratio of small errors (a pushed
    object's yaw) is uncertain by tens of percent; the interval says how much.

    ``groups`` (``B`` keys; ``None`` a group of its own): resample whole groups of ``G``,
    ``G`` at a time. With one trajectory per group this is the plain bootstrap, draw for draw.
    """
    if model.shape[0] == 0:
        return [math.nan, math.nan]
    rng = np.random.default_rng(seed)
    if groups is None:
        idx = rng.integers(0, model.shape[0], (draws, model.shape[0]))
        den = np.median(ref[idx], axis=1)
        ratios = np.median(model[idx], axis=1) / np.where(den > 0, den, np.nan)
    else:
        members = [np.asarray(m) for m in group_members(model.shape[0], groups)]
        picks = rng.integers(0, len(members), (draws, len(members)))
        ratios = np.empty(draws)
        for d in range(draws):
            idx = np.concatenate([members[g] for g in picks[d]])
            den = np.median(ref[idx])
            ratios[d] = np.median(model[idx]) / den if den > 0 else np.nan
    if np.isnan(ratios).all():  # the reference never moved (a zero median): no ratio to bound
        return [math.nan, math.nan]
    lo, hi = np.nanpercentile(ratios, INTERVAL_PERCENTILES)
    return [float(lo), float(hi)]


def paired_ratios(res: dict[str, Any], ref: dict[str, Any]) -> dict[str, Any]:
    """Ratios of two models' median errors on the same trajectories (of the ``*_final`` and
    ``*_last`` medians that :func:`score_rollouts` reports), with bootstrap 95% intervals
    (trajectories resampled in pairs; whole recordings where ``res`` carries their
    ``groups_final`` / ``groups_last``, see :func:`median_ratio_interval`):
    ``{"translation_rmse": [ratio, lo, hi], "rotation_deg": [...], "translation_rmse_last":
    [...], "rotation_deg_last": [...]}``.
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
            groups = res.get(f"groups_{at}")
            if ref.get(f"groups_{at}", groups) != groups:
                raise ValueError("paired ratios need the same trajectories (recordings differ)")
            den = ref[f"{q}_{at}"]
            out[f"{q}{suffix}"] = [res[f"{q}_{at}"] / den if den > 0 else math.nan,
                                   *median_ratio_interval(a, b, groups=groups)]
    return out

def per_recording(res: dict[str, Any], ref: dict[str, Any] | None = None) -> dict[str, Any]:
    """The per-recording view of :func:`score_rollouts` results: each recording's trajectories
    (``groups_final`` / ``groups_last``; the windows of one real push) averaged, then the median
    over recordings, so that a long push cut into ten windows counts once. Keys
    ``translation_rmse_final`` ... ``rotation_deg_last`` (and ``still_*``: no motion),
    ``recordings_final`` / ``recordings_last``; with ``ref`` (scored on the same trajectories),
    ``vs`` holds ``[ratio, lo, hi]`` per quantity, the interval a bootstrap over recordings.
    """
    out: dict[str, Any] = {}
    vs: dict[str, Any] = {}
    for at, suffix in (("final", ""), ("last", "_last")):
        n = len(res[f"translation_rmse{suffix}_per_trajectory"])
        members = [np.asarray(m) for m in group_members(n, res.get(f"groups_{at}"))]
        out[f"recordings_{at}"] = len(members)
        for q in ("translation_rmse", "rotation_deg"):
            for pre in ("", "still_"):
                a = np.asarray(res[f"{pre}{q}{suffix}_per_trajectory"])
                out[f"{pre}{q}_{at}"] = float(np.median([a[m].mean() for m in members]))
            if ref is None:
                continue
            if ref.get(f"groups_{at}", res.get(f"groups_{at}")) != res.get(f"groups_{at}"):
                raise ValueError("per-recording ratios need the same trajectories (recordings differ)")
            a, b = (np.array([np.asarray(r[f"{q}{suffix}_per_trajectory"])[m].mean() for m in members])
                    for r in (res, ref))
            den = float(np.median(b))
            vs[f"{q}{suffix}"] = [float(np.median(a)) / den if den > 0 else math.nan,
                                  *median_ratio_interval(a, b)]
    if ref is not None:
        out["vs"] = vs
    return out

