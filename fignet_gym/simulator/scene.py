"""Static scene topology for the learned simulator, read once from a compiled ``mujoco.MjModel``.

A :class:`Scene` holds every object's reference triangle mesh in its body frame, its static
properties and its kind (dynamic / static / kinematic). Several scenes concatenate into one
(disjoint union, :meth:`Scene.batch`), which is how the simulator batches many environments into
one graph. Conventions (object kinds, restitution, poses) are in ``docs/architecture.md``.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, field, replace
from enum import IntEnum
from typing import TypeVar

import mujoco
import numpy as np
import torch
import trimesh
from torch import Tensor

from fignet_gym.simulator.geometry import transform_points

#: Most memoised values a scene keeps (:meth:`Scene.cached`).
CACHE_ENTRIES = 16

T = TypeVar("T")


class ObjectKind(IntEnum):
    """How an object moves: predicted (dynamic), fixed (static) or given (kinematic, mocap)."""

    DYNAMIC = 0
    STATIC = 1
    KINEMATIC = 2


class UnsupportedSceneError(ValueError):
    """The MuJoCo model contains something FIGNet cannot represent (named in the message)."""


@dataclass(frozen=True)
class MeshOptions:
    """How MuJoCo primitives are triangulated.

    The defaults favour sparse meshes, which are FIGNet's strength: face-face edges catch contacts
    whatever the triangle size, and fewer nodes make every step cheaper.

    Attributes:
        sphere_subdivisions: icosphere level for spheres and ellipsoids (0: 12 nodes, 1: 42, 2: 162).
        cylinder_sections: facets around cylinders and capsules (each cap adds a centre node).
        capsule_rings: latitude rings per hemisphere of a capsule.
        box_subdivisions: loop subdivisions of a box (0: its 8 corners).
        plane_half_size: half extent (m) of a plane whose MuJoCo size is 0 (infinite).
        plane_cells: cells per side of a plane's grid. FIGNet needs 1 (two triangles: face-face
            edges catch any contact with them); node-based baselines (MeshGraphNets) only sense a
            floor through its nodes, so they need a subdivided one.
    """

    sphere_subdivisions: int = 1
    cylinder_sections: int = 12
    capsule_rings: int = 2
    box_subdivisions: int = 0
    plane_half_size: float = 20.0
    plane_cells: int = 1


def restitution_to_dampratio(restitution: float) -> float:
    """Damping ratio of MuJoCo's contact spring that gives a coefficient of restitution.

    Inverse of the damped oscillator relation ``e = exp(-pi z / sqrt(1 - z^2))``.
    """
    if not 0.0 <= restitution <= 1.0:
        raise ValueError(f"restitution must be in [0, 1], got {restitution}")
    if restitution <= 1e-6:
        return 1.0
    log_e = math.log(restitution)
    return -log_e / math.sqrt(math.pi**2 + log_e**2)


def dampratio_to_restitution(dampratio: float) -> float:
    """Coefficient of restitution of MuJoCo's contact spring with damping ratio ``dampratio``."""
    if dampratio >= 1.0:
        return 0.0
    return math.exp(-math.pi * dampratio / math.sqrt(1.0 - dampratio**2))


def _solref_restitution(solref: np.ndarray) -> float:
    timeconst, damp = float(solref[0]), float(solref[1])
    if timeconst > 0:
        return dampratio_to_restitution(damp)
    # Direct form (-stiffness, -damping): a unit-mass oscillator has ratio b / (2 sqrt(k)).
    k, b = -timeconst, -damp
    return dampratio_to_restitution(b / (2.0 * math.sqrt(k)) if k > 0 else 1.0)


