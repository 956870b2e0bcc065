"""The swap point between analytic and learned dynamics, mirroring MuJoCo's own calls.

A :class:`Dynamics` advances ``mujoco.MjData`` exactly where ``mujoco.mj_step`` would:

* ``step(model, data, nstep)``: like ``mujoco.mj_step(model, data, nstep)``: advances ``data`` in
  place by ``nstep`` MuJoCo timesteps (free-joint ``qpos``/``qvel``, ``time``) and leaves every
  derived quantity (``xpos``, contacts, rendering) consistent.
* ``step_many(model, datas, nstep)``: ``step`` on many ``MjData`` of one model at once (the learned
  dynamics runs them as one batched graph).
* ``rollout(model, initial_state, control, nstep, frame_skip=...)``: shaped like
  ``mujoco.rollout.rollout``: full-physics states ``float64[B, nstate]`` in, mocap trajectories as
  control, states ``float64[B, nstep, nstate]`` out.

Kinematic bodies are mocap bodies: before a step, set ``data.mocap_pos``/``mocap_quat`` to where
they should be at the *end* of the step; both implementations move them there linearly from their
current pose, as the pusher moves in the training data. Time-step contract:
``docs/architecture.md``.

Two implementations: :class:`MujocoDynamics` (``mj_step``, ``mujoco.rollout``) and
:class:`~fignet_gym.learned_dynamics.FIGNetDynamics` (a
:class:`~fignet_gym.simulator.LearnedSimulator`, in its own module). A user's own class
works too: subclass :class:`DynamicsBase` and implement ``step``, or implement the whole protocol.
"""

from __future__ import annotations

import os
import weakref
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import mujoco
import numpy as np

if TYPE_CHECKING:
    from fignet_gym.simulator import LearnedSimulator

#: State layout of :meth:`Dynamics.rollout` (``mujoco.rollout``'s): time, qpos, qvel, act, ...
STATE_SPEC = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
#: Control layout of :meth:`Dynamics.rollout`: every mocap position, then every mocap quaternion.
CONTROL_SPEC = int(mujoco.mjtState.mjSTATE_MOCAP_POS | mujoco.mjtState.mjSTATE_MOCAP_QUAT)


class DivergenceError(RuntimeError):
    """A simulation blew up: non-finite or runaway poses (learned), or MuJoCo's own instability.

    Attributes:
        reason: what went wrong, naming the object and the time.
        indices: for ``step_many``, positions in ``datas`` of the simulations that diverged (the
            others were advanced normally; the diverged ones are left as they were before the call,
            except that MuJoCo resets a simulation it found unstable).
        reasons: one reason per entry of ``indices``.
    """

    def __init__(
        self, reason: str, indices: Sequence[int] = (0,), reasons: Sequence[str] | None = None
    ) -> None:
        super().__init__(reason)
        self.reason = reason
        self.indices = tuple(int(i) for i in indices)
        self.reasons = tuple(reasons) if reasons is not None else (reason,) * len(self.indices)


@runtime_checkable
class Dynamics(Protocol):
    """What an environment needs from a physics backend (see the module docstring)."""

    def step(self, model: mujoco.MjModel, data: mujoco.MjData, nstep: int = 1) -> None:
        """Advance ``data`` in place by ``nstep`` MuJoCo timesteps, like ``mujoco.mj_step``.

        Raises :class:`DivergenceError` if the simulation blew up.
        """
        ...

    def step_many(
        self, model: mujoco.MjModel, datas: Sequence[mujoco.MjData], nstep: int = 1
    ) -> None:
        """:meth:`step` on ``B = len(datas)`` simulations of one model.

        Raises :class:`DivergenceError` with ``indices`` of the simulations that blew up, after
        advancing all the others.
        """
        ...

    def rollout(
        self,
        model: mujoco.MjModel,
        initial_state: np.ndarray,
        control: np.ndarray | None = None,
        nstep: int | None = None,
        *,
        frame_skip: int = 1,
    ) -> np.ndarray:
        """Open-loop rollouts: ``float64[B, nstate]`` states and ``float64[B, nstep, nmocap * 7]``
        mocap targets (each reached over ``frame_skip`` timesteps) -> ``float64[B, nstep, nstate]``."""
        ...

    def validate(self, model: mujoco.MjModel, nstep: int, scene_type: str = "") -> None:
        """Raise ``ValueError`` if this dynamics cannot step ``model`` (a scene of kind
        ``scene_type``: ``"push"``, ``"toss"`` or ``""``) by ``nstep`` timesteps at a time."""
        ...


