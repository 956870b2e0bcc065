"""fignet_gym: FIGNet, a learned rigid-body simulator, as a drop-in replacement for MuJoCo.

Importing the package loads the simulator core (torch, MuJoCo's model reader) and no RL stack; the
environment ids (``fignet_gym/Push-v0``, ...) are registered with Gymnasium as soon as it is
imported (:mod:`fignet_gym.registration`). Package layout: ``docs/architecture.md``.
"""

import os as _os

# MuJoCo picks its OpenGL backend when it is first imported: without a display, EGL renders
# headless. Users who set MUJOCO_GL themselves keep their choice.
if not (_os.environ.get("DISPLAY") or _os.environ.get("WAYLAND_DISPLAY")):
    _os.environ.setdefault("MUJOCO_GL", "egl")

from fignet_gym.pretrained import available_pretrained, load_pretrained  # noqa: E402
from fignet_gym.registration import register_when_gymnasium_loads  # noqa: E402
from fignet_gym.simulator import (  # noqa: E402
    CheckpointError,
    LearnedSimulator,
    MeshOptions,
    ObjectKind,
    Scene,
    ShapeMatchError,
    SimulatorConfig,
    UnsupportedSceneError,
)

__all__ = [
    "CheckpointError", "LearnedSimulator", "MeshOptions", "ObjectKind", "Scene",
    "ShapeMatchError", "SimulatorConfig", "UnsupportedSceneError", "available_pretrained",
    "load_pretrained",
]
__version__ = "0.1.0"

register_when_gymnasium_loads()
