"""Package a trained run as a shipped pretrained simulator with a model card (``fignet-gym ship``).

Copies the run's best checkpoint without optimiser state (a few MB), evaluates it on held-out data
against the no-motion and constant-velocity references, and writes ``<name>.md`` beside it with the
data, budget (steps, graphs, CPU hours) and scores, so every shipped number can be traced.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from fignet_gym.data.format import TrajectoryFile, build_scene, load_trajectories
from fignet_gym.pretrained import pretrained_dir
from fignet_gym.simulator.checkpoint import load, save
from fignet_gym.simulator.config import SimulatorConfig
from fignet_gym.simulator.model import LearnedSimulator
from fignet_gym.train.data_checks import check_data_matches
from fignet_gym.train.evaluation import rollout_metrics
from fignet_gym.train.sampling import median_node_acceleration


def ship(run: str, name: str, data: str, horizon: int, num: int | None = None, dest: str | None = None,
         notes: str = "") -> dict[str, Any]:
    """Export ``run/best.pt`` as ``<dest>/<name>.pt`` and write its model card; returns the metrics."""
    run_dir = Path(run)
    sim, meta = load(run_dir / "best.pt")
    state = _train_state(run_dir, meta.get("valid", {}))
    trajs = load_trajectories(data)[:num]
    check_data_matches(sim, trajs, data)
    metrics = rollout_metrics(sim, trajs, horizon=horizon)
    scenes = [build_scene(t, sim.config.mesh_options) for t in trajs]
    metrics["median_node_acceleration"] = median_node_acceleration(trajs, scenes)
    out = Path(dest) if dest else pretrained_dir()
    out.mkdir(parents=True, exist_ok=True)
    card_meta = {"run": str(run_dir), "validation_at_export": meta.get("valid", {}),
                 "train_state": state, "heldout": {k: v for k, v in metrics.items()
                                                   if not k.endswith("_curve")}}
    save(sim, out / f"{name}.pt", meta={"model_card": json.dumps(card_meta)})
    (out / f"{name}.md").write_text(model_card(name, sim, state, metrics, data, notes,
                                               source=_data_source(data)))
    print(f"shipped {out / (name + '.pt')} ({(out / (name + '.pt')).stat().st_size / 1e6:.1f} MB)")
    return metrics


def _train_state(run_dir: Path, valid: dict[str, Any]) -> dict[str, Any]:
    """Steps, graphs and CPU hours that produced the exported checkpoint (its validation record),
    the run's training settings and the noise std it used."""
    cfg_path = run_dir / "config.json"
    cfg = json.loads(cfg_path.read_text()) if cfg_path.is_file() else {}
    training = cfg.get("training", {})
    return {"steps": valid.get("step"), "graphs_seen": valid.get("graphs_seen"),
            "cpu_hours": valid.get("cpu_hours"), "training": training,
            "noise_std": cfg.get("noise_std", training.get("noise_std", 0.0))}


def _data_source(data: str) -> str:
    """What the card says the data is: real tracked data is named by its importer's source."""
    with TrajectoryFile(data) as f:
        source = str(f.metadata.get("source", ""))
    if source == "contactnets":
        return ("real tracked tosses of one cube (DAIRLab ContactNets, BSD-3-Clause; "
                "`fignet-gym import-contactnets`)")
    return ""


