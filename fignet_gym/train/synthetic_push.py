"""Synthetic pushes of real objects from a fitted analytic model: a prior for real pushing.

A few dozen real pushes fix an analytic model's two to six parameters well, but are far too few
to teach FIGNet how a pushed object turns. So ``fignet-gym sim2real --pretrain N --prior P``
re-simulates ``N`` new pushes of the real objects in the models fitted to them (MuJoCo with the
fitted :class:`~fignet_gym.train.analytic.ContactParams`, and the quasi-static
:class:`~fignet_gym.dynamics.limit_surface.LimitSurfaceDynamics`), pretrains FIGNet on them and
fine-tunes it on the real pushes.

A synthetic push keeps a source window's scene (MJCF: outline, mass, tip) and step, and draws
the rig's kind of push (:class:`PushDistribution`): a point on the object's outline (uniform
along it), a push direction at an angle to the outline's inward normal, and a constant tip speed
drawn from the sources' own (``metadata["vel_mm_s"]``, the rig's set of speeds). The object
starts at rest in the source's first pose; the tip approaches along its line and touches the
outline at frame 0, as ``import-mit``'s windows start at first contact. The push is simulated for
``duration`` and cut, like a long real push, into consecutive windows of the sources' length;
windows in which the object moves less than ``min_motion`` are left out, as ``import-mit`` leaves
out still pushes. The windows of one push share ``metadata["file"]`` (the split groups them).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from tqdm import tqdm

from fignet_gym.data.format import Trajectory
from fignet_gym.dynamics.base import Dynamics
from fignet_gym.dynamics.limit_surface import LimitSurfaceDynamics, PlanarGeometry, planar_geometry
from fignet_gym.dynamics.mujoco import MujocoDynamics
from fignet_gym.simulator.scene import ObjectKind
from fignet_gym.train.analytic import ContactParams, Replay
from fignet_gym.train.real_baselines import LS_STEP

#: Poses a rollout is given (``history + 1`` of the push models): the tip touches at the last.
GIVEN = 3


@dataclass(frozen=True)
class PushDistribution:
    """How synthetic pushes are drawn (units: m, s, rad).

    Attributes:
        max_angle: push directions are uniform within this angle of the inward normal at the
            contact point (the rig's pushes span +-1.396 rad, 80 deg).
        speeds_mm_s: tip speeds to draw from, uniformly (``None``: the sources' speeds).
        duration: pushing time after first contact, cut into windows of the sources' length.
        gap: tip surface to outline at first contact.
        min_motion: a window whose outline moves less than this is left out.
    """

    max_angle: float = 1.396
    speeds_mm_s: tuple[float, ...] | None = None
    duration: float = 1.0
    gap: float = 1e-4
    min_motion: float = 1e-3


@dataclass(frozen=True)
class PushSource:
    """An analytic model that simulates synthetic pushes: ``dynamics`` stepping ``params``."""

    name: str
    dynamics: Dynamics
    params: ContactParams

    @staticmethod
    def mujoco(params: ContactParams) -> PushSource:
        """MuJoCo with (fitted) contact parameters ``params``."""
        return PushSource("mujoco", MujocoDynamics(nthread=1), params)

    @staticmethod
    def limit_surface(tip_friction: float, pressure_scale: float) -> PushSource:
        """The fitted quasi-static limit-surface model (its step length does not matter)."""
        return PushSource("limit-surface", LimitSurfaceDynamics(tip_friction, pressure_scale),
                          LS_STEP)


def _rot(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def _yaw(q: np.ndarray) -> float:
    return 2.0 * math.atan2(float(q[3]), float(q[0]))


def check_pushes(trajs: Sequence[Trajectory]) -> None:
    """``ValueError`` naming the first trajectory that is not a push this module can vary: an
    MJCF with one free object and one mocap tip (:func:`planar_geometry`), a ``vel_mm_s``
    speed in its metadata unless speeds are given, and at least :data:`GIVEN` + 1 poses."""
    for t in trajs:
        where = f"{t.source or 'trajectories'}: trajectory {t.name!r}"
        if t.mjcf is None:
            raise ValueError(f"{where} has no MJCF: synthetic pushes are simulated from it")
        if t.num_steps <= GIVEN:
            raise ValueError(f"{where} has {t.num_steps} poses: a window needs more than {GIVEN}")
        if not (np.asarray(t.kinds) == int(ObjectKind.KINEMATIC)).any():
            raise ValueError(f"{where} has no kinematic pusher: synthetic pushes vary pushes")


def _outline_point(geo: PlanarGeometry, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A point uniform along the convex outline and its outward normal (body frame, from the
    centre of mass)."""
    a = geo.hull
    b = np.roll(a, -1, axis=0)
    lengths = np.linalg.norm(b - a, axis=1)
    k = int(rng.choice(len(a), p=lengths / lengths.sum()))
    edge = (b[k] - a[k]) / lengths[k]
    # The hull is counter-clockwise, so the outward normal is the edge direction turned clockwise.
    return a[k] + rng.uniform() * (b[k] - a[k]), np.array([edge[1], -edge[0]])


def outline_motion(traj: Trajectory, geo: PlanarGeometry, obj: int) -> float:
    """Largest displacement (m) of an outline vertex between the first and last pose."""
    pts = geo.hull + geo.com[:2]
    first, last = traj.poses[0, obj], traj.poses[-1, obj]
    p0 = pts @ _rot(_yaw(first[3:])).T + first[:2]
    p1 = pts @ _rot(_yaw(last[3:])).T + last[:2]
    return float(np.linalg.norm(p1 - p0, axis=1).max())


def synthetic_pushes(trajs: Sequence[Trajectory], source: PushSource, num: int, seed: int = 0,
                     dist: PushDistribution = PushDistribution(), progress: bool = True,
                     name: str = "synthetic") -> list[Trajectory]:
    """``num`` pushes simulated by ``source`` from the scenes of ``trajs`` (module docstring),
    cut into windows of ``trajs[i].num_steps`` poses; returns the windows that move (so usually
    more than ``num`` trajectories). Seeded: the same arguments give the same pushes. Each
    window's ``metadata`` names its push (``file``), source window (``synthetic_from``), model
    (``synthetic_source``), speed (``vel_mm_s``) and angle (``angle``, rad).
    """
    if num < 1:
        raise ValueError(f"num must be at least 1, got {num}")
    if not trajs:
        raise ValueError("no source pushes to vary")
    check_pushes(trajs)
    speeds = dist.speeds_mm_s or tuple(sorted({float(t.metadata["vel_mm_s"]) for t in trajs
                                               if "vel_mm_s" in t.metadata}))
    if not speeds:
        raise ValueError("the source pushes carry no tip speed (metadata 'vel_mm_s'): pass "
                         "PushDistribution(speeds_mm_s=...)")
    rng = np.random.default_rng(seed)
    replays = [Replay(t) for t in trajs]
    geos = [planar_geometry(r.base) for r in replays]
    out: list[Trajectory] = []
    for p in tqdm(range(num), desc=f"pushes ({source.name})", unit="push", disable=not progress):
        i = int(rng.integers(len(trajs)))
        src, geo = trajs[i], geos[i]
        kinds = np.asarray(src.kinds)
        obj = int(np.nonzero(kinds == int(ObjectKind.DYNAMIC))[0][0])
        tip = int(np.nonzero(kinds == int(ObjectKind.KINEMATIC))[0][0])
        dt, n_win = src.dt, src.num_steps
        point, normal = _outline_point(geo, rng)
        angle = float(rng.uniform(-dist.max_angle, dist.max_angle))
        speed = float(rng.choice(speeds))
        pose0 = np.asarray(src.poses[0, obj], np.float64)
        rot = _rot(_yaw(pose0[3:]))
        com = pose0[:2] + rot @ geo.com[:2]
        touch = com + rot @ (point + normal * (geo.tip_radius + dist.gap))
        direction = rot @ (_rot(angle) @ -normal)
        steps = int(round(dist.duration / dt))
        # GIVEN - 1 approach frames before the touch: the rollout starts at the touch, frame 0.
        k = np.arange(steps + GIVEN) - (GIVEN - 1)
        poses = np.repeat(np.asarray(src.poses[:1], np.float64), len(k), axis=0)
        poses[:, tip, :2] = touch + np.outer(k * dt * speed / 1000.0, direction)
        start = replace(src, poses=poses)
        sim = Replay(start).rollout(source.params, source.dynamics, given=GIVEN)[GIVEN - 1:]
        meta = {**src.metadata, "file": f"{name}-{p}", "synthetic_from": src.name,
                "synthetic_source": source.name, "vel_mm_s": speed, "angle": angle,
                "contact_params": source.params.to_json()}
        if isinstance(source.dynamics, LimitSurfaceDynamics):
            meta["limit_surface"] = {"tip_friction": source.dynamics.tip_friction,
                                     "pressure_scale": source.dynamics.pressure_scale}
        for w, s0 in enumerate(range(0, len(sim) - n_win + 1, n_win - 1)):
            win = replace(src, poses=sim[s0:s0 + n_win].astype(np.float32), extras={},
                          name=f"{name}-{p}" + (f"#w{w}" if w else ""),
                          metadata={**meta, "window": w, "window_start_s": s0 * dt})
            if outline_motion(win, geo, obj) >= dist.min_motion:
                out.append(win)
    return out


__all__ = ["GIVEN", "PushDistribution", "PushSource", "check_pushes", "outline_motion",
           "synthetic_pushes"]
