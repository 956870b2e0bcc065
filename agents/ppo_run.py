"""A PPO training run in a folder: resumable checkpoints, logs, evaluation on both dynamics.

``fignet-gym ppo`` is :func:`run_ppo`; ``fignet-gym ppo-table`` is :func:`transfer_table`. A run
folder holds::

    config.json          how the run was started (env, dynamics, budget, PPO settings)
    checkpoint/          the latest resumable state (written every ``checkpoint_every`` steps)
        model.zip        SB3 PPO: policy and Adam optimizer state, timestep count
        vecnormalize.pkl observation / return normaliser statistics
        state.pt         timestep count and RNG states (torch, numpy, random, every sub-env)
    tb/                  TensorBoard: rollout/ep_rew_mean, rollout/success_rate, train/*,
                         eval/{mujoco,fignet}/{success_rate,mean_return,...}
    progress.csv         the same scalars, one row per PPO iteration
    eval.csv             one row per periodic evaluation (both dynamics)
    policy.zip, vecnormalize.pkl   the final policy and its normaliser
    final_eval.json      the final policy on both dynamics (``final_episodes`` episodes each)

The training environment is the batched vector env (:func:`~fignet_gym.envs.make_sb3_vec_env`:
one dynamics call steps every sub-environment) under ``VecMonitor`` (episode returns and lengths
in the env's own reward) and ``VecNormalize`` (running mean/std of observations and of the
discounted return: the reward PPO sees is the env's reward divided by one positive number, so the
task is unchanged).

Checkpoints are taken between PPO iterations (after an update, before the next rollout), so all
experience counted by the timestep counter has been trained on. A killed run resumed with
``resume=True`` continues from the last checkpoint: it drops the log rows written after it
(TensorBoard's ``purge_step``, the CSV files rewritten) and restarts the sub-environments'
episodes with their saved random streams (the episodes in progress at the checkpoint are lost; at
most ``num_envs`` partial episodes).
"""

from __future__ import annotations

import csv
import io
import json
import os
import pickle
import random
import shutil
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import (
    HumanOutputFormat,
    KVWriter,
    Logger,
    TensorBoardOutputFormat,
    filter_excluded_keys,
)
from stable_baselines3.common.vec_env import VecEnv, VecMonitor, VecNormalize

from fignet_gym.agents.ppo import PPOConfig, evaluate_policy_on, torch_threads
from fignet_gym.atomic import write_text
from fignet_gym.envs.sb3 import SB3VecEnvAdapter, make_sb3_vec_env

#: Training dynamics a run accepts (the env's ``dynamics=`` names).
DYNAMICS = ("mujoco", "fignet")
#: First seed of the evaluation episodes (episode ``k`` is seeded ``EVAL_SEED + k``): far from the
#: training seeds ``seed .. seed + num_envs - 1``, the same episodes at every evaluation.
EVAL_SEED = 10_000


class RunError(Exception):
    """A user error about a run folder (exists, not resumable, settings differ)."""


