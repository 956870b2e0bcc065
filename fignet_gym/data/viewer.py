"""Render trajectories to MP4 or GIF with MuJoCo's offscreen renderer.

Poses are written into ``MjData`` (free-joint ``qpos`` for dynamic objects, ``mocap_pos/quat``
for kinematic ones) followed by ``mj_kinematics``, so any pose sequence can be shown: simulated,
imported or predicted by the learned simulator.

Headless machines: the OpenGL backend is ``MUJOCO_GL`` if set, else EGL when there is no
``DISPLAY`` (Linux), else GLFW. The context is created here rather than by ``mujoco.Renderer``,
because ``mujoco`` picks its default backend once, at import, which is usually before this module.
"""

from __future__ import annotations

import os
import sys

os.environ.setdefault("MUJOCO_GL", "egl" if sys.platform.startswith("linux")
                      and not os.environ.get("DISPLAY") else "glfw")

from collections.abc import Sequence  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import imageio.v2 as imageio  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from fignet_gym.data.format import Trajectory  # noqa: E402
from fignet_gym.simulator.scene import ObjectKind, Scene  # noqa: E402


@dataclass(frozen=True)
class Camera:
    """A free camera. ``None`` fields are fitted to the motion (centre and spread of the objects).

    Attributes:
        lookat: world point (m). distance: from ``lookat`` (m). azimuth, elevation: degrees.
    """

    lookat: tuple[float, float, float] | None = None
    distance: float | None = None
    azimuth: float = 90.0
    elevation: float = -45.0


def _gl_context(width: int, height: int) -> Any:
    backend = os.environ.get("MUJOCO_GL", "").lower()
    # deferred: only the backend MUJOCO_GL names is imported (each needs its own native GL
    # library: EGL, OSMesa or GLFW with a display), and only when a frame is rendered
    if backend == "egl":
        from mujoco.egl import GLContext  # deferred: see above
    elif backend == "osmesa":
        from mujoco.osmesa import GLContext  # deferred: see above
    else:
        from mujoco.glfw import GLContext  # deferred: see above
    return GLContext(width, height)


class OffscreenRenderer:
    """Minimal offscreen renderer (RGB ``uint8[H, W, 3]``) on a backend chosen as above."""

    def __init__(self, model: mujoco.MjModel, width: int = 480, height: int = 480) -> None:
        self.model, self.width, self.height = model, width, height
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, height)
        self._ctx = _gl_context(width, height)
        self._ctx.make_current()
        self._con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._con)
        self._scene = mujoco.MjvScene(model, maxgeom=2000)
        self._opt = mujoco.MjvOption()
        self._pert = mujoco.MjvPerturb()
        self._rect = mujoco.MjrRect(0, 0, width, height)

    def render(self, data: mujoco.MjData, camera: mujoco.MjvCamera) -> np.ndarray:
        self._ctx.make_current()
        mujoco.mjv_updateScene(self.model, data, self._opt, self._pert, camera,
                               mujoco.mjtCatBit.mjCAT_ALL, self._scene)
        mujoco.mjr_render(self._rect, self._scene, self._con)
        rgb = np.empty((self.height, self.width, 3), dtype=np.uint8)
        mujoco.mjr_readPixels(rgb, None, self._rect, self._con)
        return np.flipud(rgb).copy()

    def close(self) -> None:
        if self._ctx is not None:
            self._ctx.make_current()
            self._con.free()
            self._ctx.free()
            self._ctx = None

    def __enter__(self) -> OffscreenRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _as_model(model_or_mjcf: mujoco.MjModel | str) -> mujoco.MjModel:
    if isinstance(model_or_mjcf, mujoco.MjModel):
        return model_or_mjcf
    return mujoco.MjModel.from_xml_string(model_or_mjcf)


def set_poses(model: mujoco.MjModel, data: mujoco.MjData, bodies: Sequence[int],
              poses: np.ndarray) -> None:
    """Write object poses ``float[O, 7]`` of the objects with MuJoCo body ids ``bodies``."""
    for b, pose in zip(bodies, poses, strict=True):
        if b <= 0:
            continue
        mocap = int(model.body_mocapid[b])
        if mocap >= 0:
            data.mocap_pos[mocap], data.mocap_quat[mocap] = pose[:3], pose[3:]
        elif model.body_jntnum[b] == 1:
            adr = int(model.jnt_qposadr[model.body_jntadr[b]])
            data.qpos[adr:adr + 7] = pose
    mujoco.mj_kinematics(model, data)


def fit_camera(model: mujoco.MjModel, bodies: Sequence[int], poses: np.ndarray,
               camera: Camera | None = None) -> mujoco.MjvCamera:
    """A free camera looking at the moving objects over the whole trajectory."""
    camera = camera or Camera()
    moving = [i for i, b in enumerate(bodies) if b > 0 and (
        model.body_mocapid[b] >= 0 or model.body_jntnum[b] > 0)]
    dyn = [i for i in moving if model.body_mocapid[bodies[i]] < 0] or moving
    pos = poses[:, dyn, :3].reshape(-1, 3)
    radius = max([float(model.geom_rbound[g]) for g in range(model.ngeom)
                  if model.geom_bodyid[g] in [bodies[i] for i in dyn]] or [0.1])
    lookat = np.asarray(camera.lookat if camera.lookat is not None
                        else (pos.min(0) + pos.max(0)) / 2)
    spread = float(np.linalg.norm(pos - lookat, axis=1).max()) + radius
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = lookat
    cam.distance = camera.distance if camera.distance is not None else 2.6 * spread
    cam.azimuth, cam.elevation = camera.azimuth, camera.elevation
    return cam


