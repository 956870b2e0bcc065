"""Importer of MIT Pushing recordings (Yu et al. 2016) into the trajectory format.

Inputs: raw or ``pdproc`` files (read by :mod:`fignet_gym.data.mit_files`), files or folders.

The protocol (:class:`MitProtocol`, the paper's, appendix B.2 of FIGNet), applied the same way to
any folder:

1. per shape, the offset between the tracked yaw and the dataset's outline is measured on the
   pushes given (:func:`fignet_gym.data.mit_geometry.estimate_offset`); the scene's prism is the
   real outline (12.7 mm) in the recorded frame;
   (too few pushes: the offset measured on the ABS pushes if the shape has one, else none; the
   report says which);
2. a push that never moves the object (no outline point travels ``STILL_MOTION``) is reported
   and, unless ``keep_still``, not imported;
3. windows start at first contact (the first sample with the moving tip within ``CONTACT_GAP`` of
   the outline, or the object's first motion if earlier: at or just before touching; the files
   often begin with the tip resting against the object) and last ``window`` seconds; a push
   long enough gives several consecutive windows, each starting while the object still moves;
4. poses every ``dt`` (default 12 ms: every 3rd sample of the 250 Hz streams, as the paper).

Every error names the file and the field at fault (:class:`DataImportError`).
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from fignet_gym.data import mit_geometry as geo
from fignet_gym.data.format import Trajectory, TrajectoryFormatError
from fignet_gym.data.guards import ImportWriter
from fignet_gym.data.importers import IMPORTER_VERSION, DataImportError, _expand
from fignet_gym.data.mit_files import (
    MitPush,
    RawPush,
    is_pdproc,
    parse_mit_name,
    read_push,
    resample,
)
from fignet_gym.data.mit_scene import TIP_Z, real_push_scene_xml
from fignet_gym.mjcf import MIT_OBJECTS, yaw_quat
from fignet_gym.simulator.scene import Scene

#: Paper's step: every 3rd sample of the 250 Hz streams (s).
PAPER_DT = 0.012

#: Paper's window (s): error after 0.5 s.
PAPER_WINDOW = 0.5
#: A window starts at the first sample where the tip's surface is within this (m) of the outline.
CONTACT_GAP = 0.001
#: A later window must start at least this long before the object's last moving sample (s).
MIN_PUSHING = 0.1
#: The floor plane's half size (m): at least this, and this much beyond the farthest sample.
FLOOR_MIN_HALF_SIZE, FLOOR_MARGIN = 0.5, 0.2


@dataclass(frozen=True)
class MitSelection:
    """Which pushes to import (``None``: any). Defaults: constant-speed pushes (zero acceleration,
    the paper's) on any surface (a user's folder usually holds one; the paper trained on ``abs``).

    Attributes:
        surfaces, shapes: names. velocities: mm/s. accelerations: mm/s^2 (``a`` of the name).
    """

    surfaces: tuple[str, ...] | None = None
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
        offsets: ``{shape: (theta rad, dx m, dy m)}`` to use instead of measuring (e.g. from a
            larger folder's report, :func:`offsets_from_report`); other shapes are measured.
    """

    dt: float = PAPER_DT
    window: float = PAPER_WINDOW
    start: str = "contact"
    keep_still: bool = False
    friction: float = 0.25
    outlines: str | None = None
    offsets: dict[str, tuple[float, float, float]] | None = None


def offsets_from_report(path: str | os.PathLike) -> dict[str, tuple[float, float, float]]:
    """The offsets a check or import report (JSON) found, for :attr:`MitProtocol.offsets`.

    Shapes whose offset was not estimated (status ``default``) are left out.
    """
    try:
        shapes = json.loads(Path(path).read_text())["shapes"]
        return {name: (math.radians(c["offset"]["theta_deg"]), c["offset"]["shift_mm"][0] / 1e3,
                       c["offset"]["shift_mm"][1] / 1e3)
                for name, c in shapes.items() if c["offset"]["status"] != "default"}
    except (OSError, ValueError, KeyError, TypeError, IndexError) as err:
        raise DataImportError(f"{path}: not a check report of import-mit / check-mit "
                              f"(shapes.<shape>.offset.theta_deg, shift_mm): {err!r}") from None


def reference_offsets() -> dict[str, tuple[float, float, float]]:
    """Offsets of the shipped outlines measured on the 61 ABS pushes (butter, ellip1, ellip3, hex,
    rect1), the fallback for a shape the pushes being imported cannot determine."""
    return offsets_from_report(geo.outline_dir() / "reference_offsets.json")


