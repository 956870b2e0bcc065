"""fignet_gym: FIGNet, a learned rigid-body simulator, as a drop-in replacement for MuJoCo."""

from fignet_gym.geometry import ShapeMatchError
from fignet_gym.scene import MeshOptions, ObjectKind, Scene, UnsupportedSceneError

__all__ = ["MeshOptions", "ObjectKind", "Scene", "ShapeMatchError", "UnsupportedSceneError"]
__version__ = "0.1.0"
