"""Importer of MIT Pushing recordings (Yu et al. 2016) into the trajectory format.

Inputs: raw files ``motion_surface=<s>_shape=<o>_a=<acc>_v=<vel>_i=<side>_s=<pos>_t=<angle>
[_rep=N].json|.h5`` (three unsynchronised ~250 Hz streams ``tip_pose``, ``object_pose``,
``ft_wrench`` of rows ``(t, a, b, c)``), or preprocessed ``pdproc`` HDF5 files (180 Hz, in the
object's initial frame) found as ``<root>/<surface>/<shape>/<file>.h5``.

The protocol (:class:`MitProtocol`, the paper's, appendix B.2 of FIGNet), applied the same way to
any folder:

1. per shape, the offset between the tracked yaw and the dataset's outline is measured on the
   pushes given (:func:`fignet_gym.data.mit_geometry.estimate_offset`); the scene's prism is the
   real outline (12.7 mm) in the recorded frame;
2. a push that never moves the object (no outline point travels ``STILL_MOTION``) is reported
   and, unless ``keep_still``, not imported;
3. windows start at first contact (the first sample with the moving tip within ``CONTACT_GAP`` of
   the outline, or the object's first motion if earlier: at or just before touching; the files
   often begin with the tip resting against the object) and last ``window`` seconds; a push long enough gives
   several consecutive windows, each starting while the object still moves;
4. poses every ``dt`` (default 12 ms: every 3rd sample of the 250 Hz streams, as the paper).

Every error names the file and the field at fault (:class:`DataImportError`).
"""

from __future__ import annotations

import json
import os
import re
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fignet_gym.data import mit_geometry as geo
from fignet_gym.data.format import Trajectory, TrajectoryFormatError, TrajectoryWriter
from fignet_gym.data.importers import IMPORTER_VERSION, DataImportError, _expand, _read_h5
from fignet_gym.data.mit_scene import TIP_Z, real_push_scene_xml
from fignet_gym.mjcf import MIT_OBJECTS, yaw_quat
from fignet_gym.simulator.scene import Scene

#: Sample rate of the pdproc files (Hz).
PDPROC_RATE = 180.0
#: Paper's step: every 3rd sample of the 250 Hz streams (s).
PAPER_DT = 0.012
#: Paper's window (s): error after 0.5 s.
PAPER_WINDOW = 0.5
#: A window starts at the first sample where the tip's surface is within this (m) of the outline.
CONTACT_GAP = 0.001
#: A later window must start at least this long before the object's last moving sample (s).
MIN_PUSHING = 0.1

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
        try:
            with open(path) as fh:
                content = json.load(fh)
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise DataImportError(f"{path}: not a readable JSON file ({err})") from None
        if not isinstance(content, dict):
            raise DataImportError(f"{path}: expected a JSON object with {keys}")
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


def _is_pdproc(path: Path) -> bool:
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
    return _read_pdproc(path) if _is_pdproc(path) else _read_raw(path)


@dataclass(frozen=True)
class MitSelection:
    """Which pushes to import (``None``: any). Defaults: the paper's (``abs``, zero acceleration).

    Attributes:
        surfaces, shapes: names. velocities: mm/s. accelerations: mm/s^2 (``a`` of the name).
    """

    surfaces: tuple[str, ...] | None = ("abs",)
    shapes: tuple[str, ...] | None = None
    velocities: tuple[float, ...] | None = None
    accelerations: tuple[float, ...] | None = (0.0,)

    def accepts(self, surface: str | None, info: MitPush, shape: str | None) -> bool:
        """Whether a push of this surface, name and shape is selected."""
        return ((self.surfaces is None or surface in self.surfaces)
                and (self.shapes is None or shape in self.shapes)
                and (self.velocities is None or info.vel in self.velocities)
                and (self.accelerations is None or info.acc in self.accelerations))


@dataclass(frozen=True)
class MitProtocol:
    """How pushes become trajectories (defaults: the paper's).

    Attributes:
        dt: pose step (s). window: window length (s); 0 keeps one window to the push's end.
        start: ``"contact"`` (windows from first contact) or ``"file"`` (one window from the
            first common sample: the old cut, mostly approach).
        keep_still: import pushes that never move the object (always reported).
        friction: written into the MJCF (the real value is unknown; sysid fits it).
        outlines: folder of ``<shape>_ext.npy`` (default: the shipped outlines).
    """

    dt: float = PAPER_DT
    window: float = PAPER_WINDOW
    start: str = "contact"
    keep_still: bool = False
    friction: float = 0.25
    outlines: str | None = None


