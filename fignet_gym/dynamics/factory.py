"""Dynamics by name: what an environment's ``dynamics=`` and ``checkpoint=`` arguments mean."""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

from fignet_gym.dynamics.base import Dynamics
from fignet_gym.dynamics.learned import FIGNetDynamics
from fignet_gym.dynamics.mujoco import MujocoDynamics
from fignet_gym.pretrained import load_pretrained
from fignet_gym.simulator.model import LearnedSimulator


def _mujoco(checkpoint: object, scene_type: str, **kwargs: Any) -> Dynamics:
    if checkpoint is not None:
        raise ValueError("checkpoint= only applies to learned dynamics (dynamics='fignet')")
    return MujocoDynamics(**kwargs)


def _fignet(checkpoint: object, scene_type: str, **kwargs: Any) -> Dynamics:
    return FIGNetDynamics(
        checkpoint if checkpoint is not None else _pretrained(scene_type), **kwargs
    )


#: Names accepted by ``dynamics=``: factories ``(checkpoint, scene_type, **kwargs) -> Dynamics``.
#: Add an entry to make a backend selectable by name.
DYNAMICS_FACTORIES: dict[str, Callable[..., Dynamics]] = {"mujoco": _mujoco, "fignet": _fignet}
#: How tables, cards and videos name each backend of :data:`DYNAMICS_FACTORIES`.
DYNAMICS_LABELS: dict[str, str] = {"mujoco": "MuJoCo", "fignet": "FIGNet"}


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
    try:
        return load_pretrained(scene_type)
    except ValueError as exc:  # CheckpointError: not shipped, or unreadable
        raise ValueError(
            f"dynamics='fignet' without checkpoint= loads the pretrained '{scene_type}' "
            f"simulator, which failed ({exc}); pass checkpoint=<path or LearnedSimulator>"
        ) from exc