# --------------------------------------------------------------------------- shared helpers
def _check_rollout_inputs(
    model: mujoco.MjModel, initial_state: np.ndarray, control: np.ndarray | None, nstep: int | None
) -> tuple[np.ndarray, np.ndarray, int]:
    """Validate and broadcast rollout inputs.

    Returns ``float64[B, nstate]`` states, ``float64[B, T, ncontrol]`` controls and ``T``.
    """
    nstate = mujoco.mj_stateSize(model, STATE_SPEC)
    ncontrol = mujoco.mj_stateSize(model, CONTROL_SPEC)
    state = np.asarray(initial_state, dtype=np.float64)
    if state.ndim == 1:
        state = state[None]
    if state.ndim != 2 or state.shape[1] != nstate:
        raise ValueError(
            f"initial_state must be float[B, {nstate}] (mjSTATE_FULLPHYSICS), "
            f"got shape {np.shape(initial_state)}"
        )
    if control is None:
        if nstep is None:
            raise ValueError("rollout needs control or nstep")
        if ncontrol:
            raise ValueError(
                f"the model has mocap bodies: control float[B, nstep, {ncontrol}] is required"
            )
        control = np.zeros((state.shape[0], nstep, 0))
    control = np.asarray(control, dtype=np.float64)
    if control.ndim == 2:
        control = control[None]
    if control.ndim != 3 or control.shape[2] != ncontrol:
        raise ValueError(
            f"control must be float[B, nstep, {ncontrol}] (mocap_pos then mocap_quat), "
            f"got shape {np.shape(control)}"
        )
    nstep = control.shape[1] if nstep is None else int(nstep)
    if control.shape[1] not in (1, nstep):
        raise ValueError(f"control has {control.shape[1]} steps, nstep is {nstep}")
    B = max(state.shape[0], control.shape[0])
    if state.shape[0] not in (1, B) or control.shape[0] not in (1, B):
        raise ValueError(
            f"batch sizes differ: initial_state {state.shape[0]}, control {control.shape[0]}"
        )
    if not (np.isfinite(state).all() and np.isfinite(control).all()):
        raise ValueError("rollout inputs contain NaN or infinite values")
    state = np.broadcast_to(state, (B, nstate))
    control = np.broadcast_to(control, (B, nstep, ncontrol))
    return np.ascontiguousarray(state), np.ascontiguousarray(control), nstep


def _set_mocap(model: mujoco.MjModel, data: mujoco.MjData, control_row: np.ndarray) -> None:
    """Write one control row (mocap_pos then mocap_quat, ``float[nmocap * 7]``) into ``data``."""
    nm = model.nmocap
    data.mocap_pos[:] = control_row[: 3 * nm].reshape(nm, 3)
    data.mocap_quat[:] = control_row[3 * nm :].reshape(nm, 4)


