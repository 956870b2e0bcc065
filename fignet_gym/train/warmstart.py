"""Warm starts: a new model begins from a trained one's weights and normaliser statistics, even
when it adds optional face feature groups (``graph.FACE_GROUPS``)."""

from __future__ import annotations

import torch

from fignet_gym.simulator.config import SimulatorConfig
from fignet_gym.simulator.graph import FACE_BASE, FACE_GROUPS
from fignet_gym.simulator.model import LearnedSimulator


def _face_columns(config: SimulatorConfig) -> list[tuple[str, int]]:
    """Face-feature columns of ``config`` as ``(group, index within group)``, in layout order."""
    cols = [("base", i) for i in range(FACE_BASE)]
    for group in config.face_groups:
        cols += [(group.name, i) for i in range(group.size)]
    return cols


def warm_start(sim: LearnedSimulator, source: LearnedSimulator) -> None:
    """Copy ``source``'s weights and normaliser statistics into ``sim``.

    The architectures must match, except that ``sim`` may add optional face feature groups
    (``graph.FACE_GROUPS``): the face encoder's input columns for a new group start at zero, so
    the warm-started model computes exactly what ``source`` did, and the new columns' normaliser
    statistics start as those of the group's ``stats_from`` base columns (of the same scale).
    """
    own, src = sim.state_dict(), source.state_dict()
    if set(own) != set(src):
        raise ValueError(f"cannot warm-start: parameters differ ({sorted(set(own) ^ set(src))[:4]} ...)")
    new_cols, old_cols = _face_columns(sim.config), _face_columns(source.config)
    if not set(old_cols) <= set(new_cols):
        raise ValueError("cannot warm-start: the source has face features this model lacks")
    # For each of this model's face columns: the source column it copies, or (for a new group)
    # the source column its statistics start from, with its weights zeroed.
    stats_from = {g.name: g.stats_from for g in FACE_GROUPS}
    pick = [old_cols.index(c) if c in old_cols else stats_from[c[0]] + c[1] for c in new_cols]
    fresh = torch.tensor([c not in old_cols for c in new_cols])
    widen = {"net.enc.face.first.weight", "norms.face.total", "norms.face.total_sq"}
    for key, value in src.items():
        target = own[key]
        if target.shape == value.shape and (key not in widen or not fresh.any()):
            target.copy_(value)
        elif key in widen and value.shape[-1] == len(old_cols) and target.shape[-1] == len(new_cols):
            cols = value[..., pick].clone()
            if key.startswith("net."):
                cols[..., fresh] = 0.0
            target.copy_(cols)
        else:
            raise ValueError(f"cannot warm-start {key}: shape {tuple(value.shape)} -> {tuple(target.shape)}")
