"""Importers of the real datasets into the trajectory format: MIT Pushing and Kubric MOVi.

* MIT Pushing raw files (``motion_surface=..._shape=..._a=..._v=..._i=..._s=..._t=....json`` or
  ``.h5``): three unsynchronised streams ``tip_pose``, ``object_pose``, ``ft_wrench`` of
  ``(N, 4)`` rows (t, x, y, yaw) / (t, fx, fy, tz), resampled onto one clock of step ``dt`` over
  the time all three cover.
* MIT Pushing preprocessed ``pdproc`` HDF5 files (``object``, ``tip``, ``force`` at 180 Hz in the
  object's initial frame, and scalars), found as ``<root>/<surface>/<shape>/<file>.h5``.
* Kubric MOVi instance records (a worker's ``metadata.json``, or the same fields as arrays, as in
  the TFDS release), with meshes given by a shape-name-to-mesh-file mapping.

Every error names the file and the field at fault (:class:`DataImportError`).
"""

from __future__ import annotations

import json
import os
import re
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fignet_gym.data.format import (
    ObjectMeshes,
    Trajectory,
    TrajectoryFormatError,
    TrajectoryWriter,
)
from fignet_gym.mjcf import MIT_OBJECTS, push_scene_xml, yaw_quat
from fignet_gym.simulator.scene import ObjectKind, Scene

IMPORTER_VERSION = "1"
#: Sample rate of the pdproc files (Hz).
PDPROC_RATE = 180.0
#: Tip body height above the floor in ``push_scene_xml`` (bottom 1 mm up, half height 0.02 m).
_TIP_Z = 0.021


class DataImportError(ValueError):
    """A source file cannot be imported; the message names the file and field."""


# --------------------------------------------------------------------------- MIT Pushing

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


def _read_raw_mit(path: Path) -> dict[str, Any]:
    keys = ("tip_pose", "object_pose", "ft_wrench")
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
    return content


def _read_h5(path: Path, keys: Iterable[str]) -> dict[str, Any]:
    try:
        with h5py.File(path, "r") as f:
            return {k: f[k][()] for k in keys if k in f and isinstance(f[k], h5py.Dataset)}
    except OSError as err:
        raise DataImportError(f"{path}: not a readable HDF5 file ({err})") from None


@lru_cache(maxsize=32)
def _push_scene_info(shape: str, friction: float) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    import mujoco

    scene = Scene.from_mjmodel(mujoco.MjModel.from_xml_string(push_scene_xml(shape, friction)))
    return scene.object_kind.numpy(), scene.object_props.double().numpy(), scene.object_names


def _planar_poses(shape: str, obj_xyyaw: np.ndarray, tip_xy: np.ndarray,
                  tip_yaw: np.ndarray) -> np.ndarray:
    """Poses ``float[T, 3, 7]`` of (world, object, tip) from planar tracks."""
    t = len(obj_xyyaw)
    poses = np.zeros((t, 3, 7))
    poses[:, 0, 3] = 1.0
    poses[:, 1, :2] = obj_xyyaw[:, :2]
    poses[:, 1, 2] = MIT_OBJECTS[shape].thickness / 2
    poses[:, 1, 3:] = np.stack([yaw_quat(a) for a in obj_xyyaw[:, 2]])
    poses[:, 2, :2] = tip_xy
    poses[:, 2, 2] = _TIP_Z
    poses[:, 2, 3:] = np.stack([yaw_quat(a) for a in tip_yaw])
    return poses


