"""A pushing env on a user's own MJCF: :class:`ScenePushEnv`.

The scene file needs one free body to push, one mocap body to push it with (its first geom's
first size is the pusher's radius) and may hold static geometry; hinge, slide and ball joints
are refused, naming the body, as ``fignet-gym generate scene`` refuses them. The MJCF's own
options (timestep, friction, cone, solver) are kept; MuJoCo's default pyramidal cone gets one
warning line with the fix. Everything else is :class:`~fignet_gym.envs.push.PushEnv`'s: the
goal pose distribution, the tolerances, the reward, the action box and ``env.task`` (a
:class:`~fignet_gym.envs.tasks.PushTask`), so ``plan``, ``collect``, PPO and the planners work on
it unchanged.

Learned dynamics need a model trained on the scene (``fignet-gym generate scene --mjcf FILE``,
then ``fignet-gym train --config push-cpu``): ``dynamics="fignet"`` without ``checkpoint`` is
refused, since no shipped model knows a user's objects.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from fignet_gym.dynamics import compile_with_history
from fignet_gym.envs.push import PushEnv, PushScene
from fignet_gym.envs.vector import SingleEnvVectorEnv

if TYPE_CHECKING:
    from fignet_gym.data.scene_generator import SceneConfig

#: PushEnv arguments that build the shipped scene; a user's scene keeps its MJCF's own.
SCENE_OWNED = ("shape", "friction", "tip_friction", "cone")


def _geom_points(model: mujoco.MjModel, g: int) -> np.ndarray:
    """``float[P, 3]`` points of geom ``g``'s surface (its vertices, or a ring sampling of a
    round primitive) in its body's frame."""
    size, kind = model.geom_size[g], int(model.geom_type[g])
    t = np.linspace(0.0, 2 * np.pi, 48, endpoint=False)
    ring = np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], axis=1)
    sphere = np.concatenate([ring * np.cos(a) + (0, 0, np.sin(a))
                             for a in np.linspace(-np.pi / 2, np.pi / 2, 7)])
    if kind == mujoco.mjtGeom.mjGEOM_MESH:
        adr, num = model.mesh_vertadr[model.geom_dataid[g]], model.mesh_vertnum[model.geom_dataid[g]]
        local = model.mesh_vert[adr:adr + num].astype(np.float64)
    elif kind == mujoco.mjtGeom.mjGEOM_BOX:
        local = np.array(np.meshgrid(*[(-s, s) for s in size])).reshape(3, -1).T
    elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        local = np.concatenate([ring * size[0] + (0, 0, z) for z in (-size[1], size[1])])
    elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:  # a lying capsule's round ends reach farthest
        local = np.concatenate([sphere * size[0] + (0, 0, z) for z in (-size[1], size[1])])
    elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        local = sphere * size[0]
    elif kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
        local = sphere * size
    else:
        raise ValueError(f"geom {g} of type {kind}: cannot outline it (use a mesh or a primitive)")
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, model.geom_quat[g])
    return local @ rot.reshape(3, 3).T + model.geom_pos[g]


def object_outline(model: mujoco.MjModel, body: str) -> np.ndarray:
    """``float[K, 2]`` counter-clockwise convex outline (m) of ``body``'s geoms seen from above,
    in the body frame: the hull of MuJoCo's own geometry."""
    from scipy.spatial import ConvexHull  # deferred: scipy loads only for a user's scene

    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
    geoms = np.flatnonzero(model.geom_bodyid == b)
    xy = np.concatenate([_geom_points(model, int(g)) for g in geoms])[:, :2]
    hull = ConvexHull(xy)  # 2-D hulls list their vertices counter-clockwise
    return xy[hull.vertices]


