"""stable-baselines3 ``VecEnv`` adapter of :class:`~fignet_gym.envs.vector.BatchedVectorEnv`.

stable-baselines3 does not take Gymnasium vector environments: its ``VecEnv`` resets finished
sub-environments itself within the step and reports the last observation in
``info["terminal_observation"]``. The adapter steps the batched vector environment in Gymnasium's
``SAME_STEP`` autoreset mode, which has exactly these semantics, and converts the batched infos
into SB3's list of dictionaries. The environment it is given keeps its own mode: the adapter
switches to ``SAME_STEP`` only for the duration of its own steps, so the same vector env used
directly afterwards still autoresets as it was made to.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvObs, VecEnvStepReturn

from fignet_gym.envs.vector import BatchedVectorEnv


def _unbatch_info(infos: dict[str, Any], i: int) -> dict[str, Any]:
    """Sub-environment ``i``'s dictionary from Gymnasium's batched infos (``key``, ``_key``)."""
    out = {}
    for key, value in infos.items():
        if key.startswith("_"):
            continue
        mask = infos.get(f"_{key}")
        if mask is not None and not mask[i]:
            continue
        out[key] = _unbatch_info(value, i) if isinstance(value, dict) else value[i]
    return out


class SB3VecEnvAdapter(VecEnv):
    """stable-baselines3 ``VecEnv`` view of a :class:`BatchedVectorEnv` (physics still batched).

    Args:
        venv: a batched vector environment (``gym.make_vec(id, num_envs,
            vectorization_mode="vector_entry_point")``), in any autoreset mode (left unchanged).
    """

    def __init__(self, venv: BatchedVectorEnv) -> None:
        venv = (
            venv.unwrapped
            if isinstance(getattr(venv, "unwrapped", None), BatchedVectorEnv)
            else venv
        )
        if not isinstance(venv, BatchedVectorEnv):
            raise TypeError(f"SB3VecEnvAdapter wraps a BatchedVectorEnv, got {type(venv).__name__}")
        self.venv = venv
        self._actions: np.ndarray | None = None
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)

    def reset(self) -> VecEnvObs:
        """Reset every sub-environment with the seeds/options of ``seed()``/``set_options()``."""
        options = next((o for o in self._options if o), None)
        seeds = self._seeds if any(s is not None for s in self._seeds) else None
        obs, infos = self.venv.reset(seed=seeds, options=options)
        self.reset_infos = [_unbatch_info(infos, i) for i in range(self.num_envs)]
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    @contextmanager
    def _same_step(self) -> Iterator[None]:
        """Step in ``SAME_STEP`` autoreset (SB3's semantics), then give the env its mode back."""
        mode = self.venv.autoreset_mode
        self.venv.autoreset_mode = AutoresetMode.SAME_STEP
        try:
            yield
        finally:
            self.venv.autoreset_mode = mode

    def step_wait(self) -> VecEnvStepReturn:
        """Step every sub-environment; finished ones are reset at once (SB3's ``VecEnv`` rule)."""
        with self._same_step():
            obs, rewards, terminated, truncated, infos = self.venv.step(self._actions)
        dones = terminated | truncated
        out = []
        for i in range(self.num_envs):
            info = _unbatch_info(infos, i)
            if dones[i]:
                final = info.pop("final_info", {})
                final_obs = info.pop("final_obs")
                info = {
                    **final,
                    "terminal_observation": final_obs,
                    "TimeLimit.truncated": bool(truncated[i] and not terminated[i]),
                }
            else:
                info.pop("final_info", None)
                info.pop("final_obs", None)
            out.append(info)
        return obs, rewards.astype(np.float32), dones, out

    def close(self) -> None:
        self.venv.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        return list(self.venv.render())

    # ----------------------------------------------------------------- sub-environment access
    def _targets(self, indices: VecEnvIndices) -> list[Any]:
        return [self.venv.envs[i] for i in self._get_indices(indices)]

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(env, attr_name) for env in self._targets(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        for env in self._targets(indices):
            setattr(env, attr_name, value)

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: VecEnvIndices = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        return [
            getattr(env, method_name)(*method_args, **method_kwargs)
            for env in self._targets(indices)
        ]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        return [False for _ in self._targets(indices)]


def make_sb3_vec_env(env_id: str, num_envs: int, **kwargs: Any) -> SB3VecEnvAdapter:
    """SB3 view of ``gym.make_vec(env_id, num_envs, vectorization_mode="vector_entry_point")``,
    made in ``SAME_STEP`` autoreset mode (the one SB3 expects)."""
    venv = gym.make_vec(
        env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.SAME_STEP, **kwargs
    )
    return SB3VecEnvAdapter(venv)