def _mit_trajectory(path: Path, info: MitPush, shape: str, surface: str | None,
                    obj: np.ndarray, tip: np.ndarray, tip_yaw: np.ndarray, force: np.ndarray,
                    dt: float, friction: float, fmt: str) -> Trajectory:
    poses = _planar_poses(shape, obj, tip, tip_yaw)
    reach = float(np.abs(np.concatenate([obj[:, :2], tip])).max())
    floor = max(0.5, float(np.ceil((reach + 0.2) * 10) / 10))  # the floor covers the motion
    mjcf = push_scene_xml(shape, friction, floor_half_size=floor,
                          object_pose=tuple(obj[0]), tip_xy=tuple(tip[0]))
    kinds, props, names = _push_scene_info(shape, friction)
    meta = {"source": f"mit_pushing/{fmt}", "file": path.name, "surface": surface,
            "shape": shape, "acc": info.acc, "vel_mm_s": info.vel, "side": info.side,
            "position": info.position, "angle": info.angle, "rep": info.rep,
            "friction_assumed": friction, "importer_version": IMPORTER_VERSION}
    return Trajectory(poses=poses, dt=dt, kinds=kinds, props=props, names=names, mjcf=mjcf,
                      metadata=meta, extras={"force": force}, name=path.stem)


def _check_shape(path: Path, shape: str | None) -> str:
    if shape is None:
        raise DataImportError(f"{path}: no shape in the file name or directory")
    if shape not in MIT_OBJECTS:
        raise DataImportError(
            f"{path}: field 'shape': unknown shape {shape!r}; valid: {', '.join(MIT_OBJECTS)}")
    return shape


def read_mit_raw(path: str | os.PathLike, dt: float = 0.02, max_duration: float | None = None,
                 friction: float = 0.25) -> Trajectory:
    """One raw MIT push (``.json`` or ``.h5``) resampled every ``dt`` seconds.

    The clock starts when all three streams have started and ends when the first one ends (or
    after ``max_duration``). ``friction`` goes into the MJCF (the real value is unknown).
    """
    path = Path(path)
    info = parse_mit_name(path)
    shape = _check_shape(path, info.shape)
    content = _read_raw_mit(path)
    tip = _stream(path, "tip_pose", content["tip_pose"], 4)
    obj = _stream(path, "object_pose", content["object_pose"], 4)
    ft = _stream(path, "ft_wrench", content["ft_wrench"], 4)
    t0 = max(s[0, 0] for s in (tip, obj, ft))
    t1 = min(s[-1, 0] for s in (tip, obj, ft))
    if max_duration is not None:
        t1 = min(t1, t0 + max_duration)
    if t1 - t0 < dt:
        raise DataImportError(f"{path}: the three streams overlap for {max(t1 - t0, 0):.3f} s, "
                              f"less than one step of {dt} s")
    times = t0 + dt * np.arange(int(np.floor((t1 - t0) / dt + 1e-9)) + 1)
    obj_r = resample(times, obj, angle_columns=(3,))
    tip_r = resample(times, tip, angle_columns=(3,))
    force = resample(times, ft)
    traj = _mit_trajectory(path, info, shape, info.surface, obj_r, tip_r[:, :2], tip_r[:, 2],
                           force, dt, friction, "raw")
    traj.metadata["t0"] = float(t0)
    return traj


def read_mit_pdproc(path: str | os.PathLike, dt: float = 0.02, max_duration: float | None = None,
                    friction: float = 0.25, surface: str | None = None,
                    shape: str | None = None) -> Trajectory:
    """One pdproc push (180 Hz, object's initial frame) resampled every ``dt`` seconds.

    Surface and shape default to the two parent directories (``<surface>/<shape>/<file>.h5``).
    """
    path = Path(path)
    surface = surface or path.parent.parent.name or None
    shape = _check_shape(path, shape or path.parent.name)
    content = _read_h5(path, ("object", "tip", "force", "acc", "push_velocity", "push_angle",
                              "push_side", "push_point"))
    for k in ("object", "tip", "force"):
        if k not in content:
            raise DataImportError(f"{path}: missing field {k!r}")
    n = len(np.asarray(content["object"]))
    clock = np.arange(n)[:, None] / PDPROC_RATE
    obj = _stream(path, "object", np.hstack([clock, _2d(path, "object", content["object"], 3)]), 4)
    tip = _stream(path, "tip", np.hstack([clock, _2d(path, "tip", content["tip"], 2)]), 3)
    force = _stream(path, "force", np.hstack([clock, _2d(path, "force", content["force"], 3)]), 4)
    t1 = (n - 1) / PDPROC_RATE if max_duration is None else min((n - 1) / PDPROC_RATE,
                                                                  max_duration)
    if t1 < dt:
        raise DataImportError(f"{path}: {n} samples last less than one step of {dt} s")
    times = dt * np.arange(int(np.floor(t1 / dt + 1e-9)) + 1)
    try:
        named = parse_mit_name(path)
    except DataImportError:  # pdproc names are not always kept; the scalars hold the same facts
        named = None
    info = MitPush(
        surface, shape, _scalar(content, "acc", named.acc if named else float("nan")),
        _scalar(content, "push_velocity", named.vel if named else float("nan")),
        int(_scalar(content, "push_side", named.side if named else -1)),
        _scalar(content, "push_point", named.position if named else float("nan")),
        float(np.deg2rad(_scalar(content, "push_angle", np.rad2deg(named.angle) if named
                                 else float("nan")))),
        named.rep if named else None)
    return _mit_trajectory(path, info, shape, surface, resample(times, obj, angle_columns=(3,)),
                           resample(times, tip), np.zeros(len(times)), resample(times, force),
                           dt, friction, "pdproc")


