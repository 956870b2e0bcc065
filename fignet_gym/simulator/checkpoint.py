"""Checkpoint files: :func:`save` seals a simulator with a content checksum, :func:`load` reads one
back safely.

Every route that reads a checkpoint (``fignet_gym.load_pretrained``, ``--resume``, ``ship``,
``evaluate``, the envs) goes through :func:`load`, which refuses, with a :class:`CheckpointError`
naming the file, anything that is not exactly what :func:`save` wrote:

1. the file is unpickled with ``weights_only=True`` (never executes code); a file holding other
   Python objects is refused as such (torch's advice to retry with ``weights_only=False`` is not
   passed on: that would run the payload);
2. the structure (format tag :data:`CHECKPOINT_FORMAT`, ``config`` dict, ``state_dict`` of named
   tensors, ``meta`` dict);
3. the content checksum written at save time (SHA-256 over config, weights and metadata), which
   catches flipped bytes the zip container does not; a file without one (written before the
   checksum existed) loads with a warning: :func:`add_checksum` re-saves it sealed;
4. the config's bounds (:data:`~fignet_gym.simulator.config.CONFIG_BOUNDS`), checked before any
   module is built, so a config asking for ``10**7`` processor blocks or a 200 000 wide latent is
   refused at once instead of exhausting memory;
5. every weight's name and shape against those of the model the config describes (built on
   PyTorch's ``meta`` device: no memory), and every floating weight finite.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import stat
import warnings
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from fignet_gym.simulator.config import SimulatorConfig
from fignet_gym.simulator.model import LearnedSimulator

#: Format tag of the files :func:`save` writes. Format 1 kept training settings (noise, a loss
#: weight) in the model config; it is refused with a message saying so.
CHECKPOINT_FORMAT = "fignet_gym.checkpoint/2"
_OLD_FORMATS = ("fignet_gym.checkpoint/1",)
CHECKSUM_KEY = "checksum"


class CheckpointError(ValueError):
    """A checkpoint file is missing, corrupt, foreign, or does not match the requested model."""


class CheckpointWarning(UserWarning):
    """A checkpoint loads but lacks something a current one has (its content checksum)."""


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
    """``blob`` with its content checksum (what :func:`save` writes)."""
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


def check_regular_file(path: str | os.PathLike) -> Path:
    """``path`` as a ``Path`` if it is a regular file, else a one-line ``CheckpointError`` saying
    what it is (missing, a directory, or a device, FIFO or socket, which reading would block on or
    never finish)."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise CheckpointError(f"{path}: no such checkpoint file") from None
    except OSError as exc:
        raise CheckpointError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(mode):
        raise CheckpointError(f"{path}: is a directory, not a checkpoint file")
    if not stat.S_ISREG(mode):
        kind = ("a FIFO" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode)
                else "a device")
        raise CheckpointError(f"{path}: is {kind}, not a regular checkpoint file")
    return path


def _read(path: str | os.PathLike, map_location: str | torch.device = "cpu"
          ) -> tuple[SimulatorConfig, dict[str, Tensor], dict[str, Any]]:
    """Validated ``(config, state_dict, meta)`` of a checkpoint file (see the module docstring);
    the state dict matches ``LearnedSimulator(config)`` in every name and shape."""
    path = check_regular_file(path)
    blob = _unpickle(path, map_location)
    if isinstance(blob, dict) and blob.get("format") in _OLD_FORMATS:
        raise CheckpointError(f"{path}: checkpoint format {blob['format']!r} (training settings in "
                              f"the model config) is no longer read; this version reads "
                              f"{CHECKPOINT_FORMAT!r}")
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
    check_state_dict(config, state, path)
    return config, state, dict(blob.get("meta", {}))


def load(path: str | os.PathLike, map_location: str | torch.device = "cpu"
         ) -> tuple[LearnedSimulator, dict[str, Any]]:
    """The simulator (in eval mode) and metadata dictionary of a checkpoint file written by
    :func:`save`; never executes code (``weights_only=True``). Raises ``CheckpointError``.

    This is the file layer; users load names and paths with ``fignet_gym.load_pretrained``."""
    config, state, meta = _read(path, map_location)
    sim = LearnedSimulator(config)
    sim.load_state_dict(state)
    sim.to(map_location).eval()
    return sim, meta


def save(sim: LearnedSimulator, path: str | os.PathLike, meta: dict[str, Any] | None = None) -> None:
    """Write ``sim``'s weights, normalisers and config, with ``meta`` (plain values and tensors),
    atomically (temporary file, then rename) and sealed with a content checksum."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(seal({"format": CHECKPOINT_FORMAT, "config": sim.config.to_dict(),
                     "state_dict": sim.state_dict(), "meta": meta or {}}), tmp)
    tmp.replace(path)


def config_from_dict(d: dict[str, Any], path: str | os.PathLike = "checkpoint") -> SimulatorConfig:
    """A bounded :class:`SimulatorConfig` from a checkpoint's config, else ``CheckpointError``."""
    try:
        config = SimulatorConfig.from_dict(d)
    except (TypeError, ValueError, AttributeError) as exc:
        raise CheckpointError(f"{path}: config: {exc}") from None
    return config


def check_state_dict(config: SimulatorConfig, state: dict[str, Tensor],
                     path: str | os.PathLike = "checkpoint") -> None:
    """Check ``state`` against ``LearnedSimulator(config)``: same names, same shapes, finite
    floating values; ``CheckpointError`` naming the first difference."""
    with torch.device("meta"):
        want = LearnedSimulator(config).state_dict()
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


def add_checksum(path: str | os.PathLike, dest: str | os.PathLike | None = None) -> Path:
    """Re-save a checkpoint written before checksums existed with its content checksum.

    The file is read and fully validated (structure, bounds, shapes, finite weights; an existing
    checksum must match), then written to ``dest`` (default: over ``path``, atomically) with
    exactly the same content plus the checksum. Returns the written path.
    """
    path = Path(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CheckpointWarning)
        _read(path)
    blob = _unpickle(path, "cpu")
    out = Path(dest) if dest is not None else path
    tmp = out.with_name(out.name + ".tmp")
    torch.save(seal({k: v for k, v in blob.items() if k != CHECKSUM_KEY}), tmp)
    tmp.replace(out)
    return out
