"""MuJoCo's contact parameters as one type: what system identification fits, what the envs and the
analytic replays apply, and the format of every shipped fit (``pretrained/*.mujoco.json``).

A field left ``None`` keeps the value of the MJCF the parameters are applied to; :meth:`filled`
completes a partial set from a full one (an env's nominal parameters).

The JSON form (:meth:`ContactParams.to_json`) holds the set fields under their own names. An
older form, written by ``CubeToss-v0`` before this type existed (``friction`` as MuJoCo's three
numbers and an absolute ``timestep``), still loads, with a ``FutureWarning``, when the data step
it refers to is known (:meth:`ContactParams.from_json` with ``dt``).
"""

from __future__ import annotations

import json
import os
import warnings
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from fignet_gym.pretrained import pretrained_dir
from fignet_gym.simulator.scene import restitution_to_dampratio

CONES = ("pyramidal", "elliptic")
#: How far ``dt / timestep`` of the old format may be from a whole number of substeps.
SUBSTEP_RTOL = 1e-6
#: Keys of the old ``CubeToss-v0`` format that this type names otherwise.
LEGACY_KEYS = ("timestep",)
#: File-name suffix of a fitted MuJoCo shipped next to a model (``<name>.mujoco.json``).
SHIPPED_SUFFIX = ".mujoco.json"
#: Prefix that names a shipped fit where a checkpoint could also be given (``mujoco:cube-real``).
SHIPPED_PREFIX = "mujoco:"


@dataclass(frozen=True)
class ContactParams:
    """MuJoCo settings applied to a scene's MJCF (``None``: keep the MJCF's).

    Attributes:
        friction: sliding friction of every geom of static and dynamic bodies.
        friction_kinematic: sliding friction of kinematic (mocap) bodies' geoms (a pusher).
        torsional, rolling: the other two friction coefficients of every geom.
        timeconst: ``solref[0]`` (s) of every geom. dampratio: ``solref[1]`` of every geom.
        cone: ``"pyramidal"`` or ``"elliptic"``. impratio: MuJoCo's ``impratio``.
        noslip_iterations: MuJoCo's ``noslip_iterations``.
        gravity: z component (m/s^2).
        substeps: MuJoCo timesteps per data step (timestep = ``dt / substeps``; ``None``: the
            MJCF's timestep, rounded so that it divides ``dt``).
        integrator: ``"Euler"``, ``"implicitfast"``, ``"RK4"`` ... (``mjtIntegrator`` names).
        source: where the values come from (a fit's data and split); not applied.
    """

    friction: float | None = None
    friction_kinematic: float | None = None
    torsional: float | None = None
    rolling: float | None = None
    timeconst: float | None = None
    dampratio: float | None = None
    cone: str | None = None
    impratio: float | None = None
    noslip_iterations: int | None = None
    gravity: float | None = None
    substeps: int | None = None
    integrator: str | None = None
    source: str | None = None

    def __post_init__(self) -> None:
        if self.cone is not None and self.cone not in CONES:
            raise ValueError(f"cone must be one of {CONES}, got {self.cone!r}")
        if self.substeps is not None and int(self.substeps) < 1:
            raise ValueError(f"substeps must be >= 1, got {self.substeps}")

    def to_json(self) -> dict[str, Any]:
        """The set fields (JSON-serialisable)."""
        return {k: v for k, v in asdict(self).items() if v is not None}

    @staticmethod
    def from_json(d: dict[str, Any], dt: float | None = None, where: str = "contact parameters"
                  ) -> ContactParams:
        """Inverse of :meth:`to_json`; unknown keys are an error naming ``where``.

        The old ``CubeToss-v0`` form (``friction: [sliding, torsional, rolling]``, ``timestep``
        in seconds) is converted with a ``FutureWarning``; its ``timestep`` needs ``dt``, the
        data step it divides.
        """
        d = dict(d)
        if isinstance(d.get("friction"), (list, tuple)) or any(k in d for k in LEGACY_KEYS):
            d = _from_legacy(d, dt, where)
        known = {f.name for f in fields(ContactParams)}
        bad = set(d) - known
        if bad:
            raise ValueError(f"{where}: unknown contact parameters {sorted(bad)}; known: {sorted(known)}")
        return ContactParams(**d)

    @staticmethod
    def load(path: str | os.PathLike, dt: float | None = None) -> ContactParams:
        """:meth:`from_json` of a JSON file; ``source`` defaults to the file's path."""
        try:
            raw = json.loads(Path(path).read_text())
        except (OSError, json.JSONDecodeError) as err:
            raise ValueError(f"{path}: not a readable JSON file of MuJoCo parameters ({err})") from None
        if not isinstance(raw, dict):
            raise ValueError(f"{path}: holds {type(raw).__name__}, not an object of MuJoCo parameters")
        params = ContactParams.from_json(raw, dt, str(path))
        return params if params.source is not None else replace(params, source=str(path))

    def filled(self, base: ContactParams) -> ContactParams:
        """These parameters, with each unset field taken from ``base``."""
        return replace(base, **self.to_json())

    def with_restitution(self, restitution: float) -> ContactParams:
        """The same with ``dampratio`` from a coefficient of restitution."""
        return replace(self, dampratio=restitution_to_dampratio(restitution))

    def apply(self, model: mujoco.MjModel, dt: float) -> mujoco.MjModel:
        """Set these parameters on ``model`` in place (timestep ``dt / substeps``); returns it."""
        kin = np.array([model.body_mocapid[b] >= 0 for b in model.geom_bodyid])
        if self.friction is not None:
            model.geom_friction[~kin, 0] = self.friction
        if self.friction_kinematic is not None:
            model.geom_friction[kin, 0] = self.friction_kinematic
        if self.torsional is not None:
            model.geom_friction[:, 1] = self.torsional
        if self.rolling is not None:
            model.geom_friction[:, 2] = self.rolling
        if self.timeconst is not None:
            model.geom_solref[:, 0] = self.timeconst
        if self.dampratio is not None:
            model.geom_solref[:, 1] = self.dampratio
        if self.cone is not None:
            model.opt.cone = (mujoco.mjtCone.mjCONE_ELLIPTIC if self.cone == "elliptic"
                              else mujoco.mjtCone.mjCONE_PYRAMIDAL)
        if self.impratio is not None:
            model.opt.impratio = self.impratio
        if self.noslip_iterations is not None:
            model.opt.noslip_iterations = int(self.noslip_iterations)
        if self.gravity is not None:
            model.opt.gravity[:] = (0.0, 0.0, self.gravity)
        if self.integrator is not None:
            model.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{self.integrator.upper()}")
        model.opt.timestep = dt / self.substeps_for(model, dt)
        return model

    def substeps_for(self, model: mujoco.MjModel, dt: float) -> int:
        """``substeps``, or the MJCF's own: ``round(dt / timestep)`` (at least 1)."""
        if self.substeps is not None:
            return int(self.substeps)
        return max(1, int(round(dt / model.opt.timestep)))


