"""Checkpoint files: reading them safely, sealing them with a content checksum.

Every route that reads a checkpoint (:meth:`LearnedSimulator.load`, ``--resume``, ``ship``,
``evaluate``, the envs) goes through :func:`read_checkpoint`, which refuses, with a
:class:`~fignet_gym.simulator.model.CheckpointError` naming the file, anything that is not exactly
what :meth:`LearnedSimulator.save` wrote:

1. the file is unpickled with ``weights_only=True`` (never executes code); a file holding other
   Python objects is refused as such (torch's advice to retry with ``weights_only=False`` is not
   passed on: that would run the payload);
2. the structure (format tag, ``config`` dict, ``state_dict`` of named tensors, ``meta`` dict);
3. the content checksum written at save time (SHA-256 over config, weights and metadata), which
   catches flipped bytes the zip container does not; a file without one (written before the
   checksum existed) loads with a warning: :func:`add_checksum` re-saves it sealed;
4. the config's bounds (:data:`CONFIG_BOUNDS`), checked before any module is built, so a config
   asking for ``10**7`` processor blocks or a 200 000 wide latent is refused at once instead of
   exhausting memory;
5. every weight's name and shape against those of the model the config describes (built on
   PyTorch's ``meta`` device: no memory), and every floating weight finite.
"""

from __future__ import annotations

import hashlib
import math
import os
import pickle
import warnings
from dataclasses import fields
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from fignet_gym.simulator.model import (
    CHECKPOINT_FORMAT,
    CheckpointError,
    LearnedSimulator,
    SimulatorConfig,
)

#: Inclusive ``(low, high)`` bounds of numeric config fields (the paper's model: history 2,
#: latent 128, 10 blocks). Anything outside is refused in checkpoints and new configs alike.
CONFIG_BOUNDS: dict[str, tuple[float, float]] = {
    "dt": (1e-6, 10.0),
    "history": (1, 16),
    "latent_size": (1, 4096),
    "hidden_size": (1, 8192),
    "message_passing_steps": (1, 64),
    "collision_radius": (1e-6, 100.0),
    "feature_clip": (0.0, 1e4),
    "noise_std": (0.0, 100.0),
    "rotation_noise_std": (0.0, 10.0),
    "vertical_weight": (0.0, 1e6),
}
#: Bounds of the mesh options (each level multiplies node counts, so they are kept small).
MESH_BOUNDS: dict[str, tuple[float, float]] = {
    "sphere_subdivisions": (0, 5),
    "cylinder_sections": (3, 256),
    "capsule_rings": (1, 64),
    "box_subdivisions": (0, 5),
    "plane_half_size": (1e-3, 1e5),
    "plane_cells": (1, 256),
}
CHECKSUM_KEY = "checksum"


class CheckpointWarning(UserWarning):
    """A checkpoint loads but lacks something a current one has (its content checksum)."""


def check_config(config: SimulatorConfig) -> None:
    """``ValueError`` naming the first field of ``config`` of the wrong type or out of bounds."""
    def check(name: str, value: Any, lo: float, hi: float, integer: bool) -> None:
        if integer and (isinstance(value, bool) or not isinstance(value, int)):
            raise ValueError(f"{name} must be an integer, got {value!r}")
        if not integer and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise ValueError(f"{name} must be a number, got {value!r}")
        if not (math.isfinite(value) and lo <= value <= hi):
            raise ValueError(f"{name} must be in [{lo:g}, {hi:g}], got {value!r}")

    ints = {"history", "latent_size", "hidden_size", "message_passing_steps"}
    for name, (lo, hi) in CONFIG_BOUNDS.items():
        value = getattr(config, name)
        if name == "hidden_size" and value is None:
            continue
        check(name, value, lo, hi, name in ints)
    if len(config.gravity) != 3:
        raise ValueError(f"gravity must have 3 entries, got {config.gravity!r}")
    for g in config.gravity:
        check("gravity", g, -1e3, 1e3, False)
    for f in fields(SimulatorConfig):
        if f.type in ("bool", bool) and not isinstance(getattr(config, f.name), bool):
            raise ValueError(f"{f.name} must be true or false, got {getattr(config, f.name)!r}")
    if not isinstance(config.scene_type, str):
        raise ValueError(f"scene_type must be a string, got {config.scene_type!r}")
    mo = config.mesh_options
    for name, (lo, hi) in MESH_BOUNDS.items():
        check(f"mesh_options.{name}", getattr(mo, name), lo, hi, name != "plane_half_size")


