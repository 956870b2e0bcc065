"""MIT Pushing files: the raw recordings (Yu et al. 2016) and the ``pdproc`` preprocessed form.

Raw files ``motion_surface=<s>_shape=<o>_a=<acc>_v=<vel>_i=<side>_s=<pos>_t=<angle>[_rep=N]
.json|.h5`` hold three unsynchronised ~250 Hz streams ``tip_pose``, ``object_pose``,
``ft_wrench`` of rows ``(t, a, b, c)``; ``pdproc`` HDF5 files (``<root>/<surface>/<shape>/<file>
.h5``) hold ``object``, ``tip``, ``force`` at 180 Hz in the object's initial frame. Both are read
into a :class:`RawPush` (sorted streams on one relative clock). Every error names the file and
the field at fault (:class:`~fignet_gym.data.importers.DataImportError`).
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fignet_gym.data.importers import DataImportError, _read_h5, read_json_object
from fignet_gym.mjcf import MIT_OBJECTS

#: Sample rate of the pdproc files (Hz).
PDPROC_RATE = 180.0
#: ``import-mit``'s default step (s): that of the shipped push models and ``RealPush-v0``, so that
#: an imported folder is scored and fine-tuned by them as it is.
MODEL_DT = 0.02

_MIT_NAME = re.compile(
    r"^(?:motion_surface=(?P<surface>[A-Za-z0-9]+)_shape=(?P<shape>[A-Za-z0-9]+)_)?"
    r"a=(?P<a>-?[0-9.]+)_v=(?P<v>-?[0-9.]+)_i=(?P<i>-?[0-9.]+)_s=(?P<s>-?[0-9.]+)"
    r"_t=(?P<t>-?[0-9.]+)(?:_rep=(?P<rep>[0-9]+))?$")


@dataclass(frozen=True)
class MitPush:
    """What a push's file name says: surface, shape, acceleration (mm/s^2), velocity (mm/s),
    side index, position along the side, push angle (rad), repetition."""

    surface: str | None
    shape: str | None
    acc: float
    vel: float
    side: int
    position: float
    angle: float
    rep: int | None = None


def parse_mit_name(path: str | os.PathLike) -> MitPush:
    """Parse a raw (``motion_surface=...``) or pdproc (``a=..._v=...``) push file name."""
    stem = Path(path).name
    for ext in (".json", ".h5", ".hdf5"):
        if stem.endswith(ext):
            stem = stem[: -len(ext)]
    m = _MIT_NAME.match(stem)
    if m is None:
        raise DataImportError(
            f"{path}: file name does not follow 'motion_surface=<surface>_shape=<shape>_a=<acc>"
            "_v=<vel>_i=<side>_s=<pos>_t=<angle>[_rep=N]' (or the pdproc 'a=..._v=...' form)")
    g = m.groupdict()
    try:
        return MitPush(g["surface"], g["shape"], float(g["a"]), float(g["v"]), int(float(g["i"])),
                       float(g["s"]), float(g["t"]), int(g["rep"]) if g["rep"] else None)
    except ValueError as err:
        raise DataImportError(f"{path}: bad number in the file name ({err})") from None


def _stream(path: Path, name: str, raw: Any, columns: int) -> np.ndarray:
    """A time-sorted stream ``float[N, columns]`` with strictly increasing times (column 0)."""
    try:
        arr = np.asarray(raw, dtype=float)
    except (TypeError, ValueError):
        raise DataImportError(f"{path}: field {name!r} is not a numeric array") from None
    if arr.ndim == 3 and arr.shape[2] == 1:  # some pdproc arrays are (N, C, 1)
        arr = arr[..., 0]
    if arr.ndim != 2 or arr.shape[1] != columns or len(arr) < 2:
        raise DataImportError(
            f"{path}: field {name!r} has shape {arr.shape}, expected (N >= 2, {columns})")
    if not np.isfinite(arr).all():
        row = int(np.argwhere(~np.isfinite(arr).all(1))[0, 0])
        raise DataImportError(f"{path}: field {name!r} has non-finite values (row {row})")
    arr = arr[np.argsort(arr[:, 0], kind="stable")]
    keep = np.concatenate([[True], np.diff(arr[:, 0]) > 0])  # drop repeated time stamps
    return arr[keep]


def resample(times: np.ndarray, stream: np.ndarray,
             angle_columns: Sequence[int] = ()) -> np.ndarray:
    """Linear interpolation of ``float[N, 1 + C]`` (time first) at ``times``: ``float[T, C]``.

    Angle columns are unwrapped first, so an angle crossing +-pi interpolates the short way.
    """
    values = stream[:, 1:].copy()
    for c in angle_columns:
        values[:, c - 1] = np.unwrap(values[:, c - 1])
    return np.stack([np.interp(times, stream[:, 0], values[:, c])
                     for c in range(values.shape[1])], axis=1)


@dataclass
class RawPush:
    """One push's streams on their own clocks (s from the push's first common sample).

    Attributes:
        path, info, shape, surface, fmt: the file and what it says (``fmt``: raw or pdproc).
        obj: ``float[N, 4]`` (t, x, y, unwrapped yaw). tip: ``float[M, 3]`` (t, x, y).
        force: ``float[L, 4]`` (t, fx, fy, torque). t0: absolute time of ``t = 0`` (s).
        still: set by the analysis when the push never moves the object.
    """

    path: Path
    info: MitPush
    shape: str
    surface: str | None
    fmt: str
    obj: np.ndarray
    tip: np.ndarray
    force: np.ndarray
    t0: float = 0.0
    still: bool = False

    @property
    def span(self) -> tuple[float, float]:
        """Times (s) all three streams cover."""
        s = (self.obj, self.tip, self.force)
        return max(x[0, 0] for x in s), min(x[-1, 0] for x in s)

    def tracks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Object samples within the tip's span: times ``float[T]``, ``obj float[T, 3]`` (x, y,
        yaw) and ``tip float[T, 2]`` at those times (the object stream's own clock)."""
        lo, hi = self.tip[0, 0], self.tip[-1, 0]
        o = self.obj[(self.obj[:, 0] >= lo) & (self.obj[:, 0] <= hi)]
        return o[:, 0], o[:, 1:], resample(o[:, 0], self.tip)


