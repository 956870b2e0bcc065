"""The swap point between analytic and learned dynamics, mirroring MuJoCo's own calls.

A :class:`Dynamics` advances ``mujoco.MjData`` exactly where ``mujoco.mj_step`` would:

* ``step(model, data, nstep)``: like ``mujoco.mj_step(model, data, nstep)``: advances ``data`` in
  place by ``nstep`` MuJoCo timesteps (free-joint ``qpos``/``qvel``, ``time``) and leaves every
  derived quantity (``xpos``, contacts, rendering) consistent.
* ``step_many(model, datas, nstep)``: ``step`` on many ``MjData`` of one model at once (the learned
  dynamics runs them as one batched graph).
* ``rollout(model, initial_state, control, nstep, frame_skip=...)``: shaped like
  ``mujoco.rollout.rollout``: whole states ``float64[B, nstate]`` in (:data:`STATE_SPEC`: full
  physics, mocap poses *and* ``userdata``, so that a rollout starts every body, the pusher
  included, where the state says, from the pose history the state's own past left), mocap
  trajectories as control, ``nstep`` MuJoCo timesteps, one state per ``frame_skip`` of them out:
  ``float64[B, nstep // frame_skip, nstate]``.

Kinematic bodies are mocap bodies: before a step, set ``data.mocap_pos``/``mocap_quat`` to where
they should be at the *end* of the step; both implementations move them there linearly from their
current pose, as the pusher moves in the training data. Time-step contract:
``docs/architecture.md``.

Two implementations: :class:`~fignet_gym.dynamics.mujoco.MujocoDynamics` (``mj_step``,
``mujoco.rollout``) and :class:`~fignet_gym.dynamics.learned.FIGNetDynamics` (a
:class:`~fignet_gym.simulator.LearnedSimulator`). A user's own class works too: subclass
:class:`DynamicsBase` and implement ``step``, or implement the whole protocol. This module holds
the protocol and the helpers every implementation shares; it imports no implementation.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import mujoco
import numpy as np

#: State layout of :meth:`Dynamics.rollout`, in and out: ``mjSTATE_FULLPHYSICS`` (time, qpos,
#: qvel, act, plugin) plus every mocap position and quaternion and ``userdata``. ``mujoco.
#: mj_getState(model, data, s, STATE_SPEC)`` reads it from an ``MjData``. Mocap poses are part of
#: the state because with ``frame_skip > 1`` a mocap body moves linearly from where it is to its
#: next target: a state without them would start the pusher wherever a scratch ``MjData`` last
#: left it. ``userdata`` holds the pose history a learned step needs (:mod:`.history`): without
#: it, a rollout from a state taken mid-push would start from a made-up history.
STATE_SPEC = int(
    mujoco.mjtState.mjSTATE_FULLPHYSICS
    | mujoco.mjtState.mjSTATE_MOCAP_POS
    | mujoco.mjtState.mjSTATE_MOCAP_QUAT
    | mujoco.mjtState.mjSTATE_USERDATA
)
#: ``mujoco.rollout``'s own state layout (full physics, no mocap poses).
PHYSICS_SPEC = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
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
        """Open-loop rollouts of ``nstep`` MuJoCo timesteps (as ``mujoco.rollout`` counts them),
        one state recorded every ``frame_skip`` timesteps: ``float64[B, nstate]`` states and
        ``float64[B, T, nmocap * 7]`` mocap targets (each reached over ``frame_skip`` timesteps)
        -> ``float64[B, T, nstate]``, ``T = nstep // frame_skip`` (default ``nstep``: ``T``
        control rows). An empty batch or ``nstep = 0`` gives an empty array of that shape.
        ``ValueError`` where ``nstep`` is not a multiple of ``frame_skip`` or ``T`` disagrees
        with the control rows (neither 1 nor ``T``)."""
        ...

    def validate(self, model: mujoco.MjModel, nstep: int, scene_type: str = "") -> None:
        """Raise ``ValueError`` if this dynamics cannot step ``model`` (a scene of kind
        ``scene_type``: ``"push"``, ``"toss"`` or ``""``) by ``nstep`` timesteps at a time."""
        ...


# --------------------------------------------------------------------------- shared helpers
def check_rollout_inputs(
    model: mujoco.MjModel, initial_state: np.ndarray, control: np.ndarray | None, nstep: int | None,
    frame_skip: int = 1,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Validate and broadcast rollout inputs (``nstep``: MuJoCo timesteps, a multiple of
    ``frame_skip``; default: one ``frame_skip`` per control row; ``ValueError`` otherwise).

    Returns ``float64[B, nstate]`` states, ``float64[B, T, ncontrol]`` controls and the number of
    recorded states ``T = nstep // frame_skip``.
    """
    if isinstance(frame_skip, bool) or not isinstance(frame_skip, (int, np.integer)) or frame_skip < 1:
        raise ValueError(f"frame_skip must be an integer >= 1, got {frame_skip!r}")
    if nstep is not None:
        if isinstance(nstep, bool) or not isinstance(nstep, (int, np.integer)) or nstep < 0:
            raise ValueError(f"nstep must be an integer >= 0 (MuJoCo timesteps), got {nstep!r}")
        # nstep once meant recorded states (before the first release): such a call shows here or
        # as one control row per timestep below, and both errors name the fix rather than guess.
        if nstep % frame_skip:
            raise ValueError(
                f"Dynamics.rollout: nstep={nstep} is not a multiple of frame_skip={frame_skip}: "
                f"nstep counts MuJoCo timesteps (as in mujoco.rollout), so {nstep} recorded states "
                f"are nstep={nstep * frame_skip}")
        timesteps, nstep = int(nstep), int(nstep) // frame_skip
    nstate = mujoco.mj_stateSize(model, STATE_SPEC)
    ncontrol = mujoco.mj_stateSize(model, CONTROL_SPEC)
    state = np.asarray(initial_state, dtype=np.float64)
    if state.ndim == 1:
        state = state[None]
    if state.ndim != 2 or state.shape[1] != nstate:
        raise ValueError(
            f"initial_state must be float[B, {nstate}] (STATE_SPEC: mjSTATE_FULLPHYSICS | "
            f"mjSTATE_MOCAP_POS | mjSTATE_MOCAP_QUAT | mjSTATE_USERDATA, from mujoco.mj_getState), "
            f"got shape {np.shape(initial_state)}"
        )
    if control is None:
        if nstep is None:
            raise ValueError("rollout needs control or nstep")
        if ncontrol:
            raise ValueError(f"the model has mocap bodies: control float[B, nstep // frame_skip, "
                             f"{ncontrol}] is required")
        control = np.zeros((state.shape[0], nstep, 0))
    control = np.asarray(control, dtype=np.float64)
    if control.ndim == 2:
        control = control[None]
    if control.ndim != 3 or control.shape[2] != ncontrol:
        raise ValueError(
            f"control must be float[B, T, {ncontrol}] (mocap_pos then mocap_quat, one row per "
            f"recorded state), got shape {np.shape(control)}"
        )
    nstep = control.shape[1] if nstep is None else int(nstep)
    if control.shape[1] not in (1, nstep):  # only with nstep given: timesteps is set
        rows = control.shape[1]
        raise ValueError(
            f"Dynamics.rollout: control has {rows} rows but nstep={timesteps} MuJoCo timesteps "
            f"with frame_skip={frame_skip} record {nstep} states: pass nstep={rows * frame_skip} "
            f"(nstep counts timesteps, as in mujoco.rollout) or {nstep} control rows"
        )
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


