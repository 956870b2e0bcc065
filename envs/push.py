"""``fignet_gym/Push-v0``: planar pushing in the MIT Pushing setting."""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode

from fignet_gym.dynamics import Dynamics
from fignet_gym.envs.base import (
    MjDynamicsEnv,
    check_arguments,
    layout,
    layout_size,
    wrap_angle,
    yaw_of,
)
from fignet_gym.envs.vector import BatchedVectorEnv
from fignet_gym.mjcf import push_object, push_scene_xml


class PushEnv(MjDynamicsEnv):
    """Push an MIT Pushing object to a goal pose (x, y, yaw) with a cylindrical tip.

    One object of the MIT Pushing dataset (13 mm thick prism, the dataset's mass and inertia) lies
    on a floor; a vertical cylinder of radius 4.75 mm (a mocap body: kinematic for the learned
    model) moves in the plane at a bounded speed. Each episode draws the object's heading, a goal
    pose near the object and a start position of the tip next to it. One environment step is one
    learned step: ``frame_skip`` MuJoCo timesteps of 2 ms (0.02 s by default, the training data's).

    ## Action space

    ``Box(-1, 1, (2,), float32)``; out-of-range values are clipped, NaN/inf raise ``ValueError``.

    | index | action | unit |
    |---|---|---|
    | 0:1 | tip velocity along world x | ``max_speed`` m/s |
    | 1:2 | tip velocity along world y | ``max_speed`` m/s |

    ## Observation space

    ``Box(-inf, inf, (19,), float32)``; positions in metres; "object frame" is the object's body
    frame.

    | index | name | meaning |
    |---|---|---|
    | 0:2 | object_xy | object position (world) |
    | 2:4 | object_yaw | cos, sin of the object's heading |
    | 4:6 | tip_xy | tip position (world) |
    | 6:8 | goal_xy | goal position (world) |
    | 8:10 | goal_yaw | cos, sin of the goal heading |
    | 10:12 | goal_rel_xy | goal position minus object position, in the object frame |
    | 12:14 | goal_rel_yaw | cos, sin of goal heading minus object heading |
    | 14:16 | tip_rel_xy | tip position minus object position, in the object frame |
    | 16:18 | object_velocity_xy | object linear velocity (world, m/s) |
    | 18:19 | object_yaw_rate | object angular velocity about z (rad/s) |

    ## Reward

    The reward is the sum of these terms, each returned in ``info``:

    | info key | term |
    |---|---|
    | reward_position | ``-position_weight * |goal_xy - object_xy|`` |
    | reward_orientation | ``-orientation_weight * |wrap(goal_yaw - object_yaw)|`` |
    | reward_action | ``-action_weight * |action|^2`` |

    ``info`` also holds ``position_error`` (m), ``orientation_error`` (rad) and ``is_success``;
    ``info["diverged"]`` names the failure when the dynamics blew up.

    ## Episode end

    Terminated on success (both errors within tolerance). Truncated after 50 steps (1 s, the
    registered time limit), when the object leaves the workspace (``workspace`` m from its start,
    or lifted/tilted off the floor: ``info["out_of_workspace"]``), or when the dynamics diverged.

    ## Arguments

    | argument | default | meaning |
    |---|---|---|
    | dynamics | ``"mujoco"`` | ``"mujoco"``, ``"fignet"`` or a ``Dynamics`` object |
    | checkpoint | ``None`` | ``"fignet"``: path or ``LearnedSimulator`` (default: pretrained) |
    | shape | ``"rect1"`` | MIT Pushing object (``fignet_gym.mjcf.MIT_OBJECTS``) |
    | friction | ``0.25`` | object-floor friction (the training data draws 0.15 to 0.35) |
    | tip_friction | ``None`` | tip-object friction (default: ``friction``) |
    | max_speed | ``0.1`` | tip speed (m/s) at ``|action| = 1`` per axis |
    | frame_skip | ``10`` | MuJoCo timesteps (2 ms) per environment step |
    | goal_distance | ``0.05`` | goal drawn within this distance (m) of the object |
    | goal_yaw | ``0.5`` | goal heading drawn within this angle (rad) of the object's |
    | position_weight | ``10.0`` | reward weight of the position error (1/m) |
    | orientation_weight | ``1.0`` | reward weight of the heading error (1/rad) |
    | action_weight | ``0.01`` | reward weight of the squared action |
    | success_position | ``0.01`` | position tolerance (m) for success |
    | success_yaw | ``0.1`` | heading tolerance (rad) for success |
    | workspace | ``0.3`` | truncate when the object moves this far (m) from its start |
    | render_mode | ``None`` | ``"rgb_array"`` or ``None`` |
    | width | ``480`` | rendered frame width (px) |
    | height | ``480`` | rendered frame height (px) |
    | dynamics_kwargs | ``None`` | extra dynamics arguments (e.g. fignet's ``max_distance``) |
    """

    scene_type = "push"
    observation_layout = layout(
        ("object_xy", 2),
        ("object_yaw", 2),
        ("tip_xy", 2),
        ("goal_xy", 2),
        ("goal_yaw", 2),
        ("goal_rel_xy", 2),
        ("goal_rel_yaw", 2),
        ("tip_rel_xy", 2),
        ("object_velocity_xy", 2),
        ("object_yaw_rate", 1),
    )

    def __init__(
        self,
        dynamics: str | Dynamics = "mujoco",
        checkpoint: Any = None,
        shape: str = "rect1",
        friction: float = 0.25,
        tip_friction: float | None = None,
        max_speed: float = 0.1,
        frame_skip: int = 10,
        goal_distance: float = 0.05,
        goal_yaw: float = 0.5,
        position_weight: float = 10.0,
        orientation_weight: float = 1.0,
        action_weight: float = 0.01,
        success_position: float = 0.01,
        success_yaw: float = 0.1,
        workspace: float = 0.3,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        dynamics_kwargs: dict[str, Any] | None = None,
    ) -> None:
        check_arguments(
            "PushEnv", friction=(friction, "positive"), tip_friction=(tip_friction, "positive?"),
            max_speed=(max_speed, "positive"), frame_skip=(frame_skip, "count"),
            goal_distance=(goal_distance, "nonnegative"), goal_yaw=(goal_yaw, "nonnegative"),
            position_weight=(position_weight, "finite"), orientation_weight=(orientation_weight, "finite"),
            action_weight=(action_weight, "finite"), success_position=(success_position, "positive"),
            success_yaw=(success_yaw, "positive"), workspace=(workspace, "positive"),
            width=(width, "count"), height=(height, "count"))
        obj = push_object(shape)
        model = mujoco.MjModel.from_xml_string(
            push_scene_xml(shape, friction=friction, tip_friction=tip_friction)
        )
        self.shape = shape
        self.max_speed = float(max_speed)
        self.goal_distance, self.goal_yaw = float(goal_distance), float(goal_yaw)
        self.position_weight = float(position_weight)
        self.orientation_weight = float(orientation_weight)
        self.action_weight = float(action_weight)
        self.success_position, self.success_yaw = float(success_position), float(success_yaw)
        self.workspace = float(workspace)
        self._rest_z = obj.thickness / 2
        tip_radius = float(
            model.geom_size[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "tip"), 0]
        )
        # The tip starts this far from the object's frame origin: outside every corner.
        self._tip_start = float(np.linalg.norm(obj.outline, axis=1).max()) + tip_radius + 0.005
        floor = float(
            model.geom_size[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor"), 0]
        )
        self._tip_bound = floor - 0.05
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "object")
        self._qadr = int(model.jnt_qposadr[model.body_jntadr[body]])
        self._dadr = int(model.jnt_dofadr[model.body_jntadr[body]])
        self._tip_mocap = int(
            model.body_mocapid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "tip")]
        )
        self._camera_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "top")
        self._object_geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "object")
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        n = layout_size(self.observation_layout)
        self.observation_space = spaces.Box(-np.inf, np.inf, (n,), np.float32)
        super().__init__(
            model, dynamics, checkpoint, frame_skip, render_mode, width, height, dynamics_kwargs
        )
        self.step_time = self.nstep * float(model.opt.timestep)

    def _init_state(self) -> None:
        super()._init_state()
        self.goal = np.zeros(3)  # x, y, yaw
        self._start_xy = np.zeros(2)

    # ----------------------------------------------------------------- task
    def _object_pose(self) -> tuple[np.ndarray, float, float]:
        """Object ``xy float[2]``, heading (rad) and height (m)."""
        q = self.data.qpos[self._qadr : self._qadr + 7]
        return q[:2].copy(), float(yaw_of(q[3:])), float(q[2])

    def _reset_task(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        yaw = rng.uniform(-np.pi, np.pi)
        q = self.data.qpos
        q[self._qadr : self._qadr + 3] = (0.0, 0.0, self._rest_z)
        q[self._qadr + 3 : self._qadr + 7] = (np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2))
        self._start_xy = np.zeros(2)
        r = self.goal_distance * np.sqrt(rng.uniform())
        phi = rng.uniform(-np.pi, np.pi)
        self.goal = np.array(
            [
                r * np.cos(phi),
                r * np.sin(phi),
                wrap_angle(yaw + rng.uniform(-self.goal_yaw, self.goal_yaw)),
            ]
        )
        psi = rng.uniform(-np.pi, np.pi)
        self.data.mocap_pos[self._tip_mocap, :2] = self._tip_start * np.array(
            [np.cos(psi), np.sin(psi)]
        )
        self.data.mocap_quat[self._tip_mocap] = (1.0, 0.0, 0.0, 0.0)

    def _apply_action(self, action: np.ndarray) -> None:
        tip = self.data.mocap_pos[self._tip_mocap]
        tip[:2] = np.clip(
            tip[:2] + action * self.max_speed * self.step_time, -self._tip_bound, self._tip_bound
        )

    def _observe(self) -> np.ndarray:
        xy, yaw, _ = self._object_pose()
        tip = self.data.mocap_pos[self._tip_mocap, :2]
        c, s = np.cos(yaw), np.sin(yaw)
        to_obj = np.array([[c, s], [-s, c]])  # world -> object frame
        vel = self.data.qvel[self._dadr : self._dadr + 6]
        w_world = np.zeros(3)
        mujoco.mju_rotVecQuat(w_world, vel[3:], self.data.qpos[self._qadr + 3 : self._qadr + 7])
        dyaw = self.goal[2] - yaw
        obs = np.concatenate(
            [
                xy,
                [c, s],
                tip,
                self.goal[:2],
                [np.cos(self.goal[2]), np.sin(self.goal[2])],
                to_obj @ (self.goal[:2] - xy),
                [np.cos(dyaw), np.sin(dyaw)],
                to_obj @ (tip - xy),
                vel[:2],
                w_world[2:],
            ]
        )
        return obs.astype(np.float32)

    def _evaluate(self, action: np.ndarray) -> tuple[dict[str, float], bool, bool, dict[str, Any]]:
        xy, yaw, z = self._object_pose()
        pos_err = float(np.linalg.norm(self.goal[:2] - xy))
        yaw_err = float(abs(wrap_angle(self.goal[2] - yaw)))
        terms = {
            "reward_position": -self.position_weight * pos_err,
            "reward_orientation": -self.orientation_weight * yaw_err,
            "reward_action": -self.action_weight * float(np.sum(action**2)),
        }
        success = pos_err < self.success_position and yaw_err < self.success_yaw
        quat = self.data.qpos[self._qadr + 3 : self._qadr + 7]
        tilt = 1.0 - 2.0 * float(quat[1] ** 2 + quat[2] ** 2)  # cos of the tilt from upright
        out = (
            not np.isfinite(xy).all()
            or float(np.linalg.norm(xy - self._start_xy)) > self.workspace
            or abs(z - self._rest_z) > 0.02
            or tilt < 0.9
        )
        info: dict[str, Any] = {
            "position_error": pos_err,
            "orientation_error": yaw_err,
            "is_success": bool(success),
        }
        if out:
            info["out_of_workspace"] = True
        return terms, success, out, info

    def _camera(self) -> int:
        return self._camera_id

    def _decorate(self, scene: mujoco.MjvScene) -> None:
        # The goal: a translucent green copy of the object's mesh at the goal pose.
        if scene.ngeom >= scene.maxgeom:
            return
        x, y, yaw = self.goal
        c, s = np.cos(yaw), np.sin(yaw)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        g = self._object_geom
        geom_rot = np.zeros(9)
        mujoco.mju_quat2Mat(geom_rot, self.model.geom_quat[g])
        pos = np.array([x, y, self._rest_z + 0.0005]) + rot @ self.model.geom_pos[g]
        vg = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(
            vg,
            int(mujoco.mjtGeom.mjGEOM_MESH),
            np.ones(3),
            pos,
            (rot @ geom_rot.reshape(3, 3)).ravel(),
            np.array([0.1, 0.8, 0.2, 0.4], np.float32),
        )
        vg.dataid = 2 * int(self.model.geom_dataid[g])
        scene.ngeom += 1


class PushVectorEnv(BatchedVectorEnv):
    """``num_envs`` :class:`PushEnv` stepped by one batched dynamics call.

    The ``gym.make_vec(..., vectorization_mode="vector_entry_point")`` entry point.

    Args:
        num_envs: number of sub-environments.
        max_episode_steps: per-episode step limit (``gym.make_vec`` passes the registered 50).
        autoreset_mode: Gymnasium ``AutoresetMode`` (default ``NEXT_STEP``).
        kwargs: :class:`PushEnv` arguments, shared by every sub-environment.
    """

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        **kwargs: Any,
    ) -> None:
        super().__init__(PushEnv(**kwargs), num_envs, max_episode_steps, autoreset_mode)
