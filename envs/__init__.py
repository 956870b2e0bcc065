"""Gymnasium environments whose dynamics swap between MuJoCo and FIGNet.

Installed as ``fignet_gym.envs``. The ids are registered when Gymnasium is imported (by
:mod:`fignet_gym.registration`), so ``import fignet_gym`` is enough::

    import gymnasium as gym
    import fignet_gym  # noqa: F401  (registers the environments)

    env = gym.make("fignet_gym/Push-v2", dynamics="fignet", render_mode="rgb_array")
    venv = gym.make_vec("fignet_gym/Push-v2", num_envs=16, vectorization_mode="vector_entry_point",
                        dynamics="fignet", checkpoint="push")

The stable-baselines3 adapter lives in :mod:`fignet_gym.envs.sb3` and is imported (with SB3) only
when one of its names is used.
"""

from fignet_gym import check_same_install

check_same_install(__file__, "envs")  # before anything else of this copy is imported

from typing import Any

from fignet_gym.envs.base import MjDynamicsEnv
from fignet_gym.envs.cube_toss import CubeTossEnv, CubeTossVectorEnv
from fignet_gym.envs.push import PushEnv, PushVectorEnv
from fignet_gym.envs.toss import TossEnv, TossVectorEnv
from fignet_gym.envs.vector import BatchedVectorEnv
from fignet_gym.registration import ENV_IDS, register_envs

__all__ = [
    "ENV_IDS",
    "BatchedVectorEnv",
    "CubeTossEnv",
    "CubeTossVectorEnv",
    "MjDynamicsEnv",
    "PushEnv",
    "PushVectorEnv",
    "SB3VecEnvAdapter",
    "TossEnv",
    "TossVectorEnv",
    "make_sb3_vec_env",
    "register_envs",
]

register_envs()

_SB3_NAMES = ("SB3VecEnvAdapter", "make_sb3_vec_env")


def __getattr__(name: str) -> Any:
    if name in _SB3_NAMES:
        # deferred: stable-baselines3 costs seconds to import; only its adapter's users pay (PEP 562)
        from fignet_gym.envs import sb3

        return getattr(sb3, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