def render_frames(model_or_mjcf: mujoco.MjModel | str, poses: np.ndarray,
                  bodies: Sequence[int] | None = None, width: int = 480, height: int = 480,
                  camera: Camera | None = None) -> list[np.ndarray]:
    """Frames ``uint8[H, W, 3]`` of poses ``float[T, O, 7]``.

    ``bodies`` are the MuJoCo body ids of the ``O`` objects (default: the order of
    ``Scene.from_mjmodel``, which is the order stored in trajectory files).
    """
    model = _as_model(model_or_mjcf)
    poses = np.asarray(poses, dtype=float)
    if bodies is None:
        bodies = Scene.from_mjmodel(model).object_body.tolist()
    if poses.ndim != 3 or poses.shape[1:] != (len(bodies), 7):
        raise ValueError(f"poses must be float[T, {len(bodies)}, 7], got shape {poses.shape}")
    data = mujoco.MjData(model)
    cam = fit_camera(model, bodies, poses, camera)
    frames = []
    with OffscreenRenderer(model, width, height) as renderer:
        for pose in poses:
            set_poses(model, data, bodies, pose)
            frames.append(renderer.render(data, cam))
    return frames


def write_video(frames: Sequence[np.ndarray], out_path: str | os.PathLike, fps: float) -> Path:
    """Write frames to ``.mp4`` (ffmpeg, H.264) or ``.gif``."""
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    suffix = out.suffix.lower()
    if suffix == ".gif":
        imageio.mimsave(out, list(frames), duration=1000.0 / fps, loop=0)
    elif suffix == ".mp4":
        imageio.mimsave(out, list(frames), fps=fps, macro_block_size=1)
    else:
        raise ValueError(f"{out}: unsupported video format {suffix!r} (use .mp4 or .gif)")
    return out


def render_trajectory(model_or_mjcf: mujoco.MjModel | str, poses: np.ndarray,
                      out_path: str | os.PathLike, fps: float = 50.0,
                      camera: Camera | None = None, width: int = 480, height: int = 480,
                      bodies: Sequence[int] | None = None) -> Path:
    """Render poses ``float[T, O, 7]`` of a model to a video file (``.mp4`` or ``.gif``)."""
    return write_video(render_frames(model_or_mjcf, poses, bodies, width, height, camera),
                       out_path, fps)


def side_by_side(left: Sequence[np.ndarray], right: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Concatenate two equally long frame sequences horizontally (e.g. predicted | true)."""
    if len(left) != len(right):
        raise ValueError(f"frame counts differ: {len(left)} vs {len(right)}")
    return [np.concatenate([a, b], axis=1) for a, b in zip(left, right, strict=True)]


def _fmt(x: np.ndarray) -> str:
    return " ".join(f"{float(v):.9g}" for v in np.asarray(x).ravel())


def meshes_mjcf(traj: Trajectory) -> str:
    """A render-only MJCF of a trajectory stored as meshes: body ``o{i}`` per object.

    Dynamic objects get free joints, kinematic ones are mocap bodies, static ones sit at their
    first pose. Geoms do not collide (only drawn); ``inertia="shell"`` accepts flat meshes.
    """
    if traj.meshes is None:
        raise ValueError(f"trajectory {traj.name!r} has no meshes")
    assets, bodies = [], []
    colours = {ObjectKind.DYNAMIC: ".75 .35 .2 1", ObjectKind.STATIC: ".7 .7 .68 1",
               ObjectKind.KINEMATIC: ".2 .3 .8 1"}
    for i, (v, f, kind, pose) in enumerate(zip(traj.meshes.vertices, traj.meshes.faces,
                                              traj.kinds, traj.poses[0], strict=True)):
        kind = ObjectKind(int(kind))
        assets.append(f'<mesh name="m{i}" inertia="shell" vertex="{_fmt(v)}" '
                      f'face="{" ".join(map(str, np.asarray(f).ravel()))}"/>')
        joint = '<freejoint/>' if kind == ObjectKind.DYNAMIC else ""
        mocap = ' mocap="true"' if kind == ObjectKind.KINEMATIC else ""
        bodies.append(
            f'<body name="o{i}" pos="{_fmt(pose[:3])}" quat="{_fmt(pose[3:])}"{mocap}>{joint}'
            f'<inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>'
            f'<geom type="mesh" mesh="m{i}" contype="0" conaffinity="0" rgba="{colours[kind]}"/>'
            f'</body>')
    nl = "\n    "
    return f"""<mujoco model="{traj.name or 'trajectory'}">
  <asset>
    {nl.join(assets)}
  </asset>
  <worldbody>
    <light pos="0 0 50" dir="0 0 -1" directional="true"/>
    {nl.join(bodies)}
  </worldbody>
</mujoco>
"""


def trajectory_model(traj: Trajectory) -> tuple[mujoco.MjModel, list[int]]:
    """A model to render a trajectory, and the body id of each of its objects."""
    if traj.mjcf is not None:
        model = mujoco.MjModel.from_xml_string(traj.mjcf)
        return model, traj.scene.object_body.tolist()
    model = mujoco.MjModel.from_xml_string(meshes_mjcf(traj))
    return model, [model.body(f"o{i}").id for i in range(traj.num_objects)]


def render_trajectory_record(traj: Trajectory, out_path: str | os.PathLike,
                             fps: float | None = None, camera: Camera | None = None,
                             width: int = 480, height: int = 480) -> Path:
    """Render one stored trajectory (MJCF or meshes) at its own rate by default (``1 / dt``)."""
    model, bodies = trajectory_model(traj)
    return render_trajectory(model, traj.poses, out_path, fps or 1.0 / traj.dt, camera,
                             width, height, bodies)
