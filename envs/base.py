"""Shared machinery of the fignet_gym environments: one MuJoCo model, one :class:`Dynamics`.

An environment only ever talks to a :class:`~fignet_gym.dynamics.Dynamics` (``step`` /
``step_many``): whether MuJoCo or a learned FIGNet model moves the objects is decided once, by the
``dynamics=`` argument, and never branched on afterwards. One environment step is split in three
so that the vector environment (:mod:`fignet_gym.envs.vector`) can run the physics of many
environments in one batched call:

1. :meth:`MjDynamicsEnv._pre_step` checks the action and writes it into ``MjData`` (mocap targets,
   a released object's velocity);
2. the dynamics advances ``MjData`` by :attr:`MjDynamicsEnv.frame_skip` MuJoCo timesteps
   (Gymnasium's ``frame_skip``; :attr:`MjDynamicsEnv.dt` seconds);
3. :meth:`MjDynamicsEnv._post_step` computes observation, reward and termination.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from fignet_gym.dynamics import STATE_SPEC, DivergenceError, Dynamics, make_dynamics
from fignet_gym.envs.tasks import wrap_angle, yaw_of  # noqa: F401  (re-exported)


class MjDynamicsEnv(gym.Env[np.ndarray, np.ndarray]):
    """Base class: a compiled ``MjModel``, its ``MjData`` and the :class:`Dynamics` that steps it.

    Subclasses set :attr:`scene_type`, build the model and implement :meth:`_reset_task`,
    :meth:`_apply_action`, :meth:`_observe` and :meth:`_evaluate`.

    Attributes:
        model: the compiled scene (shared, read-only).
        data: this environment's state.
        dynamics: what advances ``data``.
        frame_skip: MuJoCo timesteps per environment step (Gymnasium's ``frame_skip``).
        observation_layout: name -> slice of the observation vector (as the class docstring says).
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 50}
    scene_type: str = ""
    #: Shipped simulator ``dynamics="fignet"`` loads without ``checkpoint=`` (default: the
    #: :attr:`scene_type`'s); an old env version names the model trained on its physics.
    default_checkpoint: str = ""
    observation_layout: dict[str, slice] = {}

    def __init__(
        self,
        model: mujoco.MjModel,
        dynamics: str | Dynamics,
        checkpoint: Any,
        frame_skip: int,
        render_mode: str | None,
        width: int,
        height: int,
        dynamics_kwargs: dict[str, Any] | None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"{type(self).__name__}: render_mode must be one of "
                f"{self.metadata['render_modes']} or None, got {render_mode!r}"
            )
        self.model = model
        self.frame_skip = int(frame_skip)
        if (checkpoint is None and dynamics == "fignet" and self.default_checkpoint
                and self.default_checkpoint != self.scene_type):
            checkpoint = self.default_checkpoint
        self.dynamics = make_dynamics(
            dynamics, checkpoint, self.scene_type, **(dynamics_kwargs or {})
        )
        self.dynamics.validate(model, self.frame_skip, self.scene_type)
        self.render_mode = render_mode
        self.width, self.height = int(width), int(height)
        self.metadata = {
            **self.metadata,
            "render_fps": max(1, round(1.0 / self.dt)),
        }
        self._init_state()

    @property
    def dt(self) -> float:
        """Seconds per environment step: ``frame_skip * model.opt.timestep`` (as Gymnasium's
        MuJoCo environments define it)."""
        return self.frame_skip * float(self.model.opt.timestep)

    def _init_state(self) -> None:
        """Per-instance state: ``MjData``, renderer, random generator (also for :meth:`_spawn`)."""
        self.data = mujoco.MjData(self.model)
        self._was_reset = False  # stepping a never-reset environment would use unsampled task state
        self._renderer: mujoco.Renderer | None = None
        self._np_random = None
        self._np_random_seed = None

    def get_state(self) -> np.ndarray:
        """``float64[nstate]`` the whole current state (:data:`~fignet_gym.dynamics.STATE_SPEC`:
        full physics and mocap poses): what ``Dynamics.rollout`` starts from and the tasks of
        :mod:`fignet_gym.envs.tasks` score."""
        out = np.empty(mujoco.mj_stateSize(self.model, STATE_SPEC))
        mujoco.mj_getState(self.model, self.data, out, STATE_SPEC)
        return out

    def set_state(self, state: np.ndarray) -> None:
        """Load a :meth:`get_state` state ``float64[nstate]`` into ``data`` and forward it (the
        task, e.g. the goal, is unchanged)."""
        mujoco.mj_setState(self.model, self.data, np.asarray(state, dtype=np.float64), STATE_SPEC)
        mujoco.mj_forward(self.model, self.data)

    def task_context(self) -> dict[str, Any]:
        """What the task of this episode needs besides the state (``env.task``'s
        ``plan_rollout``/``plan_cost`` keywords): ``frame_skip`` and, per env, its goal or
        target."""
        return {"frame_skip": self.frame_skip}

    def observe(self) -> np.ndarray:
        """The observation ``float32[D]`` of the current state (what ``step`` would return)."""
        return self._observe()

    def _spawn(self) -> MjDynamicsEnv:
        """A new environment sharing this one's model, dynamics and configuration (fresh state)."""
        new = copy.copy(self)
        new._init_state()
        return new

    # ----------------------------------------------------------------- subclass hooks
    def _reset_task(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        """Sample a task, write the initial state into ``self.data`` (``mj_forward`` follows)."""
        raise NotImplementedError

    def _apply_action(self, action: np.ndarray) -> None:
        """Write a checked, clipped action ``float[A]`` into ``self.data``."""
        raise NotImplementedError

    def _observe(self) -> np.ndarray:
        """Observation ``float32[D]`` of the current state."""
        raise NotImplementedError

    def _evaluate(self, action: np.ndarray) -> tuple[dict[str, float], bool, bool, dict[str, Any]]:
        """Reward terms (summed into the reward), terminated, truncated and extra info."""
        raise NotImplementedError

    # ----------------------------------------------------------------- gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Seeded reset; returns the first observation and an (empty) info dictionary."""
        super().reset(seed=seed)
        mujoco.mj_resetData(self.model, self.data)
        self._reset_task(self.np_random, options)
        mujoco.mj_forward(self.model, self.data)
        self._was_reset = True
        return self._observe(), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One environment step (``frame_skip`` MuJoCo timesteps of ``dynamics``)."""
        self._check_was_reset()
        act = self._pre_step(action)
        reason = None
        try:
            self.dynamics.step(self.model, self.data, self.frame_skip)
        except DivergenceError as err:
            reason = err.reason
        return self._post_step(act, reason)

    def _pre_step(self, action: Any) -> np.ndarray:
        """Validate (:meth:`_check_step`), clip and apply the action."""
        act = self._check_step(action)
        self._apply_action(act)
        return act

    def _check_step(self, action: Any) -> np.ndarray:
        """The clipped action ``float64[A]`` if this environment may step with it, changing
        nothing: ``ValueError`` for a wrong shape or a NaN/inf, ``RuntimeError`` when
        :meth:`_check_ready` refuses. The vector environment checks every row this way before
        applying any, so a rejected batch changes no state."""
        act = check_action(type(self).__name__, action, self.action_space)
        self._check_ready()
        return act

    def _check_was_reset(self) -> None:
        """``RuntimeError`` if ``step`` comes before the first ``reset`` (whose task state, goal
        or target, the step would otherwise silently use unsampled)."""
        if not self._was_reset:
            raise RuntimeError(f"{type(self).__name__}: call reset() before step()")

    def _check_ready(self) -> None:
        """Raise ``RuntimeError`` if the episode cannot take another step (subclass hook)."""

    def _post_step(
        self, action: np.ndarray, diverged: str | None
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Observation, reward (sum of the ``reward_*`` info terms), terminated, truncated, info."""
        terms, terminated, truncated, info = self._evaluate(action)
        if diverged is not None:
            truncated = True
            info["diverged"] = diverged
        reward = float(sum(terms.values()))
        return self._observe(), reward, bool(terminated), bool(truncated), {**terms, **info}

    def _post_step_many(
        self, envs: Sequence[MjDynamicsEnv], actions: Sequence[np.ndarray],
        diverged: Sequence[str | None]
    ) -> list[tuple[np.ndarray, float, bool, bool, dict[str, Any]]]:
        """:meth:`_post_step` of each of ``envs`` (sub-environments spawned from this one) after
        one batched dynamics step; a subclass may compute them together."""
        return [e._post_step(a, d) for e, a, d in zip(envs, actions, diverged, strict=True)]

    def render(self) -> np.ndarray | None:
        """``uint8[height, width, 3]`` frame of the current state (MuJoCo's renderer)."""
        if self.render_mode is None:
            gym.logger.warn(
                f"{type(self).__name__}.render() called without render_mode='rgb_array'"
            )
            return None
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, self.height, self.width)
        self._renderer.update_scene(self.data, camera=self._camera())
        self._decorate(self._renderer.scene)
        return self._renderer.render()

    def _camera(self) -> int | str | mujoco.MjvCamera:
        """Camera to render from (default: MuJoCo's free camera)."""
        return -1

    def _decorate(self, scene: mujoco.MjvScene) -> None:
        """Add visual-only markers (goals, targets) to the scene before rendering."""

    def close(self) -> None:
        """Release the renderer (the dynamics and model are shared and stay usable)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def check_action(owner: str, action: Any, space: gym.spaces.Box) -> np.ndarray:
    """``float64[A]`` action clipped to ``space``; ``ValueError`` naming ``owner`` if malformed."""
    try:
        act = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{owner}: action {action!r} is not numeric") from exc
    if act.shape != space.shape:
        raise ValueError(f"{owner}: action must have shape {space.shape}, got {act.shape}")
    if not np.isfinite(act).all():
        raise ValueError(f"{owner}: action {act.tolist()} contains NaN or infinite values")
    return np.clip(act, space.low, space.high)


def check_arguments(owner: str, **checks: tuple[Any, str]) -> None:
    """Validate constructor arguments, ``ValueError`` naming the first bad one.

    Each keyword is ``name=(value, rule)``; rules: ``"positive"`` / ``"nonnegative"`` /
    ``"finite"`` (a real number), ``"count"`` (an integer >= 1), ``"vector<n>"`` (``n`` finite
    numbers); a trailing ``"?"`` also allows ``None``.
    """
    for name, (value, rule) in checks.items():
        if rule.endswith("?"):
            if value is None:
                continue
            rule = rule[:-1]
        if rule == "count":
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{owner}: {name} must be an integer >= 1, got {value!r}")
            continue
        if rule.startswith("vector"):
            n = int(rule[6:])
            try:
                arr = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError):
                arr = np.zeros(0)
            if arr.shape != (n,) or not np.isfinite(arr).all():
                raise ValueError(f"{owner}: {name} must be {n} finite numbers, got {value!r}")
            continue
        ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
        ok = ok and bool(np.isfinite(value))
        if ok and rule == "positive":
            ok = value > 0
        elif ok and rule == "nonnegative":
            ok = value >= 0
        if not ok:
            what = {"positive": "a finite number > 0", "nonnegative": "a finite number >= 0",
                    "finite": "a finite number"}[rule]
            raise ValueError(f"{owner}: {name} must be {what}, got {value!r}")


def layout(*entries: tuple[str, int]) -> dict[str, slice]:
    """Consecutive named slices of an observation vector from ``(name, size)`` pairs."""
    out, start = {}, 0
    for name, size in entries:
        out[name] = slice(start, start + size)
        start += size
    return out


def layout_size(lay: dict[str, slice]) -> int:
    """Total length of a :func:`layout`."""
    return max((s.stop for s in lay.values()), default=0)


def free_camera(
    lookat: Sequence[float], distance: float, azimuth: float, elevation: float
) -> mujoco.MjvCamera:
    """A free ``MjvCamera`` aimed at ``lookat float[3]`` from ``distance`` (m), ``azimuth`` and
    ``elevation`` (deg)."""
    cam = mujoco.MjvCamera()
    cam.lookat[:] = lookat
    cam.distance, cam.azimuth, cam.elevation = distance, azimuth, elevation
    return cam


def add_disc(
    scene: mujoco.MjvScene, pos: Sequence[float], radius: float, rgba: Sequence[float]
) -> None:
    """Draw a flat translucent disc (a visual-only geom) into a MuJoCo scene."""
    if scene.ngeom >= scene.maxgeom:
        return
    mujoco.mjv_initGeom(
        scene.geoms[scene.ngeom],
        int(mujoco.mjtGeom.mjGEOM_CYLINDER),
        np.array([radius, 0.001, 0.0]),
        np.asarray(pos, dtype=np.float64),
        np.eye(3).ravel(),
        np.asarray(rgba, dtype=np.float32),
    )
    scene.ngeom += 1
