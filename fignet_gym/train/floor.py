"""The MuJoCo floor: MuJoCo's own rollout errors when its start is nudged (``fignet-gym floor``).

On chaotic data (tosses) a nudge of the start grows into errors no deterministic predictor whose
state is that far off can avoid; the table of errors against the nudge is that floor.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from fignet_gym.data.format import Trajectory, load_trajectories
from fignet_gym.data.generate import resimulate
from fignet_gym.train.metrics import HORIZON, predictor_metrics
from fignet_gym.train.report import plot_floor

#: Past poses a learned rollout is given besides the current one (the shipped models' history).
DEFAULT_HISTORY = 2


def perturbation_floor(trajs: list[Trajectory], position_noise: float, history: int = DEFAULT_HISTORY,
                       horizon: int = HORIZON, seed: int = 0) -> dict[str, Any]:
    """The rollout errors of MuJoCo itself when its start is off by ``position_noise`` (m).

    Each generated trajectory is re-simulated (:func:`~fignet_gym.data.generate.resimulate`)
    with every free body moved horizontally by ``position_noise`` at the last of the
    ``history + 1`` poses a learned rollout starts from, and scored as :func:`rollout_metrics`
    scores a model (same keys; ``horizon`` counted from frame 0). On chaotic data (tosses) this
    is a floor: a learned simulator whose state is off by ``position_noise`` after one step is at
    best a perfect simulator started that far off, so its rollouts are not expected to beat
    these errors.
    """
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
                horizon: int = HORIZON, history: int = DEFAULT_HISTORY) -> list[dict[str, Any]]:
    """Print (and write as JSON to ``out``) :func:`perturbation_floor` at several noise levels."""
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
