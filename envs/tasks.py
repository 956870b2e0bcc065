"""The environments' tasks as pure, batched functions of whole states.

A task reads :data:`~fignet_gym.dynamics.STATE_SPEC` states (``mujoco.mj_getState(model, data, s,
STATE_SPEC)``: full physics and mocap poses, the layout ``Dynamics.rollout`` takes and returns), so
the same function scores one live ``MjData`` in ``env.step`` and ``B x T`` predicted states in a
planner's cost: planner cost and environment reward cannot drift apart. Every function takes
arrays with any leading batch shape ``[...]`` and broadcasts goals and actions against it.

* :class:`Task`: what a planner calls (:meth:`Task.plan_rollout`, :meth:`Task.plan_cost`); an
  environment exposes its task as ``env.task`` and the episode's parameters (goal, target, ...) as
  ``env.task_context()``, so planners know no environment. A user's environment plans the same
  way by exposing a :class:`Task` subclass.
* :class:`PushTask`: tip motion of an action sequence, reward terms, success, truncation.
* :class:`TossTask`: the release of an object, reward terms, objects in the target.
* :class:`CubeTossTask`: the release of the cube, reward terms of its resting pose.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from fignet_gym.dynamics import Dynamics
from fignet_gym.envs.poses import (  # noqa: F401  (re-exported: the tasks' vocabulary)
    StateLayout,
    resting_yaw,
    wrap_angle,
    wrap_quarter,
    yaw_of,
)


class Task:
    """The planning side of a task: candidates rolled out and scored from a whole state.

    ``context`` is the environment's ``task_context()``: its ``frame_skip`` and the episode's
    parameters (a goal, a target, ...), passed by keyword.

    Attributes:
        plan_horizon: decisions per plan (``None``: the planner's own horizon; 1: one-shot tasks).
    """

    plan_horizon: int | None = None

    def plan_rollout(self, dynamics: Dynamics, model: mujoco.MjModel, state: np.ndarray,
                     actions: np.ndarray, **context: object) -> np.ndarray:
        """Predicted states ``float64[B, T', nstate]`` of candidates ``float[B, T, A]`` (actions in
        the env's ``action_space``) from ``state float64[nstate]``, in one ``dynamics.rollout``
        call (NaN rows: diverged)."""
        raise NotImplementedError

    def plan_cost(self, state: np.ndarray, states: np.ndarray, actions: np.ndarray,
                  shaping: float = 0.0, terminal: float = 0.0, **context: object) -> np.ndarray:
        """``float64[B]`` cost of predicted ``states float64[B, T', nstate]`` from ``state``:
        minus the reward the env would return, ``terminal`` more times the last step's, plus
        ``shaping`` times a task-specific shaping term (non-finite where the states are)."""
        raise NotImplementedError


class PushTask(Task):
    """The push task of :class:`~fignet_gym.envs.push.PushEnv` on arrays of states.

    Args:
        model: the push scene (a free body and a mocap pusher, named below).
        outline: ``float[K, 2]`` the object's outline in its frame (m).
        rest_z: the object's resting height (m).
        max_speed: tip speed (m/s) at ``|action| = 1`` per axis.
        dt: seconds per environment step.
        tip_bound: the tip stays within ``[-tip_bound, tip_bound]`` on x and y (m).
        position_weight, orientation_weight, action_weight: reward weights (1/m, 1/rad, 1).
        success_weight: reward of a step that ends in success (0: no such term).
        success_position: position tolerance (m). success_yaw: heading tolerance (rad).
        workspace: truncation when the object is this far (m) from the workspace origin.
        max_lift: truncation when the object's height differs from ``rest_z`` by more (m).
        min_upright: truncation when the cosine of the object's tilt from upright is below this.
        object_body, tip_body: the names of the pushed free body and of the pusher's mocap body
            (the pusher's first geom gives its radius).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        outline: np.ndarray,
        rest_z: float,
        max_speed: float,
        dt: float,
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
        object_body: str = "object",
        tip_body: str = "tip",
    ) -> None:
        self.layout = StateLayout(model)
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, object_body)
        tip = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, tip_body)
        self.qadr = int(model.jnt_qposadr[model.body_jntadr[body]])
        self.dadr = int(model.jnt_dofadr[model.body_jntadr[body]])
        self.tip_mocap = int(model.body_mocapid[tip])
        self.tip_radius = float(model.geom_size[model.body_geomadr[tip], 0])
        self.outline = np.asarray(outline, dtype=np.float64)
        self.rest_z = float(rest_z)
        self.max_speed, self.dt = float(max_speed), float(dt)
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
        dt`` and the tip is kept within ``tip_bound``."""
        step = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0) * (
            self.max_speed * self.dt
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
            success = self.is_success(states, goal)
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
        return self.success_of(*self.errors(states, goal))

    def measures(self, states: np.ndarray, goal: np.ndarray) -> dict[str, np.ndarray]:
        """What the env reports in ``info`` besides the reward terms: ``position_error`` (m) and
        ``orientation_error`` (rad) to ``goal float[..., 3]``, each ``float[...]``."""
        pos, yaw = self.errors(states, goal)
        return {"position_error": pos, "orientation_error": yaw}

    def success_of(self, pos: np.ndarray, yaw: np.ndarray) -> np.ndarray:
        """``bool[...]`` of the errors ``float[...]`` of :meth:`errors`: both within tolerance."""
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


    # ----------------------------------------------------------------- planning
    def plan_rollout(self, dynamics: Dynamics, model: mujoco.MjModel, state: np.ndarray,
                     actions: np.ndarray, **context: object) -> np.ndarray:
        """:meth:`Task.plan_rollout`: ``T`` tip steps of ``frame_skip`` timesteps each."""
        control = self.controls(state[None], actions)
        return dynamics.rollout(model, state[None], control, frame_skip=int(context["frame_skip"]))

    def plan_cost(self, state: np.ndarray, states: np.ndarray, actions: np.ndarray,
                  shaping: float = 0.0, terminal: float = 0.0, **context: object) -> np.ndarray:
        """:meth:`Task.plan_cost` towards ``goal``; shaping: :meth:`approach_distance`."""
        goal = np.asarray(context["goal"])
        reward = self.reward(states, goal, actions)
        cost = -reward.sum(axis=1) - terminal * reward[:, -1]
        if shaping:
            cost = cost + shaping * self.approach_distance(states[:, -1], goal)
        return cost


class TossTask(Task):
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


    # ----------------------------------------------------------------- planning
    plan_horizon = 1

    def plan_rollout(self, dynamics: Dynamics, model: mujoco.MjModel, state: np.ndarray,
                     actions: np.ndarray, **context: object) -> np.ndarray:
        """:meth:`Task.plan_rollout`: the release of object ``released`` by each candidate's only
        action, then the whole settle (``frame_skip`` timesteps); the settled state ``T' = 1``."""
        k = int(context["released"])
        if k >= self.num_objects:
            raise RuntimeError("every object was tossed: reset the environment")
        start = self.release(state[None], k, float(context["release_yaw"]), actions[:, 0])
        skip = int(context["frame_skip"])
        return dynamics.rollout(model, start, np.zeros((len(start), 1, 0)), nstep=skip,
                                frame_skip=skip)

    def plan_cost(self, state: np.ndarray, states: np.ndarray, actions: np.ndarray,
                  shaping: float = 0.0, terminal: float = 0.0, **context: object) -> np.ndarray:
        """:meth:`Task.plan_cost`: minus the reward of the release step (no shaping)."""
        k, target = int(context["released"]), np.asarray(context["target"])
        before = self.in_target(state, target, k)
        terms = self.reward_terms(states[:, -1], target, k, before)
        return -(terms["reward_distance"] + terms["reward_in_target"])


class CubeTossTask(Task):
    """The cube toss of :class:`~fignet_gym.envs.cube_toss.CubeTossEnv` on arrays of states.

    Args:
        model: the cube scene (one free body, the cube).
        speed_range: horizontal release speed (m/s) at action 1 = -1 and +1.
        vertical_range: vertical release velocity (m/s) at action 2 = -1 and +1.
        spin_range: ``float[3]`` world angular velocity (rad/s) at actions 3:6 = +1.
        target_radius: m. yaw_tolerance: rad. distance_weight: 1/m. yaw_weight: 1/rad.
        success_bonus: reward of a success.
    """

    plan_horizon = 1

    def __init__(self, model: mujoco.MjModel, speed_range: Sequence[float],
                 vertical_range: Sequence[float], spin_range: Sequence[float], target_radius: float,
                 yaw_tolerance: float, distance_weight: float, yaw_weight: float,
                 success_bonus: float) -> None:
        self.layout = StateLayout(model)
        self.qadr, self.dadr = int(model.jnt_qposadr[0]), int(model.jnt_dofadr[0])
        self.speed_range = np.asarray(speed_range, dtype=np.float64)
        self.vertical_range = np.asarray(vertical_range, dtype=np.float64)
        self.spin_range = np.asarray(spin_range, dtype=np.float64)
        self.target_radius, self.yaw_tolerance = float(target_radius), float(yaw_tolerance)
        self.distance_weight, self.yaw_weight = float(distance_weight), float(yaw_weight)
        self.success_bonus = float(success_bonus)

    def pose(self, states: np.ndarray) -> np.ndarray:
        """``float[..., nstate] -> float[..., 7]`` the cube's position and quaternion."""
        states = self.layout.check(states, "CubeTossTask")
        i = self.layout.qpos + self.qadr
        return states[..., i : i + 7]

    def release_velocity(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``float[..., 6]`` -> world linear and angular velocity, two ``float[..., 3]`` (m/s,
        rad/s): heading, speed, vertical velocity and spin, each linear in its action."""
        u = (np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0) + 1) / 2  # [0, 1]
        heading = -np.pi + 2 * np.pi * u[..., 0]
        speed = self.speed_range[0] + u[..., 1] * (self.speed_range[1] - self.speed_range[0])
        vz = self.vertical_range[0] + u[..., 2] * (self.vertical_range[1] - self.vertical_range[0])
        lin = np.stack([speed * np.cos(heading), speed * np.sin(heading), vz], -1)
        return lin, (2 * u[..., 3:] - 1) * self.spin_range

    def release(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """States with the cube given the velocity of ``actions``: ``float[..., nstate]``,
        ``float[..., 6]`` -> ``float[..., nstate]`` (a free joint's angular velocity is in its
        body frame: the world spin rotated by the inverse of the cube's quaternion)."""
        states = self.layout.check(states, "CubeTossTask")
        lin, ang = self.release_velocity(actions)
        shape = np.broadcast_shapes(states.shape[:-1], lin.shape[:-1])
        out = np.broadcast_to(states, (*shape, states.shape[-1])).copy()
        q = self.pose(out)[..., 3:]
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)
        qv, w = -q[..., 1:], q[..., :1]  # the conjugate: world -> body
        t = 2.0 * np.cross(qv, ang)
        ang_body = ang + w * t + np.cross(qv, t)
        da = self.layout.qvel + self.dadr
        out[..., da : da + 3] = lin
        out[..., da + 3 : da + 6] = ang_body
        return out

    def errors(self, states: np.ndarray, target: np.ndarray, target_yaw: float | np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """xy distance (m) to ``target float[..., 2]`` and heading error modulo 90 degrees (rad,
        signed) to ``target_yaw``: two ``float[...]``."""
        pose = self.pose(states)
        dist = np.linalg.norm(pose[..., :2] - np.asarray(target, dtype=np.float64), axis=-1)
        return dist, wrap_quarter(resting_yaw(pose[..., 3:]) - target_yaw)

    def reward_terms(self, states: np.ndarray, target: np.ndarray, target_yaw: float | np.ndarray
                     ) -> dict[str, np.ndarray]:
        """The env's reward terms of resting ``states float[..., nstate]`` (their sum is its
        reward), each ``float[...]``."""
        dist, psi = self.errors(states, target, target_yaw)
        return {"reward_distance": -self.distance_weight * dist,
                "reward_yaw": -self.yaw_weight * np.abs(psi),
                "reward_success": self.success_bonus * self.is_success(states, target, target_yaw)}

    def is_success(self, states: np.ndarray, target: np.ndarray, target_yaw: float | np.ndarray
                   ) -> np.ndarray:
        """``float[...]`` 1 where the cube rests within ``target_radius`` and ``yaw_tolerance``."""
        dist, psi = self.errors(states, target, target_yaw)
        return ((dist <= self.target_radius) & (np.abs(psi) <= self.yaw_tolerance)).astype(float)

    def plan_rollout(self, dynamics: Dynamics, model: mujoco.MjModel, state: np.ndarray,
                     actions: np.ndarray, **context: object) -> np.ndarray:
        """:meth:`Task.plan_rollout`: the toss of each candidate's only action, settled for the
        env's ``frame_skip`` timesteps; the resting state (``T' = 1``)."""
        skip = int(context["frame_skip"])
        start = self.release(state[None], actions[:, 0])
        return dynamics.rollout(model, start, np.zeros((len(start), 1, 0)), nstep=skip,
                                frame_skip=skip)

    def plan_cost(self, state: np.ndarray, states: np.ndarray, actions: np.ndarray,
                  shaping: float = 0.0, terminal: float = 0.0, **context: object) -> np.ndarray:
        """:meth:`Task.plan_cost`: minus the env's reward of the resting state (no shaping)."""
        terms = self.reward_terms(states[:, -1], np.asarray(context["target"]),
                                  float(context["target_yaw"]))
        return -sum(terms.values())
