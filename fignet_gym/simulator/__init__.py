"""The simulator core: FIGNet as a pure-torch learned simulator (no MuJoCo calls in a step, no RL).

Layers, each importing only those above it:

* :mod:`.geometry`: quaternions, transforms, batched Kabsch;
* :mod:`.scene`: static topology read once from a compiled ``MjModel``;
* :mod:`.collision`: face pairs (and node pairs) within a radius, with closest points;
* :mod:`.graph`: typed graph containers and feature building;
* :mod:`.normalization`, :mod:`.networks`: online normalisers, MLPs and typed message passing
  (knows no physics);
* :mod:`.config`: :class:`SimulatorConfig` (what defines a model) and its bounds;
* :mod:`.model`: :class:`LearnedSimulator`: network + normalisation + integration + shape matching,
  training targets;
* :mod:`.checkpoint`: ``save`` / ``load`` of checkpoint files, validated and checksummed.
"""

from fignet_gym.simulator.checkpoint import CheckpointError
from fignet_gym.simulator.config import SimulatorConfig
from fignet_gym.simulator.geometry import ShapeMatchError
from fignet_gym.simulator.model import LearnedSimulator
from fignet_gym.simulator.scene import MeshOptions, ObjectKind, Scene, UnsupportedSceneError

__all__ = [
    "CheckpointError", "LearnedSimulator", "MeshOptions", "ObjectKind", "Scene", "ShapeMatchError",
    "SimulatorConfig", "UnsupportedSceneError",
]
