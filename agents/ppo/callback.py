"""What a PPO run does between iterations: periodic evaluation, resumable checkpoints, progress."""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecNormalize
from tqdm import tqdm

from fignet_gym.agents.ppo.config import RunConfig
from fignet_gym.agents.ppo.curriculum import find_curriculum
from fignet_gym.agents.ppo.eval import evaluate_both, summary
from fignet_gym.agents.ppo.features import ObservationTransform
from fignet_gym.agents.ppo.logging import CSVRows, pending_records
from fignet_gym.agents.ppo.policy import NormalizedPolicy
from fignet_gym.agents.ppo.rng import rng_state
from fignet_gym.agents.ppo.rundir import MODEL, NORMALIZER, save_checkpoint


def write_checkpoint(root: Path, model: PPO, extra: Mapping[str, Any]) -> None:
    """Save the resumable state of ``model`` (its env, RNG streams, pending log values)."""
    vec = model.get_env()

    def write(folder: Path) -> None:
        model.save(folder / MODEL)
        if isinstance(vec, VecNormalize):
            vec.save(str(folder / NORMALIZER))

    state = {"num_timesteps": int(model.num_timesteps), "rng": rng_state(vec),
             "pending_log": pending_records(model.logger), **extra}
    save_checkpoint(root, write, state)


class Stop(Exception):
    """Raised by :class:`RunCallback` to stop a run at a checkpoint (``stop_at``, for tests)."""


class RunCallback(BaseCallback):
    """Periodic evaluation on both dynamics, resumable checkpoints and the progress bar.

    Evaluation runs at the end of a rollout (the policy is still the one that collected it), so
    its scalars are dumped with that iteration's row; checkpoints are written at the start of the
    next rollout (after the update).

    Args:
        root: the run folder. cfg: the run. evals: ``eval.csv``'s writer.
        stop_at: raise :class:`Stop` (as a kill would, after the checkpoint) at the first rollout
            start at or after this step; for tests.
        progress: show a tqdm bar.
        transform: the observation transform the training env applies (evaluation applies it too).
        cpu_before, wall_before: seconds spent by earlier processes of a resumed run.
    """

    def __init__(self, root: Path, cfg: RunConfig, evals: CSVRows, stop_at: int | None,
                 progress: bool, transform: ObservationTransform | None = None,
                 cpu_before: float = 0.0, wall_before: float = 0.0) -> None:
        super().__init__()
        self.transform = transform
        self.root, self.cfg, self.evals = root, cfg, evals
        self.stop_at = stop_at
        self.progress = progress
        self.next_eval: int | None = 0
        self.next_ckpt = 0
        self.bar: Any = None
        self.cpu0, self.wall0 = time.process_time(), time.perf_counter()
        self.cpu_before, self.wall_before = cpu_before, wall_before

    def _on_training_start(self) -> None:
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
        curriculum = find_curriculum(self.training_env)
        if curriculum is not None:
            self.logger.record("curriculum/level", curriculum.level)
            self.logger.record("curriculum/goal_success", curriculum.success_rate())
            self.logger.record("curriculum/goals_reached", curriculum.goals_reached)
        if self.next_eval is not None and t >= self.next_eval:
            self.next_eval = (t // self.cfg.eval_every + 1) * self.cfg.eval_every
            self.evaluate(t)

    def evaluate(self, t: int) -> dict[str, dict[str, Any]]:
        """Evaluate the current policy on both dynamics; log ``eval/<dynamics>/*`` at step ``t``."""
        vec = self.model.get_env()
        policy = NormalizedPolicy(self.model, vec if isinstance(vec, VecNormalize) else None,
                                  self.transform)
        # Evaluation steps its own envs: the training normaliser's statistics are only read.
        reports = evaluate_both(self.cfg, policy, self.cfg.eval_episodes)
        row = {}
        for dyn, rep in reports.items():
            for k, v in summary(rep).items():
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
            raise Stop

    def seconds(self) -> tuple[float, float]:
        """CPU and wall seconds of the run so far (earlier processes included)."""
        return (self.cpu_before + time.process_time() - self.cpu0,
                self.wall_before + time.perf_counter() - self.wall0)

    def checkpoint(self) -> None:
        """Save the resumable state at the current step."""
        cpu, wall = self.seconds()
        extra: dict[str, Any] = {"cpu_seconds": cpu, "wall_seconds": wall}
        curriculum = find_curriculum(self.model.get_env())
        if curriculum is not None:
            extra["curriculum"] = curriculum.state()
        write_checkpoint(self.root, self.model, extra)

    def _on_training_end(self) -> None:
        self.bar.close()
