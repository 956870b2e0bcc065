"""``fignet-gym ppo``: train (or resume) a PPO run in a folder, then evaluate it on both dynamics.

The training environment is the batched vector env (:func:`~fignet_gym.envs.make_sb3_vec_env`:
one dynamics call steps every sub-environment) under ``VecMonitor`` (episode returns and lengths
in the env's own reward) and ``VecNormalize`` (running mean/std of observations and of the
discounted return: the reward PPO sees is the env's reward divided by one positive number, so the
task is unchanged). The folder (:mod:`~fignet_gym.agents.ppo.rundir`) holds the config, the
latest checkpoint, the logs (:mod:`~fignet_gym.agents.ppo.logging`) and the final evaluation.

Checkpoints are taken between PPO iterations (after an update, before the next rollout), so all
experience counted by the timestep counter has been trained on. A killed run resumed with
``resume=True`` continues from the last checkpoint: it drops the log rows written after it
(TensorBoard's ``purge_step``, the CSV files rewritten), writes the update's metrics the
checkpoint carried, counts iterations on from the checkpoint's, and restarts the
sub-environments' episodes with their saved random streams (the episodes in progress at the
checkpoint are lost; at most ``num_envs`` partial episodes).
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import gymnasium as gym
import torch
from gymnasium.envs.registration import load_env_creator
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents.ppo.callback import RunCallback, Stop
from fignet_gym.agents.ppo.config import RunConfig
from fignet_gym.agents.ppo.curriculum import GoalCurriculum, find_curriculum
from fignet_gym.agents.ppo.eval import evaluate_both, run_env_kwargs
from fignet_gym.agents.ppo.features import (
    ObservationTransform,
    ProgressShaping,
    SuccessBonus,
    TransformedObservations,
)
from fignet_gym.agents.ppo.logging import CSVRows, make_logger, restore_records
from fignet_gym.agents.ppo.policy import load_run_policy
from fignet_gym.agents.ppo.rng import adapter, set_rng_state
from fignet_gym.agents.ppo.rundir import (
    CHECKPOINT,
    FINAL_EVAL,
    MODEL,
    NORMALIZER,
    POLICY,
    RunError,
    read_state,
    replace_file,
    start,
)
from fignet_gym.atomic import write_text
from fignet_gym.envs.sb3 import make_sb3_vec_env
from fignet_gym.envs.vector import BatchedVectorEnv


class RunPPO(PPO):
    """SB3's PPO whose ``time/iterations`` counts from the run's start, not the process's.

    Every iteration collects exactly ``n_steps * n_envs`` steps, so the iteration number is the
    step counter divided by that; SB3 counts per ``learn()`` call and a resumed run restarted at 1.
    """

    def dump_logs(self, iteration: int = 0) -> None:
        """SB3's log dump with the run's iteration number."""
        super().dump_logs(self.num_timesteps // (self.n_steps * self.n_envs))


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


def check_env_id(env_id: str) -> None:
    """``RunError`` unless ``env_id`` is a registered fignet_gym env (a batched vector entry point)."""
    ours = sorted(k for k in gym.registry if k.startswith("fignet_gym/"))
    if env_id not in gym.registry:
        raise RunError(f"--env {env_id!r} is not registered (fignet_gym ids: {', '.join(ours)})")
    entry = gym.spec(env_id).vector_entry_point
    creator = load_env_creator(entry) if isinstance(entry, str) else entry
    if not (isinstance(creator, type) and issubclass(creator, BatchedVectorEnv)):
        raise RunError(f"--env {env_id!r} is not a fignet_gym environment (one of: {', '.join(ours)})")


def check_features(cfg: RunConfig) -> None:
    """``RunError`` unless the env has what ``cfg.observation`` and ``cfg.shaping`` read (a push
    task): checked on a MuJoCo instance before anything is written."""
    if cfg.observation == "env" and not cfg.shaping:
        return
    env = gym.make(cfg.env_id, **{**cfg.env_kwargs, "dynamics": "mujoco"})
    try:
        task = getattr(env.unwrapped, "task", None)
        if not all(hasattr(task, a) for a in ("outline", "position_weight", "orientation_weight")):
            raise RunError(f"--observation {cfg.observation} and --shaping need a push env, "
                           f"not {cfg.env_id}")
    finally:
        env.close()


def _train_env(cfg: RunConfig) -> tuple[VecNormalize, ObservationTransform]:
    """The training env and the observation transform it applies (the policy's, too)."""
    kwargs = run_env_kwargs(cfg, cfg.dynamics)
    if cfg.dynamics == "fignet" and cfg.precision != "float32":
        kwargs["dynamics_kwargs"] = {**(kwargs.get("dynamics_kwargs") or {}), "precision": cfg.precision}
    base = make_sb3_vec_env(cfg.env_id, cfg.ppo.num_envs, **kwargs)
    first = base.venv.envs[0]
    transform = ObservationTransform.of_env(cfg.observation, first)
    vec: Any = GoalCurriculum(base) if cfg.curriculum else base
    # VecMonitor right above the env: the logged episode returns are the env's own reward,
    # whatever shaping and normalisation PPO trains on above it.
    vec = VecMonitor(vec)
    if cfg.shaping:
        task = first.task
        vec = ProgressShaping(vec, cfg.ppo.gamma, cfg.shaping, task.position_weight,
                              task.orientation_weight)
    if cfg.success_bonus:
        vec = SuccessBonus(vec, cfg.success_bonus)
    if cfg.observation != "env":
        vec = TransformedObservations(vec, transform)
    norm = VecNormalize(vec, norm_obs=cfg.norm_obs, norm_reward=cfg.norm_reward, gamma=cfg.ppo.gamma)
    return norm, transform


def _new_model(cfg: RunConfig, vec: VecNormalize) -> RunPPO:
    p = cfg.ppo
    return RunPPO(
        "MlpPolicy",
        vec,
        n_steps=p.n_steps,
        batch_size=p.batch_size,
        n_epochs=p.n_epochs,
        learning_rate=p.learning_rate,
        gamma=p.gamma,
        gae_lambda=p.gae_lambda,
        clip_range=p.clip_range,
        ent_coef=p.ent_coef,
        use_sde=p.use_sde,
        sde_sample_freq=p.sde_sample_freq,
        policy_kwargs={"net_arch": list(p.net_arch), "log_std_init": p.log_std_init},
        seed=p.seed,
        device="cpu",  # a small MLP: a GPU would only add transfers
    )


def _resumed_model(root: Path, vec: VecNormalize, state: dict[str, Any]) -> tuple[RunPPO, VecNormalize]:
    ck = root / CHECKPOINT
    if (ck / NORMALIZER).exists():
        vec = VecNormalize.load(str(ck / NORMALIZER), vec.venv)
    model = RunPPO.load(ck / MODEL, env=vec, device="cpu")
    model._last_obs = None  # the saved env state is gone: start new episodes (seeded below)
    set_rng_state(vec, state["rng"])
    curriculum = find_curriculum(vec)
    if curriculum is not None and "curriculum" in state:
        curriculum.load_state(state["curriculum"])
    adapter(vec)._reset_seeds()  # PPO.load reseeded the env; the restored streams rule
    return model, vec


def run_ppo(
    out: str | os.PathLike,
    cfg: RunConfig | None = None,
    *,
    resume: bool = False,
    force: bool = False,
    progress: bool = True,
    verbose: bool = False,
    stop_at: int | None = None,
) -> dict[str, Any]:
    """Train (or resume) a PPO run in ``out``, then evaluate its policy on both dynamics.

    Args:
        out: run folder (layout in :mod:`~fignet_gym.agents.ppo.rundir`).
        cfg: the run (default: ``RunConfig()``, the current Push version on MuJoCo); on resume it
            must equal the saved one except ``ppo.total_timesteps`` (a finished run can be
            extended; the budget may not fall below the steps already done).
        resume: continue from ``out/checkpoint`` (or start if the folder has only a config).
        force: delete an existing ``out`` first.
        progress: show a tqdm bar.
        verbose: also print SB3's log table every iteration.
        stop_at: stop (as if killed, after the checkpoint) at the first rollout start at or
            after this step; for tests.

    Returns:
        ``final_eval.json``'s content: ``{"config", "timesteps", "cpu_seconds", "wall_seconds",
        "eval": {dynamics: evaluate_policy_on report}}``. With ``stop_at`` reached: ``{}``.

    Raises:
        RunError: an env that is not a fignet_gym env, an existing folder without ``resume`` or
            ``force``, a resume with other settings; raised before anything is written.
    """
    cfg = cfg if cfg is not None else RunConfig()
    check_env_id(cfg.env_id)
    check_features(cfg)
    root = Path(out)
    cfg, resuming = start(root, cfg, resume, force)

    learned = cfg.dynamics != "mujoco"
    threads = cfg.ppo.torch_threads if cfg.ppo.torch_threads is not None else (1 if learned else None)
    with torch_threads(threads):
        vec, transform = _train_env(cfg)
        state: dict[str, Any] = {}
        if resuming:
            state = read_state(root) or {}
            model, vec = _resumed_model(root, vec, state)
        else:
            model = _new_model(cfg, vec)
        done = int(state.get("num_timesteps", 0))
        logger = make_logger(root, done if resuming else None, verbose)
        model.set_logger(logger)
        restore_records(logger, state.get("pending_log", {"values": {}, "counts": {}, "excluded": {}}))
        evals = CSVRows(root / "eval.csv", keep_until=done if resuming else None)
        cb = RunCallback(root, cfg, evals, stop_at, progress, transform=transform,
                         cpu_before=float(state.get("cpu_seconds", 0.0)),
                         wall_before=float(state.get("wall_seconds", 0.0)))
        remaining = cfg.ppo.total_timesteps - model.num_timesteps
        try:
            if remaining > 0:
                # SB3 adds the counter to total_timesteps when it is not reset.
                model.learn(total_timesteps=remaining, callback=cb, reset_num_timesteps=not resuming,
                            log_interval=1)
        except Stop:
            cb.bar.close()
            logger.close()
            vec.close()
            return {}
        if remaining > 0 or not (root / CHECKPOINT).exists():
            cb.checkpoint()
        logger.close()
        final = read_state(root) or {}
        replace_file(root / POLICY, model.save)  # a kill mid-save must not leave a torn policy.zip
        vec.save(str(root / NORMALIZER))
        vec.close()
        policy = load_run_policy(root)
        reports = evaluate_both(cfg, policy, cfg.final_episodes)
    result = {
        "config": cfg.to_json(),
        "timesteps": int(model.num_timesteps),
        "cpu_seconds": float(final["cpu_seconds"]),
        "wall_seconds": float(final["wall_seconds"]),
        "eval": reports,
    }
    write_text(root / FINAL_EVAL, json.dumps(result, indent=2))
    return result

