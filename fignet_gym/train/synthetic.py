"""Synthetic tosses from a fitted MuJoCo: pretraining data for a learned simulator of real tosses.

A few real tosses fix MuJoCo's contact parameters well (fitted on 16 ContactNets tosses, MuJoCo
scores 12.0 mm at frame 50 on validation; fitted on 64, 11.6 mm), yet are far too few to train
FIGNet from scratch. So
``fignet-gym sim2real --pretrain N`` fits MuJoCo on the real tosses a model may use, re-simulates
``N`` tosses started from randomised versions of their release states in the fitted MuJoCo,
pretrains FIGNet on those and fine-tunes it on the real ones (experiments/README.md, real tosses,
"Pretraining on a fitted MuJoCo").

A synthetic toss keeps its source's scene (MJCF, meshes, properties) and length. Its first three
poses are built from the source's release state, changed as :class:`Perturbation` says, so that
MuJoCo's start state at pose 1 (:func:`~fignet_gym.train.analytic.finite_difference_state`:
central differences over those poses) is exactly the perturbed one; from pose 2 on, every pose is
the fitted MuJoCo's. The ground is the plane ``z = 0``, as the importers write it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import mujoco
import numpy as np
import torch
from tqdm import tqdm

from fignet_gym.data.format import Trajectory
from fignet_gym.data.generate import random_quaternion
from fignet_gym.dynamics.base import Dynamics
from fignet_gym.dynamics.mujoco import MujocoDynamics
from fignet_gym.simulator.scene import ObjectKind
from fignet_gym.train.analytic import ContactParams, Replay, _axis_angle, _conj, _quat_mul


@dataclass(frozen=True)
class Perturbation:
    """How a synthetic toss's release differs from its source's (units: m, s, rad).

    Attributes:
        speed_scale: range of the factor on the horizontal speed (uniform).
        vertical_speed_std: std of the change of vertical speed (normal).
        spin_scale: range of the factor on the angular velocity (uniform).
        spin_std: std of the change of each angular velocity component (normal).
        random_orientation: start in a uniformly random orientation (else the source's).
        clearance: lowest height of any dynamic node at the release (resampled below it).
    """

    speed_scale: tuple[float, float] = (0.85, 1.15)
    vertical_speed_std: float = 0.1
    spin_scale: tuple[float, float] = (0.7, 1.3)
    spin_std: float = 1.0
    random_orientation: bool = True
    clearance: float = 0.01


def _rotvec_quat(v: np.ndarray) -> np.ndarray:
    """Unit quaternion ``float[4]`` (w x y z) of a rotation vector ``float[3]``."""
    angle = float(np.linalg.norm(v))
    if angle < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * v / angle])


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    out = np.empty(3)
    mujoco.mju_rotVecQuat(out, v, q)
    return out


def check_tosses(trajs: Sequence[Trajectory], clearance: float = 0.01) -> None:
    """``ValueError`` naming the first trajectory that is not a toss this module can vary: it
    needs an MJCF, three or more poses, no kinematic objects and its dynamic objects clear of the
    ground (``z > clearance``) at the release (pose 1)."""
    for t in trajs:
        where = f"{t.source or 'trajectories'}: trajectory {t.name!r}"
        if t.mjcf is None:
            raise ValueError(f"{where} has no MJCF: synthetic tosses are simulated in MuJoCo")
        if t.num_steps < 3:
            raise ValueError(f"{where} has {t.num_steps} poses: a release state needs 3")
        if (np.asarray(t.kinds) == int(ObjectKind.KINEMATIC)).any():
            raise ValueError(f"{where} has kinematic objects (a pusher?): synthetic pretraining "
                             "varies the release of tosses, not pushes")
        scene = t.scene
        dyn = scene.dynamic_mask[scene.node_object]
        low = float(scene.node_positions(torch.as_tensor(t.poses[1:2], dtype=torch.float32))[0, dyn, 2].min())
        if low <= clearance:
            raise ValueError(f"{where} starts on the ground (lowest node {low:.4f} m at pose 1): "
                             "synthetic pretraining needs tosses released in the air")


def synthetic_tosses(
    trajs: Sequence[Trajectory], params: ContactParams, num: int, seed: int = 0,
    perturbation: Perturbation = Perturbation(), dynamics: Dynamics | None = None,
    progress: bool = True,
) -> list[Trajectory]:
    """``num`` tosses simulated by MuJoCo with ``params`` from randomised releases of ``trajs``.

    Each draws a source toss uniformly, turns its release (position, velocity and spin) about the
    vertical through the release point by a uniform angle, varies speed and spin by
    ``perturbation`` and (by default) draws a new orientation; see the module docstring. Seeded:
    the same arguments give the same tosses. Returns trajectories ``synthetic-<i>`` with their
    source in ``metadata["synthetic_from"]``.
    """
    if num < 1:
        raise ValueError(f"num must be at least 1, got {num}")
    if not trajs:
        raise ValueError("no source tosses to vary")
    check_tosses(trajs, perturbation.clearance)
    p = perturbation
    dynamics = dynamics or MujocoDynamics(nthread=1)
    rng = np.random.default_rng(seed)
    # Gravity of the fitted model (the MJCF's where the fit leaves it), once per source.
    gravity = [Replay(t).model(params).opt.gravity.copy() for t in trajs]
    out: list[Trajectory] = []
    bar = tqdm(total=num, desc="synthetic tosses", unit="toss", disable=not progress)
    draws = 0
    while len(out) < num:
        draws += 1
        if draws > 100 * num:
            raise ValueError(f"{draws - 1} releases drawn, {len(out)} clear of the ground by "
                             f"{p.clearance} m: release the sources higher or turn off "
                             "random_orientation")
        i = int(rng.integers(len(trajs)))
        src, scene, g = trajs[i], trajs[i].scene, gravity[i]
        poses = np.asarray(src.poses, np.float64).copy()
        dt = src.dt
        dyn = [o for o, k in enumerate(src.kinds) if k == int(ObjectKind.DYNAMIC)]
        for o in dyn:
            p1 = poses[1, o, :3].copy()
            v = (poses[2, o, :3] - poses[0, o, :3]) / (2 * dt)
            w = _axis_angle(_quat_mul(poses[2, o, 3:], _conj(poses[0, o, 3:]))) / (2 * dt)
            yaw = _rotvec_quat(np.array([0.0, 0.0, rng.uniform(0, 2 * math.pi)]))
            v, w = _rotate(yaw, v), _rotate(yaw, w)
            v[:2] *= rng.uniform(*p.speed_scale)
            v[2] += rng.normal(0.0, p.vertical_speed_std)
            w = w * rng.uniform(*p.spin_scale) + rng.normal(0.0, p.spin_std, 3)
            q1 = random_quaternion(rng) if p.random_orientation else _quat_mul(yaw, poses[1, o, 3:])
            for k, sign in ((0, -1.0), (1, 0.0), (2, 1.0)):
                # Constant velocity plus gravity over one step each way: the central difference
                # of poses 0 and 2 is exactly (v, w), MuJoCo's start state at pose 1.
                poses[k, o, :3] = p1 + sign * v * dt + (0.5 * g * dt**2 if sign else 0.0)
                poses[k, o, 3:] = _quat_mul(_rotvec_quat(sign * w * dt), q1)
        nodes = scene.node_positions(torch.as_tensor(poses[:3], dtype=torch.float32))
        if float(nodes[:, scene.dynamic_mask[scene.node_object], 2].min()) <= p.clearance:
            continue  # the new orientation puts a corner in the ground: draw again
        start = replace(src, poses=poses)
        sim = Replay(start).rollout(params, dynamics, given=3)
        out.append(replace(start, poses=sim.astype(np.float32), name=f"synthetic-{len(out)}",
                           metadata={**src.metadata, "synthetic_from": src.name,
                                     "contact_params": params.to_json()}))
        bar.update(1)
    bar.close()
    return out