@dataclass
class MitReport:
    """What an import or a check found: per-shape contact checks, windows and still pushes."""

    shapes: dict[str, geo.ShapeCheck] = field(default_factory=dict)
    windows: int = 0
    pushes: int = 0
    short_windows: list[str] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {"pushes": self.pushes, "windows": self.windows,
                "short_windows": self.short_windows,
                "shapes": {k: v.as_json() for k, v in sorted(self.shapes.items())}}

    def table(self) -> str:
        """Per-shape lines: pushes, contact frames, offset, distance quantiles, inside fraction."""
        rows = [f"{'shape':8s} {'pushes':>6s} {'still':>5s} {'frames':>6s} {'offset deg':>10s} "
                f"{'shift mm':>12s} {'status':9s} distance q05/q50/q95 mm  inside>1mm"]
        for name, c in sorted(self.shapes.items()):
            q = np.quantile(c.distances, (0.05, 0.5, 0.95)) * 1e3 if len(c.distances) else []
            qs = "/".join(f"{v:.2f}" for v in q) if len(q) else "-"
            o = c.offset
            rows.append(f"{name:8s} {c.pushes:6d} {len(c.still):5d} {len(c.distances):6d} "
                        f"{np.degrees(o.theta):10.1f} {1e3 * o.shift[0]:5.2f},{1e3 * o.shift[1]:5.2f}"
                        f"  {o.status:9s} {qs:24s} {100 * c.inside_fraction:6.1f}%")
        return "\n".join(rows)


def _outline(shape: str, protocol: MitProtocol) -> np.ndarray:
    try:
        return geo.outline(shape, protocol.outlines)
    except ValueError as err:
        raise DataImportError(str(err)) from None


def _collect(paths: Iterable[str | os.PathLike], selection: MitSelection,
             skip_bad: bool) -> list[RawPush]:
    pushes = []
    for f in _expand(paths, ("*.json", "*.h5")):
        try:
            if not _is_pdproc(f):
                info = parse_mit_name(f)  # select on the name before reading the file
                if not selection.accepts(info.surface, info, info.shape):
                    continue
            push = read_push(f)
            if selection.accepts(push.surface, push.info, push.shape):
                pushes.append(push)
        except DataImportError as err:
            if not skip_bad:
                raise
            warnings.warn(f"skipped: {err}", stacklevel=3)
    return pushes


def analyse(pushes: Sequence[RawPush], protocol: MitProtocol) -> MitReport:
    """Measure each shape's offset on its pushes and check the tip's distance in contact."""
    report = MitReport(pushes=len(pushes))
    by_shape: dict[str, list[RawPush]] = {}
    for p in pushes:
        by_shape.setdefault(p.shape, []).append(p)
    for shape, group in by_shape.items():
        poly = _outline(shape, protocol)
        contacts, still = [], []
        for p in group:
            times, obj, tip = p.tracks()
            if geo.max_motion(obj, poly) < geo.STILL_MOTION:
                still.append(p.path.name)
                continue
            contacts.append(geo.tip_in_object_frame(obj, tip)[geo.contact_mask(times, obj)])
        offset = geo.estimate_offset(poly, contacts)
        dist = [geo.signed_distance(offset.to_outline_frame(c), poly) for c in contacts if len(c)]
        report.shapes[shape] = geo.ShapeCheck(shape, offset, np.concatenate(dist) if dist
                                              else np.zeros(0), len(group), still)
    return report


def _window_starts(push: RawPush, poly_rec: np.ndarray, protocol: MitProtocol) -> list[float]:
    lo, hi = push.span
    if protocol.start == "file":
        return [lo]
    times, obj, tip = push.tracks()
    gap = geo.signed_distance(geo.tip_in_object_frame(obj, tip), poly_rec) - geo.TIP_RADIUS
    # the raw files often begin with the tip resting against the object: contact counts from
    # when the tip moves there
    near = np.flatnonzero((gap <= CONTACT_GAP) & (geo.central_speed(times, tip) > geo.CONTACT_SPEED))
    moving = np.flatnonzero(geo.contact_mask(times, obj))
    first = [times[near[0]]] if len(near) else []
    first += [times[moving[0]]] if len(moving) else []
    start = max(lo, min(first)) if first else lo
    if protocol.window <= 0:
        return [start]
    last_move = times[moving[-1]] if len(moving) else start
    length = round(protocol.window / protocol.dt) * protocol.dt
    starts = [start]
    while True:
        nxt = starts[-1] + length
        if nxt + length > hi + 1e-9 or nxt + MIN_PUSHING > last_move:
            return starts
        starts.append(nxt)


def _planar_poses(obj: np.ndarray, tip: np.ndarray, thickness: float) -> np.ndarray:
    """Poses ``float[T, 3, 7]`` of (world, object, tip) from ``obj float[T, 3]``, ``tip
    float[T, 2]``."""
    poses = np.zeros((len(obj), 3, 7))
    poses[:, 0, 3] = 1.0
    poses[:, 1, :2] = obj[:, :2]
    poses[:, 1, 2] = thickness / 2
    poses[:, 1, 3:] = np.stack([yaw_quat(a) for a in obj[:, 2]])
    poses[:, 2, :2] = tip
    poses[:, 2, 2] = TIP_Z
    poses[:, 2, 3] = 1.0
    return poses


