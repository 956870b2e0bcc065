"""The push task seen from the object: observation and action in the object's own frame.

Push-v1 draws the object's heading uniformly in ``[-pi, pi)`` and its actions move the tip along
world axes, so a policy on the env's observation has to learn the same push once per heading:
the action that pushes a face is the face's direction rotated by the heading, a product of the
inputs an MLP only approximates. In the object frame the task is the same at every heading and
position (the dynamics do not depend on them on a flat floor), so every episode teaches the one
mapping: the policy sees only quantities relative to the object, in its frame, and its action is
the tip velocity along the object's axes, rotated into the world before the env clips it.

* :func:`object_frame_observation`: ``float[N, 19]`` Push observations -> ``float32[N, 14]``.
* :func:`object_to_world`: the policy's actions in the object frame -> the env's actions.
"""

from __future__ import annotations

import numpy as np

from fignet_gym.envs.tasks import wrap_angle

#: Push observation slices this module reads (``PushEnv.observation_layout``).
OBJECT_YAW, TIP_XY, GOAL_REL_XY, GOAL_REL_YAW = slice(2, 4), slice(4, 6), slice(10, 12), slice(12, 14)
TIP_REL_XY, OBJECT_VELOCITY, OBJECT_YAW_RATE = slice(14, 16), slice(16, 18), slice(18, 19)
#: Values of :func:`object_frame_observation`.
N_OBJECT_FRAME = 14


def _rotate(vec: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Vectors ``float[N, 2]`` rotated by the angles of ``(c, s)`` ``float[N]`` (counter-clockwise)."""
    return np.stack([c * vec[:, 0] - s * vec[:, 1], s * vec[:, 0] + c * vec[:, 1]], -1)


def object_frame_observation(obs: np.ndarray, outline: np.ndarray, tip_radius: float) -> np.ndarray:
    """``float[N, 19]`` Push observations -> ``float32[N, 14]``, every value in the object frame:

    | index | meaning |
    |---|---|
    | 0:2 | goal minus object |
    | 2:4 | cos, sin of goal heading minus object heading |
    | 4:6 | tip minus object |
    | 6:8 | object linear velocity (m/s) |
    | 8 | object yaw rate (rad/s) |
    | 9 | heading error ``wrap(goal_yaw - object_yaw)`` (rad) |
    | 10:12 | pushing point (behind the object, seen from the goal) minus tip |
    | 12:14 | goal minus tip |

    Invariant to the object's world position and heading (a rigid motion of the whole scene).
    """
    obs = np.asarray(obs, dtype=np.float64)
    c, s = obs[:, OBJECT_YAW][:, 0], obs[:, OBJECT_YAW][:, 1]
    goal, tip = obs[:, GOAL_REL_XY], obs[:, TIP_REL_XY]
    dyaw = np.arctan2(obs[:, GOAL_REL_YAW][:, 1], obs[:, GOAL_REL_YAW][:, 0])
    vel = _rotate(obs[:, OBJECT_VELOCITY], c, -s)  # world -> object frame
    unit = goal / np.maximum(np.linalg.norm(goal, axis=-1, keepdims=True), 1e-9)
    reach = (-unit @ np.asarray(outline, dtype=np.float64).T).max(-1) + tip_radius
    pushing_point = -reach[:, None] * unit
    out = np.concatenate([goal, obs[:, GOAL_REL_YAW], tip, vel, obs[:, OBJECT_YAW_RATE],
                          wrap_angle(dyaw)[:, None], pushing_point - tip, goal - tip], axis=-1)
    return out.astype(np.float32)


def object_to_world(actions: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """Tip velocities ``float[N, 2]`` along the object's axes -> the env's world-frame actions
    ``float32[N, 2]``, for the headings of raw Push observations ``float[N, 19]``.

    A rotated action can leave the env's box ``[-1, 1]^2`` (by up to sqrt 2); it is scaled back
    into it as a whole, so its direction is kept (the env would clip each axis and turn it).
    """
    obs = np.asarray(obs, dtype=np.float64)
    world = _rotate(np.asarray(actions, dtype=np.float64), obs[:, OBJECT_YAW][:, 0], obs[:, OBJECT_YAW][:, 1])
    scale = np.maximum(np.abs(world).max(-1, keepdims=True), 1.0)
    return (world / scale).astype(np.float32)
