"""One trajectory format for everything fignet_gym trains and evaluates on (HDF5, via h5py).

Layout of a file (see ``docs/data.md``)::

    /                       attrs: format="fignet_gym.trajectories", version=1, metadata=<JSON>
    /trajectories/000000    one group per trajectory, in order; attrs: name, dt, metadata=<JSON>
        poses               float32[T, O, 7]  body-frame poses, position then quaternion (w x y z)
        kinds               int8[O]           ObjectKind: 0 dynamic, 1 static, 2 kinematic
        props               float32[O, 3]     mass (kg), friction, restitution
        names               str[O]            object (MuJoCo body) names
        mjcf                uint8[bytes]      gzip-compressed UTF-8 MJCF text (optional)
        meshes/             (optional, when there is no MJCF) per-object meshes in the body frame:
            vertices float[N, 3], faces int32[F, 3], node_counts int32[O], face_counts int32[O],
            coms float[O, 3]
        extras/<key>        float[T, ...] optional per-step arrays (e.g. measured force)

Objects are in the order of ``Scene.from_mjmodel`` (the world body first), so
``Scene.from_mjmodel(mujoco.MjModel.from_xml_string(mjcf))`` rebuilds the scene of the poses.

Writing is atomic: :class:`TrajectoryWriter` writes into ``<out>.incomplete`` and renames it to
``<out>`` only when every trajectory is in; an interrupted run never leaves a file at ``<out>``,
and a file already at ``<out>`` stays intact until the rename.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import mujoco
import numpy as np

from fignet_gym.simulator.scene import MeshOptions, ObjectKind, Scene

FORMAT_NAME = "fignet_gym.trajectories"
FORMAT_VERSION = 1
#: Allowed deviation of a stored quaternion's norm from 1 (float32 storage keeps ~1e-7).
QUAT_NORM_TOL = 1e-3
INCOMPLETE_SUFFIX = ".incomplete"
#: Largest accepted distance (m) of any object from the origin: beyond it a pose is a data
#: error, not a scene (float32 keeps only ~1 mm at 1e4 m).
MAX_POSITION = 1e4
#: Largest accepted speed (m/s) of an object between two stored poses: faster means a teleport
#: (a tracking glitch or a broken simulation); the data sets move at a few m/s.
MAX_SPEED = 100.0
#: Largest dataset (bytes) a trajectory field may declare: checked before reading, so a small
#: corrupt file declaring gigabytes is refused instead of exhausting memory.
MAX_FIELD_BYTES = 1 << 28
#: Stored ``props`` may differ from their MJCF's by this much (relative, plus absolute; float32).
PROPS_RTOL, PROPS_ATOL = 1e-4, 1e-5


class TrajectoryIndexError(IndexError, ValueError):
    """A trajectory index beyond the file (an ``IndexError`` for sequence use; a ``ValueError``, so
    the command line reports it in one line as any other bad input)."""


class TrajectoryFormatError(ValueError):
    """A malformed trajectory file or record; the message names the file, trajectory and field."""


def _where(file: str | os.PathLike | None, traj: str | None, field_: str | None = None) -> str:
    parts = [str(file) if file is not None else "<memory>"]
    if traj is not None:
        parts.append(f"trajectory {traj!r}")
    if field_ is not None:
        parts.append(f"field {field_!r}")
    return ": ".join(parts)


@dataclass(frozen=True)
class ObjectMeshes:
    """Per-object reference meshes in each body frame, for data that has no MJCF.

    Attributes:
        vertices: ``O`` arrays ``float[n_i, 3]``. faces: ``O`` arrays ``int[f_i, 3]``.
        coms: ``float[O, 3]`` centre of mass in the body frame.
    """

    vertices: tuple[np.ndarray, ...]
    faces: tuple[np.ndarray, ...]
    coms: np.ndarray


@dataclass(eq=False)
class Trajectory:
    """One trajectory of a scene.

    Attributes:
        poses: ``float[T, O, 7]`` body-frame poses of every object (dynamic, static, kinematic).
        dt: seconds between consecutive poses (the learned step).
        kinds: ``int[O]`` :class:`ObjectKind` values. props: ``float[O, 3]`` mass, friction,
            restitution. names: ``O`` object names.
        mjcf: the MJCF text the poses were simulated in (or built for), if any.
        meshes: per-object meshes when there is no MJCF.
        metadata: free-form JSON-serialisable dict (source, seed, generator version, ...).
        extras: optional per-step arrays ``float[T, ...]`` (e.g. measured force).
        name: a label (file name of the source, or generator index).
        source: the file it was read from (not stored; named in errors).
    """

    poses: np.ndarray
    dt: float
    kinds: np.ndarray
    props: np.ndarray
    names: tuple[str, ...]
    mjcf: str | None = None
    meshes: ObjectMeshes | None = None
    metadata: dict[str, Any] = field(default_factory=dict)
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    name: str = ""
    source: str | None = field(default=None, compare=False)

    @property
    def num_steps(self) -> int:
        """``T``, the number of poses (``T - 1`` transitions)."""
        return int(self.poses.shape[0])

    @property
    def num_objects(self) -> int:
        return int(self.poses.shape[1])

    @cached_property
    def scene(self) -> Scene:
        """The static scene of the poses (built on first use, then cached)."""
        return build_scene(self)

    def validate(self, file: str | os.PathLike | None = None) -> None:
        """Raise :class:`TrajectoryFormatError` naming the file, trajectory and field at fault."""
        validate_trajectory(self, file)


def build_scene(traj: Trajectory, mesh_options: MeshOptions | None = None) -> Scene:
    """Scene of a trajectory: from its MJCF if it has one, else from its meshes.

    Checks that the rebuilt scene has the trajectory's objects (names and kinds, in order) and
    properties (``props`` within :data:`PROPS_RTOL` of the MJCF's: the MJCF is what both
    simulators use, so stored props that contradict it are an error, not silently ignored).
    """
    if traj.mjcf is not None:
        where = _where(traj.source, traj.name, "mjcf")
        try:
            model = mujoco.MjModel.from_xml_string(traj.mjcf)
        except ValueError as err:
            raise TrajectoryFormatError(f"{where}: MuJoCo cannot compile it ({err})") from None
        scene = Scene.from_mjmodel(model, mesh_options)
        if scene.object_names != tuple(traj.names) or scene.object_kind.tolist() != list(
                np.asarray(traj.kinds).tolist()):
            hint = ""
            if len(traj.names) < scene.num_objects:
                hint = (" (write every object of the MJCF, untracked static ones such as the floor "
                        "included: fignet_gym.data.tracked.tracked_trajectory does)")
            raise TrajectoryFormatError(
                f"{where}: its objects {scene.object_names} / kinds "
                f"{scene.object_kind.tolist()} differ from the stored names {tuple(traj.names)} / "
                f"kinds {np.asarray(traj.kinds).tolist()}{hint}")
        ref = scene.object_props.double().numpy()
        props = np.asarray(traj.props, float)
        bad = np.abs(props - ref) > PROPS_RTOL * np.abs(ref) + PROPS_ATOL
        if bad.any():
            o, j = (int(x) for x in np.argwhere(bad)[0])
            label = ("mass", "friction", "restitution")[j]
            raise TrajectoryFormatError(
                f"{_where(traj.source, traj.name, 'props')}: object {traj.names[o]!r} has {label} "
                f"{props[o, j]:.6g}, its MJCF gives {ref[o, j]:.6g} (props must be the MJCF's, "
                "as Scene.from_mjmodel reads them)")
        return scene
    if traj.meshes is None:
        raise TrajectoryFormatError(f"{_where(None, traj.name)}: has neither 'mjcf' nor 'meshes'")
    m = traj.meshes
    return Scene.from_meshes(list(m.vertices), list(m.faces), np.asarray(traj.kinds, np.int64),
                             np.asarray(traj.props, float), m.coms, traj.names,
                             np.asarray(traj.poses[0], float))


def validate_trajectory(traj: Trajectory, file: str | os.PathLike | None = None) -> None:
    """Shapes, finiteness, unit quaternions and scene data of one trajectory."""
    w = lambda f: _where(file, traj.name, f)  # noqa: E731
    poses = np.asarray(traj.poses)
    if poses.ndim != 3 or poses.shape[2] != 7 or poses.shape[0] < 1:
        raise TrajectoryFormatError(f"{w('poses')}: expected shape (T, O, 7), got {poses.shape}")
    n_obj = poses.shape[1]
    if not np.issubdtype(poses.dtype, np.floating):
        raise TrajectoryFormatError(f"{w('poses')}: expected floats, got {poses.dtype}")
    bad = ~np.isfinite(poses).all(axis=2)
    if bad.any():
        t, o = np.argwhere(bad)[0]
        raise TrajectoryFormatError(
            f"{w('poses')}: {int(bad.sum())} non-finite poses, first at step {t}, object {o}")
    norm_err = np.abs(np.linalg.norm(poses[..., 3:], axis=-1) - 1.0)
    if (norm_err > QUAT_NORM_TOL).any():
        t, o = np.unravel_index(int(np.argmax(norm_err)), norm_err.shape)
        raise TrajectoryFormatError(
            f"{w('poses')}: quaternions are not unit (|q| = "
            f"{np.linalg.norm(poses[t, o, 3:]):.6g} at step {t}, object {o}; tolerance "
            f"{QUAT_NORM_TOL})")
    if not (np.isfinite(traj.dt) and traj.dt > 0):
        raise TrajectoryFormatError(f"{w('dt')}: must be a positive number, got {traj.dt}")
    far = np.abs(poses[..., :3]).max(axis=-1)
    if (far > MAX_POSITION).any():
        t, o = np.unravel_index(int(np.argmax(far)), far.shape)
        raise TrajectoryFormatError(
            f"{w('poses')}: object {o} is {far[t, o]:.3g} m from the origin at step {t} "
            f"(limit {MAX_POSITION:g} m)")
    if poses.shape[0] > 1:
        speed = np.linalg.norm(np.diff(poses[..., :3].astype(np.float64), axis=0), axis=-1) / traj.dt
        if (speed > MAX_SPEED).any():
            t, o = np.unravel_index(int(np.argmax(speed)), speed.shape)
            raise TrajectoryFormatError(
                f"{w('poses')}: object {o} jumps {speed[t, o] * traj.dt:.3g} m between steps {t} "
                f"and {t + 1} ({speed[t, o]:.3g} m/s; limit {MAX_SPEED:g} m/s)")
    kinds = np.asarray(traj.kinds)
    if kinds.shape != (n_obj,) or not np.isin(kinds, [int(k) for k in ObjectKind]).all():
        raise TrajectoryFormatError(
            f"{w('kinds')}: expected {n_obj} values in {{0, 1, 2}}, got {kinds.tolist()}")
    props = np.asarray(traj.props)
    if props.shape != (n_obj, 3) or not np.isfinite(props).all():
        raise TrajectoryFormatError(f"{w('props')}: expected finite float[{n_obj}, 3], "
                                    f"got shape {props.shape}")
    if len(traj.names) != n_obj:
        raise TrajectoryFormatError(f"{w('names')}: expected {n_obj} names, got {len(traj.names)}")
    if traj.mjcf is None and traj.meshes is None:
        raise TrajectoryFormatError(f"{w('mjcf')}: a trajectory needs 'mjcf' or 'meshes'")
    if traj.meshes is not None:
        m = traj.meshes
        if len(m.vertices) != n_obj or len(m.faces) != n_obj or np.shape(m.coms) != (n_obj, 3):
            raise TrajectoryFormatError(f"{w('meshes')}: expected one mesh and com per object")
        for i, (v, f) in enumerate(zip(m.vertices, m.faces, strict=True)):
            if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
                raise TrajectoryFormatError(f"{w('meshes')}: object {i} mesh has shapes "
                                            f"{v.shape} / {f.shape}")
            if f.min() < 0 or f.max() >= len(v) or not np.isfinite(v).all():
                raise TrajectoryFormatError(f"{w('meshes')}: object {i} has bad vertices or faces")
    for key, arr in traj.extras.items():
        if np.shape(arr)[:1] != (poses.shape[0],):
            raise TrajectoryFormatError(f"{w('extras/' + key)}: expected {poses.shape[0]} steps, "
                                        f"got shape {np.shape(arr)}")
    try:
        json.dumps(traj.metadata)
    except (TypeError, ValueError) as err:
        raise TrajectoryFormatError(f"{w('metadata')}: not JSON-serialisable ({err})") from None


# --------------------------------------------------------------------------- writing


class TrajectoryWriter:
    """Append trajectories to a new file, atomically published on a clean :meth:`close`.

    Use as a context manager. Each :meth:`add` validates then writes one trajectory into
    ``<path>.incomplete``; leaving the ``with`` block normally renames it to ``path`` (replacing
    any old file in one step), leaving it by an exception deletes it. A killed process leaves only
    ``<path>.incomplete``.
    """

    def __init__(self, path: str | os.PathLike, metadata: dict[str, Any] | None = None) -> None:
        self.path = Path(path)
        if self.path.is_dir():  # else "<dir>.incomplete" would be written beside it
            raise TrajectoryFormatError(f"{self.path}: is a directory; the output must be a file")
        self.tmp_path = self.path.with_name(self.path.name + INCOMPLETE_SUFFIX)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: h5py.File | None = h5py.File(self.tmp_path, "w")
        self._file.attrs["format"] = FORMAT_NAME
        self._file.attrs["version"] = FORMAT_VERSION
        self._file.attrs["metadata"] = json.dumps(metadata or {})
        self._group = self._file.create_group("trajectories")
        self.count = 0

    def add(self, traj: Trajectory) -> None:
        """Validate and append one trajectory."""
        if self._file is None:
            raise RuntimeError(f"{self.path}: writer is closed")
        validate_trajectory(traj, self.path)
        if traj.mjcf is not None:  # objects, kinds and props against the MJCF, naming this file
            build_scene(replace(traj, source=str(self.path)))
        g = self._group.create_group(f"{self.count:06d}")
        g.attrs["name"] = traj.name or f"{self.count:06d}"
        g.attrs["dt"] = float(traj.dt)
        g.attrs["metadata"] = json.dumps(traj.metadata)
        g.create_dataset("poses", data=np.asarray(traj.poses, np.float32))
        g.create_dataset("kinds", data=np.asarray(traj.kinds, np.int8))
        g.create_dataset("props", data=np.asarray(traj.props, np.float32))
        g.create_dataset("names", data=np.array(list(traj.names), dtype=h5py.string_dtype()))
        if traj.mjcf is not None:
            raw = np.frombuffer(traj.mjcf.encode("utf-8"), dtype=np.uint8)
            g.create_dataset("mjcf", data=raw, compression="gzip", compression_opts=4)
        if traj.meshes is not None:
            m = traj.meshes
            mg = g.create_group("meshes")
            mg.create_dataset("vertices", data=np.concatenate(m.vertices).astype(np.float64))
            mg.create_dataset("faces", data=np.concatenate(m.faces).astype(np.int32))
            mg.create_dataset("node_counts", data=np.array([len(v) for v in m.vertices], np.int32))
            mg.create_dataset("face_counts", data=np.array([len(f) for f in m.faces], np.int32))
            mg.create_dataset("coms", data=np.asarray(m.coms, np.float64))
        if traj.extras:
            eg = g.create_group("extras")
            for key, arr in traj.extras.items():
                eg.create_dataset(key, data=np.asarray(arr, np.float32))
        self.count += 1

    def close(self) -> None:
        """Finish the file and publish it at ``path`` (atomic rename)."""
        if self._file is None:
            return
        self._file.attrs["count"] = self.count
        self._file.flush()
        self._file.close()
        self._file = None
        with open(self.tmp_path, "rb+") as fh:  # make the bytes durable before the rename
            os.fsync(fh.fileno())
        os.replace(self.tmp_path, self.path)

    def abort(self) -> None:
        """Drop the partial file; ``path`` is untouched."""
        if self._file is not None:
            self._file.close()
            self._file = None
        self.tmp_path.unlink(missing_ok=True)

    def __enter__(self) -> TrajectoryWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def write_trajectories(path: str | os.PathLike, trajs: Iterable[Trajectory],
                       metadata: dict[str, Any] | None = None) -> int:
    """Write trajectories to ``path`` atomically; returns how many were written."""
    with TrajectoryWriter(path, metadata) as writer:
        for traj in trajs:
            writer.add(traj)
    return writer.count


# --------------------------------------------------------------------------- reading


def _read_field(g: h5py.Group, key: str, where: str, ndim: int | None = None,
                last: int | None = None) -> np.ndarray:
    """A field's array, its declared shape and size checked before anything is read."""
    if key not in g:
        raise TrajectoryFormatError(f"{where}: missing field {key!r}")
    try:
        dset = g[key]
        shape, nbytes = dset.shape, dset.size * dset.dtype.itemsize
    except (OSError, KeyError, ValueError, TypeError, AttributeError) as err:
        raise TrajectoryFormatError(f"{where}: field {key!r} is unreadable ({err})") from None
    if (ndim is not None and len(shape or ()) != ndim) or (last is not None and shape[-1] != last):
        raise TrajectoryFormatError(f"{where}: field {key!r} has shape {shape}, expected "
                                    f"{ndim} dimensions" + (f" ending in {last}" if last else ""))
    if nbytes > MAX_FIELD_BYTES:
        raise TrajectoryFormatError(f"{where}: field {key!r} declares {nbytes / 1e9:.3g} GB "
                                    f"(shape {shape}; limit {MAX_FIELD_BYTES / 1e9:.3g} GB)")
    try:
        return dset[()]
    except (OSError, KeyError, ValueError, TypeError) as err:
        raise TrajectoryFormatError(f"{where}: field {key!r} is unreadable ({err})") from None