def _2d(path: Path, name: str, raw: Any, columns: int) -> np.ndarray:
    arr = np.asarray(raw, dtype=float)
    if arr.ndim == 3 and arr.shape[2] == 1:  # some pdproc arrays are (N, C, 1)
        arr = arr[..., 0]
    if arr.ndim != 2 or arr.shape[1] != columns:
        raise DataImportError(f"{path}: field {name!r} has shape {arr.shape}, "
                              f"expected (N, {columns})")
    return arr


def _scalar(content: Mapping[str, Any], key: str, default: float = float("nan")) -> float:
    if key not in content:
        return default
    return float(np.asarray(content[key]).ravel()[0])


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
        return ((self.surfaces is None or surface in self.surfaces)
                and (self.shapes is None or shape in self.shapes)
                and (self.velocities is None or info.vel in self.velocities)
                and (self.accelerations is None or info.acc in self.accelerations))


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


def _expand(paths: Iterable[str | os.PathLike], patterns: Sequence[str]) -> list[Path]:
    files: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            files += sorted(f for pat in patterns for f in p.rglob(pat))
        elif p.exists():
            files.append(p)
        else:
            raise FileNotFoundError(f"{p}: no such file or directory")
    return files


def import_mit(paths: Iterable[str | os.PathLike], out: str | os.PathLike,
               selection: MitSelection | None = None, dt: float = 0.02,
               max_duration: float | None = 0.5, friction: float = 0.25,
               skip_bad: bool = False) -> int:
    """Import MIT pushes (files or directories, searched recursively) into ``out``.

    Returns the number written. A bad file aborts the import (nothing is written) unless
    ``skip_bad``, which warns and goes on.
    """
    selection = selection or MitSelection()
    files = _expand(paths, ("*.json", "*.h5"))
    meta = {"source": "mit_pushing", "dt": dt, "max_duration": max_duration,
            "friction_assumed": friction, "selection": _sel_json(selection)}
    from fignet_gym.data.guards import ImportWriter  # refuses short pushes and copies

    with ImportWriter(out, meta) as writer:
        for f in files:
            try:
                if _is_pdproc(f):
                    traj = read_mit_pdproc(f, dt, max_duration, friction)
                else:
                    info = parse_mit_name(f)  # select on the name before reading the file
                    if not selection.accepts(info.surface, info, info.shape):
                        continue
                    traj = read_mit_raw(f, dt, max_duration, friction)
                m = traj.metadata
                info = MitPush(m["surface"], m["shape"], m["acc"], m["vel_mm_s"], 0, 0.0, 0.0)
                if selection.accepts(m["surface"], info, m["shape"]):
                    writer.add(traj)
            except (DataImportError, TrajectoryFormatError) as err:
                if not skip_bad:
                    raise
                warnings.warn(f"skipped: {err}", stacklevel=2)
    return writer.count


def _sel_json(sel: MitSelection) -> dict[str, Any]:
    return {k: (list(v) if v is not None else None) for k, v in sel.__dict__.items()}


# --------------------------------------------------------------------------- Kubric MOVi

