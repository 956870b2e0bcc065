"""fignet_gym: FIGNet, a learned rigid-body simulator, as a drop-in replacement for MuJoCo.

Importing the package loads the simulator core (torch, MuJoCo's model reader) and no RL stack; the
environment ids (``fignet_gym/Push-v2``, ...) are registered with Gymnasium as soon as it is
imported (:mod:`fignet_gym.registration`). Package layout: ``docs/architecture.md``.
"""

import os as _os
from pathlib import Path as _Path

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
    "CheckpointError", "LearnedSimulator", "MeshOptions", "MixedInstallError", "ObjectKind", "Scene",
    "ShapeMatchError", "SimulatorConfig", "UnsupportedSceneError", "available_pretrained",
    "check_same_install", "load_pretrained",
]
__version__ = "0.1.0"


class MixedInstallError(ImportError):
    """``fignet_gym`` and its ``envs`` / ``agents`` come from two different copies."""


def check_same_install(module_file: str, name: str) -> None:
    """``MixedInstallError`` (one line, with the fix) unless the ``fignet_gym.<name>`` package
    at ``module_file`` belongs to the same copy as this ``fignet_gym``: beside it in a checkout
    (``envs/``, ``agents/`` next to ``fignet_gym/``, an editable install) or inside it (an
    installed wheel). A second checkout on ``PYTHONPATH`` otherwise mixes its core with the
    installed tree's environments without a word."""
    core = _Path(__file__).resolve().parent
    pkg = _Path(module_file).resolve().parent
    if pkg.parent not in (core, core.parent):
        raise MixedInstallError(
            f"fignet_gym comes from {core} but fignet_gym.{name} from {pkg}: two copies are on "
            f"the path (check PYTHONPATH); install the one you want with `pip install -e <it>`")

register_when_gymnasium_loads()
