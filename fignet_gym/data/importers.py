"""Importers of the real datasets into the trajectory format: Kubric MOVi here, and the helpers
every importer shares (MIT Pushing: :mod:`fignet_gym.data.mit`; tracked poses:
:mod:`fignet_gym.data.tracked`).

* Kubric MOVi instance records (a worker's ``metadata.json``, or the same fields as arrays, as in
  the TFDS release), with meshes given by a shape-name-to-mesh-file mapping.

Every error names the file and the field at fault (:class:`DataImportError`).
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Iterable, Mapping, Sequence
from functools import lru_cache
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import trimesh

from fignet_gym.data.format import (
    ObjectMeshes,
    Trajectory,
    TrajectoryFormatError,
    TrajectoryWriter,
)
from fignet_gym.simulator.scene import ObjectKind

IMPORTER_VERSION = "2"


class DataImportError(ValueError):
    """A source file cannot be imported; the message names the file and field."""


# --------------------------------------------------------------------------- shared

def _read_h5(path: Path, keys: Iterable[str]) -> dict[str, Any]:
    """The named datasets of an HDF5 file (those present); ``DataImportError`` if unreadable."""
    try:
        with h5py.File(path, "r") as f:
            return {k: f[k][()] for k in keys if k in f and isinstance(f[k], h5py.Dataset)}
    except OSError as err:
        raise DataImportError(f"{path}: not a readable HDF5 file ({err})") from None


def read_json_object(path: Path, expected: str) -> dict[str, Any]:
    """The JSON object in ``path``; :class:`DataImportError` naming the file if it cannot be read
    or is not an object (``expected`` says what the object should hold)."""
    try:
        with open(path) as fh:
            content = json.load(fh)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DataImportError(f"{path}: not a readable JSON file ({err})") from None
    if not isinstance(content, dict):
        raise DataImportError(f"{path}: expected a JSON object with {expected}")
    return content


def _expand(paths: Iterable[str | os.PathLike], patterns: Sequence[str]) -> list[Path]:
    """Files of ``paths``: files as given, directories searched recursively for ``patterns``."""
    files: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            files += sorted(f for pat in patterns for f in p.rglob(pat))
        elif p.exists():
            files.append(p)
        else:
            raise FileNotFoundError(f"{p}: no such file or directory")
    return files


# --------------------------------------------------------------------------- Kubric MOVi

#: Kubric's floor: friction, restitution.
MOVI_FLOOR = (0.3, 0.5)
#: MOVi-A ``size_label`` -> scale.
MOVI_SIZES = {"small": 0.7, "large": 1.4}


@lru_cache(maxsize=64)
def _load_mesh(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    record = read_json_object(path, "field 'instances'")
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