def _check_shape(path: Path, shape: str | None) -> str:
    if shape is None:
        raise DataImportError(f"{path}: no shape in the file name or directory")
    if shape not in MIT_OBJECTS:
        raise DataImportError(
            f"{path}: field 'shape': unknown shape {shape!r}; valid: {', '.join(MIT_OBJECTS)}")
    return shape


def _read_raw(path: Path) -> RawPush:
    keys = ("tip_pose", "object_pose", "ft_wrench")
    info = parse_mit_name(path)
    shape = _check_shape(path, info.shape)
    if path.suffix == ".json":
        content = read_json_object(path, str(keys))
    else:
        content = _read_h5(path, keys)
    for k in keys:
        if k not in content:
            raise DataImportError(f"{path}: missing field {k!r}")
    tip = _stream(path, "tip_pose", content["tip_pose"], 4)[:, :3]
    obj = _stream(path, "object_pose", content["object_pose"], 4)
    obj[:, 3] = np.unwrap(obj[:, 3])
    ft = _stream(path, "ft_wrench", content["ft_wrench"], 4)
    t0 = max(s[0, 0] for s in (tip, obj, ft))
    for s in (tip, obj, ft):
        s[:, 0] -= t0
    return RawPush(path, info, shape, info.surface, "raw", obj, tip, ft, float(t0))


def _scalar(content: dict[str, Any], key: str, default: float) -> float:
    return float(np.asarray(content[key]).ravel()[0]) if key in content else default


def _read_pdproc(path: Path) -> RawPush:
    surface = path.parent.parent.name or None
    shape = _check_shape(path, path.parent.name)
    content = _read_h5(path, ("object", "tip", "force", "acc", "push_velocity", "push_angle",
                              "push_side", "push_point"))
    for k in ("object", "tip", "force"):
        if k not in content:
            raise DataImportError(f"{path}: missing field {k!r}")
    streams = []
    for k, cols in (("object", 3), ("tip", 2), ("force", 3)):
        arr = np.asarray(content[k], float)
        arr = arr[..., 0] if arr.ndim == 3 and arr.shape[2] == 1 else arr
        clock = np.arange(len(arr))[:, None] / PDPROC_RATE
        streams.append(_stream(path, k, np.hstack([clock, arr]) if arr.ndim == 2 else arr,
                               cols + 1))
    try:
        named: MitPush | None = parse_mit_name(path)
    except DataImportError:  # pdproc names are not always kept; the scalars hold the same facts
        named = None
    nan = float("nan")
    info = MitPush(
        surface, shape, _scalar(content, "acc", named.acc if named else nan),
        _scalar(content, "push_velocity", named.vel if named else nan),
        int(_scalar(content, "push_side", named.side if named else -1)),
        _scalar(content, "push_point", named.position if named else nan),
        float(np.deg2rad(_scalar(content, "push_angle",
                                 np.rad2deg(named.angle) if named else nan))),
        named.rep if named else None)
    streams[0][:, 3] = np.unwrap(streams[0][:, 3])
    return RawPush(path, info, shape, surface, "pdproc", *streams)


def is_pdproc(path: Path) -> bool:
    """Whether ``path`` is a pdproc file (field ``object``) rather than a raw push."""
    if path.suffix == ".json":
        return False
    try:
        with h5py.File(path, "r") as f:
            if "object_pose" in f:
                return False
            if "object" in f:
                return True
    except OSError as err:
        raise DataImportError(f"{path}: not a readable HDF5 file ({err})") from None
    raise DataImportError(f"{path}: neither a raw MIT push (field 'object_pose') nor a pdproc "
                          "file (field 'object')")


def read_push(path: str | os.PathLike) -> RawPush:
    """One raw or pdproc push file, its streams sorted and on one relative clock."""
    path = Path(path)
    return _read_pdproc(path) if is_pdproc(path) else _read_raw(path)
