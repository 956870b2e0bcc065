"""Pretrained simulators shipped inside the package, and the one route from a name or a path to a
simulator that every entry point (envs, dynamics, CLI, training) takes: :func:`load_pretrained`."""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

import torch

from fignet_gym.simulator.checkpoint import CheckpointError, check_regular_file, load
from fignet_gym.simulator.model import LearnedSimulator


def pretrained_dir() -> Path:
    """Folder of the shipped checkpoints and their model cards (shipped PPO policies: its
    ``policies/`` sub-folder, read by ``fignet_gym.agents.load_policy``)."""
    return Path(str(resources.files("fignet_gym.pretrained")))


def available_pretrained() -> list[str]:
    """Names of the shipped simulators accepted by :func:`load_pretrained`."""
    return sorted(p.stem for p in pretrained_dir().glob("*.pt"))


def pretrained_path(name: str) -> Path:
    """Checkpoint file of a shipped model; a clear error lists the names when it is unknown."""
    path = pretrained_dir() / f"{name}.pt"
    if not path.is_file():
        raise CheckpointError(
            f"no pretrained simulator {name!r}; available: {', '.join(available_pretrained()) or 'none'}")
    return path


def _resolve(spec: str | os.PathLike) -> Path:
    """The checkpoint file a user means: a pretrained name (``"push"``) or a path.

    A string that names a shipped model and is not an existing file is that model; anything else
    is a path, which must be a regular file (``CheckpointError`` naming it, what it is instead,
    and the pretrained names when it does not exist).
    """
    text = os.fspath(spec)
    path = Path(text)
    if path.is_file():
        return path
    if text in available_pretrained():
        return pretrained_path(text)
    if os.path.lexists(text):
        return check_regular_file(path)  # a directory, device, FIFO or socket: says which
    raise CheckpointError(
        f"{text}: no such checkpoint file, and not a pretrained name "
        f"({', '.join(available_pretrained()) or 'none shipped'})"
    )


def load_pretrained(
    spec: str | os.PathLike | LearnedSimulator, map_location: str | torch.device | None = None
) -> LearnedSimulator:
    """A :class:`LearnedSimulator` in eval mode from a shipped name (:func:`available_pretrained`;
    its model card ``fignet_gym/pretrained/<name>.md`` gives data, training budget and scores) or a
    checkpoint file. A simulator is returned as is (moved to ``map_location`` when given), so
    callers may take any of the three. Raises ``CheckpointError`` with one line naming the file.
    """
    if isinstance(spec, LearnedSimulator):
        return spec.to(map_location) if map_location is not None else spec
    if not isinstance(spec, (str, os.PathLike)):
        raise TypeError(
            f"checkpoint must be a pretrained name, a path or a LearnedSimulator, got {type(spec).__name__}"
        )
    return load(_resolve(spec), map_location or "cpu")[0]
