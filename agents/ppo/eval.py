"""A policy's episodes on either dynamics: :func:`evaluate_policy_on` and, for a run, :func:`evaluate_both`.

Evaluation steps up to ``max_parallel`` episodes with one batched dynamics call per step; episode
``k`` is seeded ``seed + k``, so it is the episode ``gym.make(env_id, ...).reset(seed=seed + k)``
would give, whatever the batching. Train on learned dynamics, then
``evaluate_policy_on("mujoco", policy)`` checks the policy against the analytic simulator.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.type_aliases import PolicyPredictor

from fignet_gym.agents.ppo.config import DYNAMICS, PUSH_ID, RunConfig
from fignet_gym.dynamics import Dynamics
from fignet_gym.envs.vector import BatchedVectorEnv

#: First seed of a run's evaluation episodes (episode ``k`` is seeded ``EVAL_SEED + k``): far from
#: the training seeds ``seed .. seed + num_envs - 1``, the same episodes at every evaluation.
EVAL_SEED = 10_000
#: Episodes a run's evaluation steps together (one batched dynamics call per step).
EVAL_PARALLEL = 32

#: Keys of :func:`evaluate_policy_on`'s result.
EVAL_KEYS = (
    "dynamics",
    "n_episodes",
    "success_rate",
    "mean_return",
    "std_return",
    "mean_length",
    "final_position_error",
    "final_orientation_error",
    "diverged_rate",
    "episode_returns",
    "episode_position_errors",
    "episode_orientation_errors",
    "episode_successes",
    "episode_initial_observations",
)
#: Info keys of an episode's final position error (m), first found wins: a push's distance to the
#: goal, a toss's landing distance from the target.
POSITION_ERROR_KEYS = ("position_error", "distance")
#: Info keys of an episode's final heading error and the factor to radians: a push's (rad), a
#: toss's (degrees, signed; reported as its absolute value like a push's).
ORIENTATION_ERROR_KEYS = (("orientation_error", 1.0), ("yaw_error_deg", math.pi / 180.0))
#: The scalar keys of a report logged at each periodic evaluation.
SUMMARY_KEYS = ("success_rate", "mean_return", "final_position_error", "final_orientation_error",
                "diverged_rate")


def env_kwargs_for(
    dynamics: str | Dynamics, checkpoint: Any, env_kwargs: Mapping[str, Any] | None
) -> dict[str, Any]:
    """The environment arguments of ``dynamics`` (and its ``checkpoint``, when given)."""
    kwargs = {**(env_kwargs or {}), "dynamics": dynamics}
    if checkpoint is not None:
        kwargs["checkpoint"] = checkpoint
    return kwargs


def _describe(value: Any) -> Any:
    """JSON-friendly description of a dynamics or checkpoint argument."""
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return f"<{type(value).__name__}>"


def evaluate_policy_on(
    dynamics: str | Dynamics,
    policy: PolicyPredictor,
    n_episodes: int = 10,
    seed: int = 0,
    *,
    checkpoint: Any = None,
    env_id: str | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    deterministic: bool = True,
    max_parallel: int = 16,
) -> dict[str, Any]:
    """Run ``policy`` for ``n_episodes`` episodes of ``env_id`` stepped by ``dynamics``.

    Args:
        dynamics: ``"mujoco"``, ``"fignet"`` or a :class:`Dynamics` object.
        policy: anything with SB3's ``predict(obs float32[N, D], deterministic=...)``.
        n_episodes: episodes; episode ``k`` is seeded ``seed + k``.
        seed: first episode's seed.
        checkpoint: for ``"fignet"``: path or ``LearnedSimulator``.
        env_id: a registered fignet_gym environment (default: the policy's own ``env_id`` when
            it has one, as a shipped policy does, else the current Push version).
        env_kwargs: further environment arguments (``shape``, ``friction`` ...).
        deterministic: use the policy's mean action.
        max_parallel: episodes stepped together (one batched dynamics call per step).

    Returns:
        A dictionary with the keys of :data:`EVAL_KEYS`: ``dynamics`` (its description),
        ``n_episodes``, ``success_rate`` (fraction ending with ``info["is_success"]``),
        ``mean_return``/``std_return``, ``mean_length`` (steps), ``final_position_error`` (m)
        and ``final_orientation_error`` (absolute, rad) averaged over episodes (from the last
        step's ``info``: a push's goal errors, a toss's landing errors), ``diverged_rate``
        (episodes the dynamics blew up in), and per-episode lists ``episode_returns``,
        ``episode_position_errors``, ``episode_orientation_errors``, ``episode_successes`` and
        ``episode_initial_observations`` (each episode's first observation: set by its seed
        alone, so equal across dynamics for the same seeds).
    """
    if n_episodes < 1:
        raise ValueError(f"n_episodes must be >= 1, got {n_episodes}")
    if env_id is None:
        env_id = getattr(policy, "env_id", None) or PUSH_ID
    n_par = min(n_episodes, max_parallel)
    venv = gym.make_vec(
        env_id,
        num_envs=n_par,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.NEXT_STEP,
        **env_kwargs_for(dynamics, checkpoint, env_kwargs),
    )
    if not isinstance(venv.unwrapped, BatchedVectorEnv):
        raise TypeError(f"{env_id}: not a fignet_gym batched vector environment")
    episodes: list[dict[str, Any]] = []
    for first in range(0, n_episodes, n_par):
        episodes += _run_batch(venv, policy, seed + first, deterministic)
    venv.close()
    episodes = episodes[:n_episodes]
    returns = np.array([e["return"] for e in episodes])
    pos = np.array([e["position_error"] for e in episodes])
    yaw = np.array([e["orientation_error"] for e in episodes])
    success = [e["is_success"] for e in episodes]
    return {
        "dynamics": _describe(dynamics),
        "n_episodes": n_episodes,
        "success_rate": float(np.mean(success)),
        "mean_return": float(returns.mean()),
        "std_return": float(returns.std()),
        "mean_length": float(np.mean([e["length"] for e in episodes])),
        "final_position_error": float(pos.mean()),
        "final_orientation_error": float(yaw.mean()),
        "diverged_rate": float(np.mean([e["diverged"] for e in episodes])),
        "episode_returns": returns.tolist(),
        "episode_position_errors": pos.tolist(),
        "episode_orientation_errors": yaw.tolist(),
        "episode_successes": success,
        "episode_initial_observations": [e["initial_observation"] for e in episodes],
    }


def _run_batch(
    venv: gym.vector.VectorEnv, policy: PolicyPredictor, seed: int, deterministic: bool
) -> list[dict[str, Any]]:
    """One episode per sub-environment (seeds ``seed + i``); per-episode final statistics."""
    n = venv.num_envs
    obs, _ = venv.reset(seed=seed)
    first_obs = np.asarray(obs, dtype=np.float64).copy()
    running = np.ones(n, dtype=bool)
    returns, lengths = np.zeros(n), np.zeros(n, dtype=np.int64)
    finals: list[dict[str, Any]] = [{} for _ in range(n)]
    limit = venv.unwrapped.max_episode_steps
    for _ in range(limit if limit is not None else 10**6):
        actions, _ = policy.predict(obs, deterministic=deterministic)
        obs, rewards, terminated, truncated, infos = venv.step(actions)
        returns[running] += rewards[running]
        lengths[running] += 1
        ended = running & (terminated | truncated)
        for i in np.flatnonzero(ended):
            finals[i] = {k: _item(infos, k, i) for k in infos if not k.startswith("_")}
        running &= ~ended
        if not running.any():
            break
    if running.any():
        raise RuntimeError(f"{venv}: episodes did not end; set a time limit (max_episode_steps)")
    return [
        {
            "return": float(returns[i]),
            "length": int(lengths[i]),
            "is_success": bool(finals[i].get("is_success", False)),
            "position_error": _position_error(finals[i]),
            "orientation_error": _orientation_error(finals[i]),
            "diverged": finals[i].get("diverged") is not None,
            "initial_observation": first_obs[i].tolist(),
        }
        for i in range(n)
    ]


def _position_error(info: Mapping[str, Any]) -> float:
    """An episode's final position error (m) from its last ``info`` (NaN if the env reports none)."""
    found = [info[k] for k in POSITION_ERROR_KEYS if info.get(k) is not None]
    return float(found[0]) if found else math.nan


def _orientation_error(info: Mapping[str, Any]) -> float:
    """An episode's final absolute heading error (rad) from its last ``info`` (NaN if none)."""
    found = [abs(float(info[k])) * to_rad for k, to_rad in ORIENTATION_ERROR_KEYS
             if info.get(k) is not None]
    return found[0] if found else math.nan


def _item(infos: dict[str, Any], key: str, i: int) -> Any:
    """Sub-environment ``i``'s value of a batched info ``key`` (``None`` where it is absent)."""
    mask = infos.get(f"_{key}")
    if mask is not None and not mask[i]:
        return None
    value = infos[key]
    return None if isinstance(value, dict) else value[i]


def run_env_kwargs(cfg: RunConfig, dynamics: str) -> dict[str, Any]:
    """The environment arguments of a run's env on ``dynamics`` (its simulator for FIGNet)."""
    checkpoint = cfg.simulator if dynamics == "fignet" else None
    return env_kwargs_for(dynamics, checkpoint, cfg.env_kwargs)


def evaluate_both(
    cfg: RunConfig, policy: PolicyPredictor, n_episodes: int, seed: int = EVAL_SEED
) -> dict[str, dict[str, Any]]:
    """``policy`` on MuJoCo and on FIGNet: :func:`evaluate_policy_on` reports keyed by dynamics."""
    out = {}
    for dyn in DYNAMICS:
        kwargs = run_env_kwargs(cfg, dyn)
        dynamics = kwargs.pop("dynamics")
        checkpoint = kwargs.pop("checkpoint", None)
        out[dyn] = evaluate_policy_on(
            dynamics, policy, n_episodes=n_episodes, seed=seed, checkpoint=checkpoint,
            env_id=cfg.env_id, env_kwargs=kwargs, max_parallel=EVAL_PARALLEL,
        )
    return out


def summary(report: Mapping[str, Any]) -> dict[str, float]:
    """The scalars of :data:`SUMMARY_KEYS` of an :func:`evaluate_policy_on` report."""
    return {k: float(report[k]) for k in SUMMARY_KEYS}