class DynamicsBase:
    """Defaults for a :class:`Dynamics`: subclasses implement :meth:`step` only.

    ``step_many`` loops over ``step``, ``rollout`` loops ``step`` on a scratch ``MjData`` (mocap
    bodies start at ``control[:, 0]``), ``validate`` accepts everything.
    """

    def step(self, model: mujoco.MjModel, data: mujoco.MjData, nstep: int = 1) -> None:
        """Advance ``data`` by ``nstep`` timesteps (to implement); see :meth:`Dynamics.step`."""
        raise NotImplementedError

    def step_many(
        self, model: mujoco.MjModel, datas: Sequence[mujoco.MjData], nstep: int = 1
    ) -> None:
        """Loop of :meth:`step`; see :meth:`Dynamics.step_many`."""
        bad, reasons = [], []
        for i, d in enumerate(datas):
            try:
                self.step(model, d, nstep)
            except DivergenceError as err:
                bad.append(i)
                reasons.append(err.reason)
        if bad:
            raise DivergenceError(
                "; ".join(f"[{i}] {r}" for i, r in zip(bad, reasons, strict=True)), bad, reasons
            )

    def rollout(
        self,
        model: mujoco.MjModel,
        initial_state: np.ndarray,
        control: np.ndarray | None = None,
        nstep: int | None = None,
        *,
        frame_skip: int = 1,
    ) -> np.ndarray:
        """A loop of :meth:`step` per rollout (see :meth:`Dynamics.rollout`); diverged rows: NaN."""
        state, control, nstep = _check_rollout_inputs(model, initial_state, control, nstep)
        out = np.full((state.shape[0], nstep, state.shape[1]), np.nan)
        data = mujoco.MjData(model)
        for b in range(state.shape[0]):
            rollout_loop(self, model, data, state[b], control[b], frame_skip, out[b])
        return out

    def validate(self, model: mujoco.MjModel, nstep: int, scene_type: str = "") -> None:
        """Accept every model (override to check)."""


def rollout_loop(
    dynamics: Dynamics,
    model: mujoco.MjModel,
    data: mujoco.MjData,
    initial_state: np.ndarray,
    control: np.ndarray,
    frame_skip: int,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """One rollout as a loop of single :meth:`Dynamics.step` calls (the reference for ``rollout``).

    ``data`` is reset, loaded with ``initial_state float64[nstate]``, its mocap bodies placed at
    ``control[0]`` (``float64[T, nmocap * 7]``) and forwarded; then each control row is applied
    and ``frame_skip`` timesteps taken. Returns the states ``float64[T, nstate]`` (rows after a
    :class:`DivergenceError` are NaN).
    """
    T = control.shape[0]
    out = np.full((T, mujoco.mj_stateSize(model, STATE_SPEC)), np.nan) if out is None else out
    mujoco.mj_resetData(model, data)
    mujoco.mj_setState(model, data, np.asarray(initial_state, dtype=np.float64), STATE_SPEC)
    _set_mocap(model, data, control[0])
    mujoco.mj_forward(model, data)
    for t in range(T):
        _set_mocap(model, data, control[t])
        try:
            dynamics.step(model, data, frame_skip)
        except DivergenceError:
            break
        mujoco.mj_getState(model, data, out[t], STATE_SPEC)
    return out


# --------------------------------------------------------------------------- MuJoCo
_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
)


