"""Trajectory format, generators, importers and viewer.

The format API is re-exported here; generators (:mod:`fignet_gym.data.generate`), importers
(:mod:`fignet_gym.data.importers`, and :mod:`fignet_gym.data.tracked` for tracked real data: poses
plus an MJCF), splits (:mod:`fignet_gym.data.split`) and the viewer
(:mod:`fignet_gym.data.viewer`, which picks an OpenGL backend) are imported from their modules.
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
from fignet_gym.simulator.scene import dampratio_to_restitution, restitution_to_dampratio

__all__ = ["ObjectMeshes", "Trajectory", "TrajectoryFile", "TrajectoryFormatError",
           "TrajectoryWriter", "dampratio_to_restitution", "load_trajectories",
           "restitution_to_dampratio", "write_trajectories"]