#: Kubric's floor: friction, restitution.
MOVI_FLOOR = (0.3, 0.5)
#: MOVi-A ``size_label`` -> scale.
MOVI_SIZES = {"small": 0.7, "large": 1.4}


@lru_cache(maxsize=64)
def _load_mesh(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    import trimesh

    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except Exception as err:  # trimesh raises many types for bad files
        raise DataImportError(f"{path}: cannot load mesh ({err})") from None
    if len(mesh.faces) == 0:
        raise DataImportError(f"{path}: mesh has no faces")
    com = mesh.center_mass if mesh.is_volume else mesh.vertices.mean(0)
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64), np.asarray(com)


def _instances(path: str, record: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Per-object dicts from a list of dicts (metadata.json) or a dict of stacked arrays (TFDS)."""
    inst = record.get("instances")
    if inst is None:
        raise DataImportError(f"{path}: missing field 'instances'")
    if isinstance(inst, Mapping):
        n = len(np.asarray(inst.get("positions", [])))
        return [{k: (v[i] if np.ndim(v) > 0 and len(v) == n else v) for k, v in inst.items()}
                for i in range(n)]
    if not isinstance(inst, list):
        raise DataImportError(f"{path}: field 'instances' must be a list or a dict of arrays")
    return list(inst)


def movi_record_to_trajectory(record: Mapping[str, Any], mesh_map: Mapping[str, str | os.PathLike],
                              name: str = "movi", frame_rate: float | None = None,
                              floor_half_size: float = 20.0) -> Trajectory:
    """One MOVi scene (``{"instances": ..., "metadata": {"frame_rate": ...}}``) as a trajectory.

    Objects: the floor (static, a square at z = 0) then the instances in record order. Each
    instance's mesh is ``mesh_map[shape_label or asset_id]`` scaled by ``scale`` (or the
    ``size_label``: small 0.7, large 1.4).
    """
    instances = _instances(name, record)
    if not instances:
        raise DataImportError(f"{name}: field 'instances' is empty")
    rate = frame_rate or float((record.get("metadata") or {}).get("frame_rate", 12.0))
    fl = floor_half_size
    verts = [np.array([[-fl, -fl, 0], [fl, -fl, 0], [fl, fl, 0], [-fl, fl, 0]], float)]
    faces = [np.array([[0, 1, 2], [0, 2, 3]])]
    coms, props, names, tracks = [np.zeros(3)], [[0.0, *MOVI_FLOOR]], ["floor"], []
    steps = None
    for k, inst in enumerate(instances):
        where = f"{name}: instance {k}"
        label = inst.get("shape_label", inst.get("asset_id"))
        if label is None:
            raise DataImportError(f"{where}: missing field 'shape_label' (or 'asset_id')")
        label = label.decode() if isinstance(label, bytes) else str(label)
        if label not in mesh_map:
            raise DataImportError(f"{where}: field 'shape_label': no mesh for shape {label!r}; "
                                  f"the mesh map has {sorted(mesh_map)}")
        v, f, com = _load_mesh(str(mesh_map[label]))
        scale = _movi_scale(inst, where)
        verts.append(v * scale)
        faces.append(f)
        coms.append(com * scale)
        try:
            pos = np.asarray(inst["positions"], float)
            quat = np.asarray(inst["quaternions"], float)
            props.append([float(inst["mass"]), float(inst["friction"]),
                          float(inst["restitution"])])
        except KeyError as err:
            raise DataImportError(f"{where}: missing field {err.args[0]!r}") from None
        except (TypeError, ValueError) as err:
            raise DataImportError(f"{where}: non-numeric field ({err})") from None
        if pos.ndim != 2 or pos.shape[1] != 3 or quat.shape != (len(pos), 4):
            raise DataImportError(f"{where}: fields 'positions' {pos.shape} / 'quaternions' "
                                  f"{quat.shape}: expected (s, 3) and (s, 4)")
        if steps is not None and len(pos) != steps:
            raise DataImportError(f"{where}: field 'positions' has {len(pos)} frames, "
                                  f"others have {steps}")
        steps = len(pos)
        tracks.append(np.concatenate([pos, quat], axis=1))
        names.append(f"{label}{k}")
    floor_pose = np.tile([0, 0, 0, 1.0, 0, 0, 0], (steps, 1))
    poses = np.stack([floor_pose, *tracks], axis=1)
    kinds = np.array([ObjectKind.STATIC] + [ObjectKind.DYNAMIC] * len(instances), np.int64)
    meta = {"source": "kubric_movi", "importer_version": IMPORTER_VERSION,
            "frame_rate": rate, "shapes": names[1:]}
    traj = Trajectory(poses=poses, dt=1.0 / rate, kinds=kinds, props=np.array(props),
                      names=tuple(names), meshes=ObjectMeshes(tuple(verts), tuple(faces),
                                                              np.array(coms)),
                      metadata=meta, name=name)
    try:
        traj.validate()
    except TrajectoryFormatError as err:  # e.g. non-unit quaternions: name the source
        raise DataImportError(str(err).replace("<memory>: ", "", 1)) from None
    return traj


def _movi_scale(inst: Mapping[str, Any], where: str) -> np.ndarray:
    if "scale" in inst:
        scale = np.asarray(inst["scale"], float).ravel()
        if scale.size not in (1, 3) or not np.all(scale > 0):
            raise DataImportError(f"{where}: field 'scale' must be one or three positive numbers")
        return scale if scale.size == 3 else np.full(3, scale[0])
    label = inst.get("size_label")
    label = label.decode() if isinstance(label, bytes) else label
    if label in MOVI_SIZES:
        return np.full(3, MOVI_SIZES[label])
    raise DataImportError(f"{where}: missing field 'scale' (or 'size_label' small/large)")


def read_movi_json(path: str | os.PathLike, mesh_map: Mapping[str, str | os.PathLike],
                   **kwargs: Any) -> Trajectory:
    """A Kubric worker's ``metadata.json`` as a trajectory (:func:`movi_record_to_trajectory`)."""
    path = Path(path)
    try:
        with open(path) as fh:
            record = json.load(fh)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DataImportError(f"{path}: not a readable JSON file ({err})") from None
    if not isinstance(record, dict):
        raise DataImportError(f"{path}: expected a JSON object with field 'instances'")
    traj = movi_record_to_trajectory(record, mesh_map, name=str(path), **kwargs)
    traj.name = path.parent.name if path.name == "metadata.json" else path.stem
    return traj


