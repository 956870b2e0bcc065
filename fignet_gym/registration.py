"""Gymnasium ids of the package's environments, registered by string entry points.

Registering imports Gymnasium but no environment module: ``gym.make`` imports the env (and MuJoCo,
torch) only when an env is made. :mod:`fignet_gym` calls :func:`register_envs` as soon as Gymnasium
is imported, so ``import fignet_gym`` alone keeps the simulator core free of the RL stack.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys
from types import ModuleType
from typing import Any

#: Push-v1's arguments (why: the Version History of ``PushEnv``'s docstring).
PUSH_V1_KWARGS: dict[str, Any] = {
    "tip_start": "behind",
    "goal_distance_min": 0.02,
    "goal_distance": 0.05,
    "goal_yaw": 0.3,
    "success_position": 0.01,
    "success_yaw": 0.2,
    "success_weight": 1.0,
}
#: Push-v2's: v1's task under isotropic friction (``PushEnv``'s Version History).
PUSH_V2_KWARGS: dict[str, Any] = {**PUSH_V1_KWARGS, "cone": "elliptic"}
#: Registered ids: (entry point, vector entry point, episode step limit or None, arguments).
ENV_SPECS: dict[str, tuple[str, str, int | None, dict[str, Any]]] = {
    "fignet_gym/Push-v1": (
        "fignet_gym.envs.push:PushEnv", "fignet_gym.envs.push:PushVectorEnv", 75,
        {**PUSH_V1_KWARGS, "cone": "pyramidal"},
    ),
    "fignet_gym/Push-v2": (
        "fignet_gym.envs.push:PushEnv", "fignet_gym.envs.push:PushVectorEnv", 75, PUSH_V2_KWARGS
    ),
    # A user's MJCF: gym.make("fignet_gym/ScenePush-v0", mjcf=FILE, object=..., pusher=...)
    # with Push-v1's task arguments; the friction cone is the MJCF's own.
    "fignet_gym/ScenePush-v0": (
        "fignet_gym.envs.scene_push:ScenePushEnv", "fignet_gym.envs.scene_push:ScenePushVectorEnv",
        75, PUSH_V1_KWARGS,
    ),
    # Push-T (a T block, scored by coverage of the goal): Push-v2's task and its isotropic
    # physics, success at 90% coverage (gym-pusht's 95% is success_coverage=0.95).
    "fignet_gym/PushT-v0": (
        "fignet_gym.envs.pusht:PushTEnv", "fignet_gym.envs.pusht:PushTVectorEnv", 100,
        {**PUSH_V1_KWARGS, "success_coverage": 0.9},
    ),
    "fignet_gym/Toss-v0": (
        "fignet_gym.envs.toss:TossEnv", "fignet_gym.envs.toss:TossVectorEnv", None,
        {"cone": "pyramidal"},
    ),
    "fignet_gym/Toss-v1": (
        "fignet_gym.envs.toss:TossEnv", "fignet_gym.envs.toss:TossVectorEnv", None,
        {"cone": "elliptic"},
    ),
    "fignet_gym/RealPush-v0": (
        "fignet_gym.envs.real_push:RealPushEnv", "fignet_gym.envs.real_push:RealPushVectorEnv", 75,
        {"learned": "push-real-v0"},
    ),
    "fignet_gym/RealPush-v1": (
        "fignet_gym.envs.real_push:RealPushEnv", "fignet_gym.envs.real_push:RealPushVectorEnv", 75,
        {"learned": "push-real"},
    ),
    "fignet_gym/CubeToss-v0": (
        "fignet_gym.envs.cube_toss:CubeTossEnv", "fignet_gym.envs.cube_toss:CubeTossVectorEnv",
        None, {},
    ),
}
#: Registered ids and their episode limits (Toss ends by itself once every object is released).
ENV_IDS: dict[str, int | None] = {k: v[2] for k, v in ENV_SPECS.items()}


def register_envs() -> None:
    """Register every id of :data:`ENV_SPECS` with Gymnasium (idempotent)."""
    # deferred: called once Gymnasium is imported; `import fignet_gym` must not load it (module doc)
    import gymnasium as gym

    for env_id, (entry, vector_entry, limit, kwargs) in ENV_SPECS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry, vector_entry_point=vector_entry,
                         max_episode_steps=limit, kwargs=dict(kwargs))


class _RegisterAfterImport(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Runs :func:`register_envs` right after ``gymnasium`` itself has been imported.

    Gymnasium 1.x loads no plugin entry points, and importing it from the core would load the RL
    stack for users who only want the simulator; this finder defers registration to the moment a
    user's own ``import gymnasium`` happens, whichever of the two packages is imported first.
    """

    def __init__(self) -> None:
        self._spec: importlib.machinery.ModuleSpec | None = None

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> Any:
        if name != "gymnasium" or self._spec is not None:
            return None
        sys.meta_path.remove(self)
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is None or spec.loader is None:
            return None
        self._spec = spec
        self._inner = spec.loader
        spec.loader = self
        return spec

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return self._inner.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        self._inner.exec_module(module)
        register_envs()


def register_when_gymnasium_loads() -> None:
    """Register now if Gymnasium is imported, else as soon as it is."""
    if "gymnasium" in sys.modules:
        register_envs()
    elif not any(isinstance(f, _RegisterAfterImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _RegisterAfterImport())