def _primitive_mesh(model: mujoco.MjModel, g: int, opts: MeshOptions) -> trimesh.Trimesh:
    """Triangle mesh of geom ``g`` in its own frame."""
    gtype, size = int(model.geom_type[g]), model.geom_size[g]
    G = mujoco.mjtGeom
    if gtype == G.mjGEOM_PLANE:
        hx = size[0] if size[0] > 0 else opts.plane_half_size
        hy = size[1] if size[1] > 0 else opts.plane_half_size
        k = max(int(opts.plane_cells), 1)
        gx, gy = np.meshgrid(np.linspace(-hx, hx, k + 1), np.linspace(-hy, hy, k + 1), indexing="xy")
        v = np.stack((gx.ravel(), gy.ravel(), np.zeros(gx.size)), axis=1)
        i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="xy")
        a = (j * (k + 1) + i).ravel()  # lower-left corner of each cell
        b, c, d = a + 1, a + k + 2, a + k + 1
        faces = np.concatenate((np.stack((a, b, c), 1), np.stack((a, c, d), 1)))
        return trimesh.Trimesh(v, faces, process=False)
    if gtype in (G.mjGEOM_SPHERE, G.mjGEOM_ELLIPSOID):
        m = trimesh.creation.icosphere(subdivisions=opts.sphere_subdivisions, radius=1.0)
        scale = size[:3] if gtype == G.mjGEOM_ELLIPSOID else np.full(3, size[0])
        return trimesh.Trimesh(m.vertices * scale, m.faces, process=False)
    if gtype == G.mjGEOM_CYLINDER:
        return trimesh.creation.cylinder(radius=size[0], height=2 * size[1],
                                         sections=opts.cylinder_sections)
    if gtype == G.mjGEOM_CAPSULE:
        return trimesh.creation.capsule(height=2 * size[1], radius=size[0],
                                        count=[opts.cylinder_sections, 2 * opts.capsule_rings + 2])
    if gtype == G.mjGEOM_BOX:
        m = trimesh.creation.box(extents=2 * size[:3])
        for _ in range(opts.box_subdivisions):
            m = m.subdivide()
        return m
    if gtype == G.mjGEOM_MESH:
        mid = int(model.geom_dataid[g])
        va, vn = int(model.mesh_vertadr[mid]), int(model.mesh_vertnum[mid])
        fa, fn = int(model.mesh_faceadr[mid]), int(model.mesh_facenum[mid])
        return trimesh.Trimesh(model.mesh_vert[va:va + vn].astype(float),
                               model.mesh_face[fa:fa + fn].astype(np.int64), process=False)
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"#{g}"
    raise UnsupportedSceneError(f"geom '{name}' has type {gtype} (hfield/sdf), which has no mesh")


def _geom_in_body(model: mujoco.MjModel, g: int, opts: MeshOptions) -> tuple[np.ndarray, np.ndarray]:
    mesh = _primitive_mesh(model, g, opts)
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, model.geom_quat[g])
    verts = mesh.vertices @ rot.reshape(3, 3).T + model.geom_pos[g]
    return verts, np.asarray(mesh.faces, dtype=np.int64)


def _mesh_edges(faces: np.ndarray) -> np.ndarray:
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    return np.concatenate([e, e[:, ::-1]]).T.copy()