def _from_legacy(d: dict[str, Any], dt: float | None, where: str) -> dict[str, Any]:
    """The old ``CubeToss-v0`` keys as :class:`ContactParams` fields (a ``FutureWarning``)."""
    fr = d.pop("friction", None)
    if isinstance(fr, (list, tuple)):
        if len(fr) != 3:
            raise ValueError(f"{where}: friction needs 1 or 3 numbers (sliding, torsional, rolling), "
                             f"got {len(fr)}")
        d["friction"], d["torsional"], d["rolling"] = (float(x) for x in fr)
    elif fr is not None:
        d["friction"] = fr
    if "timestep" in d:
        timestep = float(d.pop("timestep"))
        if dt is None:
            raise ValueError(f"{where}: 'timestep' is the old CubeToss-v0 format; write "
                             "'substeps' (the data step / timestep) instead")
        ratio = dt / timestep
        if round(ratio) < 1 or abs(ratio - round(ratio)) > SUBSTEP_RTOL * ratio:
            raise ValueError(f"{where}: timestep {timestep} s does not divide the data's step {dt} s")
        d["substeps"] = int(round(ratio))
    warnings.warn(f"{where}: MuJoCo parameters in the old CubeToss-v0 format (friction as three "
                  "numbers, 'timestep'); convert the file once: json.dumps(ContactParams.load(path, "
                  "dt).to_json())", FutureWarning, stacklevel=3)
    return d


def available_fits() -> list[str]:
    """Names of the shipped fitted MuJoCo parameters (``pretrained/<name>.mujoco.json``)."""
    return sorted(p.name[: -len(SHIPPED_SUFFIX)] for p in pretrained_dir().glob(f"*{SHIPPED_SUFFIX}"))


def fit_path(spec: str | os.PathLike) -> Path:
    """The file of ``mujoco:<name>`` (a shipped fit) or of a path to a parameters JSON; a
    ``ValueError`` lists the shipped names when there is no such fit."""
    text = str(spec)
    if text.startswith(SHIPPED_PREFIX):
        name = text[len(SHIPPED_PREFIX):]
        path = pretrained_dir() / f"{name}{SHIPPED_SUFFIX}"
        if not path.is_file():
            raise ValueError(f"{text}: no shipped fitted MuJoCo {name!r}; available: "
                             f"{', '.join(SHIPPED_PREFIX + n for n in available_fits()) or 'none'}")
        return path
    path = Path(spec)
    if not path.is_file():
        raise ValueError(f"{text}: no such file of MuJoCo parameters")
    return path
