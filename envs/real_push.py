"""``RealPush-v0``: :class:`~fignet_gym.envs.push.PushEnv`'s task on dynamics fitted to real pushes.

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
from pathlib import Path
from typing import Any

from fignet_gym.dynamics.base import Dynamics
from fignet_gym.envs.push import PushEnv, PushVectorEnv
from fignet_gym.registration import PUSH_V1_KWARGS

#: Seconds per environment step: the real pushes' resampling step, the one ``push-real`` learned.
STEP_SECONDS = 0.02
#: Timesteps per step that ``PushEnv`` builds its model with (2 ms each: one 0.02 s step).
BUILD_FRAME_SKIP = 10
#: The objects of the shipped real pushes (MIT Pushing on ABS).
REAL_SHAPES = ("butter", "ellip1", "ellip3", "hex", "rect1")


def fitted_params_path() -> Path:
    """The shipped fitted MuJoCo of the real pushes (next to ``push-real.pt``)."""
    from fignet_gym.pretrained import pretrained_dir

    return pretrained_dir() / "push-real.mujoco.json"


def load_fitted_params(spec: str | os.PathLike | dict[str, Any] | None = None) -> Any:
    """``ContactParams`` from a JSON file or dict in ``ContactParams`` form plus an optional
    ``"source"`` (default: the shipped :func:`fitted_params_path`)."""
    from fignet_gym.train.analytic import ContactParams

    raw = spec if isinstance(spec, dict) else json.loads(Path(spec or fitted_params_path()).read_text())
    return ContactParams.from_json({k: v for k, v in raw.items() if k != "source"})


class RealPushEnv(PushEnv):
    """Push a real MIT Pushing object on ABS to a goal pose, on reality-fitted dynamics.

    Everything of ``Push-v1`` (see :class:`~fignet_gym.envs.push.PushEnv`: spaces, reward,
    episode end, the other arguments), with these differences:

    | argument | default | meaning |
    |---|---|---|
    | dynamics | ``"mujoco"`` | ``"mujoco"`` (fitted), ``"fignet"`` (``push-real``) or a ``Dynamics`` |
    | checkpoint | ``None`` | ``"fignet"``: default ``push-real`` |
    | shape | ``"rect1"`` | one of :data:`REAL_SHAPES` |
    | mujoco_params | ``None`` | fitted parameters (JSON path or dict; default: the shipped fit) |

    One step is 0.02 s whatever the backend (MuJoCo: the fit's substeps per step).
    """

    def __init__(self, dynamics: str | Dynamics = "mujoco", checkpoint: Any = None,
                 shape: str = "rect1", mujoco_params: str | os.PathLike | dict[str, Any] | None = None,
                 **kwargs: Any) -> None:
        if shape not in REAL_SHAPES:
            raise ValueError(f"RealPushEnv: shape must be one of {', '.join(REAL_SHAPES)}, got {shape!r}")
        for fixed in ("friction", "tip_friction", "frame_skip"):
            if fixed in kwargs:
                raise ValueError(f"RealPushEnv: {fixed} comes from the fit; pass mujoco_params instead")
        self.fitted = load_fitted_params(mujoco_params)
        if dynamics == "fignet" and checkpoint is None:
            checkpoint = "push-real"
        super().__init__(dynamics, checkpoint, shape=shape,
                         friction=self.fitted.friction or 0.25,
                         tip_friction=self.fitted.friction_kinematic,
                         frame_skip=BUILD_FRAME_SKIP, **{**PUSH_V1_KWARGS, **kwargs})
        if dynamics == "mujoco":
            # The fit's solref, cone, torsional friction and timestep; a learned model keeps the
            # built model (it reads only geometry and its own step).
            self.fitted.apply(self.model, STEP_SECONDS)
            self.nstep = self.fitted.substeps_for(self.model, STEP_SECONDS)
            self.dynamics.validate(self.model, self.nstep, self.scene_type)
        self.step_time = self.nstep * float(self.model.opt.timestep)


class RealPushVectorEnv(PushVectorEnv):
    """``gym.make_vec("fignet_gym/RealPush-v0", ...)``: ``RealPushEnv`` copies run as one batch."""

    env_class = RealPushEnv


__all__ = ["REAL_SHAPES", "RealPushEnv", "RealPushVectorEnv", "fitted_params_path",
           "load_fitted_params"]