@dataclass(frozen=True)
class Scene:
    """Static topology of one scene, or of a batch of scenes (disjoint union).

    Attributes:
        ref_vertices: ``float[N, 3]`` node positions in their object's body frame.
        faces: ``int64[F, 3]`` node indices of each triangle (outward normal by right-hand rule).
        node_object: ``int64[N]`` object of each node.
        face_object: ``int64[F]`` object of each face.
        mesh_edges: ``int64[2, E]`` directed mesh edges (sender, receiver), both directions.
        object_kind: ``int64[O]`` :class:`ObjectKind` values.
        object_props: ``float[O, 3]`` static features: mass (kg), friction, restitution.
        object_com: ``float[O, 3]`` centre of mass in the body frame (the object node).
        object_scene: ``int64[O]`` which scene of a batch the object belongs to.
        object_names: MuJoCo body names (one per object, ``O`` entries).
        object_body: ``int64[O]`` MuJoCo body id in its source model (-1 if none).
        object_mocap: ``int64[O]`` mocap id of kinematic objects, else -1.
        object_qpos_adr: ``int64[O]`` free-joint ``qpos`` address of dynamic objects, else -1.
        object_dof_adr: ``int64[O]`` free-joint ``qvel`` address of dynamic objects, else -1.
        static_poses: ``float[O, 7]`` poses of objects at the model's reference configuration (the
            fixed pose of static objects).
        num_scenes: number of scenes in the union (``B``).
    """

    ref_vertices: Tensor
    faces: Tensor
    node_object: Tensor
    face_object: Tensor
    mesh_edges: Tensor
    object_kind: Tensor
    object_props: Tensor
    object_com: Tensor
    object_scene: Tensor
    object_names: tuple[str, ...]
    object_body: Tensor
    object_mocap: Tensor
    object_qpos_adr: Tensor
    object_dof_adr: Tensor
    static_poses: Tensor
    num_scenes: int = 1
    _cache: OrderedDict = field(default_factory=OrderedDict, compare=False, repr=False)

    # ----------------------------------------------------------------- construction
    @staticmethod
    def from_meshes(
        vertices: Sequence[np.ndarray], faces: Sequence[np.ndarray], kinds: Sequence[int],
        props: np.ndarray, coms: np.ndarray | None = None, names: Sequence[str] | None = None,
        static_poses: np.ndarray | None = None,
    ) -> Scene:
        """Scene from per-object meshes (each ``float[n_i, 3]`` in its body frame, ``int[f_i, 3]``).

        ``props`` is ``float[O, 3]`` (mass, friction, restitution); ``coms`` ``float[O, 3]``
        (default: mesh vertex centroid); ``static_poses`` ``float[O, 7]`` (default: identity).
        """
        n_obj = len(vertices)
        if not (len(faces) == len(kinds) == n_obj == len(props)):
            raise ValueError("from_meshes: vertices, faces, kinds and props need one entry per object")
        names = tuple(names) if names is not None else tuple(f"object{i}" for i in range(n_obj))
        vs, fs, node_obj, face_obj, offset = [], [], [], [], 0
        for i, (v, f) in enumerate(zip(vertices, faces, strict=True)):
            v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
            f = np.asarray(f, dtype=np.int64).reshape(-1, 3)
            if len(f) == 0 or f.min() < 0 or f.max() >= len(v):
                raise UnsupportedSceneError(f"object '{names[i]}': empty mesh or face index out of range")
            vs.append(v)
            fs.append(f + offset)
            node_obj.append(np.full(len(v), i))
            face_obj.append(np.full(len(f), i))
            offset += len(v)
        faces_all = np.concatenate(fs)
        if coms is None:
            coms = np.stack([v.mean(0) for v in vs])
        if static_poses is None:
            static_poses = np.tile([0, 0, 0, 1.0, 0, 0, 0], (n_obj, 1))
        minus1 = torch.full((n_obj,), -1, dtype=torch.long)
        f32 = dict(dtype=torch.float32)
        return Scene(
            ref_vertices=torch.tensor(np.concatenate(vs), **f32),
            faces=torch.tensor(faces_all),
            node_object=torch.tensor(np.concatenate(node_obj)),
            face_object=torch.tensor(np.concatenate(face_obj)),
            mesh_edges=torch.tensor(_mesh_edges(faces_all)),
            object_kind=torch.tensor(np.asarray(kinds, dtype=np.int64)),
            object_props=torch.tensor(np.asarray(props, dtype=np.float64), **f32),
            object_com=torch.tensor(np.asarray(coms, dtype=np.float64), **f32),
            object_scene=torch.zeros(n_obj, dtype=torch.long),
            object_names=names,
            object_body=minus1.clone(), object_mocap=minus1.clone(),
            object_qpos_adr=minus1.clone(), object_dof_adr=minus1.clone(),
            static_poses=torch.tensor(np.asarray(static_poses, dtype=np.float64), **f32),
        )

    @staticmethod
    def from_mjmodel(model: mujoco.MjModel, options: MeshOptions | None = None) -> Scene:
        """Read objects, meshes and properties from a compiled model.

        Free-jointed bodies are dynamic, mocap bodies kinematic, the world body and bodies welded to
        it static. Only geoms that can collide (``contype`` or ``conaffinity`` non-zero) are meshed;
        visual-only geoms are ignored. Raises :class:`UnsupportedSceneError` naming the body for
        hinge, slide or ball joints, free bodies without a collidable geom, or bodies welded to a
        moving body.
        """
        opts = options or MeshOptions()
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        body_name = lambda b: mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or f"#{b}"  # noqa: E731
        collidable = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
        per_body: dict[int, list[int]] = {}
        for g in range(model.ngeom):
            if collidable[g]:
                per_body.setdefault(int(model.geom_bodyid[g]), []).append(g)

        def kind_of(b: int) -> ObjectKind:
            if b == 0:
                return ObjectKind.STATIC
            if model.body_mocapid[b] >= 0:
                return ObjectKind.KINEMATIC
            jn, ja = int(model.body_jntnum[b]), int(model.body_jntadr[b])
            if jn == 0:
                parent = int(model.body_parentid[b])
                if parent != 0 and kind_of(parent) != ObjectKind.STATIC:
                    raise UnsupportedSceneError(
                        f"body '{body_name(b)}' is welded to moving body '{body_name(parent)}': "
                        "merge its geoms into the parent body")
                return ObjectKind.STATIC
            types = [int(model.jnt_type[j]) for j in range(ja, ja + jn)]
            if jn == 1 and types[0] == mujoco.mjtJoint.mjJNT_FREE:
                if int(model.body_parentid[b]) != 0:
                    raise UnsupportedSceneError(
                        f"body '{body_name(b)}' has a free joint but is nested in another body")
                return ObjectKind.DYNAMIC
            raise UnsupportedSceneError(
                f"body '{body_name(b)}' has joints {types} (hinge, slide or ball): FIGNet only "
                "represents free bodies, static geoms and mocap bodies")

        verts, faces, kinds, props, coms, names, poses = [], [], [], [], [], [], []
        bodies, mocaps, qadr, dadr = [], [], [], []
        for b in range(model.nbody):
            kind = kind_of(b)  # validate every body, even those without geometry
            if b not in per_body:
                if kind == ObjectKind.DYNAMIC:
                    # MuJoCo would move it (gravity, its joint); FIGNet has no node for it, so it
                    # would hang in the air: a silently wrong answer.
                    raise UnsupportedSceneError(
                        f"body '{body_name(b)}' has a free joint but no collidable geom "
                        "(contype or conaffinity non-zero): FIGNet cannot represent it")
                continue
            parts = [_geom_in_body(model, g, opts) for g in per_body[b]]
            offs = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])
            verts.append(np.concatenate([p[0] for p in parts]))
            faces.append(np.concatenate([p[1] + o for p, o in zip(parts, offs, strict=True)]))
            g0 = per_body[b][0]
            mass = 0.0 if kind == ObjectKind.STATIC else float(model.body_mass[b])
            props.append([mass, float(model.geom_friction[g0, 0]),
                          _solref_restitution(model.geom_solref[g0])])
            kinds.append(int(kind))
            coms.append(model.body_ipos[b] if kind != ObjectKind.STATIC else verts[-1].mean(0))
            names.append(body_name(b) if b else "world")
            poses.append(np.concatenate([data.xpos[b], data.xquat[b]]))
            bodies.append(b)
            mocaps.append(int(model.body_mocapid[b]))
            if kind == ObjectKind.DYNAMIC:
                j = int(model.body_jntadr[b])
                qadr.append(int(model.jnt_qposadr[j]))
                dadr.append(int(model.jnt_dofadr[j]))
            else:
                qadr.append(-1)
                dadr.append(-1)
        if not any(k == ObjectKind.DYNAMIC for k in kinds):
            raise UnsupportedSceneError("the model has no free-jointed body with collidable geoms")
        scene = Scene.from_meshes(verts, faces, kinds, np.asarray(props), np.asarray(coms), names,
                                  np.asarray(poses))
        as_long = lambda x: torch.tensor(x, dtype=torch.long)  # noqa: E731
        return replace(scene, object_body=as_long(bodies), object_mocap=as_long(mocaps),
                       object_qpos_adr=as_long(qadr), object_dof_adr=as_long(dadr), _cache=OrderedDict())

    # ----------------------------------------------------------------- batching
    @staticmethod
    def batch(scenes: Sequence[Scene]) -> Scene:
        """Disjoint union of scenes: objects, nodes and faces concatenated, indices offset."""
        if len(scenes) == 1:
            return scenes[0]
        n_off = np.cumsum([0] + [s.num_nodes for s in scenes[:-1]])
        o_off = np.cumsum([0] + [s.num_objects for s in scenes[:-1]])
        s_off = np.cumsum([0] + [s.num_scenes for s in scenes[:-1]])
        cat = lambda name, offs=None: torch.cat([  # noqa: E731
            getattr(s, name) + (int(o) if offs is not None else 0)
            for s, o in zip(scenes, offs if offs is not None else [0] * len(scenes), strict=True)])
        return Scene(
            ref_vertices=cat("ref_vertices"),
            faces=cat("faces", n_off),
            node_object=cat("node_object", o_off),
            face_object=cat("face_object", o_off),
            mesh_edges=torch.cat([s.mesh_edges + int(o) for s, o in zip(scenes, n_off, strict=True)], dim=1),
            object_kind=cat("object_kind"),
            object_props=cat("object_props"),
            object_com=cat("object_com"),
            object_scene=cat("object_scene", s_off),
            object_names=sum((s.object_names for s in scenes), ()),
            object_body=cat("object_body"), object_mocap=cat("object_mocap"),
            object_qpos_adr=cat("object_qpos_adr"), object_dof_adr=cat("object_dof_adr"),
            static_poses=cat("static_poses"),
            num_scenes=int(sum(s.num_scenes for s in scenes)),
        )

    def repeat(self, count: int) -> Scene:
        """``count`` copies of this scene as one batch (cached: envs ask for it every step)."""
        return self.cached(("repeat", count), lambda: Scene.batch([self] * count))

    def to(self, device: torch.device | str) -> Scene:
        """The same scene with every tensor on ``device``."""
        def build() -> Scene:
            moved = {k: (v.to(device) if isinstance(v, Tensor) else v)
                     for k, v in self.__dict__.items() if k != "_cache"}
            return Scene(**moved)

        return self.cached(("to", str(device)), build)

    def cached(self, key: Hashable, build: Callable[[], T]) -> T:
        """``build()``, computed once per scene and ``key`` and then memoised.

        For data derived from the topology alone (a scene never changes): batched copies, collision
        pairs, the pose-independent parts of graph features. ``key`` must name everything the
        value depends on besides the scene.

        Least recently used entries beyond :data:`CACHE_ENTRIES` are dropped: a caller that
        batches many different counts (``repeat(k)`` for every planner population or last chunk)
        must not keep one batched copy per count alive for the scene's lifetime.
        """
        cache = self._cache
        if key in cache:
            cache.move_to_end(key)
            return cache[key]
        value = cache[key] = build()
        while len(cache) > CACHE_ENTRIES:
            cache.popitem(last=False)
        return value

    # ----------------------------------------------------------------- queries
    @property
    def num_nodes(self) -> int:
        return int(self.ref_vertices.shape[0])

    @property
    def num_objects(self) -> int:
        return int(self.object_kind.shape[0])

    @property
    def device(self) -> torch.device:
        return self.ref_vertices.device

    @property
    def dynamic_mask(self) -> Tensor:
        """``bool[O]``: objects whose motion is predicted."""
        return self.object_kind == ObjectKind.DYNAMIC

    @property
    def collision_pairs(self) -> Tensor:
        """``int64[K, 2]`` object pairs (i < j) of the same scene, at least one of them dynamic.

        Pairs of two non-dynamic objects (a pusher touching the floor) never need an edge: neither
        object's motion is predicted.
        """
        def build() -> Tensor:
            i, j = torch.triu_indices(self.num_objects, self.num_objects, 1,
                                      device=self.object_kind.device)
            keep = (self.object_scene[i] == self.object_scene[j]) & (
                self.dynamic_mask[i] | self.dynamic_mask[j])
            return torch.stack((i[keep], j[keep]), dim=1)

        return self.cached("pairs", build)

    def node_positions(self, poses: Tensor) -> Tensor:
        """World node positions. ``float[..., O, 7] -> float[..., N, 3]``."""
        return transform_points(poses[..., self.node_object, :], self.ref_vertices)

    def com_positions(self, poses: Tensor) -> Tensor:
        """World centre-of-mass positions. ``float[..., O, 7] -> float[..., O, 3]``."""
        return transform_points(poses, self.object_com)

    def poses_from_data(self, data: mujoco.MjData) -> np.ndarray:
        """Current object poses ``float64[O, 7]`` of an (unbatched) scene from ``MjData``.

        Dynamic objects read their free joint's ``qpos``, kinematic ones ``mocap_pos/quat``, static
        ones keep their reference pose.
        """
        if self.num_scenes != 1:
            raise ValueError("poses_from_data needs an unbatched scene")
        out = self.static_poses.double().cpu().numpy().copy()
        adrs = zip(self.object_qpos_adr.tolist(), self.object_mocap.tolist(), strict=True)
        for o, (q, m) in enumerate(adrs):
            if q >= 0:
                out[o] = data.qpos[q:q + 7]
            elif m >= 0:
                out[o, :3] = data.mocap_pos[m]
                out[o, 3:] = data.mocap_quat[m]
        return out
