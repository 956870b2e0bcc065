"""Trajectories of a user's own MJCF: free bodies pushed by mocap bodies in straight strokes.

``fignet-gym generate scene --mjcf FILE`` simulates the scene as written (its options, friction,
masses and timestep kept), with a seeded start and seeded pusher motion drawn per trajectory
(:class:`SceneConfig`, documented in ``docs/data.md``):

* **start**: each free body's horizontal position moves by up to ``position_jitter`` (uniform in
  a disc) and its heading turns about the vertical by up to ``yaw_range`` (uniform), from its
  MJCF pose; it starts at rest.
* **pushers**: each mocap body makes a straight stroke (or ``segments`` straight pieces, each
  turned by up to ``turn`` from the last) at a constant speed drawn from ``speed``, aimed at a
  free body (``target``, else one drawn per stroke) from a uniform direction, passing the
  body's centre at a lateral ``offset`` (uniform), and starting ``clearance`` beyond the two
  bodies' bounding radii. Its height and orientation stay the MJCF's.

The records are the one trajectory format with the scene's MJCF, so ``train``, ``evaluate``,
``split`` and ``sim2real`` take them unchanged. Refused in one line: a scene FIGNet cannot
represent (hinge, slide or ball joints, named by :class:`~fignet_gym.simulator.scene.Scene`),
no free body, no mocap body, a ``target`` that is not a free body, a timestep that does not
divide the step ``dt``. A pyramidal friction cone (MuJoCo's default) is kept, with one warning.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import trimesh

from fignet_gym.data.format import Trajectory
from fignet_gym.data.generator_base import (
    GENERATED_SOURCE,
    GENERATOR_VERSION,
    GenerationError,
    PoseHook,
    num_poses,
    simulate_driven,
)
from fignet_gym.simulator.scene import Scene

#: How far ``dt / timestep`` may be from a whole number of substeps.
SUBSTEP_RTOL = 1e-6


class AnisotropicFrictionWarning(UserWarning):
    """The scene uses MuJoCo's pyramidal friction cone: the same push turns an object by a
    different angle at each world heading (docs/data.md, "The friction cone")."""


@dataclass(frozen=True)
class SceneConfig:
    """Seeded distributions of a user's scene (module docstring; units m, s, rad).

    Attributes:
        mjcf: the scene's MJCF text (:meth:`from_file` reads a file, its assets resolved).
        dt: learned step (a whole number of the MJCF's timesteps). duration: seconds per record.
        position_jitter, yaw_range: start of each free body.
        speed, offset: ranges (uniform) of each stroke's speed and lateral offset.
        clearance: gap between the bounding spheres at a stroke's start.
        segments, turn: straight pieces per stroke and their largest turn.
        target: free body every stroke aims at (``None``: one drawn per stroke).
        source: where the MJCF came from (recorded in the metadata).
    """

    mjcf: str
    dt: float = 0.02
    duration: float = 1.0
    position_jitter: float = 0.0
    yaw_range: float = math.pi
    speed: tuple[float, float] = (0.05, 0.15)
    offset: tuple[float, float] = (-0.02, 0.02)
    clearance: float = 0.005
    segments: int = 1
    turn: float = 0.5
    target: str | None = None
    source: str = ""

    @staticmethod
    def from_file(path: str | os.PathLike, **kwargs: Any) -> SceneConfig:
        """The configuration of the MJCF at ``path`` (meshes and other assets are embedded, so
        the records replay without the file)."""
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"{path}: no such MJCF file")
        try:
            model = mujoco.MjModel.from_xml_path(str(path))
        except ValueError as err:
            raise ValueError(f"{path}: MuJoCo cannot load it ({str(err).splitlines()[0]})") from None
        return SceneConfig(mjcf=_standalone_xml(model, path), source=str(path), **kwargs)

    @property
    def substeps(self) -> int:
        return round(self.dt / mujoco.MjModel.from_xml_string(self.mjcf).opt.timestep)


def _standalone_xml(model: mujoco.MjModel, path: Path) -> str:
    """The MJCF at ``path`` as one string: mesh files inlined (their vertices and faces as read
    from the file, so MuJoCo compiles them as before); texture files, which do not change the
    physics, dropped with the materials' references to them."""
    spec = mujoco.MjSpec.from_file(str(path))
    mesh_dir = path.parent / (spec.meshdir or "")
    for mesh in spec.meshes:
        if mesh.file:
            try:
                tm = trimesh.load(str(mesh_dir / mesh.file), process=False, force="mesh")
            except (OSError, ValueError) as err:
                raise ValueError(f"{path}: mesh {mesh.name!r} ({mesh.file}): {err}") from None
            mesh.file = ""
            mesh.uservert = np.asarray(tm.vertices, float).ravel().tolist()
            mesh.userface = np.asarray(tm.faces, int).ravel().tolist()
    dropped = {t.name for t in spec.textures if t.file}
    for t in [t for t in spec.textures if t.file]:
        spec.delete(t)
    for mat in spec.materials:
        mat.textures = ["" if name in dropped else name for name in mat.textures]
    spec.compile()
    return spec.to_xml()


def check_scene(cfg: SceneConfig) -> tuple[mujoco.MjModel, Scene, int]:
    """The compiled model, its :class:`Scene` and the substeps per step; ``ValueError`` naming
    the body or value the generator cannot use (module docstring)."""
    where = cfg.source or "scene"
    model = mujoco.MjModel.from_xml_string(cfg.mjcf)
    scene = Scene.from_mjmodel(model)  # hinge, slide and ball joints: refused, naming the body
    ratio = cfg.dt / model.opt.timestep
    if round(ratio) < 1 or abs(ratio - round(ratio)) > SUBSTEP_RTOL * ratio:
        raise ValueError(f"{where}: timestep {model.opt.timestep:g} s does not divide the step "
                         f"dt {cfg.dt:g} s (choose --dt as a multiple of it)")
    free = _free_bodies(model)
    if not free:
        raise ValueError(f"{where}: no free body (a <freejoint/>) to push")
    if model.nmocap == 0:
        raise ValueError(f"{where}: no mocap body (mocap=\"true\") to push with")
    if cfg.target is not None and cfg.target not in free:
        raise ValueError(f"{where}: --target {cfg.target!r} is not a free body; free bodies: "
                         f"{', '.join(free)}")
    lo, hi = cfg.speed
    if not (0 < lo <= hi and cfg.offset[0] <= cfg.offset[1] and cfg.segments >= 1
            and cfg.duration > 0 and cfg.position_jitter >= 0 and cfg.yaw_range >= 0):
        raise ValueError(f"{where}: need 0 < speed min <= max, offset min <= max, segments >= 1, "
                         "duration > 0 and non-negative jitter and yaw range")
    if model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL:
        warnings.warn(f"{where}: pyramidal friction cone (MuJoCo's default) kept: the same push "
                      "turns an object by a different angle at each world heading; add "
                      "<option cone=\"elliptic\"/> for isotropic friction",
                      AnisotropicFrictionWarning, stacklevel=2)
    return model, scene, int(round(ratio))


def _free_bodies(model: mujoco.MjModel) -> dict[str, int]:
    """Names (or ``body<i>``) of the bodies with a free joint, to their free joint's id."""
    out = {}
    for j in np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE):
        b = int(model.jnt_bodyid[j])
        out[mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"] = int(j)
    return out


def _radius(model: mujoco.MjModel, body: int) -> float:
    """Horizontal bounding radius (m) of a body's geoms about its frame origin."""
    r = 0.0
    for g in np.flatnonzero(model.geom_bodyid == body):
        r = max(r, float(np.linalg.norm(model.geom_pos[g][:2])) + float(model.geom_rbound[g]))
    return r


def _yaw_quat(q: np.ndarray, yaw: float) -> np.ndarray:
    """``q`` (w x y z) turned by ``yaw`` about the world vertical."""
    out = np.empty(4)
    mujoco.mju_mulQuat(out, np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]), q)
    return out


