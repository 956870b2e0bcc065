"""Trajectory format, generators, importers and viewer.

The format API is re-exported here; generators (:mod:`fignet_gym.data.generate`), importers
(:mod:`fignet_gym.data.importers`) and the viewer (:mod:`fignet_gym.data.viewer`, which picks an
OpenGL backend) are imported from their modules.
"""

from fignet_gym.data.format import (
    ObjectMeshes,
    Trajectory,
    TrajectoryFile,
    TrajectoryFormatError,
    TrajectoryWriter,
    load_trajectories,
    write_trajectories,
)

__all__ = ["ObjectMeshes", "Trajectory", "TrajectoryFile", "TrajectoryFormatError",
           "TrajectoryWriter", "load_trajectories", "write_trajectories"]
