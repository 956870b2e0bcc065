"""What every MuJoCo generator shares: the version stamp of its records, its error, pose counts."""

from __future__ import annotations

GENERATOR_VERSION = "1"
#: ``metadata["source"]`` of every generated trajectory.
GENERATED_SOURCE = "fignet_gym.generate"


class GenerationError(RuntimeError):
    """A trajectory could not be generated (named by kind, seed and index)."""


def num_poses(duration: float, dt: float) -> int:
    """Poses of a trajectory of ``duration`` seconds at step ``dt``, both ends included."""
    return int(round(duration / dt)) + 1
