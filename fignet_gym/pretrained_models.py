"""Pretrained simulators shipped inside the package (loaded offline, by name)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from fignet_gym.simulator import CheckpointError, LearnedSimulator


def pretrained_dir() -> Path:
    """Folder of the shipped checkpoints and their model cards."""
    return Path(str(resources.files("fignet_gym") / "pretrained"))


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


def load_pretrained(name: str, map_location: str = "cpu") -> LearnedSimulator:
    """Load a shipped simulator (``"push"`` or ``"toss"``) in eval mode; see its model card
    ``fignet_gym/pretrained/<name>.md`` for data, training budget and scores."""
    return LearnedSimulator.load(pretrained_path(name), map_location)


def resolve_checkpoint(spec: str) -> Path:
    """A checkpoint path, or the file of a pretrained name."""
    p = Path(spec)
    return p if p.suffix == ".pt" or p.exists() else pretrained_path(spec)
