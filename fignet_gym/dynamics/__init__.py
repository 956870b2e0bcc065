"""The swap point: one :class:`Dynamics` protocol mirroring ``mujoco.mj_step`` / ``mujoco.rollout``,
with MuJoCo (:mod:`.mujoco`) and learned FIGNet (:mod:`.learned`) implementations.

Layers: :mod:`.base` (protocol, shared helpers), :mod:`.history` (the pose history in
``userdata``) <- :mod:`.mujoco`, :mod:`.learned` <- :mod:`.factory`
(``dynamics="mujoco" | "fignet"``). No module imports one above it.
"""

from fignet_gym.dynamics.base import (
    CONTROL_SPEC,
    PHYSICS_SPEC,
    STATE_SPEC,
    DivergenceError,
    Dynamics,
    DynamicsBase,
    check_rollout_inputs,
    join_state,
    rollout_loop,
    set_mocap,
    split_state,
    state_offsets,
    userdata_slice,
)
from fignet_gym.dynamics.factory import DYNAMICS_FACTORIES, DYNAMICS_LABELS, make_dynamics
from fignet_gym.dynamics.history import compile_with_history, with_history
from fignet_gym.dynamics.learned import FIGNetDynamics
from fignet_gym.dynamics.mujoco import MujocoDynamics

__all__ = [
    "CONTROL_SPEC", "DYNAMICS_FACTORIES", "DYNAMICS_LABELS", "PHYSICS_SPEC", "STATE_SPEC", "DivergenceError",
    "Dynamics", "DynamicsBase",
    "FIGNetDynamics", "MujocoDynamics", "check_rollout_inputs", "make_dynamics", "rollout_loop",
    "join_state", "set_mocap", "split_state", "state_offsets", "compile_with_history", "with_history",
    "userdata_slice",
]