def model_card(name: str, sim: LearnedSimulator, state: dict[str, Any], m: dict[str, Any],
               data: str, notes: str, source: str = "") -> str:
    """Markdown model card of a shipped simulator (``source``: what the data is, if not
    MuJoCo-generated)."""
    c = sim.config
    n_params = sum(p.numel() for p in sim.parameters())
    tr = state.get("training", {})
    noise = state.get("noise_std", 0.0)
    vertical = tr.get("vertical_weight", 1.0)
    generated = (f"MuJoCo-generated `{c.scene_type}` trajectories "
                 "(`fignet-gym generate`, see `docs/data.md`)")
    return f"""# Pretrained simulator `{name}`

Load with `fignet_gym.load_pretrained("{name}")` (offline; the file is in the package).

## Model
FIGNet, latent {c.latent_size}, {c.message_passing_steps} message-passing steps, mesh-mesh edges
{"on" if c.mesh_edges else "off"}, object nodes {"on" if c.object_nodes else "off"}, {c.collision}
collision edges with d_c = {c.collision_radius} m, history {c.history} velocities, learned step
dt = {c.dt} s, scene type `{c.scene_type}`, {n_params / 1e6:.2f} M parameters.
Face-edge features beyond the paper's: {_extras(c)}.
Output: per-node accelerations, {"projected onto each object's rigid motions in training and in every step"
if c.rigid_output else "shape matched into poses in rollouts (as in the paper)"}.
Mesh options: {c.mesh_options}.

## Training
- Data: {source or generated}.
- Budget: {state.get("steps")} optimiser steps of {tr.get("batch_size")} graphs
  ({state.get("graphs_seen")} graphs), {_fmt(state.get("cpu_hours"), 2)} CPU hours on a 2-core
  machine (one core per run).
- Recipe: per-node acceleration MSE in normalised space (vertical weight {vertical}), plus a
  per-object linear/rotational acceleration term (weight {tr.get("rigid_loss_weight")}); rigid random-walk
  input noise std {noise:.3g} m ({noise / m["median_node_acceleration"]:.2g} x the median
  per-step acceleration of moving nodes in the held-out data, {m["median_node_acceleration"]:.2g} m);
  rotational noise std {tr.get("rotation_noise_std") or "(from the position noise)"} rad; pushforward unrolls
  of up to {tr.get("unroll_steps", 0)} steps (from step {tr.get("unroll_after", 0)});{_rollout(tr)}
  random rotations about z{"; half of the windows mirrored in y = 0" if tr.get("mirror") else ""};
  Adam, lr {tr.get("lr")} decaying to {tr.get("lr_final")};
  weight average (EMA) decay {tr.get("ema_decay", 0)}.
{notes.rstrip()}

## Scores on held-out data (`{data}`, {m["trajectories"]} trajectories)
Rollouts from the first {c.history + 1} true poses; errors at frame {m["horizon_step"]} counted from frame 0
({m["seconds"]:.2f} s), medians over trajectories.

| model | translation RMSE (m) | rotation error (deg) |
|---|---|---|
| FIGNet (this model) | {m["translation_rmse_final"]:.4f} | {m["rotation_deg_final"]:.2f} |
| no motion | {m["still_translation_rmse_final"]:.4f} | {m["still_rotation_deg_final"]:.2f} |
| constant velocity | {m["constvel_translation_rmse_final"]:.4f} | {m["constvel_rotation_deg_final"]:.2f} |

Ratio to no motion: translation {m["translation_rmse_ratio_still"]:.1%}, rotation
{m["rotation_deg_ratio_still"]:.1%} (bootstrap 95% intervals resampling whole recordings, or
trajectories where none is named: {_interval(m["translation_rmse_ratio_still_ci95"])} and
{_interval(m["rotation_deg_ratio_still_ci95"])}).
Teacher-forced one-step error (summed over steps, divided by the motion over each step; the
constant-velocity model's in brackets): translation {m["one_step_translation"]:.3f}
({m["one_step_constvel_translation"]:.3f}), rotation {m["one_step_rotation"]:.3f}
({m["one_step_constvel_rotation"]:.3f}).
Collision edges per scene-step: {m["collision_edges_per_step"]:.1f}.
Floor penetration ratio (predicted / MuJoCo): {m["penetration_ratio"]:.2f}.
Rotation gain (median of predicted / true turn, objects turning more than 1 deg): {m["rotation_gain"]:.2f};
teacher-forced one-step spin gain (slope of predicted on true change of angular velocity):
{m["one_step_spin_gain"]:.2f}.{_free_flight(m)}
"""


def _rollout(tr: dict[str, Any]) -> str:
    steps = tr.get("rollout_steps", 0)
    return "" if not steps else (
        f"\n  training through rollouts of {steps} steps (`rollout_steps`, weight "
        f"{tr.get('rollout_weight')});")


def _extras(c: SimulatorConfig) -> str:
    return ", ".join(g.description for g in c.face_groups) or "none"


def _free_flight(m: dict) -> str:
    x = m["one_step_free_flight"]
    return "" if not math.isfinite(x) else (
        f"\nTeacher-forced acceleration error of objects in free flight (RMS / |g| dt^2): {x:.3f}.")


def _interval(ci: list[float]) -> str:
    return f"{ci[0]:.0%}-{ci[1]:.0%}"


def _fmt(x: float | None, digits: int) -> str:
    return "?" if x is None else f"{x:.{digits}f}"