class MujocoDynamics(DynamicsBase):
    """MuJoCo itself: ``mujoco.mj_step`` and threaded ``mujoco.rollout``.

    ``step`` is ``mujoco.mj_step(model, data, nstep)``, then raises :class:`DivergenceError` if
    MuJoCo reported an instability (bad ``qacc``/``qpos``/``qvel`` warnings; MuJoCo has then
    already reset ``data``). Mocap targets move linearly over the ``nstep`` timesteps, from the
    mocap bodies' current poses (``xpos``/``xquat``) to ``mocap_pos``/``mocap_quat``, as the
    training data's pusher does: holding a target for all substeps would make the pusher jump and
    kick the object (a 0.1 m/s push launched it at 0.7 m/s). With targets at the current poses,
    ``step`` is exactly ``mj_step``.

    Args:
        nthread: threads of :meth:`rollout` (default: the CPU count).
    """

    def __init__(self, nthread: int | None = None) -> None:
        self.nthread = int(nthread or os.cpu_count() or 1)
        self._pool: mujoco.rollout.Rollout | None = None
        self._scratch: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def step(self, model: mujoco.MjModel, data: mujoco.MjData, nstep: int = 1) -> None:
        """``mujoco.mj_step(model, data, nstep)``; :class:`DivergenceError` if MuJoCo blew up."""
        before = [data.warning[w].number for w in _WARNINGS]
        bodies = _mocap_bodies(model)
        start = np.concatenate((data.xpos[bodies].ravel(), data.xquat[bodies].ravel()))
        target = np.concatenate((data.mocap_pos.ravel(), data.mocap_quat.ravel()))
        if nstep == 1 or np.array_equal(start, target):
            mujoco.mj_step(model, data, nstep)
        else:
            path = _interpolate_mocap(start[None], target[None, None], nstep, model.nmocap)[0]
            for row in path:
                data.mocap_pos[:] = row[: 3 * model.nmocap].reshape(-1, 3)
                data.mocap_quat[:] = row[3 * model.nmocap :].reshape(-1, 4)
                mujoco.mj_step(model, data, 1)
        after = [data.warning[w].number for w in _WARNINGS]
        if after != before:
            names = [w.name for w, a, b in zip(_WARNINGS, after, before, strict=True) if a != b]
            raise DivergenceError(
                f"MuJoCo reported {', '.join(names)} at t={data.time:.3f}s "
                "(it reset the simulation)"
            )

    def rollout(
        self,
        model: mujoco.MjModel,
        initial_state: np.ndarray,
        control: np.ndarray | None = None,
        nstep: int | None = None,
        *,
        frame_skip: int = 1,
    ) -> np.ndarray:
        """``mujoco.rollout`` on a persistent thread pool, one state per ``frame_skip`` timesteps.

        Args:
            initial_state: ``float64[B or 1, nstate]`` (``mjSTATE_FULLPHYSICS``).
            control: ``float64[B or 1, nstep, nmocap * 7]`` mocap targets (positions, then
                quaternions): row ``t`` is reached linearly over the ``frame_skip`` timesteps of
                step ``t``, from row ``t - 1`` (from the initial state's mocap pose for ``t = 0``).
            nstep: number of recorded states (default: ``control.shape[1]``).
            frame_skip: MuJoCo timesteps per recorded state (1: exactly ``mujoco.rollout``).

        Returns:
            ``float64[B, nstep, nstate]`` the state after each ``frame_skip`` timesteps.
        """
        state, control, nstep = _check_rollout_inputs(model, initial_state, control, nstep)
        if frame_skip < 1:
            raise ValueError(f"frame_skip must be >= 1, got {frame_skip}")
        from mujoco import rollout as mj_rollout

        if self._pool is None:
            self._pool = mj_rollout.Rollout(nthread=self.nthread if self.nthread > 1 else 0)
        datas = self._scratch.get(model)
        if datas is None:
            datas = [mujoco.MjData(model) for _ in range(max(self.nthread, 1))]
            self._scratch[model] = datas
        fine = control
        if frame_skip > 1 and model.nmocap:
            start = np.empty((state.shape[0], control.shape[2]))
            scratch = datas[0]
            for b in range(state.shape[0]):
                mujoco.mj_setState(model, scratch, state[b], STATE_SPEC)
                start[b] = np.concatenate((scratch.mocap_pos.ravel(), scratch.mocap_quat.ravel()))
            fine = _interpolate_mocap(start, control, frame_skip, model.nmocap)
        elif frame_skip > 1:
            fine = np.repeat(control, frame_skip, axis=1)
        out, _ = self._pool.rollout(
            model, datas, state, fine, control_spec=CONTROL_SPEC, nstep=nstep * frame_skip
        )
        return np.ascontiguousarray(out[:, frame_skip - 1 :: frame_skip])

    def close(self) -> None:
        """Stop the rollout thread pool."""
        if self._pool is not None:
            self._pool.close()
            self._pool = None


def _mocap_bodies(model: mujoco.MjModel) -> np.ndarray:
    """Body id of each mocap id, ``int[nmocap]``."""
    ids = np.nonzero(model.body_mocapid >= 0)[0]
    return ids[np.argsort(model.body_mocapid[ids])]


def _interpolate_mocap(start: np.ndarray, targets: np.ndarray, substeps: int, nmocap: int) -> np.ndarray:
    """Per-timestep mocap controls moving linearly through a sequence of targets.

    ``start float[B, C]`` and ``targets float[B, T, C]`` (``C = nmocap * 7``: positions then
    quaternions) -> ``float[B, T * substeps, C]``; quaternions are normalised linear blends.
    """
    prev = np.concatenate((start[:, None], targets[:, :-1]), axis=1)  # [B, T, C]
    frac = (np.arange(1, substeps + 1) / substeps)[None, None, :, None]
    path = prev[:, :, None] + (targets - prev)[:, :, None] * frac  # [B, T, S, C]
    q = path[..., 3 * nmocap :].reshape(*path.shape[:-1], nmocap, 4)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    path[..., 3 * nmocap :] = q.reshape(*path.shape[:-1], nmocap * 4)
    return path.reshape(path.shape[0], -1, path.shape[-1])