def _read_json_attr(obj: h5py.HLObject, key: str, where: str) -> dict[str, Any]:
    raw = obj.attrs.get(key, "{}")
    try:
        value = json.loads(raw)
    except (TypeError, ValueError) as err:
        raise TrajectoryFormatError(f"{where}: field {key!r} is not JSON ({err})") from None
    if not isinstance(value, dict):
        raise TrajectoryFormatError(f"{where}: field {key!r} is not a JSON object")
    return value


class TrajectoryFile:
    """Read-only access to a trajectory file, one trajectory at a time.

    ``len(f)``, ``f[i]``, iteration and :attr:`names`; each trajectory is validated when read.
    Use as a context manager (or call :meth:`close`).
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(f"{self.path}: no such trajectory file")
        try:
            self._file = h5py.File(self.path, "r")
        except OSError as err:
            raise TrajectoryFormatError(
                f"{self.path}: not a readable HDF5 file (truncated or foreign?): {err}") from None
        fmt = self._file.attrs.get("format")
        if fmt != FORMAT_NAME or "trajectories" not in self._file:
            self._file.close()
            raise TrajectoryFormatError(
                f"{self.path}: not a fignet_gym trajectory file (attribute 'format' is {fmt!r}, "
                f"expected {FORMAT_NAME!r})")
        version = int(self._file.attrs.get("version", -1))
        if version > FORMAT_VERSION:
            self._file.close()
            raise TrajectoryFormatError(
                f"{self.path}: format version {version} is newer than this reader's "
                f"{FORMAT_VERSION}")
        try:
            self._keys = sorted(self._file["trajectories"].keys())
        except (OSError, KeyError, RuntimeError) as err:
            self._file.close()
            raise TrajectoryFormatError(
                f"{self.path}: unreadable trajectory index ({err})") from None
        self.metadata = _read_json_attr(self._file, "metadata", str(self.path))

    def __len__(self) -> int:
        return len(self._keys)

    @property
    def names(self) -> list[str]:
        """Trajectory names, in file order."""
        g = self._file["trajectories"]
        return [str(g[k].attrs.get("name", k)) for k in self._keys]

    def __getitem__(self, index: int) -> Trajectory:
        if not -len(self) <= index < len(self):
            raise TrajectoryIndexError(f"{self.path}: trajectory index {index} out of range "
                             f"(the file holds {len(self)})")
        key = self._keys[index]
        try:
            g = self._file["trajectories"][key]
            name = str(g.attrs.get("name", key))
        except (OSError, KeyError, RuntimeError) as err:
            raise TrajectoryFormatError(
                f"{_where(self.path, key)}: unreadable group ({err})") from None
        where = _where(self.path, name)
        if "dt" not in g.attrs:
            raise TrajectoryFormatError(f"{where}: missing field 'dt'")
        mjcf = None
        if "mjcf" in g:
            mjcf = bytes(_read_field(g, "mjcf", where)).decode("utf-8", errors="replace")
        meshes = None
        if "meshes" in g:
            meshes = self._read_meshes(g["meshes"], _where(self.path, name, "meshes"))
        extras = {}
        if "extras" in g:
            extras = {k: _read_field(g["extras"], k, where) for k in g["extras"]}
        names_raw = _read_field(g, "names", where)
        traj = Trajectory(
            poses=_read_field(g, "poses", where, ndim=3, last=7),
            dt=float(g.attrs["dt"]),
            kinds=_read_field(g, "kinds", where).astype(np.int64),
            props=_read_field(g, "props", where),
            names=tuple(n.decode() if isinstance(n, bytes) else str(n) for n in names_raw),
            mjcf=mjcf, meshes=meshes,
            metadata=_read_json_attr(g, "metadata", where),
            extras=extras, name=name, source=str(self.path),
        )
        validate_trajectory(traj, self.path)
        return traj

    @staticmethod
    def _read_meshes(mg: h5py.Group, where: str) -> ObjectMeshes:
        v = _read_field(mg, "vertices", where)
        f = _read_field(mg, "faces", where)
        nc = _read_field(mg, "node_counts", where)
        fc = _read_field(mg, "face_counts", where)
        if nc.sum() != len(v) or fc.sum() != len(f):
            raise TrajectoryFormatError(f"{where}: node/face counts do not add up to the arrays")
        return ObjectMeshes(tuple(np.split(v, np.cumsum(nc)[:-1])),
                            tuple(np.split(f.astype(np.int64), np.cumsum(fc)[:-1])),
                            _read_field(mg, "coms", where))

    def __iter__(self) -> Iterator[Trajectory]:
        for i in range(len(self)):
            yield self[i]

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> TrajectoryFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def load_trajectories(path: str | os.PathLike,
                      indices: Sequence[int] | None = None) -> list[Trajectory]:
    """All trajectories of a file (or those at ``indices``), validated."""
    with TrajectoryFile(path) as f:
        return [f[i] for i in (range(len(f)) if indices is None else indices)]
