"""``fignet_gym/Push-v2`` (and the deprecated ``Push-v1``): planar pushing in the MIT Pushing
setting."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from gymnasium import spaces

from fignet_gym.dynamics import Dynamics, compile_with_history
from fignet_gym.envs.base import (
    MjDynamicsEnv,
    check_arguments,
    layout,
    layout_size,
    wrap_angle,
    yaw_of,
)
from fignet_gym.envs.tasks import PushTask
from fignet_gym.envs.vector import SingleEnvVectorEnv
from fignet_gym.mjcf import DEFAULT_CONE, push_object, push_scene_xml

#: The easiest goals of a curriculum (``PushEnv.goal_level = 0``): distance range (m) and heading
#: range (rad), just beyond the 1 cm success tolerance; each is capped by the env's own.
EASY_GOAL = (0.011, 0.02, 0.1)
#: The shipped push simulator trained on each friction cone's data (Push-v2 and Push-v1).
PRETRAINED_BY_CONE = {"elliptic": "push", "pyramidal": "push-pyramidal"}


@dataclass(frozen=True)
class PushScene:
    """What :class:`PushEnv` needs of its scene (:meth:`PushEnv._push_scene`).

    Attributes:
        mjcf, model: the scene's MJCF and its compiled model (room for the pose history).
        outline: ``float[K, 2]`` counter-clockwise outline (m) of the object in its body frame.
        rest_z: the object's resting height (m). object_body, tip_body: body names.
        tip_bound: the tip stays within ``[-tip_bound, tip_bound]`` on x and y (m).
        camera: the rendering camera's name (``""``: MuJoCo's free camera).
        default_checkpoint: the learned model ``dynamics="fignet"`` loads by default.
    """

    mjcf: str
    model: mujoco.MjModel
    outline: np.ndarray
    rest_z: float
    object_body: str
    tip_body: str
    tip_bound: float
    camera: str
    default_checkpoint: str


class PushEnv(MjDynamicsEnv):
    """Push an MIT Pushing object to a goal pose (x, y, yaw) with a cylindrical tip.

    One object of the MIT Pushing dataset (13 mm thick prism, the dataset's mass and inertia) lies
    on a floor; a vertical cylinder of radius 4.75 mm (a mocap body: kinematic for the learned
    model) moves in the plane at a bounded speed. Each episode draws the object's heading, a goal
    pose near the object and a start position of the tip next to it (``tip_start``). The reward,
    success and truncation rules are :class:`fignet_gym.envs.tasks.PushTask` (``env.task``), the
    functions a planner's cost calls on predicted states. One environment step is one
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
    | reward_success | ``success_weight`` on the step that succeeds (only when ``success_weight`` > 0) |

    ``info`` also holds ``position_error`` (m), ``orientation_error`` (rad) and ``is_success``;
    ``info["diverged"]`` names the failure when the dynamics blew up.

    ## Episode end

    Terminated on success (both errors within tolerance). Truncated at the registered time limit
    (75 steps, 1.5 s), when the object leaves the workspace (``workspace`` m from its start, its
    height off by ``max_lift``, or tilted below ``min_upright``: ``info["out_of_workspace"]``),
    or when the dynamics diverged.

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
    | goal_distance_min | ``0.0`` | and at least this far (m; uniform over the annulus) |
    | goal_yaw | ``0.5`` | goal heading drawn within this angle (rad) of the object's |
    | tip_start | ``"around"`` | ``"around"``: circling the corners; ``"behind"``: opposite the goal |
    | tip_gap | ``0.005`` | ``"behind"``: clearance (m) between tip and outline |
    | tip_jitter | ``0.01`` | ``"behind"``: uniform sideways offset (m) of the start |
    | position_weight | ``10.0`` | reward weight of the position error (1/m) |
    | orientation_weight | ``1.0`` | reward weight of the heading error (1/rad) |
    | action_weight | ``0.01`` | reward weight of the squared action |
    | success_weight | ``0.0`` | reward of the step that succeeds |
    | success_position | ``0.01`` | position tolerance (m) for success |
    | success_yaw | ``0.1`` | heading tolerance (rad) for success |
    | workspace | ``0.3`` | truncate when the object moves this far (m) from its start |
    | max_lift | ``0.02`` | truncate when the object's height is off its resting height by more (m) |
    | min_upright | ``0.9`` | truncate when the cosine of its tilt from upright drops below this |
    | render_mode | ``None`` | ``"rgb_array"`` or ``None`` |
    | width | ``480`` | rendered frame width (px) |
    | height | ``480`` | rendered frame height (px) |
    | dynamics_kwargs | ``None`` | extra dynamics arguments (e.g. fignet's ``max_distance``) |
    | cone | ``"elliptic"`` | MuJoCo friction cone; ``"pyramidal"``: Push-v1's physics |

    ## Version History

    * v2: isotropic friction (MuJoCo's elliptic cone); the task is v1's. Under v1's pyramidal
      cone a push turns the object by a different angle at each world heading (-1.9 to -12.4 deg
      for one push over 12 headings; -8.73 deg at every heading with the elliptic cone), so the
      learned model could only learn the average turn. ``dynamics="fignet"`` loads the ``push``
      model trained on isotropic pushes; v1 keeps the pyramidal cone and loads
      ``push-pyramidal``, the model trained on its physics. v1 is deprecated.

    * v1: a task a planner with a perfect model solves (MPC with MuJoCo as its model: see
      ``experiments/README.md``, "Planning"). The tip starts 5 mm behind the object on the side
      away from the goal (``tip_start="behind"``, up to 1 cm sideways), instead of anywhere
      around it: in v0 45% of episodes need more than the 50-step limit to get there. The goal
      lies 2 to 5 cm away (``goal_distance_min=0.02``: never already solved; 5 cm is the travel
      of an MIT Pushing push past contact) with a heading within 0.3 rad of the object's, and
      success needs 1 cm and 0.2 rad (about 11 degrees: v0's 0.1 rad failed 9 of 10 scripted
      pushes that reached the position). The time limit is 75 steps (1.5 s). The tip speed stays
      0.1 m/s, the quasi-static end of the MIT Pushing speeds (10 to 500 mm/s): a block released
      at 0.1 m/s with friction 0.25 slides v^2 / (2 mu g) = 2 mm, a fifth of the tolerance, so
      the object goes where the pusher puts it.
    * v0: the initial version (goal within 5 cm and 0.5 rad, success 1 cm and 0.1 rad, tip
      anywhere around the object, 50 steps); removed before the first release.
    """

    scene_type = "push"
    #: The task class; a subclass adds its own arguments by :meth:`_task_arguments`.
    task_class: type[PushTask] = PushTask
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
        goal_distance_min: float = 0.0,
        goal_yaw: float = 0.5,
        tip_start: str = "around",
        tip_gap: float = 0.005,
        tip_jitter: float = 0.01,
        position_weight: float = 10.0,
        orientation_weight: float = 1.0,
        action_weight: float = 0.01,
        success_weight: float = 0.0,
        success_position: float = 0.01,
        success_yaw: float = 0.1,
        workspace: float = 0.3,
        max_lift: float = 0.02,
        min_upright: float = 0.9,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        dynamics_kwargs: dict[str, Any] | None = None,
        cone: str = DEFAULT_CONE,
    ) -> None:
        check_arguments(
            "PushEnv", friction=(friction, "positive"), tip_friction=(tip_friction, "positive?"),
            max_speed=(max_speed, "positive"), frame_skip=(frame_skip, "count"),
            goal_distance=(goal_distance, "nonnegative"), goal_yaw=(goal_yaw, "nonnegative"),
            position_weight=(position_weight, "finite"), orientation_weight=(orientation_weight, "finite"),
            action_weight=(action_weight, "finite"), success_position=(success_position, "positive"),
            success_yaw=(success_yaw, "positive"), workspace=(workspace, "positive"),
            goal_distance_min=(goal_distance_min, "nonnegative"), tip_gap=(tip_gap, "nonnegative"),
            tip_jitter=(tip_jitter, "nonnegative"), success_weight=(success_weight, "finite"),
            max_lift=(max_lift, "positive"), min_upright=(min_upright, "finite"),
            width=(width, "count"), height=(height, "count"))
        scene = self._push_scene(shape, friction, tip_friction, cone)
        #: The scene's MJCF (object at the origin; recorded trajectories store their poses).
        self.mjcf = scene.mjcf
        self.cone = cone
        self.default_checkpoint = scene.default_checkpoint
        model = scene.model
        self.shape = shape
        self.max_speed = float(max_speed)
        self.goal_distance, self.goal_yaw = float(goal_distance), float(goal_yaw)
        self.goal_distance_min = float(goal_distance_min)
        if not 0.0 <= self.goal_distance_min <= self.goal_distance:
            raise ValueError(
                f"PushEnv: need 0 <= goal_distance_min <= goal_distance, got "
                f"{goal_distance_min} and {goal_distance}"
            )
        if tip_start not in ("around", "behind"):
            raise ValueError(f"PushEnv: tip_start must be 'around' or 'behind', got {tip_start!r}")
        self.tip_start = tip_start
        self.tip_gap, self.tip_jitter = float(tip_gap), float(tip_jitter)
        #: Training-time settings a curriculum changes on a live env (``set_attr``), never
        #: registered arguments, so an evaluation env always has the task's own goals:
        #: ``goal_level`` in [0, 1] scales the goal ranges from :data:`EASY_GOAL` (0) to the
        #: env's own (1, :meth:`goal_ranges`); ``resample_goal`` draws a new goal on success
        #: (``info["goal_reached"]``) instead of terminating.
        self.goal_level = 1.0
        self.resample_goal = False
        self._rest_z = scene.rest_z
        self._tip_bound = scene.tip_bound
        self.task = self.task_class(
            model,
            scene.outline,
            self._rest_z,
            max_speed=self.max_speed,
            dt=frame_skip * float(model.opt.timestep),
            tip_bound=self._tip_bound,
            position_weight=position_weight,
            orientation_weight=orientation_weight,
            action_weight=action_weight,
            success_weight=success_weight,
            success_position=success_position,
            success_yaw=success_yaw,
            workspace=workspace,
            max_lift=max_lift,
            min_upright=min_upright,
            object_body=scene.object_body,
            tip_body=scene.tip_body,
            **self._task_arguments(),
        )
        self._qadr, self._dadr, self._tip_mocap = self.task.qadr, self.task.dadr, self.task.tip_mocap
        # The tip starts this far from the object's frame origin: outside every corner.
        self._tip_start = (float(np.linalg.norm(scene.outline, axis=1).max())
                           + self.task.tip_radius + 0.005)
        self._camera_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, scene.camera)
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, scene.object_body)
        first = int(model.body_geomadr[body])
        self._object_geoms = range(first, first + int(model.body_geomnum[body]))
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        n = layout_size(self.observation_layout)
        self.observation_space = spaces.Box(-np.inf, np.inf, (n,), np.float32)
        super().__init__(
            model, dynamics, checkpoint, frame_skip, render_mode, width, height, dynamics_kwargs
        )

    def _push_scene(self, shape: str, friction: float, tip_friction: float | None,
                    cone: str) -> PushScene:
        """The shipped scene of ``shape``: object ``"object"``, tip ``"tip"``, camera ``"top"``;
        the tip stays 5 cm inside the floor's edge."""
        obj = push_object(shape)
        mjcf = push_scene_xml(shape, friction=friction, tip_friction=tip_friction, cone=cone)
        model = compile_with_history(mjcf)
        floor = float(
            model.geom_size[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor"), 0]
        )
        return PushScene(mjcf, model, obj.outline, obj.thickness / 2, "object", "tip",
                         floor - 0.05, "top", PRETRAINED_BY_CONE[cone])

    def _task_arguments(self) -> dict[str, Any]:
        """Arguments of :attr:`task_class` beyond :class:`PushTask`'s (none here)."""
        return {}

    def _init_state(self) -> None:
        super()._init_state()
        self.goal = np.zeros(3)  # x, y, yaw
        self.workspace_origin = np.zeros(2)  # where the object started (truncation)

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
        self.workspace_origin = np.zeros(2)
        self.goal, phi = self._draw_goal(rng, np.zeros(2), yaw)
        if self.tip_start == "around":
            psi = rng.uniform(-np.pi, np.pi)
            tip = self._tip_start * np.array([np.cos(psi), np.sin(psi)])
        else:  # behind the object, seen from the goal, with a sideways offset
            mujoco.mj_forward(self.model, self.data)
            unit = np.array([np.cos(phi), np.sin(phi)])
            side = np.array([-unit[1], unit[0]]) * rng.uniform(-self.tip_jitter, self.tip_jitter)
            state = self.get_state()
            contact = self.task.pushing_point(state, self.goal)
            tip = contact - self.tip_gap * unit + side
        self.data.mocap_pos[self._tip_mocap, :2] = tip
        self.data.mocap_quat[self._tip_mocap] = (1.0, 0.0, 0.0, 0.0)

    def goal_ranges(self) -> tuple[float, float, float]:
        """Goal distance range (m) and heading range (rad) at :attr:`goal_level`: the env's own
        at 1, :data:`EASY_GOAL` at 0, linear in between."""
        lv = float(np.clip(self.goal_level, 0.0, 1.0))
        own = (self.goal_distance_min, self.goal_distance, self.goal_yaw)
        easy = (min(e, o) for e, o in zip(EASY_GOAL, own, strict=True))
        # o * lv + e * (1 - lv): exactly the env's own ranges at level 1 (e + lv * (o - e) is not)
        lo, hi, yaw = (o * lv + e * (1.0 - lv) for e, o in zip(easy, own, strict=True))
        return lo, hi, yaw

    def _draw_goal(self, rng: np.random.Generator, xy: np.ndarray, yaw: float
                   ) -> tuple[np.ndarray, float]:
        """A goal ``float[3]`` (x, y, yaw) around the object pose ``xy float[2]``, ``yaw``, and its
        direction (rad) from the object."""
        lo, hi, dyaw = self.goal_ranges()
        r = np.sqrt(rng.uniform(lo**2, hi**2))  # uniform over the annulus
        phi = rng.uniform(-np.pi, np.pi)
        goal = np.array([xy[0] + r * np.cos(phi), xy[1] + r * np.sin(phi),
                         wrap_angle(yaw + rng.uniform(-dyaw, dyaw))])
        return goal, float(phi)

    def task_context(self) -> dict[str, Any]:
        """The episode's goal, for :class:`~fignet_gym.envs.tasks.PushTask`."""
        return {**super().task_context(), "goal": self.goal.copy()}

    def _apply_action(self, action: np.ndarray) -> None:
        tip = self.data.mocap_pos[self._tip_mocap]
        tip[:2] = self.task.tip_path(tip[:2], action[None])[0]

    def _observe(self) -> np.ndarray:
        return self._observe_many([self])[0]

    def _observe_many(self, envs: Sequence[PushEnv]) -> np.ndarray:
        """Observations ``float32[B, 19]`` of ``envs`` (this one's spawned copies)."""
        qa = self._qadr + np.arange(7)
        q = np.stack([e.data.qpos[qa] for e in envs])
        vel = np.stack([e.data.qvel[self._dadr : self._dadr + 6] for e in envs])
        tip = np.stack([e.data.mocap_pos[self._tip_mocap, :2] for e in envs])
        goal = np.stack([e.goal for e in envs])
        xy, yaw = q[:, :2], yaw_of(q[:, 3:])
        c, s = np.cos(yaw), np.sin(yaw)

        rot = np.stack([np.stack([c, s], -1), np.stack([-s, c], -1)], -2)  # world -> object

        def to_obj(v: np.ndarray) -> np.ndarray:  # float[B, 2]; matmul rounds as one env's R @ v
            return (rot @ v[:, :, None])[:, :, 0]

        w_world = np.zeros((len(envs), 3))
        for i in range(len(envs)):  # MuJoCo's own rotation of the body-frame angular velocity
            mujoco.mju_rotVecQuat(w_world[i], vel[i, 3:], q[i, 3:])
        dyaw = goal[:, 2] - yaw
        obs = np.concatenate([
            xy, np.stack([c, s], -1), tip, goal[:, :2],
            np.stack([np.cos(goal[:, 2]), np.sin(goal[:, 2])], -1), to_obj(goal[:, :2] - xy),
            np.stack([np.cos(dyaw), np.sin(dyaw)], -1), to_obj(tip - xy), vel[:, :2],
            w_world[:, 2:],
        ], -1)
        return obs.astype(np.float32)

    def _post_step(
        self, action: np.ndarray, diverged: str | None
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        return self._post_step_many([self], [action], [diverged])[0]

    def _post_step_many(
        self, envs: Sequence[PushEnv], actions: Sequence[np.ndarray],
        diverged: Sequence[str | None]
    ) -> list[tuple[np.ndarray, float, bool, bool, dict[str, Any]]]:
        """The task's reward, success and workspace of every env from one batched call each
        (single envs take the same path, so a vector env reproduces them bit for bit)."""
        task = self.task
        states = np.stack([e.get_state() for e in envs])
        goals = np.stack([e.goal for e in envs])
        terms = task.reward_terms(states, goals, np.stack(actions))
        measures = task.measures(states, goals)
        success = task.is_success(states, goals)
        out = task.out_of_workspace(states, np.stack([e.workspace_origin for e in envs]))
        reward = sum(terms.values())  # the env's term order, as the planners' task.reward
        rows: list[tuple[float, bool, bool, dict[str, Any]]] = []
        for i, e in enumerate(envs):
            info: dict[str, Any] = {k: float(v[i]) for k, v in terms.items()}
            info.update({k: float(v[i]) for k, v in measures.items()}, is_success=bool(success[i]))
            terminated, truncated = bool(success[i]), bool(out[i])
            if truncated:
                info["out_of_workspace"] = True
            if terminated and e.resample_goal:
                # The next goal is drawn around where the object now is; the episode goes on.
                xy, yaw, _ = e._object_pose()
                e.goal = e._draw_goal(e.np_random, xy, yaw)[0]
                info["goal_reached"] = True
                terminated = False
            if diverged[i] is not None:
                truncated = True
                info["diverged"] = diverged[i]
            rows.append((float(reward[i]), terminated, truncated, info))
        obs = self._observe_many(envs)  # after any new goal: the policy sees the goal it now has
        return [(o, *r) for o, r in zip(obs, rows, strict=True)]

    def _camera(self) -> int:
        return self._camera_id

    def _decorate(self, scene: mujoco.MjvScene) -> None:
        # The goal: a translucent green copy of the object's geoms at the goal pose.
        x, y, yaw = self.goal
        c, s = np.cos(yaw), np.sin(yaw)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        for g in self._object_geoms:
            if scene.ngeom >= scene.maxgeom:
                return
            geom_rot = np.zeros(9)
            mujoco.mju_quat2Mat(geom_rot, self.model.geom_quat[g])
            pos = np.array([x, y, self._rest_z + 0.0005]) + rot @ self.model.geom_pos[g]
            vg = scene.geoms[scene.ngeom]
            kind = int(self.model.geom_type[g])
            mesh = kind == int(mujoco.mjtGeom.mjGEOM_MESH)
            mujoco.mjv_initGeom(
                vg,
                kind,
                np.ones(3) if mesh else self.model.geom_size[g],
                pos,
                (rot @ geom_rot.reshape(3, 3)).ravel(),
                np.array([0.1, 0.8, 0.2, 0.4], np.float32),
            )
            if mesh:
                vg.dataid = 2 * int(self.model.geom_dataid[g])
            scene.ngeom += 1


class PushVectorEnv(SingleEnvVectorEnv):
    """``num_envs`` :class:`PushEnv` stepped by one batched dynamics call; arguments as
    :class:`~fignet_gym.envs.vector.SingleEnvVectorEnv`.

    ``max_episode_steps``: ``gym.make_vec`` passes the registered 50.
    """

    env_class = PushEnv