def set_mocap(model: mujoco.MjModel, data: mujoco.MjData, control_row: np.ndarray) -> None:
    """Write one control row (mocap_pos then mocap_quat, ``float[nmocap * 7]``) into ``data``."""
    nm = model.nmocap
    data.mocap_pos[:] = control_row[: 3 * nm].reshape(nm, 3)
    data.mocap_quat[:] = control_row[3 * nm :].reshape(nm, 4)


def normalize_mocap_quat(quat: np.ndarray) -> np.ndarray:
    """Quaternions ``float[..., 4]`` normalised as MuJoCo normalises ``mocap_quat``: a (near-)zero
    one becomes the identity instead of NaN."""
    quat = np.asarray(quat, dtype=np.float64)
    norm = np.linalg.norm(quat, axis=-1, keepdims=True)
    unit = quat / np.where(norm < mujoco.mjMINVAL, 1.0, norm)
    return np.where(norm < mujoco.mjMINVAL, np.array([1.0, 0.0, 0.0, 0.0]), unit)


def state_offsets(model: mujoco.MjModel) -> tuple[int, int, int]:
    """Sizes in :data:`STATE_SPEC`: physics before the mocap poses, mocap poses, plugin state."""
    pre = mujoco.mj_stateSize(
        model,
        int(
            mujoco.mjtState.mjSTATE_TIME
            | mujoco.mjtState.mjSTATE_QPOS
            | mujoco.mjtState.mjSTATE_QVEL
            | mujoco.mjtState.mjSTATE_ACT
        ),
    )
    return pre, 7 * model.nmocap, mujoco.mj_stateSize(model, int(mujoco.mjtState.mjSTATE_PLUGIN))


