"""Gymnasium environments whose dynamics swap between MuJoCo and FIGNet.

Installed as ``fignet_gym.envs``.

Importing this package registers ``fignet_gym/Push-v0`` and ``fignet_gym/Toss-v0``::

    import gymnasium as gym
    import fignet_gym.envs  # noqa: F401  (registers the environments)

    env = gym.make("fignet_gym/Push-v0", dynamics="fignet", checkpoint="push.pt",
                   render_mode="rgb_array")
    venv = gym.make_vec("fignet_gym/Push-v0", num_envs=16, vectorization_mode="vector_entry_point",
                        dynamics="fignet", checkpoint="push.pt")

``gym.make("fignet_gym.envs:fignet_gym/Push-v0")`` imports and registers in one go.
"""

import gymnasium as gym

from fignet_gym.envs.base import MjDynamicsEnv
from fignet_gym.envs.push import PushEnv, PushVectorEnv
from fignet_gym.envs.sb3 import SB3VecEnvAdapter, make_sb3_vec_env
from fignet_gym.envs.toss import TossEnv, TossVectorEnv
from fignet_gym.envs.vector import BatchedVectorEnv

__all__ = [
    "BatchedVectorEnv",
    "MjDynamicsEnv",
    "PushEnv",
    "PushVectorEnv",
    "SB3VecEnvAdapter",
    "TossEnv",
    "TossVectorEnv",
    "make_sb3_vec_env",
    "register_envs",
]

#: Registered ids and their episode limits (Toss ends by itself once every object is released).
ENV_IDS = {"fignet_gym/Push-v0": 50, "fignet_gym/Toss-v0": None}


def register_envs() -> None:
    """Register ``fignet_gym/Push-v0`` and ``fignet_gym/Toss-v0`` with Gymnasium (idempotent)."""
    specs = {
        "fignet_gym/Push-v0": (
            "fignet_gym.envs.push:PushEnv",
            "fignet_gym.envs.push:PushVectorEnv",
        ),
        "fignet_gym/Toss-v0": (
            "fignet_gym.envs.toss:TossEnv",
            "fignet_gym.envs.toss:TossVectorEnv",
        ),
    }
    for env_id, (entry, vector_entry) in specs.items():
        if env_id not in gym.registry:
            gym.register(
                id=env_id,
                entry_point=entry,
                vector_entry_point=vector_entry,
                max_episode_steps=ENV_IDS[env_id],
            )


register_envs()
