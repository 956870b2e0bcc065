"""fignet_gym: FIGNet, a learned rigid-body simulator, as a drop-in replacement for MuJoCo."""

import os as _os

# MuJoCo picks its OpenGL backend when it is first imported: without a display, EGL renders
# headless. Users who set MUJOCO_GL themselves keep their choice.
if not (_os.environ.get("DISPLAY") or _os.environ.get("WAYLAND_DISPLAY")):
    _os.environ.setdefault("MUJOCO_GL", "egl")

from fignet_gym.geometry import ShapeMatchError
from fignet_gym.pretrained_models import available_pretrained, load_pretrained
from fignet_gym.scene import MeshOptions, ObjectKind, Scene, UnsupportedSceneError
from fignet_gym.simulator import CheckpointError, LearnedSimulator, SimulatorConfig

__all__ = [
    "CheckpointError", "LearnedSimulator", "MeshOptions", "ObjectKind", "Scene",
    "ShapeMatchError", "SimulatorConfig", "UnsupportedSceneError", "available_pretrained",
    "load_pretrained",
]
__version__ = "0.1.0"

# Registers fignet_gym/Push-v0 and fignet_gym/Toss-v0 with Gymnasium (whose 1.x releases do not load
# the package's entry point by themselves).
import fignet_gym.envs  # noqa: E402, F401