@dataclass(frozen=True)
class RunConfig:
    """Everything that defines a PPO run (saved as ``config.json``).

    Args:
        env_id: registered environment id (``fignet_gym/Push-v1`` ...).
        dynamics: training dynamics, ``"mujoco"`` or ``"fignet"``.
        ppo: PPO settings; ``ppo.total_timesteps`` is the run's budget, ``ppo.seed`` its seed.
        simulator: learned simulator for ``"fignet"`` (training and evaluation): a pretrained
            name or a checkpoint path; ``None``: the pretrained simulator of the env's scene.
        env_kwargs: further environment arguments (JSON values only).
        norm_obs, norm_reward: ``VecNormalize`` of observations / of rewards (by the running
            std of the discounted return).
        eval_every: evaluate on both dynamics every this many environment steps (0: never).
        eval_episodes: episodes per dynamics at each periodic evaluation.
        final_episodes: episodes per dynamics of the final evaluation (the transfer table).
        checkpoint_every: save a resumable checkpoint every this many environment steps.
    """

    env_id: str
    dynamics: str
    ppo: PPOConfig = field(default_factory=PPOConfig)
    simulator: str | None = None
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    norm_obs: bool = True
    norm_reward: bool = True
    eval_every: int = 50_000
    eval_episodes: int = 32
    final_episodes: int = 50
    checkpoint_every: int = 20_000

    def __post_init__(self) -> None:
        if self.dynamics not in DYNAMICS:
            raise ValueError(f"dynamics must be one of {DYNAMICS}, got {self.dynamics!r}")
        if self.eval_every < 0 or self.checkpoint_every < 1:
            raise ValueError("eval_every must be >= 0 and checkpoint_every >= 1")
        if self.eval_episodes < 1 or self.final_episodes < 1:
            raise ValueError("eval_episodes and final_episodes must be >= 1")

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dictionary (``net_arch`` as a list)."""
        return asdict(self)

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> RunConfig:
        """Inverse of :meth:`to_json`."""
        ppo = {**asdict(PPOConfig()), **data["ppo"]}
        ppo["net_arch"] = tuple(ppo["net_arch"])
        names = {f.name for f in fields(cls)}
        return cls(**{**{k: v for k, v in data.items() if k in names}, "ppo": PPOConfig(**ppo)})


# ----------------------------------------------------------------------------- policy + normaliser
class NormalizedPolicy:
    """A PPO policy and the observation normaliser it was trained with, acting on raw observations.

    SB3's ``predict`` interface, so :func:`~fignet_gym.agents.evaluate_policy_on` and
    ``stable_baselines3.common.evaluation.evaluate_policy`` take it as is.

    Args:
        model: the trained PPO model.
        normalizer: its ``VecNormalize`` (statistics only; ``None``: observations as they are).
    """

    def __init__(self, model: PPO, normalizer: VecNormalize | None) -> None:
        self.model = model
        self.normalizer = normalizer

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, Any]:
        """Actions ``float32[N, A]`` for raw observations ``float32[N, D]``."""
        obs = observation if self.normalizer is None else self.normalizer.normalize_obs(observation)
        return self.model.predict(obs, state, episode_start, deterministic)


def _load_normalizer(path: Path) -> VecNormalize | None:
    """A saved ``VecNormalize`` in evaluation mode, detached from any environment (or ``None``)."""
    if not path.exists():
        return None
    with path.open("rb") as f:
        norm = pickle.load(f)  # VecNormalize.load would also attach a venv; only its stats are used
    norm.training = False
    norm.norm_reward = False
    return norm


def load_run_policy(run: str | os.PathLike) -> NormalizedPolicy:
    """The final policy of a run folder (``policy.zip`` + ``vecnormalize.pkl``)."""
    root = Path(run)
    if not (root / "policy.zip").exists():
        raise RunError(f"{root}: no policy.zip (the run has not finished)")
    model = PPO.load(root / "policy.zip", device="cpu")
    return NormalizedPolicy(model, _load_normalizer(root / "vecnormalize.pkl"))


# ----------------------------------------------------------------------------- logging
class CSVRows(KVWriter):
    """SB3 logger output: one CSV row per dump, keyed by step, rewritten whole on every dump.

    SB3's own CSV writer truncates its file when it opens it; this one starts from the rows of an
    earlier process, keeps those up to ``keep_until`` (a resumed run's checkpoint) and drops the
    rest, so a resumed log has every step once. Columns are the union of all keys seen.

    Args:
        path: the CSV file.
        keep_until: keep existing rows whose ``step`` is at most this (``None``: start empty).
    """

    def __init__(self, path: Path, keep_until: int | None = None) -> None:
        self.path = path
        self.rows: list[dict[str, Any]] = []
        if keep_until is not None and path.exists():
            with path.open(newline="") as f:
                self.rows = [r for r in csv.DictReader(f) if int(r["step"]) <= keep_until]
        self._flush()

    def add(self, step: int, values: Mapping[str, Any]) -> None:
        """Append one row (``values`` must not contain ``step``)."""
        self.rows.append({"step": int(step), **values})
        self._flush()

    def write(self, key_values: dict[str, Any], key_excluded: dict[str, Any], step: int = 0) -> None:
        values = filter_excluded_keys(key_values, key_excluded, "csv")
        self.add(step, {k: v for k, v in values.items() if isinstance(v, (int, float, np.number))})

    def _flush(self) -> None:
        columns = list(dict.fromkeys(k for r in self.rows for k in r)) or ["step"]
        buf = io.StringIO(newline="")
        writer = csv.DictWriter(buf, fieldnames=columns)
        writer.writeheader()
        writer.writerows(self.rows)
        write_text(self.path, buf.getvalue())

    def close(self) -> None:
        pass


class _TensorBoard(TensorBoardOutputFormat):
    """SB3's TensorBoard output whose writer hides earlier events from ``purge_step`` on."""

    def __init__(self, folder: Path, purge_step: int | None) -> None:
        from torch.utils.tensorboard import SummaryWriter

        # Events at steps after a checkpoint were written by a killed process and are redone
        # from it: SummaryWriter(purge_step=...) tells TensorBoard to drop them.
        self.writer = SummaryWriter(str(folder), purge_step=purge_step)
        self._is_closed = False


def read_csv(path: str | os.PathLike) -> list[dict[str, str]]:
    """Rows of a run's ``progress.csv`` / ``eval.csv``."""
    with Path(path).open(newline="") as f:
        return list(csv.DictReader(f))


def _logger(root: Path, resume_step: int | None, verbose: bool) -> tuple[Logger, CSVRows]:
    """SB3 logger writing TensorBoard (``tb/``) and ``progress.csv``; resumed: purge after the step."""
    tb = _TensorBoard(root / "tb", None if resume_step is None else resume_step + 1)
    rows = CSVRows(root / "progress.csv", keep_until=resume_step)
    outputs: list[KVWriter] = [tb, rows]
    if verbose:
        outputs.append(HumanOutputFormat(sys.stdout))
    return Logger(str(root), outputs), rows


# ----------------------------------------------------------------------------- environments
def _adapter(vec: VecEnv) -> SB3VecEnvAdapter:
    """The batched env's SB3 adapter under SB3 wrappers (``VecNormalize``, ``VecMonitor``)."""
    inner: Any = vec
    while not isinstance(inner, SB3VecEnvAdapter):
        inner = inner.venv
    return inner


def _sub_envs(vec: VecEnv) -> list[Any]:
    """The single environments under SB3 wrappers (their ``np_random`` streams)."""
    return list(_adapter(vec).venv.envs)


def _env_kwargs(cfg: RunConfig, dynamics: str) -> dict[str, Any]:
    kwargs = {**cfg.env_kwargs, "dynamics": dynamics}
    if dynamics == "fignet" and cfg.simulator is not None:
        kwargs["checkpoint"] = cfg.simulator
    return kwargs


def _train_env(cfg: RunConfig) -> VecNormalize:
    vec = make_sb3_vec_env(cfg.env_id, cfg.ppo.num_envs, **_env_kwargs(cfg, cfg.dynamics))
    # VecMonitor below the normaliser: the logged episode returns are the env's own reward.
    return VecNormalize(
        VecMonitor(vec), norm_obs=cfg.norm_obs, norm_reward=cfg.norm_reward, gamma=cfg.ppo.gamma
    )


def evaluate_both(
    cfg: RunConfig, policy: NormalizedPolicy, n_episodes: int, seed: int = EVAL_SEED
) -> dict[str, dict[str, Any]]:
    """``policy`` on MuJoCo and on FIGNet: :func:`evaluate_policy_on` reports keyed by dynamics."""
    out = {}
    for dyn in DYNAMICS:
        kwargs = _env_kwargs(cfg, dyn)
        dynamics = kwargs.pop("dynamics")
        checkpoint = kwargs.pop("checkpoint", None)
        out[dyn] = evaluate_policy_on(
            dynamics,
            policy,
            n_episodes=n_episodes,
            seed=seed,
            checkpoint=checkpoint,
            env_id=cfg.env_id,
            env_kwargs=kwargs,
            max_parallel=32,
        )
    return out


def _summary(report: Mapping[str, Any]) -> dict[str, float]:
    keys = ("success_rate", "mean_return", "final_position_error", "final_orientation_error",
            "diverged_rate")
    return {k: float(report[k]) for k in keys}


# ----------------------------------------------------------------------------- checkpoints
def _rng_state(vec: VecEnv) -> dict[str, Any]:
    return {
        "torch": torch.get_rng_state(),
        "numpy": np.random.get_state(),
        "random": random.getstate(),
        "envs": [env.np_random.bit_generator.state for env in _sub_envs(vec)],
    }


def _set_rng_state(vec: VecEnv, state: Mapping[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["random"])
    for env, s in zip(_sub_envs(vec), state["envs"], strict=True):
        env.np_random.bit_generator.state = s


def save_checkpoint(root: Path, model: PPO, extra: Mapping[str, Any]) -> None:
    """Write ``root/checkpoint/`` atomically (a new folder renamed over the old one)."""
    tmp, final = root / "checkpoint.tmp", root / "checkpoint"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    model.save(tmp / "model.zip")
    vec = model.get_env()
    if isinstance(vec, VecNormalize):
        vec.save(str(tmp / "vecnormalize.pkl"))
    torch.save(
        {"num_timesteps": int(model.num_timesteps), "rng": _rng_state(vec), **extra},
        tmp / "state.pt",
    )
    old = root / "checkpoint.old"
    shutil.rmtree(old, ignore_errors=True)
    if final.exists():
        final.rename(old)
    tmp.rename(final)
    shutil.rmtree(old, ignore_errors=True)


class RunCallback(BaseCallback):
    """Periodic evaluation on both dynamics, resumable checkpoints and the progress bar.

    Evaluation runs at the end of a rollout (the policy is still the one that collected it), so
    its scalars are dumped with that iteration's row; checkpoints are written at the start of the
    next rollout (after the update).
    """

    def __init__(self, root: Path, cfg: RunConfig, evals: CSVRows, stop_at: int | None,
                 progress: bool) -> None:
        super().__init__()
        self.root, self.cfg, self.evals = root, cfg, evals
        self.stop_at = stop_at  # tests: stop (as a kill would) at a rollout start >= this step
        self.progress = progress
        self.next_eval = self.next_ckpt = 0
        self.bar: Any = None
        self.cpu0, self.wall0 = time.process_time(), time.perf_counter()
        self.cpu_before = self.wall_before = 0.0

    def _on_training_start(self) -> None:
        from tqdm import tqdm

        t = self.model.num_timesteps
        every = self.cfg.eval_every
        self.next_eval = (t // every + 1) * every if every else None
        self.next_ckpt = (t // self.cfg.checkpoint_every + 1) * self.cfg.checkpoint_every
        self.cpu0, self.wall0 = time.process_time(), time.perf_counter()
        self.bar = tqdm(total=self.cfg.ppo.total_timesteps, initial=t, unit="step",
                        desc=f"ppo {self.cfg.dynamics}", disable=not self.progress,
                        mininterval=2.0, dynamic_ncols=True)

    def _on_step(self) -> bool:
        self.bar.update(self.training_env.num_envs)
        return True

    def _on_rollout_end(self) -> None:
        t = self.model.num_timesteps
        buf = self.model.ep_success_buffer
        self.bar.set_postfix(
            ret=f"{np.mean([e['r'] for e in self.model.ep_info_buffer]):.1f}"
            if self.model.ep_info_buffer else "-",
            success=f"{np.mean(buf):.0%}" if buf else "-",
            refresh=False,
        )
        if self.next_eval is not None and t >= self.next_eval:
            self.next_eval = (t // self.cfg.eval_every + 1) * self.cfg.eval_every
            self.evaluate(t)

    def evaluate(self, t: int) -> dict[str, dict[str, Any]]:
        """Evaluate the current policy on both dynamics; log ``eval/<dynamics>/*`` at step ``t``."""
        vec = self.model.get_env()
        policy = NormalizedPolicy(self.model, vec if isinstance(vec, VecNormalize) else None)
        # Evaluation steps its own envs: the training normaliser's statistics are only read.
        reports = evaluate_both(self.cfg, policy, self.cfg.eval_episodes)
        row = {}
        for dyn, rep in reports.items():
            for k, v in _summary(rep).items():
                self.logger.record(f"eval/{dyn}/{k}", v)
                row[f"{dyn}/{k}"] = v
        self.evals.add(t, row)
        return reports

    def _on_rollout_start(self) -> None:
        t = self.model.num_timesteps
        if t >= self.next_ckpt:
            self.next_ckpt = (t // self.cfg.checkpoint_every + 1) * self.cfg.checkpoint_every
            self.checkpoint()
        if self.stop_at is not None and t >= self.stop_at:
            raise _Stop

    def checkpoint(self) -> None:
        """Save the resumable state at the current step."""
        save_checkpoint(self.root, self.model, {
            "cpu_seconds": self.cpu_before + time.process_time() - self.cpu0,
            "wall_seconds": self.wall_before + time.perf_counter() - self.wall0,
        })

    def _on_training_end(self) -> None:
        self.bar.close()


class _Stop(Exception):
    """Raised by :class:`RunCallback` to stop a run at a checkpoint (``stop_at``, for tests)."""


# ----------------------------------------------------------------------------- the run
def _prepare_dir(root: Path, resume: bool, force: bool) -> bool:
    """Whether to resume; creates ``root``. ``RunError`` for an existing folder without a flag."""
    if resume and not (root / "checkpoint").exists() and (root / "checkpoint.old").exists():
        (root / "checkpoint.old").rename(root / "checkpoint")  # killed between the two renames
    if resume and (root / "checkpoint" / "state.pt").exists():
        return True
    if resume and not (root / "config.json").exists():
        raise RunError(f"{root}: nothing to resume (no config.json); start it without --resume")
    if resume:
        # Stopped before its first checkpoint: start again, without the stopped process's logs.
        for item in root.iterdir():
            if item.name != "config.json":
                shutil.rmtree(item) if item.is_dir() else item.unlink()
        return False
    if root.exists() and any(root.iterdir()) and not resume:
        if not force:
            raise RunError(f"{root} exists: pass --resume to continue it or --force to overwrite it")
        shutil.rmtree(root)
    root.mkdir(parents=True, exist_ok=True)
    return False


def _check_same(saved: RunConfig, given: RunConfig, root: Path) -> RunConfig:
    """The saved config with the given budget; ``RunError`` if anything else differs."""
    same_budget = replace(given, ppo=replace(given.ppo, total_timesteps=saved.ppo.total_timesteps))
    a, b = saved.to_json(), same_budget.to_json()
    diff = [k for k in a if a[k] != b[k]]
    if diff:
        raise RunError(f"{root}/config.json: --resume with different settings ({', '.join(diff)}); "
                       f"saved {', '.join(f'{k}={a[k]}' for k in diff)}")
    return replace(saved, ppo=replace(saved.ppo, total_timesteps=given.ppo.total_timesteps))


def run_ppo(
    out: str | os.PathLike,
    cfg: RunConfig,
    *,
    resume: bool = False,
    force: bool = False,
    progress: bool = True,
    verbose: bool = False,
    stop_at: int | None = None,
) -> dict[str, Any]:
    """Train (or resume) a PPO run in ``out``, then evaluate its policy on both dynamics.

    Args:
        out: run folder (layout in the module docstring).
        cfg: the run; on resume it must equal the saved one except ``ppo.total_timesteps``
            (a finished run can be extended).
        resume: continue from ``out/checkpoint`` (or start if the folder has only a config).
        force: delete an existing ``out`` first.
        progress: show a tqdm bar.
        verbose: also print SB3's log table every iteration.
        stop_at: stop (as if killed, without saving) at the first rollout start at or after
            this step; for tests.

    Returns:
        ``final_eval.json``'s content: ``{"config", "timesteps", "cpu_seconds", "wall_seconds",
        "eval": {dynamics: evaluate_policy_on report}}``. With ``stop_at`` reached: ``{}``.
    """
    root = Path(out)
    resuming = _prepare_dir(root, resume, force)
    if (root / "config.json").exists():
        cfg = _check_same(RunConfig.from_json(json.loads((root / "config.json").read_text())), cfg, root)
    write_text(root / "config.json", json.dumps(cfg.to_json(), indent=2))

    learned = cfg.dynamics != "mujoco"
    threads = cfg.ppo.torch_threads if cfg.ppo.torch_threads is not None else (1 if learned else None)
    with torch_threads(threads):
        vec = _train_env(cfg)
        state: dict[str, Any] = {}
        if resuming:
            ck = root / "checkpoint"
            state = torch.load(ck / "state.pt", weights_only=False)
            if (ck / "vecnormalize.pkl").exists():
                vec = VecNormalize.load(str(ck / "vecnormalize.pkl"), vec.venv)
            model = PPO.load(ck / "model.zip", env=vec, device="cpu")
            model._last_obs = None  # the saved env state is gone: start new episodes (seeded below)
            _set_rng_state(vec, state["rng"])
            _adapter(vec)._reset_seeds()  # PPO.load reseeded the env; the restored streams rule
        else:
            model = PPO(
                "MlpPolicy",
                vec,
                n_steps=cfg.ppo.n_steps,
                batch_size=cfg.ppo.batch_size,
                n_epochs=cfg.ppo.n_epochs,
                learning_rate=cfg.ppo.learning_rate,
                gamma=cfg.ppo.gamma,
                gae_lambda=cfg.ppo.gae_lambda,
                clip_range=cfg.ppo.clip_range,
                ent_coef=cfg.ppo.ent_coef,
                policy_kwargs={"net_arch": list(cfg.ppo.net_arch),
                               "log_std_init": cfg.ppo.log_std_init},
                seed=cfg.ppo.seed,
                device="cpu",  # a small MLP: a GPU would only add transfers
            )
        done = int(state.get("num_timesteps", 0))
        logger, _ = _logger(root, done if resuming else None, verbose)
        model.set_logger(logger)
        evals = CSVRows(root / "eval.csv", keep_until=done if resuming else None)
        cb = RunCallback(root, cfg, evals, stop_at, progress)
        cb.cpu_before = float(state.get("cpu_seconds", 0.0))
        cb.wall_before = float(state.get("wall_seconds", 0.0))
        remaining = cfg.ppo.total_timesteps - model.num_timesteps
        try:
            if remaining > 0:
                # SB3 adds the counter to total_timesteps when it is not reset.
                model.learn(total_timesteps=remaining, callback=cb, reset_num_timesteps=not resuming,
                            log_interval=1)
        except _Stop:
            cb.bar.close()
            logger.close()
            vec.close()
            return {}
        if remaining > 0 or not (root / "checkpoint").exists():
            cb.checkpoint()
        logger.close()
        cpu = float(torch.load(root / "checkpoint" / "state.pt", weights_only=False)["cpu_seconds"])
        wall = float(torch.load(root / "checkpoint" / "state.pt", weights_only=False)["wall_seconds"])
        model.save(root / "policy.tmp.zip")  # a kill mid-save must not leave a torn policy.zip
        os.replace(root / "policy.tmp.zip", root / "policy.zip")
        vec.save(str(root / "vecnormalize.pkl"))
        vec.close()
        policy = load_run_policy(root)
        reports = evaluate_both(cfg, policy, cfg.final_episodes)
    result = {
        "config": cfg.to_json(),
        "timesteps": int(model.num_timesteps),
        "cpu_seconds": cpu,
        "wall_seconds": wall,
        "eval": reports,
    }
    write_text(root / "final_eval.json", json.dumps(result, indent=2))
    return result


# ----------------------------------------------------------------------------- transfer table
def read_final_eval(path: Path) -> dict[str, Any]:
    """A run's ``final_eval.json``, checked for what :func:`transfer_table` reads.

    Raises ``ValueError("{path}: ...")`` for a file that is not JSON or lacks a field.
    """
    try:
        res = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not valid JSON ({err.msg} at line {err.lineno})") from None
    evals = res.get("eval") if isinstance(res, dict) else None
    ok = (isinstance(res, dict) and isinstance(res.get("config"), dict)
          and "dynamics" in res["config"] and isinstance(res.get("timesteps"), int)
          and isinstance(res.get("cpu_seconds"), (int, float)) and isinstance(evals, dict)
          and all(isinstance(evals.get(k), dict)
                  and all(f in evals[k] for f in ("success_rate", "mean_return", "n_episodes"))
                  for k in ("mujoco", "fignet")))
    if not ok:
        raise ValueError(f"{path}: not a final evaluation (needs config.dynamics, timesteps, "
                         "cpu_seconds and eval.mujoco / eval.fignet with success_rate, "
                         "mean_return, n_episodes)")
    return res


def transfer_table(runs: Sequence[str | os.PathLike]) -> str:
    """Markdown table: each run (its training dynamics) x evaluated on MuJoCo / on FIGNet.

    Reads every run's ``final_eval.json`` (same seeds ``EVAL_SEED + k`` for all runs and both
    dynamics). Cells: success rate and mean return (the env's reward) over the episodes.
    """
    lines = [
        "| trained on | steps | CPU h | eval on MuJoCo: success | return "
        "| eval on FIGNet: success | return | episodes |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for run in runs:
        path = Path(run) / "final_eval.json"
        if not path.exists():
            raise RunError(f"{path}: missing (the run has not finished)")
        res = read_final_eval(path)
        m, f = res["eval"]["mujoco"], res["eval"]["fignet"]
        lines.append(
            f"| {res['config']['dynamics']} ({Path(run).name}) | {res['timesteps']:,} | "
            f"{res['cpu_seconds'] / 3600:.2f} | {m['success_rate']:.0%} | {m['mean_return']:.1f} | "
            f"{f['success_rate']:.0%} | {f['mean_return']:.1f} | {m['n_episodes']} / {f['n_episodes']} |"
        )
    return "\n".join(lines)


def plot_curves(runs: Sequence[str | os.PathLike], path: str | os.PathLike) -> Path:
    """Periodic evaluation of each run (``eval.csv``): success rate and return vs training steps.

    One line per run and evaluation dynamics (solid: MuJoCo, dashed: FIGNet); saved as an image.
    """
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for i, run in enumerate(runs):
        rows = read_csv(Path(run) / "eval.csv")
        if not rows:
            continue
        trained = json.loads((Path(run) / "config.json").read_text())["dynamics"]
        x = [int(r["step"]) for r in rows]
        for dyn, style in (("mujoco", "-"), ("fignet", "--")):
            for ax, key in zip(axes, ("success_rate", "mean_return"), strict=True):
                ax.plot(x, [float(r[f"{dyn}/{key}"]) for r in rows], style, color=f"C{i}",
                        label=f"trained on {trained}, eval on {dyn}")
    axes[0].set_ylabel("success rate")
    axes[1].set_ylabel("mean episode return (env reward)")
    for ax in axes:
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v / 1000:g}k"))
        ax.set_xlabel("training environment steps")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
