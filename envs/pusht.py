"""``fignet_gym/PushT-v0``: push a T block to a goal pose, scored by its overlap with the goal.

The Push-T task (Chi et al. 2023, Diffusion Policy; LeRobot's ``gym-pusht``) on MuJoCo physics:
the scene of :mod:`fignet_gym.mjcf.pusht` (a 10 x 10 cm T of two convex pieces, isotropic
friction, a cylindrical tip), built as a user's scene is (:class:`ScenePushEnv`: the generic
scene checks, the convex hull as the outline the tip starts behind), with a task that adds
gym-pusht's **coverage**: the fraction of the goal T's area the T covers. ``dynamics="fignet"``
loads the shipped ``pusht`` model, trained on ``fignet-gym generate scene`` pushes of this scene
(its card: ``fignet_gym/pretrained/pusht.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fignet_gym.envs.base import wrap_angle, yaw_of
from fignet_gym.envs.scene_push import ScenePushEnv
from fignet_gym.envs.tasks import PushTask
from fignet_gym.envs.vector import SingleEnvVectorEnv
from fignet_gym.mjcf.pusht import pusht_rectangles, pusht_scene_xml


def _polygon_area(poly: np.ndarray) -> np.ndarray:
    """``float[..., M, 2] -> float[...]`` signed shoelace area (repeated vertices add nothing)."""
    x, y = poly[..., 0], poly[..., 1]
    return 0.5 * (x * np.roll(y, -1, -1) - y * np.roll(x, -1, -1)).sum(-1)


def convex_overlap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact area of the intersection of convex counter-clockwise polygons.

    ``float[..., M, 2]``, ``float[..., K, 2] -> float[...]``: Sutherland-Hodgman clipping of
    ``a`` by each edge of ``b``, batched with a fixed number of vertex slots. A stage keeps a
    vertex inside the edge and adds the crossing of an edge that crosses it; unused slots repeat
    the last used vertex, which leaves the shoelace area unchanged.
    """
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    batch = np.broadcast_shapes(a.shape[:-2], b.shape[:-2])
    poly = np.broadcast_to(a, batch + a.shape[-2:])
    empty = np.zeros(batch, dtype=bool)
    for k in range(b.shape[-2]):
        p0, p1 = b[..., k, None, :], b[..., (k + 1) % b.shape[-2], None, :]
        edge = p1 - p0
        side = edge[..., 0] * (poly[..., 1] - p0[..., 1]) - edge[..., 1] * (poly[..., 0] - p0[..., 0])
        nxt, side_n = np.roll(poly, -1, -2), np.roll(side, -1, -1)
        cross = side * side_n < 0
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.where(cross, side / np.where(cross, side - side_n, 1.0), 0.0)
        hit = poly + t[..., None] * (nxt - poly)
        slots = np.stack([poly, hit], -2).reshape(*hit.shape[:-2], -1, 2)
        used = np.stack(np.broadcast_arrays(side >= 0, cross), -1).reshape(*cross.shape[:-1], -1)
        empty = empty | ~used.any(-1)
        # Each unused slot takes the last used one before it (cyclically: the final one first).
        idx = np.where(used, np.arange(used.shape[-1]), -1)
        last = idx.max(-1, keepdims=True)
        idx = np.maximum.accumulate(idx, axis=-1)
        idx = np.where(idx < 0, last, idx).clip(0)
        poly = np.take_along_axis(slots, idx[..., None].repeat(2, -1), axis=-2)
    return np.where(empty, 0.0, _polygon_area(poly).clip(0.0))


