"""PPO (stable-baselines3) on either dynamics, and its check on MuJoCo.

The project's core user story in three calls::

    model = train_ppo("fignet", checkpoint="push.pt", config=PPOConfig(total_timesteps=200_000),
                      save_path="runs/ppo_fignet")             # train on the learned simulator
    report = evaluate_policy_on("mujoco", model, n_episodes=50, seed=0)   # check on MuJoCo
    print(report["success_rate"], report["final_position_error"])

Training steps all ``num_envs`` environments with one batched dynamics call per step
(``make_sb3_vec_env``: one learned graph of ``num_envs`` scenes). Evaluation does the same with up
to ``max_parallel`` episodes at once; episode ``k`` is seeded ``seed + k``, so it is the episode
``gym.make(env_id, ...).reset(seed=seed + k)`` would give, whatever the batching.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback
from stable_baselines3.common.type_aliases import PolicyPredictor

from fignet_gym.dynamics import Dynamics, MujocoDynamics
from fignet_gym.envs import make_sb3_vec_env
from fignet_gym.envs.vector import BatchedVectorEnv

PUSH_ID = "fignet_gym/Push-v0"

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


@dataclass(frozen=True)
class PPOConfig:
    """PPO settings (stable-baselines3 names; rollout buffer ``n_steps * num_envs``).

    Args:
        total_timesteps: environment steps in total (over all sub-environments).
        num_envs: sub-environments stepped as one batch.
        n_steps: steps per sub-environment between updates.
        batch_size: minibatch size (at most ``n_steps * num_envs``).
        n_epochs: passes over the rollout buffer per update.
        learning_rate, gamma, gae_lambda, clip_range, ent_coef: PPO's usual meanings.
        net_arch: hidden layer sizes of the policy and value MLPs.
        log_std_init: initial log standard deviation of the Gaussian policy's actions.
        seed: of PPO and the environments.
        torch_threads: torch threads during training; ``None``: 1 when the dynamics is not MuJoCo
            (a learned model in this process: policy and simulator would fight over the same
            cores, and the small policy gains nothing from more), else torch's current setting.
        checkpoint_every: also save the policy every this many environment steps (``None``:
            only at the end); needs ``save_path``.
    """

    total_timesteps: int = 200_000
    num_envs: int = 16
    n_steps: int = 128
    batch_size: int = 256
    n_epochs: int = 10
    learning_rate: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    net_arch: tuple[int, ...] = (64, 64)
    log_std_init: float = 0.0
    seed: int = 0
    torch_threads: int | None = None
    checkpoint_every: int | None = None

    def __post_init__(self) -> None:
        if min(self.total_timesteps, self.num_envs, self.n_steps, self.batch_size) < 1:
            raise ValueError("total_timesteps, num_envs, n_steps and batch_size must be >= 1")
        if self.batch_size > self.n_steps * self.num_envs:
            raise ValueError(
                f"batch_size {self.batch_size} exceeds the rollout buffer "
                f"n_steps * num_envs = {self.n_steps * self.num_envs}"
            )


@contextmanager
def torch_threads(n: int | None) -> Iterator[None]:
    """Run the block with ``n`` torch threads (``None``: unchanged), then restore the setting."""
    before = torch.get_num_threads()
    if n is not None:
        torch.set_num_threads(int(n))
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _env_kwargs(
    dynamics: str | Dynamics, checkpoint: Any, env_kwargs: Mapping[str, Any] | None
) -> dict[str, Any]:
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


def train_ppo(
    dynamics: str | Dynamics = "mujoco",
    *,
    checkpoint: Any = None,
    config: PPOConfig | None = None,
    env_id: str = PUSH_ID,
    env_kwargs: Mapping[str, Any] | None = None,
    save_path: str | os.PathLike | None = None,
    callback: BaseCallback | None = None,
    verbose: int = 0,
) -> PPO:
    """Train an SB3 PPO ``MlpPolicy`` on ``env_id`` stepped by ``dynamics``.

    Args:
        dynamics: ``"mujoco"``, ``"fignet"`` or a :class:`Dynamics` object (the env's
            ``dynamics=`` argument).
        checkpoint: for ``"fignet"``: a checkpoint path or a ``LearnedSimulator`` (default: the
            pretrained model).
        config: :class:`PPOConfig` (default: ``PPOConfig()``).
        env_id: a registered fignet_gym environment.
        env_kwargs: further environment arguments (``shape``, ``friction`` ...).
        save_path: save the trained policy to ``<save_path>.zip`` (SB3's format) with a
            ``<save_path>.json`` describing how it was trained; periodic checkpoints (see
            ``config.checkpoint_every``) go to ``<save_path>_checkpoints/``.
        callback: extra SB3 callback.
        verbose: SB3 verbosity.

    Returns:
        The trained model (its environment is the SB3 vector environment it was trained on).
    """
    cfg = config or PPOConfig()
    if cfg.checkpoint_every is not None and save_path is None:
        raise ValueError("config.checkpoint_every needs save_path")
    vec = make_sb3_vec_env(env_id, cfg.num_envs, **_env_kwargs(dynamics, checkpoint, env_kwargs))
    learned = not isinstance(vec.venv.dynamics, MujocoDynamics)
    threads = cfg.torch_threads if cfg.torch_threads is not None else (1 if learned else None)
    callbacks: list[BaseCallback] = [callback] if callback is not None else []
    if cfg.checkpoint_every is not None and save_path is not None:
        path = Path(save_path)
        callbacks.append(
            CheckpointCallback(
                save_freq=max(1, cfg.checkpoint_every // cfg.num_envs),  # counted in vector steps
                save_path=str(path.parent / f"{path.name}_checkpoints"),
                name_prefix=path.name,
            )
        )
    with torch_threads(threads):
        model = PPO(
            "MlpPolicy",
            vec,
            n_steps=cfg.n_steps,
            batch_size=cfg.batch_size,
            n_epochs=cfg.n_epochs,
            learning_rate=cfg.learning_rate,
            gamma=cfg.gamma,
            gae_lambda=cfg.gae_lambda,
            clip_range=cfg.clip_range,
            ent_coef=cfg.ent_coef,
            policy_kwargs={"net_arch": list(cfg.net_arch), "log_std_init": cfg.log_std_init},
            seed=cfg.seed,
            device="cpu",  # a 64x64 MLP: a GPU would only add transfers
            verbose=verbose,
        )
        model.learn(total_timesteps=cfg.total_timesteps, callback=callbacks or None)
    if save_path is not None:
        meta = {
            "env_id": env_id,
            "dynamics": _describe(dynamics),
            "checkpoint": _describe(checkpoint),
            "env_kwargs": {k: _describe(v) for k, v in (env_kwargs or {}).items()},
            "config": asdict(cfg),
            "timesteps": int(model.num_timesteps),
        }
        save_policy(model, save_path, meta)
    return model


def save_policy(model: PPO, path: str | os.PathLike, metadata: Mapping[str, Any] | None = None) -> Path:
    """Save ``model`` to ``<path>.zip`` and ``metadata`` to ``<path>.json``; returns the zip."""
    base = Path(path)
    if base.suffix == ".zip":
        base = base.with_suffix("")
    base.parent.mkdir(parents=True, exist_ok=True)
    model.save(base)
    if metadata is not None:
        base.with_suffix(".json").write_text(json.dumps(dict(metadata), indent=2))
    return base.with_suffix(".zip")


def load_policy(path: str | os.PathLike) -> PPO:
    """A policy saved by :func:`train_ppo` / :func:`save_policy`, on the CPU, without an env."""
    return PPO.load(Path(path), device="cpu")


def evaluate_policy_on(
    dynamics: str | Dynamics,
    policy: PolicyPredictor,
    n_episodes: int = 10,
    seed: int = 0,
    *,
    checkpoint: Any = None,
    env_id: str = PUSH_ID,
    env_kwargs: Mapping[str, Any] | None = None,
    deterministic: bool = True,
    max_parallel: int = 16,
) -> dict[str, Any]:
    """Run ``policy`` for ``n_episodes`` episodes of ``env_id`` stepped by ``dynamics``.

    Train on learned dynamics, then ``evaluate_policy_on("mujoco", model)`` checks the policy
    against the analytic simulator.

    Args:
        dynamics: ``"mujoco"``, ``"fignet"`` or a :class:`Dynamics` object.
        policy: anything with SB3's ``predict(obs float32[N, D], deterministic=...)``.
        n_episodes: episodes; episode ``k`` is seeded ``seed + k``.
        seed: first episode's seed.
        checkpoint: for ``"fignet"``: path or ``LearnedSimulator``.
        env_id, env_kwargs: the environment (as for :func:`train_ppo`).
        deterministic: use the policy's mean action.
        max_parallel: episodes stepped together (one batched dynamics call per step).

    Returns:
        A dictionary with the keys of :data:`EVAL_KEYS`: ``dynamics`` (its description),
        ``n_episodes``, ``success_rate`` (fraction ending with ``info["is_success"]``),
        ``mean_return``/``std_return``, ``mean_length`` (steps), ``final_position_error`` (m)
        and ``final_orientation_error`` (rad) averaged over episodes (from the last step's
        ``info``), ``diverged_rate`` (episodes the dynamics blew up in), and per-episode lists
        ``episode_returns``, ``episode_position_errors``, ``episode_orientation_errors``,
        ``episode_successes`` and ``episode_initial_observations`` (each episode's first
        observation: set by its seed alone, so equal across dynamics for the same seeds).
    """
    if n_episodes < 1:
        raise ValueError(f"n_episodes must be >= 1, got {n_episodes}")
    n_par = min(n_episodes, max_parallel)
    venv = gym.make_vec(
        env_id,
        num_envs=n_par,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.NEXT_STEP,
        **_env_kwargs(dynamics, checkpoint, env_kwargs),
    )
    assert isinstance(venv.unwrapped, BatchedVectorEnv)
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
            "position_error": float(finals[i].get("position_error", math.nan)),
            "orientation_error": float(finals[i].get("orientation_error", math.nan)),
            "diverged": finals[i].get("diverged") is not None,
            "initial_observation": first_obs[i].tolist(),
        }
        for i in range(n)
    ]


def _item(infos: dict[str, Any], key: str, i: int) -> Any:
    """Sub-environment ``i``'s value of a batched info ``key`` (``None`` where it is absent)."""
    mask = infos.get(f"_{key}")
    if mask is not None and not mask[i]:
        return None
    value = infos[key]
    return None if isinstance(value, dict) else value[i]