def userdata_slice(model: mujoco.MjModel) -> slice:
    """Where ``userdata`` sits in a :data:`STATE_SPEC` vector."""
    pre, nm7, _ = state_offsets(model)
    return slice(pre + nm7, pre + nm7 + model.nuserdata)


def split_state(model: mujoco.MjModel, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:data:`STATE_SPEC` states ``float64[..., nstate]`` -> ``mjSTATE_FULLPHYSICS`` states
    ``float64[..., nphys]`` and mocap poses ``float64[..., nmocap * 7]`` (positions, then
    quaternions: the control layout). ``userdata``: ``state[..., userdata_slice(model)]``."""
    pre, nm7, _ = state_offsets(model)
    user = userdata_slice(model)
    state = np.asarray(state, dtype=np.float64)
    phys = np.concatenate((state[..., :pre], state[..., user.stop :]), axis=-1)
    return phys, state[..., pre : pre + nm7].copy()


def join_state(
    model: mujoco.MjModel, phys: np.ndarray, mocap: np.ndarray, userdata: np.ndarray | None = None
) -> np.ndarray:
    """Inverse of :func:`split_state`: ``float64[..., nphys]``, ``float64[..., nmocap * 7]`` and
    ``float64[..., nuserdata]`` (default: zeros) -> ``float64[..., nstate]``."""
    pre, _, _ = state_offsets(model)
    lead = phys.shape[:-1]
    mocap = np.broadcast_to(mocap, (*lead, mocap.shape[-1]))
    user = np.zeros((*lead, model.nuserdata)) if userdata is None else userdata
    user = np.broadcast_to(user, (*lead, model.nuserdata))
    return np.concatenate((phys[..., :pre], mocap, user, phys[..., pre:]), axis=-1)


class DynamicsBase:
    """Defaults for a :class:`Dynamics`: subclasses implement :meth:`step` only.

    ``step_many`` loops over ``step``, ``rollout`` checks its inputs and calls ``_rollout`` (the
    batched override point), which loops ``step`` on a scratch ``MjData`` loaded with each initial
    state (mocap poses included), ``validate`` accepts everything.
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
        """:meth:`Dynamics.rollout`: the inputs checked and broadcast by
        :func:`check_rollout_inputs`, then :meth:`_rollout` (what a subclass overrides)."""
        state, control, nrec = check_rollout_inputs(model, initial_state, control, nstep, frame_skip)
        return self._rollout(model, state, control, nrec, frame_skip)

    def _rollout(
        self, model: mujoco.MjModel, state: np.ndarray, control: np.ndarray, nstep: int,
        frame_skip: int,
    ) -> np.ndarray:
        """A loop of :meth:`step` per rollout on checked inputs: ``float64[B, nstate]`` states,
        ``float64[B, nstep, nmocap * 7]`` controls -> ``float64[B, nstep, nstate]``; diverged
        rows: NaN."""
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

    ``data`` is reset, loaded with ``initial_state float64[nstate]`` (:data:`STATE_SPEC`: mocap
    bodies where the state has them) and forwarded; then each control row (``float64[T, nmocap *
    7]``) is applied and ``frame_skip`` timesteps taken. Returns the states ``float64[T, nstate]``
    (rows after a :class:`DivergenceError` are NaN).
    """
    T = control.shape[0]
    out = np.full((T, mujoco.mj_stateSize(model, STATE_SPEC)), np.nan) if out is None else out
    mujoco.mj_resetData(model, data)
    mujoco.mj_setState(model, data, np.asarray(initial_state, dtype=np.float64), STATE_SPEC)
    mujoco.mj_forward(model, data)
    for t in range(T):
        set_mocap(model, data, control[t])
        try:
            dynamics.step(model, data, frame_skip)
        except DivergenceError:
            break
        mujoco.mj_getState(model, data, out[t], STATE_SPEC)
    return out
