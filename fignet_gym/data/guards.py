"""What a data set must not hold: copies, trajectories too short to score, mixed scene types.

* :class:`ImportWriter`: the importers' :class:`~fignet_gym.data.format.TrajectoryWriter`. It
  refuses a trajectory with fewer than :data:`MIN_MODEL_FRAMES` poses (it passes the format but
  breaks every fit and rollout later) and one whose content equals an earlier one's (a copy of a
  file under another name, which a split could put in both training and test), naming both
  source files.
* :func:`scene_type` / :func:`check_single_scene_type`: a split, a fit or a table over a file
  that mixes pushes and tosses compares nothing; they are told apart by structure (a kinematic
  pusher or not), so metadata cannot hide a mix.
"""

from __future__ import annotations

import hashlib
import os
from typing import Any

import numpy as np

from fignet_gym.data.format import Trajectory, TrajectoryFile, TrajectoryFormatError, TrajectoryWriter
from fignet_gym.simulator.scene import ObjectKind

#: Fewest poses an imported trajectory may have: the 3 a model is given (``history`` 2, as every
#: shipped model and the sim-to-real baselines) and one to predict.
MIN_MODEL_FRAMES = 4
#: Scene types told apart by structure (:func:`scene_type`).
PUSH_SCENE, TOSS_SCENE = "push", "toss"


def scene_type(kinds: np.ndarray) -> str:
    """``"push"`` if the objects ``int[O]`` (:class:`ObjectKind` values) include a kinematic one
    (a pusher), else ``"toss"`` (free objects over static geometry)."""
    return PUSH_SCENE if (np.asarray(kinds) == int(ObjectKind.KINEMATIC)).any() else TOSS_SCENE


def check_single_scene_type(path: str | os.PathLike, option: str = "") -> str:
    """The scene type of every trajectory in ``path``; :class:`TrajectoryFormatError` naming a
    trajectory of each type if it holds more than one."""
    first: dict[str, str] = {}
    with TrajectoryFile(path) as f:
        for i in range(len(f)):
            traj = f[i]
            first.setdefault(scene_type(traj.kinds), f"{i} ({traj.name!r})")
            if len(first) > 1:
                (a, at), (b, bt) = first.items()
                raise TrajectoryFormatError(
                    f"{option + ' ' if option else ''}{path}: mixes scene types: trajectory {at} "
                    f"is a {a}, trajectory {bt} a {b} (with{'' if b == PUSH_SCENE else 'out'} a "
                    "kinematic pusher); use one file per scene type")
    return next(iter(first), TOSS_SCENE)


def _origin(traj: Trajectory) -> str:
    """The source file a trajectory was imported from, as the importer recorded it."""
    return f"file {traj.metadata.get('file') or traj.source or traj.name}"


def content_digest(traj: Trajectory) -> bytes:
    """What a copy shares: the poses as stored (float32, with their shape), ``dt`` and the scene
    (MJCF or meshes): the same motion of another object is not a copy."""
    poses = np.ascontiguousarray(traj.poses, np.float32)
    h = hashlib.sha256(repr(poses.shape).encode())
    h.update(poses.tobytes())
    h.update(np.float64(traj.dt).tobytes())
    if traj.mjcf is not None:
        h.update(traj.mjcf.encode())
    if traj.meshes is not None:
        for v in traj.meshes.vertices:
            h.update(np.ascontiguousarray(v, np.float64).tobytes())
    return h.digest()


class ImportWriter(TrajectoryWriter):
    """A :class:`TrajectoryWriter` that also refuses short trajectories and copies (module doc).

    The refusals are :class:`TrajectoryFormatError`, which importers skip with a warning under
    ``--skip-bad``; the copy's message names both source files.
    """

    def __init__(self, path: str | os.PathLike, metadata: dict[str, Any] | None = None,
                 min_frames: int = MIN_MODEL_FRAMES) -> None:
        super().__init__(path, metadata)
        self.min_frames = min_frames
        self._seen: dict[bytes, str] = {}  # content digest -> the first trajectory with it

    def add(self, traj: Trajectory) -> None:
        """Check, then validate and append one trajectory."""
        if traj.num_steps < self.min_frames:
            raise TrajectoryFormatError(
                f"{self.path}: trajectory {traj.name!r} ({_origin(traj)}): field 'poses' has "
                f"{traj.num_steps} poses; at least {self.min_frames} are needed (a model is "
                f"given {self.min_frames - 1} and predicts from there)")
        digest = content_digest(traj)
        if digest in self._seen:
            raise TrajectoryFormatError(
                f"{self.path}: trajectory {traj.name!r} ({_origin(traj)}) is a copy of "
                f"{self._seen[digest]} (same poses, dt and scene): remove one of the two files")
        super().add(traj)
        self._seen[digest] = f"trajectory {traj.name!r} ({_origin(traj)})"