# --------------------------------------------------------------------------- construction
def _mujoco(checkpoint: object, scene_type: str, **kwargs: Any) -> Dynamics:
    if checkpoint is not None:
        raise ValueError("checkpoint= only applies to learned dynamics (dynamics='fignet')")
    return MujocoDynamics(**kwargs)


def _fignet(checkpoint: object, scene_type: str, **kwargs: Any) -> Dynamics:
    from fignet_gym.learned_dynamics import FIGNetDynamics

    return FIGNetDynamics(
        checkpoint if checkpoint is not None else _pretrained(scene_type), **kwargs
    )


#: Names accepted by ``dynamics=``: factories ``(checkpoint, scene_type, **kwargs) -> Dynamics``.
#: Add an entry to make a backend selectable by name.
DYNAMICS_FACTORIES: dict[str, Callable[..., Dynamics]] = {"mujoco": _mujoco, "fignet": _fignet}


def make_dynamics(
    dynamics: str | Dynamics = "mujoco",
    checkpoint: str | os.PathLike | LearnedSimulator | None = None,
    scene_type: str = "",
    **kwargs: Any,
) -> Dynamics:
    """A :class:`Dynamics` from an environment's ``dynamics=`` argument.

    Args:
        dynamics: a name of :data:`DYNAMICS_FACTORIES` (``"mujoco"``, ``"fignet"``), or any object
            with the :class:`Dynamics` methods (returned as is).
        checkpoint: for ``"fignet"``: a checkpoint path or a ``LearnedSimulator``; default: the
            pretrained simulator for ``scene_type`` (``fignet_gym.load_pretrained``).
        scene_type: ``"push"``, ``"toss"`` or ``""``.
        kwargs: passed to the constructor (e.g. ``max_distance`` for ``"fignet"``).
    """
    if isinstance(dynamics, str):
        factory = DYNAMICS_FACTORIES.get(dynamics)
        if factory is None:
            raise ValueError(
                f"unknown dynamics {dynamics!r}: use one of {sorted(DYNAMICS_FACTORIES)} "
                "or a Dynamics object"
            )
        return factory(checkpoint, scene_type, **kwargs)
    if checkpoint is not None or kwargs:
        raise ValueError("checkpoint= and dynamics_kwargs only apply to dynamics given by name")
    missing = [
        m
        for m in ("step", "step_many", "rollout", "validate")
        if not callable(getattr(dynamics, m, None))
    ]
    if missing:
        raise TypeError(
            f"dynamics object {type(dynamics).__name__} lacks {', '.join(missing)} "
            "(subclass fignet_gym.dynamics.DynamicsBase)"
        )
    return dynamics


def _pretrained(scene_type: str) -> LearnedSimulator:
    """The shipped simulator for ``scene_type``; ``ValueError`` saying how to pass one otherwise."""
    if not scene_type:
        raise ValueError("dynamics='fignet' needs checkpoint=<path or LearnedSimulator>")
    from fignet_gym.pretrained_models import load_pretrained

    try:
        return load_pretrained(scene_type)
    except ValueError as exc:  # CheckpointError: not shipped, or unreadable
        raise ValueError(
            f"dynamics='fignet' without checkpoint= loads the pretrained '{scene_type}' "
            f"simulator, which failed ({exc}); pass checkpoint=<path or LearnedSimulator>"
        ) from exc


def __getattr__(name: str) -> Any:
    # FIGNetDynamics lives in fignet_gym.learned_dynamics (which imports this module); resolving it
    # lazily keeps ``from fignet_gym.dynamics import FIGNetDynamics`` working without a cycle.
    if name == "FIGNetDynamics":
        from fignet_gym.learned_dynamics import FIGNetDynamics

        return FIGNetDynamics
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

