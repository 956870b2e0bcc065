"""``fignet_gym/Toss-v1`` (and the deprecated ``Toss-v0``): toss objects one by one onto a target
region of the floor."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np
from gymnasium import spaces

from fignet_gym.dynamics import STATE_SPEC, Dynamics, compile_with_history
from fignet_gym.envs.base import MjDynamicsEnv, add_disc, check_arguments, free_camera, layout, layout_size
from fignet_gym.envs.tasks import TossTask
from fignet_gym.envs.vector import SingleEnvVectorEnv
from fignet_gym.mjcf import DEFAULT_CONE, TossObject, toss_scene_xml, unit_shape_mesh

#: The shipped toss simulator for each friction cone (Toss-v1 and Toss-v0). ``toss`` was trained
#: on pyramidal-cone tosses and is not yet retrained on isotropic ones (issue 38's note).
PRETRAINED_BY_CONE = {"elliptic": "toss", "pyramidal": "toss"}

#: The default objects: three metal cubes of Kubric's small size (flat faces: face-face contacts).
DEFAULT_OBJECTS = (TossObject("cube", 0.7, "metal"),) * 3
#: Where unreleased objects wait: resting on the floor on this line, far from the action.
PARK_X, PARK_SPACING = -10.0, 3.5


def toss_layout(num_objects: int) -> dict[str, slice]:
    """Observation layout of :class:`TossEnv` for ``K = num_objects`` objects."""
    k = num_objects
    return layout(
        ("released", k),
        ("position", 3 * k),
        ("quaternion", 4 * k),
        ("target_rel_xy", 2 * k),
        ("target_xy", 2),
        ("next_object", k),
    )


class TossEnv(MjDynamicsEnv):
    """Toss K objects, one per step, so that they come to rest in a target region on the floor.

    Each step releases the next object from a fixed point (``release_position``, a random heading
    drawn at reset) with the horizontal velocity chosen by the action, then lets the scene evolve
    for ``settle_steps`` learned steps (``settle_steps * settle_frame_skip`` MuJoCo timesteps:
    the env's ``frame_skip``, 1.5 s by default) so that it comes to rest, possibly against or on
    top of the objects already there.
    If an object already lies under the release point, the release point rises above it (a chute
    over the pile) so that objects never start interpenetrating. Unreleased objects wait at rest on
    the floor far away (``x = -10`` m). The episode ends after the K-th release.

    The scene follows the toss training data (``fignet_gym.data.generate.TossConfig``, Kubric MOVi
    scale): ``TossObject`` shapes of size 0.7 (half extent, m), a 40 x 40 m floor, gravity -10,
    release at rest height >= 1 m with zero vertical velocity and speeds up to about 5 m/s.

    ## Action space

    ``Box(-1, 1, (2,), float32)``, mapped linearly to
    ``[release_velocity_low, release_velocity_high]`` (the vertical release velocity is zero, as in
    the training data); out-of-range values are clipped, NaN/inf raise ``ValueError``. The
    release, reward and target rules are :class:`fignet_gym.envs.tasks.TossTask` (``env.task``),
    which a planner calls on predicted states.

    | index | action | unit |
    |---|---|---|
    | 0:1 | release velocity along world x | m/s (``[2.5, 5]`` by default) |
    | 1:2 | release velocity along world y | m/s (``[-2, 2]``) |

    ## Observation space

    ``Box(-inf, inf, (11 K + 2,), float32)``; 35 for the default ``K = 3`` objects (slices below),
    ``toss_layout(K)`` in general. Entries of unreleased objects are zero.

    | index | name | meaning |
    |---|---|---|
    | 0:3 | released | 1 for each object already tossed |
    | 3:12 | position | object positions (world, m), 3 per object |
    | 12:24 | quaternion | object orientations (w, x, y, z), 4 per object |
    | 24:30 | target_rel_xy | object xy minus target centre (m), 2 per object |
    | 30:32 | target_xy | target centre (m) |
    | 32:35 | next_object | one-hot of the object the next action tosses (zeros when done) |

    ## Reward

    The reward is the sum of these terms, each returned in ``info`` (``d``: xy distance from the
    tossed object's final position to the target centre; ``n``: objects within ``target_radius``
    of the centre):

    | info key | term |
    |---|---|
    | reward_distance | ``-distance_weight * d`` |
    | reward_in_target | ``in_target_weight * (n after the step - n before)`` |

    Summed over an episode, ``reward_in_target`` is ``in_target_weight`` times the number of
    objects in the target at the end: knocking an earlier object out costs what it earned.
    ``info`` also holds ``num_in_target``, ``distance`` (m) and ``max_speed`` (m/s, the fastest
    released object at the end of the step: how nearly at rest they are); ``info["diverged"]``
    names a dynamics failure.

    ## Episode end

    Terminated after the last object's step; truncated when the dynamics diverged.

    ## Arguments

    | argument | default | meaning |
    |---|---|---|
    | dynamics | ``"mujoco"`` | ``"mujoco"``, ``"fignet"`` or a ``Dynamics`` object |
    | checkpoint | ``None`` | ``"fignet"``: path or ``LearnedSimulator`` (default: pretrained) |
    | objects | ``None`` | ``Sequence[TossObject]`` (default: three metal cubes of size 0.7) |
    | floor_half_size | ``20.0`` | floor half side (m; the training data's: keep it for fignet) |
    | settle_frame_skip | ``10`` | MuJoCo timesteps (2 ms) per learned step of the settle |
    | settle_steps | ``75`` | learned steps (of 0.02 s) each toss is simulated for |
    | release_position | ``(-2, 0, 1.2)`` | where objects are released (m) |
    | release_velocity_low | ``(2.5, -2)`` | horizontal release velocity at action -1 (m/s) |
    | release_velocity_high | ``(5, 2)`` | horizontal release velocity at action +1 (m/s) |
    | target_low | ``(-0.5, -1.5)`` | lower corner of the box of target centres (m) |
    | target_high | ``(1.5, 1.5)`` | upper corner of that box (m) |
    | target_radius | ``1.5`` | radius of the target region (m) |
    | distance_weight | ``1.0`` | reward weight of the distance to the target (1/m) |
    | in_target_weight | ``1.0`` | reward per object brought into the target |
    | render_mode | ``None`` | ``"rgb_array"`` or ``None`` |
    | width | ``480`` | rendered frame width (px) |
    | height | ``480`` | rendered frame height (px) |
    | dynamics_kwargs | ``None`` | extra dynamics arguments (e.g. fignet's ``max_distance``) |
    | cone | ``"elliptic"`` | MuJoCo friction cone; ``"pyramidal"``: Toss-v0's physics |

    ## Version History

    * v1: isotropic friction (MuJoCo's elliptic cone), so a toss turned about the vertical lands
      turned. v0 (deprecated) keeps MuJoCo's default pyramidal cone. Both load the ``toss``
      model, trained on pyramidal-cone tosses (not yet retrained on isotropic ones).
    * v0: the initial version.
    """

    scene_type = "toss"

    def __init__(
        self,
        dynamics: str | Dynamics = "mujoco",
        checkpoint: Any = None,
        objects: Sequence[TossObject] | None = None,
        floor_half_size: float = 20.0,
        settle_frame_skip: int = 10,
        settle_steps: int = 75,
        release_position: Sequence[float] = (-2.0, 0.0, 1.2),
        release_velocity_low: Sequence[float] = (2.5, -2.0),
        release_velocity_high: Sequence[float] = (5.0, 2.0),
        target_low: Sequence[float] = (-0.5, -1.5),
        target_high: Sequence[float] = (1.5, 1.5),
        target_radius: float = 1.5,
        distance_weight: float = 1.0,
        in_target_weight: float = 1.0,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        dynamics_kwargs: dict[str, Any] | None = None,
        cone: str = DEFAULT_CONE,
    ) -> None:
        check_arguments(
            "TossEnv", floor_half_size=(floor_half_size, "positive"),
            settle_frame_skip=(settle_frame_skip, "count"),
            settle_steps=(settle_steps, "count"), release_position=(release_position, "vector3"),
            release_velocity_low=(release_velocity_low, "vector2"),
            release_velocity_high=(release_velocity_high, "vector2"),
            target_low=(target_low, "vector2"), target_high=(target_high, "vector2"),
            target_radius=(target_radius, "positive"), distance_weight=(distance_weight, "finite"),
            in_target_weight=(in_target_weight, "finite"), width=(width, "count"),
            height=(height, "count"))
        if np.any(np.asarray(target_low, float) > np.asarray(target_high, float)):
            raise ValueError(f"TossEnv: target_low {target_low} must not exceed target_high {target_high}")
        self.objects = tuple(objects) if objects is not None else DEFAULT_OBJECTS
        k = len(self.objects)
        if k < 1:
            raise ValueError("TossEnv needs at least one object")
        self.settle_steps = int(settle_steps)
        self.release_position = np.asarray(release_position, dtype=np.float64)
        self.release_velocity_low = np.asarray(release_velocity_low, dtype=np.float64)
        self.release_velocity_high = np.asarray(release_velocity_high, dtype=np.float64)
        self.target_low = np.asarray(target_low, dtype=np.float64)
        self.target_high = np.asarray(target_high, dtype=np.float64)
        if (
            self.release_position.shape != (3,)
            or self.release_velocity_low.shape != (2,)
            or self.release_velocity_high.shape != (2,)
            or self.target_low.shape != (2,)
            or self.target_high.shape != (2,)
        ):
            raise ValueError(
                "release_position needs 3 entries; release_velocity_low/high and target_low/high 2"
            )
        self.target_radius = float(target_radius)
        self.distance_weight, self.in_target_weight = (
            float(distance_weight),
            float(in_target_weight),
        )
        # Unreleased objects rest on the floor on a line far from the release point and target.
        meshes = [unit_shape_mesh(o.shape)[0] * o.size for o in self.objects]
        rest_z = [-v[:, 2].min() + 1e-3 for v in meshes]
        self._radius = np.array(
            [np.linalg.norm(v, axis=1).max() for v in meshes]
        )  # bounding spheres
        park_y = (np.arange(k) - (k - 1) / 2) * PARK_SPACING
        self._park = np.array(
            [[PARK_X, y, z, 1, 0, 0, 0] for y, z in zip(park_y, rest_z, strict=True)]
        )
        self.cone = cone
        self.default_checkpoint = PRETRAINED_BY_CONE[cone]
        model = compile_with_history(
            toss_scene_xml(self.objects, floor_half_size=floor_half_size, poses=self._park,
                           cone=cone)
        )
        self.task = TossTask(
            model,
            self._radius,
            self.release_position,
            self.release_velocity_low,
            self.release_velocity_high,
            self.target_radius,
            self.distance_weight,
            self.in_target_weight,
        )
        self._qadr, self._dadr = self.task.qadr, self.task.dadr
        self.settle_frame_skip = int(settle_frame_skip)
        self.observation_layout = toss_layout(k)
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.observation_space = spaces.Box(
            -np.inf, np.inf, (layout_size(self.observation_layout),), np.float32
        )
        super().__init__(
            model,
            dynamics,
            checkpoint,
            self.settle_frame_skip * self.settle_steps,
            render_mode,
            width,
            height,
            dynamics_kwargs,
        )

    def _init_state(self) -> None:
        super()._init_state()
        self.target = np.zeros(2)
        self.released = 0
        self._in_before = 0
        self.release_yaws = np.zeros(len(self.objects))  # heading of each object's release

    # ----------------------------------------------------------------- task
    def _positions(self) -> np.ndarray:
        """``float[K, 3]`` object positions."""
        return self.data.qpos[self._qadr[:, None] + np.arange(3)].copy()

    def _in_target(self, count: int) -> int:
        return int(self.task.in_target(self.get_state(), self.target, count))

    def _reset_task(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        self.target = rng.uniform(self.target_low, self.target_high)
        self.release_yaws = rng.uniform(-np.pi, np.pi, len(self.objects))
        self.released = 0
        self._in_before = 0
        # qpos0 holds the parked poses (mj_resetData ran before this).

    def task_context(self) -> dict[str, Any]:
        """The target, the next object and its heading, for
        :class:`~fignet_gym.envs.tasks.TossTask`."""
        k = self.released
        yaw = float(self.release_yaws[k]) if k < len(self.objects) else 0.0
        return {**super().task_context(), "target": self.target.copy(), "released": k,
                "release_yaw": yaw}

    def _check_ready(self) -> None:
        if self.released >= len(self.objects):
            raise RuntimeError(f"{type(self).__name__}: every object was tossed; call reset()")

    def _apply_action(self, action: np.ndarray) -> None:
        self._check_ready()
        k = self.released
        self._in_before = self._in_target(k)
        state = self.task.release(self.get_state(), k, float(self.release_yaws[k]), action)
        mujoco.mj_setState(self.model, self.data, state, STATE_SPEC)
        self.released = k + 1

    def _release_point(self, k: int) -> np.ndarray:
        """``float[3]`` release position of object ``k``: raised above released objects under it."""
        return self.task.release_point(self.get_state(), k)

    def _observe(self) -> np.ndarray:
        k, n = self.released, len(self.objects)
        lay = self.observation_layout
        obs = np.zeros(layout_size(lay), dtype=np.float64)
        pose = self.data.qpos[self._qadr[:, None] + np.arange(7)]
        mask = (np.arange(n) < k).astype(np.float64)
        obs[lay["released"]] = mask
        obs[lay["position"]] = (pose[:, :3] * mask[:, None]).ravel()
        obs[lay["quaternion"]] = (pose[:, 3:] * mask[:, None]).ravel()
        obs[lay["target_rel_xy"]] = ((pose[:, :2] - self.target) * mask[:, None]).ravel()
        obs[lay["target_xy"]] = self.target
        if k < n:
            obs[lay["next_object"].start + k] = 1.0
        return obs.astype(np.float32)

    def _evaluate(self, action: np.ndarray) -> tuple[dict[str, float], bool, bool, dict[str, Any]]:
        k = self.released
        state = self.get_state()
        terms = {
            key: float(v)
            for key, v in self.task.reward_terms(state, self.target, k - 1, self._in_before).items()
        }
        dist = float(np.linalg.norm(self.task.positions(state)[k - 1, :2] - self.target))
        n_in = int(self.task.in_target(state, self.target, k))
        speed = self.data.qvel[self._dadr[:k, None] + np.arange(3)]
        info = {
            "num_in_target": n_in,
            "distance": dist,
            "max_speed": float(np.linalg.norm(speed, axis=1).max()),
        }
        return terms, k >= len(self.objects), False, info

    def _camera(self) -> mujoco.MjvCamera:
        return free_camera((-0.3, 0.0, 0.5), 11.0, -150.0, -30.0)

    def _decorate(self, scene: mujoco.MjvScene) -> None:
        add_disc(scene, (*self.target, 0.002), self.target_radius, (0.1, 0.8, 0.2, 0.35))


class TossVectorEnv(SingleEnvVectorEnv):
    """``num_envs`` :class:`TossEnv` stepped by one batched dynamics call; arguments as
    :class:`~fignet_gym.envs.vector.SingleEnvVectorEnv`.

    ``max_episode_steps=None``: episodes end after the last toss.
    """

    env_class = TossEnv
