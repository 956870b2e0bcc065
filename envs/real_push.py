"""``RealPush-v1`` (and ``-v0``): :class:`~fignet_gym.envs.push.PushEnv`'s task on dynamics fitted
to real pushes.

The object is one of the MIT Pushing objects recorded on ABS (the five of the shipped real
pushes), and both backends come from those recordings: ``dynamics="fignet"`` is ``push-real``
(FIGNet fine-tuned on them), ``dynamics="mujoco"`` is MuJoCo with the contact parameters fitted to
the same training pushes (``fignet_gym/pretrained/push-real.mujoco.json``: object-floor and
tip-object friction, torsional friction, ``solref``, cone and substeps). The task, observation,
action and reward are ``Push-v1``'s (:class:`~fignet_gym.envs.tasks.PushTask`, ``env.task``), so
planners and PPO run on it unchanged.
"""

from __future__ import annotations

import json
import os
from typing import Any

from fignet_gym.dynamics.base import Dynamics
from fignet_gym.dynamics.contact_params import ContactParams, fit_path
from fignet_gym.envs.push import PushEnv, PushVectorEnv
from fignet_gym.registration import PUSH_V1_KWARGS

#: Seconds per environment step: the real pushes' resampling step, the one ``push-real`` learned.
STEP_SECONDS = 0.02
#: Timesteps per step that ``PushEnv`` builds its model with (2 ms each: one 0.02 s step).
BUILD_FRAME_SKIP = 10
#: Object-floor friction of a fit that left it alone (``PushEnv``'s default).
DEFAULT_FRICTION = 0.25
#: The objects of the shipped real pushes (MIT Pushing on ABS).
REAL_SHAPES = ("butter", "ellip1", "ellip3", "hex", "rect1")


#: The shipped fit of the real pushes (next to ``push-real.pt``).
FIT = "mujoco:push-real"
#: The :class:`ContactParams` fields a fit of the real pushes sets (as ``sim2real`` writes them in
#: ``mujoco_fit.json``'s ``params``), besides ``"source"``.
FIT_KEYS = ("friction", "friction_kinematic", "torsional", "rolling", "timeconst", "dampratio",
            "cone", "impratio", "noslip_iterations", "substeps")


def load_fitted_params(spec: str | os.PathLike | dict[str, Any] | None = None) -> dict[str, Any]:
    """The fitted parameters (a JSON file or dict of :data:`FIT_KEYS`, plus an optional
    ``"source"``; default: the shipped ``mujoco:push-real``); ``ValueError`` on other keys."""
    raw = spec if isinstance(spec, dict) else json.loads(fit_path(spec or FIT).read_text())
    params = {k: v for k, v in raw.items() if k != "source"}
    unknown = sorted(set(params) - set(FIT_KEYS))
    if unknown:
        raise ValueError(f"RealPushEnv: mujoco_params: unknown keys {unknown}; known: {list(FIT_KEYS)}")
    return params


class RealPushEnv(PushEnv):
    """Push a real MIT Pushing object on ABS to a goal pose, on reality-fitted dynamics.

    Everything of ``Push-v1`` (see :class:`~fignet_gym.envs.push.PushEnv`: spaces, reward,
    episode end, the other arguments), with these differences:

    | argument | default | meaning |
    |---|---|---|
    | dynamics | ``"mujoco"`` | ``"mujoco"`` (fitted), ``"fignet"`` (``push-real``) or a ``Dynamics`` |
    | checkpoint | ``None`` | ``"fignet"``: default ``learned`` |
    | learned | ``"push-real"`` | the default learned model (``RealPush-v0``: ``push-real-v0``) |
    | shape | ``"rect1"`` | one of :data:`REAL_SHAPES` |
    | mujoco_params | ``None`` | fitted parameters (JSON path or dict; default: the shipped fit) |

    One step is 0.02 s whatever the backend (MuJoCo: the fit's substeps per step).

    Version History: v1 steps the ``push-real`` of issue 39 (pretrained on pushes of the fitted
    MuJoCo and limit surface); v0 the first one (``push-real-v0``). The MuJoCo backend is the
    same fit in both.
    """

    def __init__(self, dynamics: str | Dynamics = "mujoco", checkpoint: Any = None,
                 shape: str = "rect1", mujoco_params: str | os.PathLike | dict[str, Any] | None = None,
                 learned: str = "push-real", **kwargs: Any) -> None:
        if shape not in REAL_SHAPES:
            raise ValueError(f"RealPushEnv: shape must be one of {', '.join(REAL_SHAPES)}, got {shape!r}")
        for fixed in ("friction", "tip_friction", "frame_skip"):
            if fixed in kwargs:
                raise ValueError(f"RealPushEnv: {fixed} comes from the fit; pass mujoco_params instead")
        self.fitted = load_fitted_params(mujoco_params)
        if dynamics == "fignet" and checkpoint is None:
            checkpoint = learned
        super().__init__(dynamics, checkpoint, shape=shape,
                         friction=self.fitted.get("friction") or DEFAULT_FRICTION,
                         tip_friction=self.fitted.get("friction_kinematic"),
                         frame_skip=BUILD_FRAME_SKIP, **{**PUSH_V1_KWARGS, **kwargs})
        # The fit's solref, cone, frictions and timestep, whatever acts: a planner's MuJoCo model
        # of this env is then the fitted MuJoCo too (a learned model reads only geometry and the
        # step's length, still 0.02 s).
        params = ContactParams.from_json(self.fitted, where="RealPushEnv: mujoco_params")
        params.apply(self.model, STEP_SECONDS)
        self.frame_skip = params.substeps_for(self.model, STEP_SECONDS)
        self.dynamics.validate(self.model, self.frame_skip, self.scene_type)


class RealPushVectorEnv(PushVectorEnv):
    """``gym.make_vec("fignet_gym/RealPush-v1", ...)``: ``RealPushEnv`` copies run as one batch."""

    env_class = RealPushEnv


__all__ = ["FIT", "FIT_KEYS", "REAL_SHAPES", "RealPushEnv", "RealPushVectorEnv", "load_fitted_params"]