# ----------------------------------------------------------------------------- checksum
def _feed(h: Any, obj: Any) -> None:
    """Add a canonical, type-tagged encoding of ``obj`` (what ``torch.save`` stores) to ``h``."""
    if isinstance(obj, Tensor):
        t = obj.detach().cpu().contiguous()
        h.update(f"T{t.dtype}{tuple(t.shape)}".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes())
    elif isinstance(obj, dict):
        h.update(f"D{len(obj)}".encode())
        for key in sorted(obj, key=repr):
            _feed(h, key)
            _feed(h, obj[key])
    elif isinstance(obj, (list, tuple)):
        h.update(f"{'L' if isinstance(obj, list) else 'U'}{len(obj)}".encode())
        for item in obj:
            _feed(h, item)
    elif obj is None or isinstance(obj, (bool, int, float, str, bytes)):
        h.update(f"{type(obj).__name__}:{obj!r};".encode())
    else:
        h.update(f"{type(obj).__name__}:{obj!r};".encode())


def content_checksum(blob: dict[str, Any]) -> str:
    """``"sha256:<hex>"`` of everything in a checkpoint dictionary except its checksum."""
    h = hashlib.sha256()
    _feed(h, {k: v for k, v in blob.items() if k != CHECKSUM_KEY})
    return "sha256:" + h.hexdigest()


def seal(blob: dict[str, Any]) -> dict[str, Any]:
    """``blob`` with its content checksum (what :meth:`LearnedSimulator.save` writes)."""
    return {**blob, CHECKSUM_KEY: content_checksum(blob)}


# ----------------------------------------------------------------------------- reading
def _unpickle(path: Path, map_location: str | torch.device) -> Any:
    try:
        return torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as exc:
        lines = str(exc).strip().splitlines()
        # torch's message always mentions weights_only; only a refused GLOBAL means objects
        what = next((ln.strip() for ln in lines if "Unsupported global" in ln or "GLOBAL" in ln), "")
        if what:
            raise CheckpointError(
                f"{path}: holds Python objects other than tensors and plain values, refused "
                f"because unpickling them could run code ({what})") from None
        cause = next((ln.strip() for ln in lines if ln.strip().startswith("Unsupported")),
                     lines[0] if lines else type(exc).__name__)
        raise CheckpointError(f"{path}: not a readable checkpoint (truncated, corrupt or not "
                              f"written by torch.save: {cause})") from None
    except (RuntimeError, EOFError, OSError, ValueError, KeyError, AttributeError, TypeError,
            IndexError, UnicodeDecodeError, MemoryError) as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise CheckpointError(f"{path}: not a readable checkpoint (truncated, corrupt or not "
                              f"written by torch.save: {first})") from None