class PushTTask(PushTask):
    """:class:`PushTask` scored by coverage as well as by pose error.

    Args (beyond :class:`PushTask`'s):
        pieces: ``float[R, K, 2]`` the object's footprint as convex counter-clockwise polygons
            in its body frame (m), disjoint but for their edges.
        success_coverage: success when the coverage reaches this (gym-pusht: 0.95).
        coverage_weight: reward weight of the coverage (``reward_coverage``).
    """

    def __init__(self, *args: Any, pieces: np.ndarray, success_coverage: float,
                 coverage_weight: float, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.pieces = np.asarray(pieces, dtype=np.float64)
        self.area = float(_polygon_area(self.pieces).sum())
        self.success_coverage, self.coverage_weight = float(success_coverage), float(coverage_weight)

    def coverage(self, states: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """``float[...]``: the fraction of the goal's footprint that the object covers, the
        object at its pose in ``states float[..., nstate]`` and the goal at ``goal float[..., 3]``
        (x, y, yaw): exact, as gym-pusht's polygon intersection (NaN for non-finite states)."""
        pose = self.object_pose(states)
        goal = np.asarray(goal, dtype=np.float64)
        # The object's pieces in the goal's frame: float[..., R, 4, 2].
        rel = wrap_angle(yaw_of(pose[..., 3:]) - goal[..., 2])
        c, s = np.cos(goal[..., 2]), np.sin(goal[..., 2])
        d = pose[..., :2] - goal[..., :2]
        shift = np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], -1)
        cr, sr = np.cos(rel)[..., None, None], np.sin(rel)[..., None, None]
        px, py = self.pieces[..., 0], self.pieces[..., 1]
        placed = np.stack([cr * px - sr * py, sr * px + cr * py], -1) + shift[..., None, None, :]
        # The pieces are disjoint: the overlap is the sum over pairs of convex intersections.
        pairs = convex_overlap(placed[..., :, None, :, :], self.pieces[None])  # [..., R, R]
        out = pairs.sum((-2, -1)) / self.area
        return np.where(np.isfinite(pose).all(-1), out, np.nan)

    def is_success(self, states: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """``bool[...]``: the coverage reaches ``success_coverage`` (termination)."""
        with np.errstate(invalid="ignore"):
            return self.coverage(states, goal) >= self.success_coverage

    def measures(self, states: np.ndarray, goal: np.ndarray) -> dict[str, np.ndarray]:
        """:meth:`PushTask.measures` and ``coverage`` (a fraction), each ``float[...]``."""
        return {**super().measures(states, goal), "coverage": self.coverage(states, goal)}

    def reward_terms(self, states: np.ndarray, goal: np.ndarray, actions: np.ndarray
                     ) -> dict[str, np.ndarray]:
        """:meth:`PushTask.reward_terms` and ``reward_coverage``: ``coverage_weight`` times the
        coverage, each ``float[...]``."""
        terms = super().reward_terms(states, goal, actions)
        terms["reward_coverage"] = self.coverage_weight * self.coverage(states, goal)
        return terms


class PushTEnv(ScenePushEnv):
    """Push the T block to a goal pose with a cylindrical tip (module docstring).

    Observations, actions, the episode's start (tip behind the T, seen from the goal) and the
    pose terms of the reward are :class:`~fignet_gym.envs.push.PushEnv`'s; ``env.task`` is a
    :class:`PushTTask`. ``info`` adds ``coverage`` and ``reward_coverage``.

    ## Arguments (beyond ``PushEnv``'s; ``PushT-v0`` registers Push-v2's task arguments)

    | argument | default | meaning |
    |---|---|---|
    | goal_pose | ``None`` | fixed goal ``(x, y, yaw)`` (m, rad); ``None``: drawn around the T |
    | success_coverage | ``0.95`` | success at this coverage (gym-pusht's threshold) |
    | coverage_weight | ``1.0`` | reward weight of the coverage |

    With a fixed goal the episode's start is drawn as for a drawn goal, then the whole scene
    (T, tip, goal) is turned and shifted so the goal lands on ``goal_pose``: the physics is
    isotropic, so the task is the same at every goal.

    ## Version History

    * v0: the initial version.
    """

    _default_checkpoint = "pusht"

    def __init__(self, dynamics: Any = "mujoco", checkpoint: Any = None,
                 goal_pose: Sequence[float] | None = None, success_coverage: float = 0.95,
                 coverage_weight: float = 1.0, **kwargs: Any) -> None:
        if goal_pose is not None:
            goal_pose = np.asarray(goal_pose, dtype=np.float64)
            if goal_pose.shape != (3,) or not np.isfinite(goal_pose).all():
                raise ValueError(f"PushTEnv: goal_pose must be three finite numbers (x, y, yaw), "
                                 f"got {goal_pose.tolist()}")
        if not 0.0 < success_coverage <= 1.0:
            raise ValueError(f"PushTEnv: success_coverage must be in (0, 1], got {success_coverage}")
        self.goal_pose = goal_pose
        self._coverage_args = {"pieces": pusht_rectangles(), "success_coverage": success_coverage,
                               "coverage_weight": float(coverage_weight)}
        super().__init__("PushT-v0", "object", "tip", dynamics=dynamics, checkpoint=checkpoint,
                         camera="top", **kwargs)

    task_class = PushTTask

    def _task_arguments(self) -> dict[str, Any]:
        return dict(self._coverage_args)

    def _scene_config(self) -> Any:
        # deferred: the data layer (h5py, trimesh) loads only when a scene env is made
        from fignet_gym.data.scene_generator import SceneConfig

        return SceneConfig(mjcf=pusht_scene_xml(), target="object", source="PushT-v0")

    def _reset_task(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        super()._reset_task(rng, options)
        if self.goal_pose is None:
            return
        # A rigid motion of the whole start (T, tip, goal) that puts the goal on goal_pose.
        turn = float(self.goal_pose[2] - self.goal[2])
        c, s = np.cos(turn), np.sin(turn)
        rot = np.array([[c, -s], [s, c]])

        def move(xy: np.ndarray) -> np.ndarray:
            return rot @ (np.asarray(xy) - self.goal[:2]) + self.goal_pose[:2]

        q = self.data.qpos[self._qadr : self._qadr + 7]
        q[:2] = move(q[:2])
        yaw = yaw_of(q[3:]) + turn
        q[3:] = (np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2))
        tip = self.data.mocap_pos[self._tip_mocap]
        tip[:2] = move(tip[:2])
        self.workspace_origin = q[:2].copy()
        self.goal = np.array([*self.goal_pose[:2], wrap_angle(self.goal_pose[2])])


class PushTVectorEnv(SingleEnvVectorEnv):
    """``num_envs`` :class:`PushTEnv` stepped by one batched dynamics call."""

    env_class = PushTEnv


__all__ = ["PushTEnv", "PushTTask", "PushTVectorEnv", "convex_overlap"]