def _strokes(model: mujoco.MjModel, data: mujoco.MjData, cfg: SceneConfig, rng: np.random.Generator
             ) -> list[dict[str, Any]]:
    """One stroke per mocap body (module docstring), as JSON-ready pieces ``(t0, start, velocity)``."""
    free = _free_bodies(model)
    names = sorted(free)
    out = []
    for b in np.flatnonzero(model.body_mocapid >= 0):
        target = cfg.target or names[int(rng.integers(len(names)))]
        tb = int(model.jnt_bodyid[free[target]])
        direction = rng.uniform(0.0, 2.0 * math.pi)
        d = np.array([math.cos(direction), math.sin(direction)])
        perp = np.array([-d[1], d[0]])
        centre = data.xpos[tb, :2]
        back = _radius(model, tb) + _radius(model, int(b)) + cfg.clearance
        start = centre + perp * rng.uniform(*cfg.offset) - d * back
        speed = float(rng.uniform(*cfg.speed))
        pieces, t0, p0 = [], 0.0, start
        length = cfg.duration / cfg.segments
        heading = direction
        for k in range(cfg.segments):
            if k:
                heading += rng.uniform(-cfg.turn, cfg.turn)
            v = speed * np.array([math.cos(heading), math.sin(heading)])
            pieces.append({"t0": t0, "start": p0.tolist(), "velocity": v.tolist()})
            p0, t0 = p0 + v * length, t0 + length
        out.append({"mocap": int(model.body_mocapid[b]), "target": target, "speed": speed,
                    "z": float(data.mocap_pos[model.body_mocapid[b], 2]), "pieces": pieces})
    return out