def _scene_info(mjcf: str) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Kinds, properties and names of the scene (as the trajectory file checks them)."""
    import mujoco

    scene = Scene.from_mjmodel(mujoco.MjModel.from_xml_string(mjcf))
    return scene.object_kind.numpy(), scene.object_props.double().numpy(), scene.object_names


def push_windows(push: RawPush, offset: geo.FrameOffset, protocol: MitProtocol,
                 report: MitReport | None = None) -> list[Trajectory]:
    """The trajectories (windows) of one push under ``protocol``, with the shape's ``offset``."""
    poly_rec = offset.outline_in_recorded_frame(_outline(push.shape, protocol))
    lo, hi = push.span
    n_full = int(round(protocol.window / protocol.dt)) if protocol.window > 0 else None
    obj_spec = MIT_OBJECTS[push.shape]
    out = []
    for k, start in enumerate(_window_starts(push, poly_rec, protocol)):
        n = int(np.floor((hi - start) / protocol.dt + 1e-9))
        if n_full is not None:
            if n < n_full and report is not None:
                report.short_windows.append(f"{push.path.name}#{k}")
            n = min(n, n_full)
        if n < 1:
            raise DataImportError(f"{push.path}: the streams cover {max(hi - start, 0):.3f} s "
                                  f"after the window start, less than one step of {protocol.dt} s")
        times = start + protocol.dt * np.arange(n + 1)
        obj = resample(times, push.obj)
        tip = resample(times, push.tip)
        force = resample(times, push.force)
        reach = float(np.abs(np.concatenate([obj[:, :2], tip])).max())
        floor = max(0.5, float(np.ceil((reach + 0.2) * 10) / 10))  # the floor covers the motion
        mjcf = real_push_scene_xml(push.shape, poly_rec, obj_spec.mass, obj_spec.inertia_z,
                                   protocol.friction, floor_half_size=floor,
                                   object_pose=tuple(obj[0]), tip_xy=tuple(tip[0]))
        meta = {"source": f"mit_pushing/{push.fmt}", "file": push.path.name,
                "surface": push.surface, "shape": push.shape, "acc": push.info.acc,
                "vel_mm_s": push.info.vel, "side": push.info.side,
                "position": push.info.position, "angle": push.info.angle, "rep": push.info.rep,
                "window": k, "window_start_s": float(start), "t0": push.t0 + float(start),
                "frame_offset": offset.as_json(), "protocol": asdict(protocol),
                "friction_assumed": protocol.friction, "importer_version": IMPORTER_VERSION}
        kinds, props, names = _scene_info(mjcf)
        out.append(Trajectory(poses=_planar_poses(obj, tip, geo.REAL_THICKNESS),
                              dt=protocol.dt, kinds=kinds, props=props, names=names,
                              mjcf=mjcf, metadata=meta, extras={"force": force},
                              name=push.path.stem if k == 0 else f"{push.path.stem}#w{k}"))
    return out


def check_mit(paths: Iterable[str | os.PathLike], selection: MitSelection | None = None,
              protocol: MitProtocol | None = None, skip_bad: bool = False) -> MitReport:
    """The geometry check alone: per shape, the offset found and the tip's distance in contact."""
    protocol = protocol or MitProtocol()
    return analyse(_collect(paths, selection or MitSelection(), skip_bad), protocol)


def import_mit(paths: Iterable[str | os.PathLike], out: str | os.PathLike,
               selection: MitSelection | None = None, protocol: MitProtocol | None = None,
               skip_bad: bool = False) -> MitReport:
    """Import MIT pushes (files or directories, searched recursively) into ``out``.

    Returns the report (``windows``: trajectories written). A bad file aborts the import
    (nothing is written) unless ``skip_bad``, which warns and goes on.
    """
    selection = selection or MitSelection()
    protocol = protocol or MitProtocol()
    if protocol.start not in ("contact", "file"):
        raise ValueError(f"start must be 'contact' or 'file', got {protocol.start!r}")
    pushes = _collect(paths, selection, skip_bad)
    report = analyse(pushes, protocol)
    meta = {"source": "mit_pushing", "protocol": asdict(protocol),
            "selection": {k: (list(v) if v is not None else None)
                          for k, v in asdict(selection).items()},
            "check": report.as_json()}
    with TrajectoryWriter(out, meta) as writer:
        for p in pushes:
            check = report.shapes[p.shape]
            if p.path.name in check.still and not protocol.keep_still:
                continue
            for traj in push_windows(p, check.offset, protocol, report):
                try:
                    writer.add(traj)
                except TrajectoryFormatError:
                    if not skip_bad:
                        raise
                    warnings.warn(f"skipped: {p.path}", stacklevel=2)
    report.windows = writer.count
    return report
