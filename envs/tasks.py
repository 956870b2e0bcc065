"""The environments' tasks as pure, batched functions of whole states.

A task reads :data:`~fignet_gym.dynamics.STATE_SPEC` states (``mujoco.mj_getState(model, data, s,
STATE_SPEC)``: full physics and mocap poses, the layout ``Dynamics.rollout`` takes and returns), so
the same function scores one live ``MjData`` in ``env.step`` and ``B x T`` predicted states in a
planner's cost: planner cost and environment reward cannot drift apart. Every function takes
arrays with any leading batch shape ``[...]`` and broadcasts goals and actions against it.

* :class:`PushTask`: tip motion of an action sequence, reward terms, success, truncation.
* :class:`TossTask`: the release of an object, reward terms, objects in the target.
"""

from __future__ import annotations

from collections.abc import Sequence

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


class PushTask:
    """The push task of :class:`~fignet_gym.envs.push.PushEnv` on arrays of states.

    Args:
        model: the push scene (object body ``"object"``, mocap tip ``"tip"``).
        outline: ``float[K, 2]`` the object's outline in its frame (m).
        rest_z: the object's resting height (m).
        max_speed: tip speed (m/s) at ``|action| = 1`` per axis.
        step_time: seconds per environment step.
        tip_bound: the tip stays within ``[-tip_bound, tip_bound]`` on x and y (m).
        position_weight, orientation_weight, action_weight: reward weights (1/m, 1/rad, 1).
        success_weight: reward of a step that ends in success (0: no such term).
        success_position: position tolerance (m). success_yaw: heading tolerance (rad).
        workspace: truncation when the object is this far (m) from the workspace origin.
        max_lift: truncation when the object's height differs from ``rest_z`` by more (m).
        min_upright: truncation when the cosine of the object's tilt from upright is below this.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        outline: np.ndarray,
        rest_z: float,
        max_speed: float,
        step_time: float,
        tip_bound: float,
        position_weight: float,
        orientation_weight: float,
        action_weight: float,
        success_weight: float,
        success_position: float,
        success_yaw: float,
        workspace: float,
        max_lift: float,
        min_upright: float,
    ) -> None:
        self.layout = StateLayout(model)
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "object")
        tip_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "tip")
        self.qadr = int(model.jnt_qposadr[model.body_jntadr[body]])
        self.dadr = int(model.jnt_dofadr[model.body_jntadr[body]])
        self.tip_mocap = int(model.body_mocapid[tip_body])
        tip_geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "tip")
        self.tip_radius = float(model.geom_size[tip_geom, 0])
        self.outline = np.asarray(outline, dtype=np.float64)
        self.rest_z = float(rest_z)
        self.max_speed, self.step_time = float(max_speed), float(step_time)
        self.tip_bound = float(tip_bound)
        self.position_weight = float(position_weight)
        self.orientation_weight = float(orientation_weight)
        self.action_weight = float(action_weight)
        self.success_weight = float(success_weight)
        self.success_position, self.success_yaw = float(success_position), float(success_yaw)
        self.workspace, self.max_lift = float(workspace), float(max_lift)
        self.min_upright = float(min_upright)

    # ----------------------------------------------------------------- reading states
    def object_pose(self, states: np.ndarray) -> np.ndarray:
        """``float[..., nstate] -> float[..., 7]`` object position and quaternion (w, x, y, z)."""
        states = self.layout.check(states, "PushTask")
        i = self.layout.qpos + self.qadr
        return states[..., i : i + 7]

    def tip_xy(self, states: np.ndarray) -> np.ndarray:
        """``float[..., nstate] -> float[..., 2]`` the tip's position (its mocap target)."""
        states = self.layout.check(states, "PushTask")
        i = self.layout.mocap_pos + 3 * self.tip_mocap
        return states[..., i : i + 2]

    # ----------------------------------------------------------------- actions
    def tip_path(self, tip_xy: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Tip positions after each action: ``float[..., 2]``, ``float[..., T, 2] -> float[..., T,
        2]``. Actions are clipped to ``[-1, 1]``, each step moves the tip by ``action * max_speed *
        step_time`` and the tip is kept within ``tip_bound``."""
        step = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0) * (
            self.max_speed * self.step_time
        )
        out = np.empty(np.broadcast_shapes(step.shape, np.shape(tip_xy)[:-1] + (1, 2)))
        tip = np.asarray(tip_xy, dtype=np.float64)
        for t in range(step.shape[-2]):  # clipping at every step makes the path sequential
            tip = np.clip(tip + step[..., t, :], -self.tip_bound, self.tip_bound)
            out[..., t, :] = tip
        return out

    def controls(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """``Dynamics.rollout`` controls of action sequences from states.

        ``float[B or 1, nstate]``, ``float[B, T, 2] -> float[B, T, nmocap * 7]``: every mocap body
        held at its pose in the state, the tip moved along :meth:`tip_path`.
        """
        states = self.layout.check(states, "PushTask")
        actions = np.asarray(actions, dtype=np.float64)
        path = self.tip_path(self.tip_xy(states), actions)
        mocap = self.layout.mocap(states)
        control = np.repeat(mocap[:, None], actions.shape[-2], axis=1)
        control = np.broadcast_to(control, (*path.shape[:-1], control.shape[-1])).copy()
        control[..., 3 * self.tip_mocap : 3 * self.tip_mocap + 2] = path
        return control

    # ----------------------------------------------------------------- scoring
    def errors(self, states: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position (m) and absolute heading (rad) errors to ``goal float[..., 3]`` (x, y, yaw):
        two ``float[...]``."""
        pose = self.object_pose(states)
        goal = np.asarray(goal, dtype=np.float64)
        pos = np.linalg.norm(goal[..., :2] - pose[..., :2], axis=-1)
        yaw = np.abs(wrap_angle(goal[..., 2] - yaw_of(pose[..., 3:])))
        return pos, yaw

    def reward_terms(
        self, states: np.ndarray, goal: np.ndarray, actions: np.ndarray
    ) -> dict[str, np.ndarray]:
        """The environment's reward terms (their sum is its reward), each ``float[...]``.

        Args:
            states: ``float[..., nstate]`` states after the step. goal: ``float[..., 3]``.
            actions: ``float[..., 2]`` the actions of the step (clipped to ``[-1, 1]`` here, as
                the environment applies them).
        """
        pos, yaw = self.errors(states, goal)
        act = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
        terms = {
            "reward_position": -self.position_weight * pos,
            "reward_orientation": -self.orientation_weight * yaw,
            "reward_action": -self.action_weight * np.sum(act**2, axis=-1),
        }
        if self.success_weight:
            success = (pos < self.success_position) & (yaw < self.success_yaw)
            terms["reward_success"] = self.success_weight * success.astype(np.float64)
        return terms

    def reward(self, states: np.ndarray, goal: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Sum of :meth:`reward_terms`: ``float[...]`` (NaN for non-finite states)."""
        total = 0.0
        for term in self.reward_terms(states, goal, actions).values():  # the env's order
            total = total + term
        return np.asarray(total)

    def is_success(self, states: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """``bool[...]``: both errors within tolerance (termination)."""
        pos, yaw = self.errors(states, goal)
        return (pos < self.success_position) & (yaw < self.success_yaw)

    def out_of_workspace(self, states: np.ndarray, origin_xy: np.ndarray) -> np.ndarray:
        """``bool[...]``: the object is non-finite, farther than ``workspace`` from ``origin_xy
        float[..., 2]``, lifted or lowered by more than ``max_lift``, or tilted past
        ``min_upright`` (truncation)."""
        pose = self.object_pose(states)
        quat = pose[..., 3:]
        upright = 1.0 - 2.0 * (quat[..., 1] ** 2 + quat[..., 2] ** 2)  # cos of the tilt
        with np.errstate(invalid="ignore"):
            return (
                ~np.isfinite(pose).all(-1)
                | (np.linalg.norm(pose[..., :2] - origin_xy, axis=-1) > self.workspace)
                | (np.abs(pose[..., 2] - self.rest_z) > self.max_lift)
                | (upright < self.min_upright)
            )

    def pushing_point(self, states: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """``float[..., 2]``: where the tip touches the object's outline coming from the side
        opposite ``goal``, on the line through the object's origin (for a straight push)."""
        pose = self.object_pose(states)
        obj, yaw = pose[..., :2], yaw_of(pose[..., 3:])
        to_goal = np.asarray(goal, dtype=np.float64)[..., :2] - obj
        unit = to_goal / np.maximum(np.linalg.norm(to_goal, axis=-1, keepdims=True), 1e-9)
        c, s = np.cos(yaw), np.sin(yaw)
        back = np.stack([-(c * unit[..., 0] + s * unit[..., 1]), s * unit[..., 0] - c * unit[..., 1]], -1)
        reach = (back @ self.outline.T).max(-1) + self.tip_radius  # outline support along -unit
        return obj - reach[..., None] * unit

    def approach_distance(self, states: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """``float[...]``: distance (m) of the tip from :meth:`pushing_point`. A planner-side
        shaping term, not part of the reward: with a short horizon most candidates never touch
        the object and the reward alone cannot rank them."""
        return np.linalg.norm(self.tip_xy(states) - self.pushing_point(states, goal), axis=-1)


class TossTask:
    """The toss task of :class:`~fignet_gym.envs.toss.TossEnv` on arrays of states.

    Args:
        model: the toss scene (free bodies ``"obj0"``, ``"obj1"``, ...).
        radius: ``float[K]`` bounding-sphere radius of each object (m).
        release_position: ``float[3]`` where objects are released (m).
        release_velocity_low, release_velocity_high: ``float[2]`` horizontal release velocity at
            action -1 and +1 (m/s).
        target_radius: m. distance_weight: 1/m. in_target_weight: reward per object.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        radius: np.ndarray,
        release_position: Sequence[float],
        release_velocity_low: Sequence[float],
        release_velocity_high: Sequence[float],
        target_radius: float,
        distance_weight: float,
        in_target_weight: float,
    ) -> None:
        self.layout = StateLayout(model)
        k = len(radius)
        bodies = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"obj{i}") for i in range(k)]
        self.qadr = np.array([model.jnt_qposadr[model.body_jntadr[b]] for b in bodies])
        self.dadr = np.array([model.jnt_dofadr[model.body_jntadr[b]] for b in bodies])
        self.radius = np.asarray(radius, dtype=np.float64)
        self.release_position = np.asarray(release_position, dtype=np.float64)
        self.release_velocity_low = np.asarray(release_velocity_low, dtype=np.float64)
        self.release_velocity_high = np.asarray(release_velocity_high, dtype=np.float64)
        self.target_radius = float(target_radius)
        self.distance_weight = float(distance_weight)
        self.in_target_weight = float(in_target_weight)

    @property
    def num_objects(self) -> int:
        """``K``."""
        return len(self.radius)

    def positions(self, states: np.ndarray) -> np.ndarray:
        """``float[..., nstate] -> float[..., K, 3]`` object positions."""
        states = self.layout.check(states, "TossTask")
        return states[..., self.layout.qpos + self.qadr[:, None] + np.arange(3)]

    def release_velocity(self, actions: np.ndarray) -> np.ndarray:
        """``float[..., 2] -> float[..., 2]`` horizontal release velocity (m/s) of actions
        (clipped to ``[-1, 1]``)."""
        a = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
        lo, hi = self.release_velocity_low, self.release_velocity_high
        return lo + (a + 1) / 2 * (hi - lo)

    def release_point(self, states: np.ndarray, k: int) -> np.ndarray:
        """``float[..., nstate] -> float[..., 3]`` release position of object ``k``: above the
        released objects ``0..k-1`` under the release point (a chute over the pile)."""
        pos = self.positions(states)
        flat = pos.reshape(-1, *pos.shape[-2:])
        out = np.repeat(self.release_position[None], len(flat), axis=0)
        for b, p in enumerate(flat):
            for j in np.argsort(p[:k, 2]):  # bottom to top, so a pile is climbed in order
                if np.linalg.norm(p[j, :2] - out[b, :2]) < self.radius[j] + self.radius[k]:
                    out[b, 2] = max(out[b, 2], p[j, 2] + self.radius[j] + self.radius[k] + 0.05)
        return out.reshape(*pos.shape[:-2], 3)

    def release(
        self, states: np.ndarray, k: int, yaw: float, actions: np.ndarray
    ) -> np.ndarray:
        """States right after releasing object ``k`` with heading ``yaw`` (rad) and the velocity
        of ``actions``: ``float[..., nstate]``, ``float[..., 2] -> float[..., nstate]``."""
        states = self.layout.check(states, "TossTask")
        if not 0 <= k < self.num_objects:
            raise ValueError(f"TossTask: object {k} does not exist ({self.num_objects} objects)")
        vel = self.release_velocity(actions)
        shape = np.broadcast_shapes(states.shape[:-1], vel.shape[:-1])
        out = np.broadcast_to(states, (*shape, states.shape[-1])).copy()
        qa = self.layout.qpos + self.qadr[k]
        da = self.layout.qvel + self.dadr[k]
        out[..., qa : qa + 3] = self.release_point(out, k)
        out[..., qa + 3 : qa + 7] = (np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2))
        out[..., da : da + 6] = 0.0
        out[..., da : da + 2] = vel
        return out

    def in_target(self, states: np.ndarray, target: np.ndarray, count: int) -> np.ndarray:
        """``int[...]``: how many of objects ``0..count-1`` are within ``target_radius`` of
        ``target float[..., 2]``."""
        xy = self.positions(states)[..., :count, :2]
        target = np.asarray(target, dtype=np.float64)[..., None, :]
        return (np.linalg.norm(xy - target, axis=-1) <= self.target_radius).sum(-1)

    def reward_terms(
        self, states: np.ndarray, target: np.ndarray, k: int, in_before: np.ndarray | int
    ) -> dict[str, np.ndarray]:
        """Reward terms of the step that released object ``k`` (their sum is the reward).

        Args:
            states: ``float[..., nstate]`` after the settle. target: ``float[..., 2]``.
            k: the object released by the step. in_before: objects in the target before it.
        """
        dist = np.linalg.norm(self.positions(states)[..., k, :2] - target, axis=-1)
        n_in = self.in_target(states, target, k + 1)
        return {
            "reward_distance": -self.distance_weight * dist,
            "reward_in_target": self.in_target_weight * (n_in - np.asarray(in_before)).astype(float),
        }
