"""Checks that a trajectory file fits a model before it is scored, and what the file holds.

The metadata written by each route into the trajectory format (:mod:`fignet_gym.data.format`)
says where the poses come from: ``source = "fignet_gym.generate"`` (MuJoCo, ``kind`` push or
toss-*), ``synthetic_from`` (MuJoCo re-run of a real trajectory, :mod:`fignet_gym.train.synthetic`),
``kubric_movi`` (Kubric's simulator), ``contactnets`` or ``mit_pushing*`` (tracked real objects).
"""

from __future__ import annotations

from pathlib import Path

from fignet_gym.data.format import Trajectory
from fignet_gym.simulator.model import LearnedSimulator

#: Relative tolerance of the data-dt vs model-dt check.
DT_RTOL = 1e-4
#: ``metadata["source"]`` of trajectories simulated by this project's MuJoCo generators.
GENERATED_SOURCE = "fignet_gym.generate"
#: ``metadata["source"]`` prefix of Kubric MOVi scenes (simulated, not MuJoCo).
KUBRIC_SOURCE = "kubric_movi"


def same_dt(data_dt: float, model_dt: float) -> bool:
    """Whether data stored every ``data_dt`` s can be stepped by a model of step ``model_dt``."""
    return abs(data_dt - model_dt) <= DT_RTOL * model_dt


def check_dt(trajs: list[Trajectory], dt: float) -> None:
    """Raise ``ValueError`` naming the file and trajectory whose ``dt`` is not the model's ``dt``.

    A learned simulator predicts one step of its training ``dt``; scoring a 12 fps file with a
    50 Hz model would compare it with poses four steps away.
    """
    for t in trajs:
        if not same_dt(t.dt, dt):
            where = f"{t.source}: " if t.source else ""
            fix = (f"re-import with `fignet-gym import-mit ... --dt {dt:g}`"
                   if str(t.metadata.get("source", "")).startswith("mit_pushing")
                   else "resample or import the data at the model's dt")
            raise ValueError(f"{where}trajectory {t.name!r}: field 'dt' is {t.dt:.6g} s, the model "
                             f"steps {dt:.6g} s ({fix}, or train a model at the data's dt)")


def data_scene_type(traj: Trajectory) -> str:
    """The scene type (``"push"``, ``"toss"``; ``""``: unknown) a trajectory's metadata implies."""
    kind, source = str(traj.metadata.get("kind", "")), str(traj.metadata.get("source", ""))
    if kind == "push" or source.startswith("mit_pushing"):
        return "push"
    if kind.startswith("toss") or source.startswith(KUBRIC_SOURCE):
        return "toss"
    return ""


def truth_label(traj: Trajectory) -> str:
    """What a trajectory's poses are, for a video or plot label: ``"MuJoCo (ground truth)"``,
    ``"Kubric (ground truth)"`` or ``"recorded"`` (tracked real data, and any file of unknown
    origin: a user's own tracks)."""
    source = str(traj.metadata.get("source", ""))
    if source == GENERATED_SOURCE or "synthetic_from" in traj.metadata:
        return "MuJoCo (ground truth)"
    if source.startswith(KUBRIC_SOURCE):
        return "Kubric (ground truth)"
    return "recorded"


def check_data_matches(sim: LearnedSimulator, trajs: list[Trajectory], data: str | Path) -> None:
    """``ValueError`` naming ``data`` if it is empty or of another scene type than ``sim``'s."""
    if not trajs:
        raise ValueError(f"{data}: holds no trajectories")
    trained = sim.config.scene_type
    kinds = {data_scene_type(t) for t in trajs} - {""}
    if trained and kinds and kinds != {trained}:
        raise ValueError(f"{data}: holds {'/'.join(sorted(kinds))} trajectories, the checkpoint was "
                         f"trained on '{trained}' scenes")
