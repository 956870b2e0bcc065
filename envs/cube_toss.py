"""``fignet_gym/CubeToss-v0``: toss the real ContactNets cube so that it comes to rest at a target pose."""

from __future__ import annotations

import math
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from gymnasium import spaces

from fignet_gym.dynamics import STATE_SPEC, Dynamics, compile_with_history
from fignet_gym.dynamics.contact_params import ContactParams
from fignet_gym.envs.base import MjDynamicsEnv, add_disc, free_camera, layout, layout_size
from fignet_gym.envs.tasks import CubeTossTask, resting_yaw, wrap_quarter  # noqa: F401  (re-exported)
from fignet_gym.envs.vector import SingleEnvVectorEnv
from fignet_gym.mjcf import (
    ROLLING_FRICTION,
    TORSIONAL_FRICTION,
    cube_scene_xml,
    restitution_to_dampratio,
)
from fignet_gym.pretrained import pretrained_dir

#: The ContactNets cube (``params_processed/experiment.json``, lengths in metres): half-width,
#: mass (kg), principal inertia (kg m^2), nominal friction and restitution; the data's step (s).
CUBE_HALF_WIDTH = 0.0524
CUBE_MASS = 0.37
CUBE_INERTIA = 0.2950002913583124 * CUBE_HALF_WIDTH**2
NOMINAL_FRICTION, NOMINAL_RESTITUTION = 0.18, 0.125
DATA_DT = 0.006756756756756757
#: Floor half-size (m) of the imported data (``import-contactnets``' default): the learned
#: model's floor mesh must be the one it was trained with.
FLOOR_HALF_SIZE = 2.0

#: MuJoCo parameters: ``source`` says where they come from. The nominal ones are the data's
#: ``experiment.json`` with MuJoCo's defaults; ``fignet_gym/pretrained/cube-real.mujoco.json``
#: (written by ``fignet-gym sim2real``'s fit) replaces them when present.
NOMINAL_MUJOCO = ContactParams(
    source="nominal (experiment.json friction and restitution, MuJoCo defaults otherwise)",
    friction=NOMINAL_FRICTION, torsional=TORSIONAL_FRICTION, rolling=ROLLING_FRICTION, timeconst=0.02,
    dampratio=restitution_to_dampratio(NOMINAL_RESTITUTION), cone="pyramidal", impratio=1.0,
    gravity=-9.81, substeps=4,
)
#: Fields of :class:`ContactParams` the cube scene has no use for (no pusher, MJCF defaults).
UNUSED_FIELDS = ("friction_kinematic", "noslip_iterations", "integrator")


def fitted_mujoco_path() -> Path:
    """Where the fitted MuJoCo parameters of the cube are shipped (next to ``cube-real.pt``)."""
    return pretrained_dir() / "cube-real.mujoco.json"


def mujoco_parameters(spec: str | os.PathLike | dict[str, Any] | ContactParams | None = None
                      ) -> ContactParams:
    """MuJoCo parameters of the cube scene: ``"nominal"``, ``"fitted"`` (the shipped fit; the
    nominal ones, with a warning in ``source``, if none is shipped), a JSON file, a dict or a
    :class:`ContactParams`; unset fields are the nominal ones.

    Fields (:class:`ContactParams`): ``friction``, ``torsional``, ``rolling``, ``timeconst`` (s)
    and ``dampratio`` (``solref``), ``cone``, ``impratio``, ``gravity`` (m/s^2 along z),
    ``substeps`` (MuJoCo steps per data step), ``source`` (text). Unknown keys raise
    ``ValueError``; the old format of this env (``friction`` as three numbers, ``timestep``)
    loads with a ``FutureWarning``.
    """
    if spec is None or spec == "fitted":
        path = fitted_mujoco_path()
        if not path.is_file():
            return replace(NOMINAL_MUJOCO, source="NOMINAL: no fitted parameters shipped "
                           f"({path.name} missing); {NOMINAL_MUJOCO.source}")
        spec = path
    if spec == "nominal":
        return NOMINAL_MUJOCO
    if isinstance(spec, ContactParams):
        params, where = spec, "mujoco parameters"
    elif isinstance(spec, (str, os.PathLike)):
        params, where = ContactParams.load(spec, DATA_DT), str(spec)
    else:
        where = "mujoco parameters"
        params = ContactParams.from_json(spec, DATA_DT, where)
    unused = [k for k in UNUSED_FIELDS if getattr(params, k) is not None]
    if unused:
        raise ValueError(f"{where}: the cube scene does not use {unused}")
    return replace(params.filled(NOMINAL_MUJOCO), source=params.source or where)


