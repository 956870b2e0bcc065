"""Reading whole states: where ``qpos``, ``qvel`` and mocap poses sit in a
:data:`~fignet_gym.dynamics.STATE_SPEC` vector, and the headings the tasks score (numpy, batched
over any leading shape ``[...]``)."""

from __future__ import annotations

import mujoco
import numpy as np

from fignet_gym.dynamics import STATE_SPEC, state_offsets


def yaw_of(quat: np.ndarray) -> np.ndarray:
    """Heading (rad) about +z of unit quaternions (w, x, y, z): ``float[..., 4] -> float[...]``."""
    w, x, y, z = np.moveaxis(np.asarray(quat, dtype=np.float64), -1, 0)
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def wrap_angle(a: np.ndarray | float) -> np.ndarray:
    """Angle(s) wrapped to ``[-pi, pi)``."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


class StateLayout:
    """Where ``qpos``, ``qvel`` and the mocap poses sit in a :data:`STATE_SPEC` vector.

    Attributes:
        nstate: its length. qpos, qvel: offsets of ``qpos[0]`` and ``qvel[0]``.
        mocap_pos, mocap_quat: offsets of ``mocap_pos[0, 0]`` and ``mocap_quat[0, 0]``.
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        self.nstate = mujoco.mj_stateSize(model, STATE_SPEC)
        self.qpos = 1  # after time
        self.qvel = 1 + model.nq
        self.mocap_pos = state_offsets(model)[0]
        self.mocap_quat = self.mocap_pos + 3 * model.nmocap
        self.nmocap = model.nmocap

    def check(self, states: np.ndarray, owner: str) -> np.ndarray:
        """``states`` as ``float64[..., nstate]``; ``ValueError`` naming ``owner`` otherwise."""
        states = np.asarray(states, dtype=np.float64)
        if states.shape[-1:] != (self.nstate,):
            raise ValueError(
                f"{owner}: states must be float[..., {self.nstate}] (STATE_SPEC, from "
                f"mujoco.mj_getState or Dynamics.rollout), got shape {states.shape}"
            )
        return states

    def mocap(self, states: np.ndarray) -> np.ndarray:
        """``float[..., nmocap * 7]`` mocap positions then quaternions (the control layout)."""
        return states[..., self.mocap_pos : self.mocap_quat + 4 * self.nmocap]


def wrap_quarter(a: float | np.ndarray) -> np.ndarray:
    """Angle(s) modulo a quarter turn, in ``[-pi/4, pi/4)``."""
    q = np.pi / 2
    return (np.asarray(a) + q / 2) % q - q / 2


def resting_yaw(quat: np.ndarray) -> np.ndarray:
    """Heading (rad, in ``[-pi/4, pi/4)``) of a cube about the vertical, modulo its 90-degree
    symmetry: the angle of the body axis after the most vertical one. ``float[..., 4]`` (w, x, y,
    z) -> ``float[...]``."""
    w, x, y, z = np.moveaxis(np.asarray(quat, dtype=np.float64), -1, 0)
    n = w * w + x * x + y * y + z * z
    s = np.where(n > 0, 2.0 / np.where(n > 0, n, 1.0), 0.0)
    # columns of the rotation matrix: the body axes in world coordinates (MuJoCo's mju_quat2Mat)
    axes = np.stack([
        np.stack([1 - s * (y * y + z * z), s * (x * y + w * z), s * (x * z - w * y)], -1),
        np.stack([s * (x * y - w * z), 1 - s * (x * x + z * z), s * (y * z + w * x)], -1),
        np.stack([s * (x * z + w * y), s * (y * z - w * x), 1 - s * (x * x + y * y)], -1),
    ], -2)  # [..., axis, xyz]
    up = np.argmax(np.abs(axes[..., 2]), axis=-1)
    side = np.take_along_axis(axes, ((up + 1) % 3)[..., None, None], axis=-2)[..., 0, :]
    return wrap_quarter(np.arctan2(side[..., 1], side[..., 0]))
