"""Training windows: the data's motion scale, contact-weighted window sampling, and the
augmentations (rotation about the vertical, mirroring in ``y = 0``) applied to each window."""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

from fignet_gym.data.format import Trajectory
from fignet_gym.simulator.geometry import quat_mul
from fignet_gym.simulator.scene import Scene

#: Node accelerations (m/step^2) above this count as motion in the data's motion scale: float32
#: finite differences of poses at rest are below it.
MOVING_ACCELERATION = 1e-7
#: A dynamic object that moves more than this (m) between poses is moving in a window.
MOVING_DISPLACEMENT = 1e-6
#: Largest sampling weight of a moving window, in units of the median moving window's acceleration
#: (plus 1): an impact is favoured tenfold, not without bound.
ACCEL_CAP = 10.0
#: Floor of the reference acceleration (data entirely at rest up to rounding).
_TINY_ACCELERATION = 1e-12
#: Relative tolerance (of an object's size) of the mirror-symmetry check.
MIRROR_TOLERANCE = 1e-4


def node_accelerations(traj: Trajectory, scene: Scene) -> Tensor:
    """Per-step finite-difference accelerations of dynamic nodes, ``float[T-2, N_dyn, 3]``."""
    poses = torch.as_tensor(traj.poses, dtype=torch.float32)
    x = scene.node_positions(poses)[:, scene.dynamic_mask[scene.node_object]]
    return x[2:] - 2 * x[1:-1] + x[:-2]


def median_node_acceleration(trajs: list[Trajectory], scenes: list[Scene]) -> float:
    """Median acceleration norm (m/step^2) of moving dynamic nodes: the data's motion scale."""
    norms = []
    for traj, scene in zip(trajs, scenes, strict=True):
        a = node_accelerations(traj, scene).norm(dim=-1).flatten()
        norms.append(a[a > MOVING_ACCELERATION])
    allnorms = torch.cat(norms)
    if allnorms.numel() == 0:
        raise ValueError("trajectories have no motion: no acceleration scale to measure")
    return float(allnorms.median())


class WindowSampler:
    """Draws training windows ``float[H + 1, O, 7]`` weighted towards contact events, reproducibly.

    A window's weight is ``1 + min(a / a_ref, accel_cap)``, where ``a`` is the window's largest
    dynamic-node acceleration and ``a_ref`` the median over moving windows. Contact onsets (a pusher
    starting an object, an impact) are a few windows per trajectory but carry most of what a model
    must learn. A window in which no dynamic object moves weighs ``still_weight``, or
    ``near_weight`` if motion happens within ``near`` poses before or after it. Without the
    approach windows a model learns that a pusher within the collision radius always moves the
    object, and starts it too early; without the settling windows, that a slowly sliding object
    keeps sliding (a rollout's small excess velocity after a glancing push then never dies out).
    """

    def __init__(self, trajs: list[Trajectory], scenes: list[Scene], history: int,
                 still_weight: float, seed: int, accel_cap: float = ACCEL_CAP, unroll: int = 0,
                 near: int = 0, near_weight: float = 1.0, targets: int = 1) -> None:
        self.trajs, self.scenes, self.span = trajs, scenes, history + 2 + unroll
        if not 1 <= targets <= unroll + 1:
            raise ValueError(f"targets must be in 1..{unroll + 1}, got {targets}")
        index, weight, accel = [], [], []
        for i, (traj, scene) in enumerate(zip(trajs, scenes, strict=True)):
            poses = traj.poses
            dyn = scene.dynamic_mask.numpy()
            moved = np.abs(np.diff(poses[:, dyn, :3], axis=0)).max(axis=(1, 2)) > MOVING_DISPLACEMENT
            acc = node_accelerations(traj, scene).norm(dim=-1).amax(dim=-1).numpy()  # [T-2]
            for t in range(poses.shape[0] - self.span + 1):
                index.append((i, t))
                # The acceleration of target pose p is acc[p - 2]; the last target is t + span - 1.
                end_acc = t + self.span - 2
                accel.append(float(acc[end_acc - targets:end_acc].max()))
                end = t + self.span - 1
                if moved[t:end].any():
                    weight.append(-1.0)
                else:
                    close = moved[end:end + near].any() or moved[max(t - near, 0):t].any()
                    weight.append(near_weight if close else still_weight)
        if not index:
            raise ValueError(f"no trajectory has the {self.span} poses a training window needs")
        self.index = np.asarray(index)
        w, a = np.asarray(weight), np.asarray(accel)
        moving = w < 0
        a_ref = float(np.median(a[moving])) if moving.any() else 1.0
        w[moving] = 1.0 + np.minimum(a[moving] / max(a_ref, _TINY_ACCELERATION), accel_cap)
        self.prob = w / w.sum()
        self.rng = np.random.default_rng(seed)

    def sample(self, count: int) -> list[tuple[int, int]]:
        """``count`` (trajectory, start) pairs."""
        picks = self.rng.choice(len(self.index), size=count, p=self.prob)
        return [tuple(map(int, self.index[p])) for p in picks]


def rotate_about_z(poses: Tensor, angle: float) -> Tensor:
    """Rotate whole-scene poses ``float[..., O, 7]`` about the world z axis through the origin."""
    c, s = math.cos(angle), math.sin(angle)
    rot = poses.new_tensor([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    qz = poses.new_tensor([math.cos(angle / 2), 0, 0, math.sin(angle / 2)])
    return torch.cat((poses[..., :3] @ rot.T, quat_mul(qz.expand_as(poses[..., 3:]), poses[..., 3:])), -1)


def mirror_y(poses: Tensor) -> Tensor:
    """Reflect whole-scene poses ``float[..., O, 7]`` in the world plane ``y = 0``.

    With ``M = diag(1, -1, 1)`` a pose ``(p, R)`` becomes ``(M p, M R M)``, i.e. quaternion
    ``(w, x, y, z) -> (w, -x, y, -z)``. For an object symmetric under its body-frame ``M``
    (:func:`mirror_asymmetric`), the posed mesh is the mirror image of the original one, so a
    reflected trajectory is the mirror image of a physical one.
    """
    sign = poses.new_tensor([1.0, -1.0, 1.0, 1.0, -1.0, 1.0, -1.0])
    return poses * sign


def mirror_asymmetric(scene: Scene, tol: float = MIRROR_TOLERANCE) -> list[str]:
    """Names of the objects of ``scene`` whose body-frame mesh or centre of mass is not symmetric
    under ``y -> -y`` (within ``tol`` times the object's size): :func:`mirror_y` would turn them
    into shapes that do not exist."""
    bad = []
    for o, name in enumerate(scene.object_names):
        v = scene.ref_vertices[scene.node_object == o].double()
        size = float((v.amax(0) - v.amin(0)).norm()) or 1.0
        flipped = v * v.new_tensor([1.0, -1.0, 1.0])
        gap = torch.cdist(flipped, v).amin(dim=1).max()  # Scene refuses empty meshes
        if float(gap) > tol * size or abs(float(scene.object_com[o, 1])) > tol * size:
            bad.append(name)
    return bad