def cube_toss_xml(params: ContactParams) -> str:
    """MJCF of the cube (free joint, box ``cube``) over the floor plane (the world body) with
    MuJoCo parameters ``params`` (complete, as :func:`mujoco_parameters` returns them)."""
    return cube_scene_xml(
        CUBE_HALF_WIDTH, CUBE_MASS, CUBE_INERTIA, [params.friction, params.torsional, params.rolling],
        None, timestep=DATA_DT / params.substeps, gravity=params.gravity,
        floor_half_size=FLOOR_HALF_SIZE, contact_timeconst=params.timeconst,
        dampratio=params.dampratio, cone=params.cone, impratio=params.impratio)


def cube_toss_layout() -> dict[str, slice]:
    """Observation layout of :class:`CubeTossEnv`."""
    return layout(("tossed", 1), ("position", 3), ("quaternion", 4), ("target_rel_xy", 2),
                  ("target_xy", 2), ("target_yaw", 2), ("yaw_error", 1))


class CubeTossEnv(MjDynamicsEnv):
    """Toss the real ContactNets cube (10.5 cm, 0.37 kg) so that it comes to rest at a target pose.

    An episode is one toss. At reset the cube is held at ``release_position`` in a random
    orientation and a target pose on the floor is drawn (a position ``target_distance`` from the
    release point in any direction, and a heading). The action sets the release velocity and spin
    within the range of the real rig's tosses (5th to 95th percentiles of the training tosses'
    initial velocities: horizontal speed 1.0 to 1.27 m/s in any direction, vertical -0.4 to 0.13
    m/s, spin up to about 4 rad/s); the cube then flies, lands, bounces, slides and comes to rest
    during ``settle_steps`` learned steps of the data's 6.76 ms (1 s by default: the real tosses
    stop within 0.8 s). ``dynamics="fignet"`` is the ``cube-real`` simulator learned from the
    real tosses; ``dynamics="mujoco"`` is MuJoCo with the parameters fitted to the same tosses
    (``mujoco_params``, see :func:`mujoco_parameters`; nominal ones, marked as such in
    ``info["mujoco_source"]``, if no fit is shipped). The learned model always gets the
    nominal scene it was trained with (its friction and restitution inputs are the data's).
    The two agree to a few cm on where the cube comes to rest (tosses of ~0.4 m: median 4.2 cm,
    worst 9.1 cm over 32 seeded random actions; the errors of each against held-out real tosses
    are in ``fignet_gym/pretrained/cube-real.md``).

    ## Action space

    ``Box(-1, 1, (6,), float32)``, each entry mapped linearly to its range; out-of-range values
    are clipped, NaN/inf raise ``ValueError``.

    | index | action | unit |
    |---|---|---|
    | 0:1 | release heading (direction of horizontal velocity) | rad, ``[-pi, pi]`` |
    | 1:2 | horizontal release speed | m/s, ``speed_range`` |
    | 2:3 | vertical release velocity | m/s, ``vertical_range`` |
    | 3:6 | spin (angular velocity, world x y z) | rad/s, ``spin_range`` per axis |

    ## Observation space

    ``Box(-inf, inf, (15,), float32)``; positions in metres, the cube's pose at release before the
    toss and at rest after it.

    | index | name | meaning |
    |---|---|---|
    | 0:1 | tossed | 0 before the toss, 1 after |
    | 1:4 | position | cube centre (world, m) |
    | 4:8 | quaternion | cube orientation (w, x, y, z) |
    | 8:10 | target_rel_xy | cube xy minus target xy (m) |
    | 10:12 | target_xy | target position on the floor (m) |
    | 12:14 | target_yaw | cos and sin of 4 x the target heading (a cube looks the same every 90 degrees) |
    | 14:15 | yaw_error | cube heading minus target heading, modulo 90 degrees (rad, ``[-pi/4, pi/4)``) |

    ## Reward

    The sum of these terms, each in ``info`` (``d``: xy distance of the resting cube from the
    target; ``psi``: heading error modulo 90 degrees, rad):

    | info key | term |
    |---|---|
    | reward_distance | ``-distance_weight * d`` |
    | reward_yaw | ``-yaw_weight * abs(psi)`` |
    | reward_success | ``success_bonus`` if ``d <= target_radius`` and ``abs(psi) <= yaw_tolerance`` |

    ``info`` also holds ``distance`` (m), ``yaw_error_deg``, ``is_success``, ``speed`` (m/s at the
    end: how nearly at rest the cube is), ``mujoco_source``; ``info["diverged"]`` names a
    dynamics failure.

    ## Episode end

    Terminated after the toss (one step); truncated when the dynamics diverged.

    ## Arguments

    | argument | default | meaning |
    |---|---|---|
    | dynamics | ``"mujoco"`` | ``"mujoco"`` (fitted), ``"fignet"`` (``cube-real``) or a ``Dynamics`` object |
    | checkpoint | ``None`` | ``"fignet"``: path, name or ``LearnedSimulator`` (default ``cube-real``) |
    | mujoco_params | ``"fitted"`` | ``"fitted"``, ``"nominal"``, a JSON path or a dict |
    | settle_steps | ``148`` | learned steps of 6.76 ms per toss (1 s) |
    | release_position | ``(0.0, 0.0, 0.14)`` | where the cube is released (m; the rig's median height) |
    | speed_range | ``(1.0, 1.27)`` | horizontal release speed at action -1 and +1 (m/s) |
    | vertical_range | ``(-0.4, 0.13)`` | vertical release velocity range (m/s) |
    | spin_range | ``(4.0, 4.0, 1.2)`` | largest spin about world x, y, z (rad/s, symmetric) |
    | target_distance | ``(0.2, 0.45)`` | range of the target's distance from the release point (m) |
    | target_radius | ``0.03`` | success radius (m) |
    | yaw_tolerance | ``0.1745`` | success heading tolerance (rad, 10 degrees) |
    | distance_weight | ``10.0`` | reward weight of the distance (1/m) |
    | yaw_weight | ``1.0`` | reward weight of the heading error (1/rad) |
    | success_bonus | ``1.0`` | reward of a success |
    | render_mode | ``None`` | ``"rgb_array"`` or ``None`` |
    | width | ``480`` | rendered frame width (px) |
    | height | ``480`` | rendered frame height (px) |
    | dynamics_kwargs | ``None`` | extra dynamics arguments (e.g. fignet's ``max_distance``) |
    """

    scene_type = "cube-real"

    def __init__(
        self,
        dynamics: str | Dynamics = "mujoco",
        checkpoint: Any = None,
        mujoco_params: str | os.PathLike | dict[str, Any] = "fitted",
        settle_steps: int = 148,
        release_position: tuple[float, float, float] = (0.0, 0.0, 0.14),
        speed_range: tuple[float, float] = (1.0, 1.27),
        vertical_range: tuple[float, float] = (-0.4, 0.13),
        spin_range: tuple[float, float, float] = (4.0, 4.0, 1.2),
        target_distance: tuple[float, float] = (0.2, 0.45),
        target_radius: float = 0.03,
        yaw_tolerance: float = 0.1745,
        distance_weight: float = 10.0,
        yaw_weight: float = 1.0,
        success_bonus: float = 1.0,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        dynamics_kwargs: dict[str, Any] | None = None,
    ) -> None:
        if settle_steps < 1:
            raise ValueError(f"settle_steps must be >= 1, got {settle_steps}")
        self.settle_steps = int(settle_steps)
        self.release_position = np.asarray(release_position, dtype=np.float64)
        self.speed_range = np.asarray(speed_range, dtype=np.float64)
        self.vertical_range = np.asarray(vertical_range, dtype=np.float64)
        self.spin_range = np.asarray(spin_range, dtype=np.float64)
        self.target_distance = np.asarray(target_distance, dtype=np.float64)
        if (self.release_position.shape != (3,) or self.speed_range.shape != (2,)
                or self.vertical_range.shape != (2,) or self.spin_range.shape != (3,)
                or self.target_distance.shape != (2,)):
            raise ValueError("release_position and spin_range need 3 entries; speed_range, "
                             "vertical_range and target_distance 2")
        if self.release_position[2] < CUBE_HALF_WIDTH * math.sqrt(3) + 1e-3:
            raise ValueError(f"release_position z must clear the floor in any orientation "
                             f"(> {CUBE_HALF_WIDTH * math.sqrt(3):.3f} m)")
        self.target_radius, self.yaw_tolerance = float(target_radius), float(yaw_tolerance)
        self.distance_weight, self.yaw_weight = float(distance_weight), float(yaw_weight)
        self.success_bonus = float(success_bonus)
        # The learned model sees the scene it was trained on (its props are input features);
        # only MuJoCo gets the fitted contact parameters.
        self.mujoco_params = mujoco_parameters(mujoco_params if dynamics == "mujoco" else "nominal")
        model = compile_with_history(cube_toss_xml(self.mujoco_params))
        self.settle_frame_skip = round(DATA_DT / model.opt.timestep)  # per learned step
        self.task = CubeTossTask(
            model, self.speed_range, self.vertical_range, self.spin_range, self.target_radius,
            self.yaw_tolerance, self.distance_weight, self.yaw_weight, self.success_bonus)
        self.observation_layout = cube_toss_layout()
        self.action_space = spaces.Box(-1.0, 1.0, (6,), np.float32)
        self.observation_space = spaces.Box(
            -np.inf, np.inf, (layout_size(self.observation_layout),), np.float32)
        super().__init__(model, dynamics, checkpoint, self.settle_frame_skip * self.settle_steps,
                         render_mode,
                         width, height, dynamics_kwargs)

    def _init_state(self) -> None:
        super()._init_state()
        self.target = np.zeros(2)
        self.target_yaw = 0.0
        self.tossed = False

    # ----------------------------------------------------------------- task
    def _reset_task(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        angle = rng.uniform(-np.pi, np.pi)
        dist = rng.uniform(*self.target_distance)
        self.target = self.release_position[:2] + dist * np.array([np.cos(angle), np.sin(angle)])
        self.target_yaw = float(rng.uniform(-np.pi / 4, np.pi / 4))
        q = rng.normal(size=4)
        self.data.qpos[:7] = (*self.release_position, *(q / np.linalg.norm(q)))
        self.data.qvel[:] = 0.0
        self.tossed = False

    def release_velocity(self, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World linear ``float[3]`` (m/s) and angular ``float[3]`` (rad/s) velocity of an action."""
        return self.task.release_velocity(action)

    def task_context(self) -> dict[str, Any]:
        """The episode's target pose, for :class:`~fignet_gym.envs.tasks.CubeTossTask`."""
        return {**super().task_context(), "target": self.target.copy(),
                "target_yaw": self.target_yaw}

    def _check_ready(self) -> None:
        if self.tossed:
            raise RuntimeError(f"{type(self).__name__}: the cube was tossed; call reset()")

    def _apply_action(self, action: np.ndarray) -> None:
        self._check_ready()
        mujoco.mj_setState(self.model, self.data, self.task.release(self.get_state(), action),
                           STATE_SPEC)
        self.tossed = True

    def _yaw_error(self) -> float:
        return float(self.task.errors(self.get_state(), self.target, self.target_yaw)[1])

    def _observe(self) -> np.ndarray:
        lay = self.observation_layout
        obs = np.zeros(layout_size(lay), dtype=np.float64)
        obs[lay["tossed"]] = float(self.tossed)
        obs[lay["position"]] = self.data.qpos[:3]
        obs[lay["quaternion"]] = self.data.qpos[3:7]
        obs[lay["target_rel_xy"]] = self.data.qpos[:2] - self.target
        obs[lay["target_xy"]] = self.target
        obs[lay["target_yaw"]] = (np.cos(4 * self.target_yaw), np.sin(4 * self.target_yaw))
        obs[lay["yaw_error"]] = self._yaw_error()
        return obs.astype(np.float32)

    def _evaluate(self, action: np.ndarray) -> tuple[dict[str, float], bool, bool, dict[str, Any]]:
        state = self.get_state()
        dist, psi = (float(x) for x in self.task.errors(state, self.target, self.target_yaw))
        success = bool(self.task.is_success(state, self.target, self.target_yaw))
        terms = {k: float(v) for k, v in
                 self.task.reward_terms(state, self.target, self.target_yaw).items()}
        info = {"distance": dist, "yaw_error_deg": math.degrees(psi),
                "is_success": success,  # SB3's key (evaluate_policy), as in Push
                "speed": float(np.linalg.norm(self.data.qvel[:3])),
                "mujoco_source": self.mujoco_params.source}
        return terms, True, False, info

    def _camera(self) -> mujoco.MjvCamera:
        return free_camera((*self.release_position[:2], 0.05), 1.6, -135.0, -40.0)

    def _decorate(self, scene: mujoco.MjvScene) -> None:
        add_disc(scene, (*self.target, 0.001), self.target_radius, (0.1, 0.8, 0.2, 0.5))


class CubeTossVectorEnv(SingleEnvVectorEnv):
    """``num_envs`` :class:`CubeTossEnv` stepped by one batched dynamics call; arguments as
    :class:`~fignet_gym.envs.vector.SingleEnvVectorEnv`.

    ``max_episode_steps=None``: an episode is one toss.
    """

    env_class = CubeTossEnv