@dataclass
class MitReport:
    """What an import or a check found: per-shape contact checks, windows and still pushes."""

    shapes: dict[str, geo.ShapeCheck] = field(default_factory=dict)
    windows: int = 0
    pushes: int = 0
    surfaces: dict[str, int] = field(default_factory=dict)
    short_windows: list[str] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {"pushes": self.pushes, "windows": self.windows, "surfaces": self.surfaces,
                "short_windows": self.short_windows,
                "shapes": {k: v.as_json() for k, v in sorted(self.shapes.items())}}

    def table(self) -> str:
        """Per-shape lines: pushes, contact frames, offset, distance quantiles, inside fraction."""
        rows = [f"{'shape':8s} {'pushes':>6s} {'still':>5s} {'frames':>6s} {'offset deg':>10s} "
                f"{'shift mm':>12s} {'status':9s} distance q05/q50/q95 mm  inside>1mm  refit"]
        for name, c in sorted(self.shapes.items()):
            q = np.quantile(c.distances, (0.05, 0.5, 0.95)) * 1e3 if len(c.distances) else []
            qs = "/".join(f"{v:.2f}" for v in q) if len(q) else "-"
            inside = f"{100 * c.inside_fraction:6.1f}%" if len(c.distances) else "     -"
            o = c.offset
            rows.append(f"{name:8s} {c.pushes:6d} {len(c.still):5d} {len(c.distances):6d} "
                        f"{np.degrees(o.theta):10.1f} {1e3 * o.shift[0]:5.2f},{1e3 * o.shift[1]:5.2f}"
                        f"  {o.status:9s} {qs:24s} {inside}  {_refit_label(o)}")
        return "\n".join(rows)


def _refit_label(o: geo.FrameOffset) -> str:
    """The offset refit's convergence for the report (``-`` where nothing was refitted)."""
    if not o.refit:
        return "-"
    return f"{o.refit} ({o.evaluations} ev)"


def _outline(shape: str, protocol: MitProtocol) -> np.ndarray:
    try:
        return geo.outline(shape, protocol.outlines)
    except ValueError as err:
        raise DataImportError(str(err)) from None


def _collect(paths: Sequence[str | os.PathLike], selection: MitSelection,
             skip_bad: bool) -> list[RawPush]:
    """The selected pushes; ``DataImportError`` naming what was found if none is selected."""
    pushes, unselected = [], []
    files = _expand(paths, ("*.json", "*.h5"))
    for f in files:
        try:
            if not is_pdproc(f):
                info = parse_mit_name(f)  # select on the name before reading the file
                if not selection.accepts(info.surface, info, info.shape):
                    unselected.append(info)
                    continue
            push = read_push(f)
            if selection.accepts(push.surface, push.info, push.shape):
                pushes.append(push)
            else:
                unselected.append(push.info)
        except DataImportError as err:
            if not skip_bad:
                raise
            warnings.warn(f"skipped: {err}", stacklevel=3)
    if not pushes and unselected:
        found = ", ".join(f"{k} {sorted({str(getattr(i, k)) for i in unselected})}"
                          for k in ("surface", "shape", "acc", "vel"))
        raise DataImportError(f"{', '.join(map(str, paths))}: {len(unselected)} MIT pushes, none "
                              f"selected (found: {found}); see --surface, --shape, "
                              "--acceleration / --any-acceleration, --velocity")
    return pushes


def analyse(pushes: Sequence[RawPush], protocol: MitProtocol) -> MitReport:
    """Measure each shape's offset on its pushes and check the tip's distance in contact."""
    report = MitReport(pushes=len(pushes))
    for p in pushes:
        report.surfaces[str(p.surface)] = report.surfaces.get(str(p.surface), 0) + 1
    by_shape: dict[str, list[RawPush]] = {}
    for p in pushes:
        by_shape.setdefault(p.shape, []).append(p)
    for shape, group in by_shape.items():
        poly = _outline(shape, protocol)
        contacts, still = [], []
        for p in group:
            times, obj, tip = p.tracks()
            p.still = geo.max_motion(obj, poly) < geo.STILL_MOTION
            if p.still:
                still.append(p.path.name)
                continue
            contacts.append(geo.tip_in_object_frame(obj, tip)[geo.contact_mask(times, obj)])
        given = (protocol.offsets or {}).get(shape)
        if given is not None:
            offset = geo.FrameOffset(given[0], (given[1], given[2]), "given", len(contacts),
                                     sum(len(c) for c in contacts))
        else:
            offset = geo.estimate_offset(poly, contacts)
        if offset.status == "default" and protocol.outlines is None:
            ref = reference_offsets().get(shape)  # the shipped outlines' offset on the ABS pushes
            if ref is not None:
                offset = geo.FrameOffset(ref[0], (ref[1], ref[2]), "reference", offset.pushes,
                                         offset.frames)
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
    near = np.flatnonzero((gap <= CONTACT_GAP) & geo.moving_mask(times, tip))
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
        floor = max(FLOOR_MIN_HALF_SIZE, float(np.ceil((reach + FLOOR_MARGIN) * 10) / 10))
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
    return analyse(_collect(list(paths), selection or MitSelection(), skip_bad), protocol)


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
    if 0 < protocol.window < protocol.dt or protocol.window < 0 or protocol.dt <= 0:
        raise ValueError(f"window (--duration) must be 0 or at least one step dt; got window "
                         f"{protocol.window} s, dt {protocol.dt} s")
    pushes = _collect(list(paths), selection, skip_bad)
    report = analyse(pushes, protocol)
    meta = {"source": "mit_pushing", "protocol": asdict(protocol),
            "selection": {k: (list(v) if v is not None else None)
                          for k, v in asdict(selection).items()},
            "check": {k: v for k, v in report.as_json().items() if k == "shapes"}}
    with ImportWriter(out, meta) as writer:
        for p in pushes:
            if p.still and not protocol.keep_still:
                continue
            for traj in push_windows(p, report.shapes[p.shape].offset, protocol, report):
                try:
                    writer.add(traj)
                except TrajectoryFormatError:
                    if not skip_bad:
                        raise
                    warnings.warn(f"skipped: {p.path}", stacklevel=2)
    report.windows = writer.count
    return report
