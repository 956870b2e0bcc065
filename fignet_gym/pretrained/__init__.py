"""Pretrained simulators shipped inside the package, and the one route from a name or a path to a
checkpoint that every entry point (envs, dynamics, CLI, training) takes."""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

import torch

from fignet_gym.simulator.model import CheckpointError, LearnedSimulator


def pretrained_dir() -> Path:
    """Folder of the shipped checkpoints and their model cards."""
    return Path(str(resources.files("fignet_gym.pretrained")))


def available_pretrained() -> list[str]:
    """Names accepted by :func:`load_pretrained`."""
    return sorted(p.stem for p in pretrained_dir().glob("*.pt"))


def pretrained_path(name: str) -> Path:
    """Checkpoint file of a shipped model; a clear error lists the names when it is unknown."""
    path = pretrained_dir() / f"{name}.pt"
    if not path.is_file():
        raise CheckpointError(
            f"no pretrained simulator {name!r}; available: {', '.join(available_pretrained()) or 'none'}")
    return path


def load_pretrained(name: str, map_location: str | torch.device = "cpu") -> LearnedSimulator:
    """Load a shipped simulator (see :func:`available_pretrained`) in eval mode; its model card
    ``fignet_gym/pretrained/<name>.md`` gives data, training budget and scores."""
    return LearnedSimulator.load(pretrained_path(name), map_location)


def resolve_checkpoint(spec: str | os.PathLike) -> Path:
    """The checkpoint file a user means: a pretrained name (``"push"``) or a path.

    A string that names a shipped model and is not an existing file is that model; anything else
    is a path, which must exist (``CheckpointError`` naming it and the pretrained names).
    """
    text = os.fspath(spec)
    path = Path(text)
    if path.is_file():
        return path
    if text in available_pretrained():
        return pretrained_path(text)
    if path.exists():
        raise CheckpointError(f"{text}: is a directory, not a checkpoint file")
    raise CheckpointError(
        f"{text}: no such checkpoint file, and not a pretrained name "
        f"({', '.join(available_pretrained()) or 'none shipped'})"
    )


def load_checkpoint(
    spec: str | os.PathLike | LearnedSimulator, map_location: str | torch.device | None = None
) -> LearnedSimulator:
    """A :class:`LearnedSimulator` from a pretrained name, a checkpoint path or a simulator.

    A simulator is returned as is (moved to ``map_location`` when given); names and paths are
    resolved by :func:`resolve_checkpoint` and loaded in eval mode.
    """
    if isinstance(spec, LearnedSimulator):
        return spec.to(map_location) if map_location is not None else spec
    if not isinstance(spec, (str, os.PathLike)):
        raise TypeError(
            f"checkpoint must be a pretrained name, a path or a LearnedSimulator, got {type(spec).__name__}"
        )
    return LearnedSimulator.load(resolve_checkpoint(spec), map_location or "cpu")