def load_mesh_map(path: str | os.PathLike) -> dict[str, Path]:
    """A JSON object ``{shape name: mesh file}``; relative paths are relative to the JSON file."""
    path = Path(path)
    try:
        with open(path) as fh:
            raw = json.load(fh)
    except (OSError, json.JSONDecodeError) as err:
        raise DataImportError(f"{path}: not a readable JSON mesh map ({err})") from None
    if not isinstance(raw, dict) or not all(isinstance(v, str) for v in raw.values()):
        raise DataImportError(f"{path}: expected a JSON object {{shape name: mesh file}}")
    return {k: (path.parent / v) if not Path(v).is_absolute() else Path(v)
            for k, v in raw.items()}


def import_movi(paths: Iterable[str | os.PathLike], mesh_map: Mapping[str, str | os.PathLike],
                out: str | os.PathLike, skip_bad: bool = False, **kwargs: Any) -> int:
    """Import MOVi records into ``out``: JSON files, or directories searched for ``metadata.json``
    (a Kubric worker's output folder also holds other JSON files)."""
    files = _expand(paths, ("metadata.json",))
    if not files:
        raise DataImportError(f"{', '.join(map(str, paths))}: no metadata.json found (a Kubric "
                              "worker writes one per scene)")
    with TrajectoryWriter(out, {"source": "kubric_movi"}) as writer:
        for f in files:
            try:
                writer.add(read_movi_json(f, mesh_map, **kwargs))
            except (DataImportError, TrajectoryFormatError) as err:
                if not skip_bad:
                    raise
                warnings.warn(f"skipped: {err}", stacklevel=2)
    return writer.count
