"""What every MuJoCo generator shares: its version stamp, its error, pose counts, the driven loop."""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np

from fignet_gym.simulator.scene import Scene

GENERATOR_VERSION = "1"
#: ``metadata["source"]`` of every generated trajectory.
GENERATED_SOURCE = "fignet_gym.generate"


class GenerationError(RuntimeError):
    """A trajectory could not be generated (named by kind, seed and index)."""


def num_poses(duration: float, dt: float) -> int:
    """Poses of a trajectory of ``duration`` seconds at step ``dt``, both ends included."""
    return int(round(duration / dt)) + 1


#: Called before pose ``k`` is recorded; may change the state (``generate.resimulate``'s nudge).
PoseHook = Callable[[int, mujoco.MjModel, mujoco.MjData], None]


def simulate_driven(mjcf: str, poses: int, substeps: int,
                    drive: Callable[[mujoco.MjData, float], None],
                    start: Callable[[mujoco.MjData], None] | None = None,
                    hook: PoseHook | None = None) -> tuple[np.ndarray, Scene]:
    """Poses ``float[T, O, 7]`` of a scene whose mocap bodies ``drive(data, t)`` places before
    each timestep at where they should be at its end ``t`` (an implicit position drive);
    ``start(data)`` sets the initial state (default: the MJCF's); pose 0 is that state."""
    model = mujoco.MjModel.from_xml_string(mjcf)
    data = mujoco.MjData(model)
    scene = Scene.from_mjmodel(model)
    if start is not None:
        start(data)
    mujoco.mj_forward(model, data)
    h = model.opt.timestep
    out = np.empty((poses, scene.num_objects, 7))
    step = 0
    for k in range(poses):
        for _ in range(substeps if k else 0):
            step += 1
            drive(data, step * h)
            mujoco.mj_step(model, data)
        if hook is not None:
            hook(k, model, data)
        out[k] = scene.poses_from_data(data)
    return out, scene
