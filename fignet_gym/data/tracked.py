"""Tracked real data: object poses plus a scene description (MJCF), and the ContactNets cube tosses.

Real data tracks only the objects that move (a tossed cube, a pushed object, a pusher); the floor and
other fixed geometry are not tracked but are part of the scene. :func:`tracked_trajectory` is the one
validated path from tracks to the trajectory format:

* the MJCF describes every object, tracked or not (the floor as world-body geoms); its bodies give
  the objects, kinds and properties (``Scene.from_mjmodel``);
* every dynamic (free-joint) and kinematic (mocap) body needs a track ``float[T, 7]`` (position,
  quaternion w x y z, in metres and the MJCF's world frame); static objects keep the MJCF's pose;
* props given with the tracks (mass, friction, restitution) must agree with the MJCF's;
* every mismatch raises :class:`~fignet_gym.data.importers.DataImportError` naming the file.

``fignet-gym import-contactnets DIR --out F.h5`` (:func:`import_contactnets`) uses it for the
DAIRLab ContactNets tosses (``tosses_processed/K.pt`` and ``params_processed/experiment.json``).
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Iterator, Mapping, Sequence
from functools import lru_cache
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch
from tqdm import tqdm

from fignet_gym.data.format import Trajectory, TrajectoryFormatError
from fignet_gym.data.guards import ImportWriter
from fignet_gym.data.importers import IMPORTER_VERSION, DataImportError
from fignet_gym.mjcf import cube_scene_xml
from fignet_gym.simulator.scene import ObjectKind, Scene, UnsupportedSceneError

#: Standard gravity (m/s^2): the ContactNets files give ``g`` in their length unit, so the unit is
#: ``STANDARD_GRAVITY / g`` metres (0.0524 m, the cube's half-width).
STANDARD_GRAVITY = 9.81
#: Allowed deviation of a tracked quaternion's norm from 1 before it is normalised (trackers and
#: float32 files drift a little; more than this is a wrong column or unit).
TRACK_QUAT_TOL = 1e-2
#: Tolerances of the props check: mass relative, friction and restitution absolute.
PROPS_RTOL_MASS, PROPS_ATOL = 1e-3, 1e-3


def _src(source: str | os.PathLike | None) -> str:
    return str(source) if source is not None else "<memory>"


def compile_mjcf(mjcf: str, source: str | os.PathLike | None = None) -> Any:
    """``mujoco.MjModel`` of MJCF text; :class:`DataImportError` naming ``source`` if it fails."""
    try:
        return mujoco.MjModel.from_xml_string(mjcf)
    except ValueError as err:
        raise DataImportError(f"{_src(source)}: field 'mjcf': MuJoCo cannot compile it ({err})") from None


@lru_cache(maxsize=16)
def _scene_of(mjcf: str, where: str) -> Scene:
    # Importers build many tracks in one MJCF: compile and mesh it once.
    model = compile_mjcf(mjcf, where)
    try:
        return Scene.from_mjmodel(model)
    except UnsupportedSceneError as err:
        raise DataImportError(f"{where}: field 'mjcf': {err}") from None


def check_props(scene: Scene, props: Mapping[str, Sequence[float]] | np.ndarray,
                where: str) -> None:
    """Raise :class:`DataImportError` if given props contradict the scene's (its MJCF's).

    ``props``: ``{object name: (mass, friction, restitution)}`` or ``float[O, 3]`` in scene order.
    Static objects' mass is not compared (the scene stores 0).
    """
    names = scene.object_names
    ref = scene.object_props.double().numpy()
    if not isinstance(props, Mapping):
        arr = np.asarray(props, float)
        if arr.shape != ref.shape:
            raise DataImportError(f"{where}: field 'props' has shape {arr.shape}, the MJCF's "
                                  f"objects {names} need {ref.shape}")
        props = dict(zip(names, arr, strict=True))
    for obj, p in props.items():
        if obj not in names:
            raise DataImportError(f"{where}: field 'props' names object {obj!r}, which the MJCF "
                                  f"does not have (its objects: {', '.join(names)})")
        i = names.index(obj)
        p = np.asarray(p, float)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise DataImportError(f"{where}: field 'props' of {obj!r} must be 3 finite numbers "
                                  f"(mass, friction, restitution), got {p.tolist()}")
        checks = [("friction", 1), ("restitution", 2)]
        if int(scene.object_kind[i]) != ObjectKind.STATIC:
            checks.insert(0, ("mass", 0))
        for label, j in checks:
            tol = PROPS_RTOL_MASS * abs(ref[i, j]) + 1e-6 if j == 0 else PROPS_ATOL
            if abs(p[j] - ref[i, j]) > tol:
                raise DataImportError(
                    f"{where}: field 'props': object {obj!r} has {label} {p[j]:.6g}, the MJCF "
                    f"gives {ref[i, j]:.6g}; the MJCF is what simulators and the learned model "
                    "use, so fix one of them")


def tracked_trajectory(
    mjcf: str, tracks: Mapping[str, np.ndarray], dt: float, *,
    props: Mapping[str, Sequence[float]] | None = None, name: str = "",
    metadata: dict[str, Any] | None = None, extras: dict[str, np.ndarray] | None = None,
    source: str | os.PathLike | None = None,
) -> Trajectory:
    """A trajectory of every object of an MJCF scene from the tracks of its moving objects.

    Args:
        mjcf: MJCF text of the whole scene, untracked static geometry (a floor) included.
        tracks: ``{body name: float[T, 7]}`` (m, quaternion w x y z) for every dynamic and
            kinematic body; a track of a static object is allowed if it stays at the MJCF's pose.
        dt: seconds between poses (the data's own rate).
        props: optional ``{body name: (mass kg, friction, restitution)}`` the data claims; checked
            against the MJCF (a contradiction is an error, not silently ignored).
        source: the file the tracks come from, named in every error.

    Returns:
        A validated :class:`Trajectory` with ``poses float[T, O, 7]`` in ``Scene.from_mjmodel``
        order and the MJCF stored.
    """
    where = _src(source)
    scene = _scene_of(mjcf, where)
    names = scene.object_names
    kinds = scene.object_kind.numpy()
    unknown = [n for n in tracks if n not in names]
    if unknown:
        raise DataImportError(
            f"{where}: tracks of {unknown}, which the MJCF has no collidable body for "
            f"(its objects: {', '.join(names)})")
    missing = [n for n, k in zip(names, kinds, strict=True)
               if k != ObjectKind.STATIC and n not in tracks]
    if missing:
        raise DataImportError(
            f"{where}: the MJCF's moving bodies {missing} have no track (every free-joint and "
            "mocap body needs poses; untracked geometry must be static)")
    lengths = {n: np.shape(t)[0] if np.ndim(t) == 2 else -1 for n, t in tracks.items()}
    T = next(iter(lengths.values()), 0)
    if not tracks or T < 1:
        raise DataImportError(f"{where}: no tracks")
    static = scene.static_poses.double().numpy()
    poses = np.repeat(static[None], T, axis=0)
    for obj, track in tracks.items():
        track = np.asarray(track, float)
        if track.shape != (T, 7):
            raise DataImportError(f"{where}: track of {obj!r} has shape {track.shape}, expected "
                                  f"({T}, 7) like the others")
        if not np.isfinite(track).all():
            row = int(np.argwhere(~np.isfinite(track).all(1))[0, 0])
            raise DataImportError(f"{where}: track of {obj!r} has non-finite values (row {row})")
        norm = np.linalg.norm(track[:, 3:], axis=1)
        if np.abs(norm - 1).max() > TRACK_QUAT_TOL:
            row = int(np.argmax(np.abs(norm - 1)))
            raise DataImportError(
                f"{where}: track of {obj!r}: quaternion norm {norm[row]:.4g} at row {row} "
                f"(expected 1 within {TRACK_QUAT_TOL}; columns are x y z qw qx qy qz)")
        track = track.copy()
        track[:, 3:] /= norm[:, None]
        i = names.index(obj)
        if kinds[i] == ObjectKind.STATIC:
            off = np.abs(track[:, :3] - static[i, :3]).max()
            if off > 1e-4:
                raise DataImportError(f"{where}: track of static object {obj!r} moves {off:.4g} m "
                                      "away from its MJCF pose")
            continue
        poses[:, i] = track
    if props is not None:
        check_props(scene, props, where)
    if not (np.isfinite(dt) and dt > 0):
        raise DataImportError(f"{where}: field 'dt' must be a positive number of seconds, got {dt}")
    traj = Trajectory(poses=poses, dt=float(dt), kinds=kinds.astype(np.int64),
                      props=scene.object_props.double().numpy(), names=names, mjcf=mjcf,
                      metadata=dict(metadata or {}), extras=dict(extras or {}), name=name)
    try:
        traj.validate(source)
    except TrajectoryFormatError as err:
        raise DataImportError(str(err)) from None
    return traj


# --------------------------------------------------------------------------- ContactNets tosses

#: Columns of a ContactNets frame: position (3), quaternion (4, w x y z), linear velocity (3),
#: angular velocity (3), control (6).
CONTACTNETS_COLUMNS = 19


def _contactnets_paths(directory: Path) -> tuple[Path, list[Path]]:
    params = directory / "params_processed" / "experiment.json"
    if not params.exists():
        params = directory / "experiment.json"
    if not params.exists():
        raise DataImportError(f"{directory}: no params_processed/experiment.json (or experiment.json)")
    tosses = directory / "tosses_processed"
    tosses = tosses if tosses.is_dir() else directory
    files = [p for p in tosses.glob("*.pt")]
    if not files:
        raise DataImportError(f"{tosses}: no toss files (*.pt)")
    key = lambda p: (0, int(p.stem), "") if p.stem.isdigit() else (1, 0, p.stem)  # noqa: E731
    return params, sorted(files, key=key)


def read_contactnets_params(path: str | os.PathLike) -> dict[str, Any]:
    """``experiment.json`` of ContactNets with its fields checked (values in the data's units)."""
    path = Path(path)
    try:
        raw = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DataImportError(f"{path}: not a readable JSON file ({err})") from None
    if not isinstance(raw, dict):
        raise DataImportError(f"{path}: expected a JSON object")
    for key in ("dt", "g", "mass", "mu", "restitution", "inertia", "vertices"):
        if key not in raw:
            raise DataImportError(f"{path}: missing field {key!r}")
    for key in ("dt", "g", "mass", "inertia"):
        if not (isinstance(raw[key], (int, float)) and raw[key] > 0):
            raise DataImportError(f"{path}: field {key!r} must be a positive number, got {raw[key]!r}")
    for key in ("mu", "restitution"):
        if not (isinstance(raw[key], (int, float)) and raw[key] >= 0):
            raise DataImportError(f"{path}: field {key!r} must be a non-negative number")
    v = np.asarray(raw["vertices"], float)
    if v.shape != (8, 3) or not np.isfinite(v).all():
        raise DataImportError(f"{path}: field 'vertices' must be the cube's 8 corners (8, 3), "
                              f"got shape {v.shape}")
    half = np.abs(v).max(0)
    if np.ptp(half) > 1e-6 * half.max() or not np.allclose(np.abs(v), half, rtol=1e-6):
        raise DataImportError(f"{path}: field 'vertices' is not an axis-aligned cube centred at 0")
    return raw


def load_contactnets_toss(path: str | os.PathLike) -> np.ndarray:
    """One ``K.pt`` toss as ``float64[T, 19]`` (data units), checked."""
    path = Path(path)
    try:
        x = torch.load(path, weights_only=True, map_location="cpu")
    except Exception as err:  # torch raises many types for foreign or truncated files
        raise DataImportError(f"{path}: not a readable torch tensor file ({err})") from None
    if not isinstance(x, torch.Tensor):
        raise DataImportError(f"{path}: holds a {type(x).__name__}, expected a tensor [1, T, 19]")
    arr = x.detach().double().numpy()
    if arr.ndim == 3 and arr.shape[0] == 1:
        arr = arr[0]
    if arr.ndim != 2 or arr.shape[1] != CONTACTNETS_COLUMNS or arr.shape[0] < 2:
        raise DataImportError(f"{path}: tensor has shape {tuple(x.shape)}, expected "
                              f"[1, T >= 2, {CONTACTNETS_COLUMNS}]")
    if not np.isfinite(arr).all():
        row = int(np.argwhere(~np.isfinite(arr).all(1))[0, 0])
        raise DataImportError(f"{path}: non-finite values (frame {row})")
    return arr


def contactnets_scene(params: Mapping[str, Any], length_unit: float | None = None,
                      floor_half_size: float = 2.0, timestep: float | None = None) -> tuple[str, float]:
    """MJCF of the ContactNets cube and floor, and the length unit (m) it converted with.

    Geometry (half-width from the corners), mass, inertia and the nominal friction and restitution
    come from ``experiment.json``; gravity is standard (the data's ``g`` is standard gravity in
    its unit); the default timestep is a quarter of the data's ``dt``.
    """
    unit = float(length_unit) if length_unit is not None else STANDARD_GRAVITY / float(params["g"])
    half = float(np.abs(np.asarray(params["vertices"], float)).max()) * unit
    xml = cube_scene_xml(half, float(params["mass"]), float(params["inertia"]) * unit**2,
                         float(params["mu"]), float(params["restitution"]),
                         timestep=timestep or float(params["dt"]) / 4, gravity=-STANDARD_GRAVITY,
                         floor_half_size=floor_half_size)
    return xml, unit


def read_contactnets(directory: str | os.PathLike, length_unit: float | None = None,
                     floor_half_size: float = 2.0, skip_bad: bool = False) -> Iterator[Trajectory]:
    """The tosses of a ContactNets directory as trajectories (metres, the data's own ``dt``).

    Objects: ``world`` (the floor, static) and ``cube`` (dynamic). The recorded velocities are kept
    as ``extras["recorded_velocity"]`` (``float[T, 6]``: linear m/s, angular rad/s; their frame is
    not documented, so nothing here uses them).
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise FileNotFoundError(f"{directory}: no such directory")
    params_path, files = _contactnets_paths(directory)
    params = read_contactnets_params(params_path)
    mjcf, unit = contactnets_scene(params, length_unit, floor_half_size)
    dt = float(params["dt"])
    claimed = {"cube": (float(params["mass"]), float(params["mu"]), float(params["restitution"]))}
    for f in files:
        try:
            arr = load_contactnets_toss(f)
            track = np.concatenate([arr[:, :3] * unit, arr[:, 3:7]], axis=1)
            reach = float(np.abs(track[:, :2]).max())
            if reach > floor_half_size:
                raise DataImportError(f"{f}: the cube moves {reach:.2f} m from the origin, beyond "
                                      f"the floor's half-size {floor_half_size} m "
                                      "(raise --floor-half-size)")
            vel = np.concatenate([arr[:, 7:10] * unit, arr[:, 10:13]], axis=1)
            meta = {"source": "contactnets", "file": f.name, "length_unit_m": unit,
                    "g_data": float(params["g"]), "importer_version": IMPORTER_VERSION}
            yield tracked_trajectory(mjcf, {"cube": track}, dt, props=claimed,
                                     name=f"toss-{f.stem}", metadata=meta,
                                     extras={"recorded_velocity": vel}, source=f)
        except DataImportError as err:
            if not skip_bad:
                raise
            warnings.warn(f"skipped: {err}", stacklevel=2)


def import_contactnets(directory: str | os.PathLike, out: str | os.PathLike,
                       length_unit: float | None = None, floor_half_size: float = 2.0,
                       skip_bad: bool = False) -> int:
    """Import every toss of a ContactNets directory into ``out`` (atomic); returns the count.

    Tosses too short to score and copies of an earlier toss are refused (skipped with a warning
    under ``skip_bad``): :class:`~fignet_gym.data.guards.ImportWriter`."""
    directory = Path(directory)
    meta = {"source": "contactnets", "directory": str(directory), "length_unit_m": length_unit,
            "importer_version": IMPORTER_VERSION,
            "licence": "BSD-3-Clause, DAIRLab ContactNets (keep its LICENSE with derived files)"}
    total = len(_contactnets_paths(directory)[1]) if directory.is_dir() else None
    with ImportWriter(out, meta) as writer:
        for traj in tqdm(read_contactnets(directory, length_unit, floor_half_size, skip_bad),
                         total=total, desc="import-contactnets", unit="toss", leave=False):
            try:
                writer.add(traj)
            except TrajectoryFormatError as err:
                if not skip_bad:
                    raise
                warnings.warn(f"skipped: {err}", stacklevel=2)
    return writer.count