def stroke_position(stroke: dict[str, Any], t: float) -> np.ndarray:
    """``float[2]`` position of a stroke's mocap body at time ``t`` (s)."""
    piece = [p for p in stroke["pieces"] if p["t0"] <= t + 1e-12][-1]
    return np.asarray(piece["start"]) + np.asarray(piece["velocity"]) * (t - piece["t0"])


def simulate_scene(mjcf: str, meta: dict[str, Any], poses: int, substeps: int,
                   hook: PoseHook | None = None) -> tuple[np.ndarray, Scene]:
    """Poses ``float[T, O, 7]`` of a scene from its start state and strokes (``meta``);
    ``hook(k, model, data)`` runs before pose ``k`` is recorded (``resimulate``'s nudge)."""

    def drive(data: mujoco.MjData, t: float) -> None:
        for s in meta["strokes"]:
            data.mocap_pos[s["mocap"], :2] = stroke_position(s, t)

    def start(data: mujoco.MjData) -> None:
        data.qpos[:] = meta["qpos0"]
        drive(data, 0.0)

    return simulate_driven(mjcf, poses, substeps, drive, start, hook)


def generate_scene(rng: np.random.Generator, cfg: SceneConfig) -> Trajectory:
    """One record of a user's scene: a seeded start and strokes (module docstring)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", AnisotropicFrictionWarning)  # said once, by the caller
        model, _, substeps = check_scene(cfg)
    data = mujoco.MjData(model)
    mujoco.mj_resetData(model, data)
    for j in _free_bodies(model).values():
        a = int(model.jnt_qposadr[j])
        r, phi = cfg.position_jitter * math.sqrt(rng.uniform()), rng.uniform(0.0, 2.0 * math.pi)
        data.qpos[a:a + 2] += r * np.array([math.cos(phi), math.sin(phi)])
        data.qpos[a + 3:a + 7] = _yaw_quat(data.qpos[a + 3:a + 7], rng.uniform(-cfg.yaw_range,
                                                                             cfg.yaw_range))
    mujoco.mj_forward(model, data)
    meta: dict[str, Any] = {
        "source": GENERATED_SOURCE, "kind": "scene", "generator_version": GENERATOR_VERSION,
        "scene_source": cfg.source, "qpos0": data.qpos.tolist(),
        "strokes": _strokes(model, data, cfg, rng), "timestep": float(model.opt.timestep),
        "substeps": substeps,
    }
    poses, scene = simulate_scene(cfg.mjcf, meta, num_poses(cfg.duration, cfg.dt), substeps)
    if not np.isfinite(poses).all():
        raise GenerationError("scene: simulation diverged")
    return Trajectory(poses=poses, dt=cfg.dt, kinds=scene.object_kind.numpy(),
                      props=scene.object_props.double().numpy(), names=scene.object_names,
                      mjcf=cfg.mjcf, metadata=meta)


__all__ = ["AnisotropicFrictionWarning", "SceneConfig", "check_scene", "generate_scene",
           "simulate_scene", "stroke_position"]