class ScenePushEnv(PushEnv):
    """Push the free body ``object`` of the MJCF file ``mjcf`` to a goal pose with its mocap body
    ``pusher`` (module docstring).

    Args:
        mjcf: path of the scene's MJCF file (meshes and other assets beside it, as MuJoCo finds
            them).
        object: name of the free body to push. pusher: name of the mocap body that pushes.
        dynamics, checkpoint: as :class:`PushEnv`; ``"fignet"`` needs ``checkpoint``.
        tip_bound: the pusher stays within ``[-tip_bound, tip_bound]`` on x and y (m).
        camera: the MJCF camera that renders (``""``: MuJoCo's free camera).
        **kwargs: any other :class:`PushEnv` argument (goal ranges, tolerances, reward weights,
            ``max_speed``, ``frame_skip``, ``tip_start``, rendering); not those of
            :data:`SCENE_OWNED`, which the MJCF sets.
    """

    def __init__(self, mjcf: str | os.PathLike, object: str, pusher: str,
                 dynamics: Any = "mujoco", checkpoint: Any = None, tip_bound: float = 0.3,
                 camera: str = "", **kwargs: Any) -> None:
        owned = [k for k in SCENE_OWNED if k in kwargs]
        if owned:
            raise ValueError(f"ScenePushEnv: {', '.join(owned)} come from the MJCF file; edit "
                             f"{mjcf} instead")
        if dynamics == "fignet" and checkpoint is None and not self._default_checkpoint:
            raise ValueError("ScenePushEnv: dynamics='fignet' needs checkpoint=..., a model "
                             "trained on this scene (fignet-gym generate scene --mjcf FILE, "
                             "then fignet-gym train)")
        if not (isinstance(tip_bound, (int, float)) and tip_bound > 0):
            raise ValueError(f"ScenePushEnv: tip_bound must be a positive number, got {tip_bound!r}")
        self._scene_args = (Path(mjcf), str(object), str(pusher), float(tip_bound), str(camera))
        super().__init__(dynamics=dynamics, checkpoint=checkpoint, shape=str(object), **kwargs)

    def _push_scene(self, shape: str, friction: float, tip_friction: float | None,
                    cone: str) -> PushScene:
        # deferred: the data layer (h5py, trimesh) loads only for a user's scene
        from fignet_gym.data.scene_generator import check_scene

        path, obj, pusher, tip_bound, camera = self._scene_args
        cfg = self._scene_config()
        raw = mujoco.MjModel.from_xml_string(cfg.mjcf)
        # Refuses what FIGNet cannot represent, an object that is not a free body; warns on the
        # pyramidal cone. The env's step is whole timesteps, so any dt it checks divides.
        check_scene(dataclasses.replace(cfg, dt=float(raw.opt.timestep)))
        tip = mujoco.mj_name2id(raw, mujoco.mjtObj.mjOBJ_BODY, pusher)
        if tip < 0 or raw.body_mocapid[tip] < 0:
            mocap = [mujoco.mj_id2name(raw, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
                     for b in range(raw.nbody) if raw.body_mocapid[b] >= 0]
            raise ValueError(f"{path}: pusher {pusher!r} is not a mocap body; mocap bodies: "
                             f"{', '.join(mocap)}")
        if raw.body_geomnum[tip] == 0:
            raise ValueError(f"{path}: pusher {pusher!r} has no geom to push with")
        if camera and mujoco.mj_name2id(raw, mujoco.mjtObj.mjOBJ_CAMERA, camera) < 0:
            raise ValueError(f"{path}: no camera {camera!r}")
        model = compile_with_history(cfg.mjcf)
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, obj)
        rest_z = float(model.qpos0[model.jnt_qposadr[model.body_jntadr[body]] + 2])
        return PushScene(cfg.mjcf, model, object_outline(model, obj), rest_z, obj, pusher,
                         tip_bound, camera, default_checkpoint=self._default_checkpoint)

    #: The learned model ``dynamics="fignet"`` loads without ``checkpoint`` (none: a user's
    #: scene needs a model trained on it).
    _default_checkpoint = ""

    def _scene_config(self) -> SceneConfig:
        """The scene as the generator reads it: the MJCF file, its assets embedded."""
        from fignet_gym.data.scene_generator import SceneConfig  # deferred: as in _push_scene

        path, obj = self._scene_args[:2]
        return SceneConfig.from_file(path, target=obj)  # one-line errors for a file MuJoCo refuses


class ScenePushVectorEnv(SingleEnvVectorEnv):
    """``num_envs`` :class:`ScenePushEnv` stepped by one batched dynamics call."""

    env_class = ScenePushEnv