def read_checkpoint(path: str | os.PathLike, map_location: str | torch.device = "cpu"
                    ) -> tuple[SimulatorConfig, dict[str, Tensor], dict[str, Any]]:
    """Validated ``(config, state_dict, meta)`` of a checkpoint file (see the module docstring).

    The state dict is already upgraded (:meth:`LearnedSimulator.upgrade_state_dict`) and matches
    ``LearnedSimulator(config)`` in every name and shape. Raises ``CheckpointError``.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: no such checkpoint file")
    blob = _unpickle(path, map_location)
    if not isinstance(blob, dict) or blob.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{path}: not a fignet_gym checkpoint (format tag missing)")
    for key, kind in (("config", dict), ("state_dict", dict), ("meta", dict)):
        if key == "meta" and key not in blob:
            continue
        if not isinstance(blob.get(key), kind):
            raise CheckpointError(f"{path}: field {key!r} is missing or not a dictionary")
    if CHECKSUM_KEY in blob:
        if blob[CHECKSUM_KEY] != content_checksum(blob):
            raise CheckpointError(f"{path}: content checksum mismatch: the file is corrupt "
                                  "(changed after it was saved)")
    else:
        warnings.warn(f"{path}: checkpoint has no content checksum (saved by an older "
                      "fignet_gym), so corruption cannot be detected; re-save it with "
                      "fignet_gym.simulator.checkpoint.add_checksum(path)", CheckpointWarning,
                      stacklevel=3)
    config = config_from_dict(blob["config"], path)
    state = blob["state_dict"]
    bad = [k for k, v in state.items() if not isinstance(k, str) or not isinstance(v, Tensor)]
    if bad:
        raise CheckpointError(f"{path}: state_dict entry {bad[0]!r} is not a named tensor")
    state = check_state_dict(config, state, path)
    return config, state, dict(blob.get("meta", {}))


def config_from_dict(d: dict[str, Any], path: str | os.PathLike = "checkpoint") -> SimulatorConfig:
    """A bounded :class:`SimulatorConfig` from a checkpoint's config, else ``CheckpointError``."""
    try:
        config = SimulatorConfig.from_dict(d)
        check_config(config)
    except CheckpointError as exc:  # already says "config key ..."
        raise CheckpointError(f"{path}: {exc}") from None
    except (TypeError, ValueError, AttributeError) as exc:
        raise CheckpointError(f"{path}: config: {exc}") from None
    return config


def check_state_dict(config: SimulatorConfig, state: dict[str, Tensor],
                     path: str | os.PathLike = "checkpoint") -> dict[str, Tensor]:
    """``state`` upgraded and checked against ``LearnedSimulator(config)``: same names, same
    shapes, finite floating values; ``CheckpointError`` naming the first difference."""
    with torch.device("meta"):
        ref = LearnedSimulator(config)
    state = ref.upgrade_state_dict(state)
    want = ref.state_dict()
    missing, extra = sorted(set(want) - set(state)), sorted(set(state) - set(want))
    if missing or extra:
        raise CheckpointError(
            f"{path}: weights do not match its config: "
            + (f"missing {missing[:3]}{' ...' if len(missing) > 3 else ''}" if missing else "")
            + ("; " if missing and extra else "")
            + (f"unexpected {extra[:3]}{' ...' if len(extra) > 3 else ''}" if extra else ""))
    for key, ref_t in want.items():
        t = state[key]
        if tuple(t.shape) != tuple(ref_t.shape):
            raise CheckpointError(f"{path}: weights do not match its config: {key!r} has shape "
                                  f"{tuple(t.shape)}, the config needs {tuple(ref_t.shape)}")
        if t.is_floating_point() and not bool(torch.isfinite(t).all()):
            n = int((~torch.isfinite(t)).sum())
            raise CheckpointError(f"{path}: weight {key!r} has {n} NaN or infinite values")
    return state


def add_checksum(path: str | os.PathLike, dest: str | os.PathLike | None = None) -> Path:
    """Re-save a checkpoint written before checksums existed with its content checksum.

    The file is read and fully validated (structure, bounds, shapes, finite weights; an existing
    checksum must match), then written to ``dest`` (default: over ``path``, atomically) with
    exactly the same content plus the checksum. Returns the written path.
    """
    path = Path(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CheckpointWarning)
        read_checkpoint(path)
    blob = _unpickle(path, "cpu")
    out = Path(dest) if dest is not None else path
    tmp = out.with_name(out.name + ".tmp")
    torch.save(seal({k: v for k, v in blob.items() if k != CHECKSUM_KEY}), tmp)
    tmp.replace(out)
    return out
