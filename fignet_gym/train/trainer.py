"""The trainer: one-step supervision with random-walk noise, pushforward and rollout losses, a
weight average (EMA), validation rollouts that select ``best.pt``, and exact resumption.

``fignet-gym train --data train.h5 --valid valid.h5 --config push-cpu --out runs/push``
(:func:`train_from_files`; the config is :mod:`fignet_gym.train.config`, the windows
:mod:`fignet_gym.train.sampling`, ``--init`` :mod:`fignet_gym.train.warmstart`).

Data-parallel training over several processes (``torchrun --nproc_per_node N -m fignet_gym train
...``; gloo on CPU, NCCL on GPUs) wraps the loss in ``torch.nn.parallel.DistributedDataParallel``:
each process draws its own windows, gradients are averaged across processes in every backward
pass, rank 0's weights and normaliser statistics are shared, and only rank 0 validates, logs and
writes checkpoints. The model runs on CUDA when available.

A run directory holds ``config.json``, ``last.pt`` (model + optimiser + sampler state, written
atomically every ``checkpoint_every`` steps and on interruption), ``best.pt`` (lowest validation
rollout error), ``curve.jsonl`` (one JSON line per validation: step, CPU hours of the training
steps summed over processes (validation and checkpoint writes not counted), graphs seen, errors)
and TensorBoard logs. ``--resume`` continues exactly where a killed run stopped: a SIGKILL loses
the steps since ``last.pt`` (fewer than ``checkpoint_every``), which the resumed run recomputes;
records of those steps are dropped on resume (:mod:`fignet_gym.train.rundir`). A folder holding a
run is never overwritten without ``--force``, and ``--resume`` refuses a config other than the
run's.
"""

from __future__ import annotations

import copy
import json
import math
import os
import signal
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
import torch.distributed as dist
from torch import Tensor, nn
from torch.nn.parallel import DistributedDataParallel
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm

from fignet_gym.data.format import Trajectory, build_scene, load_trajectories
from fignet_gym.pretrained import load_pretrained
from fignet_gym.simulator.checkpoint import CheckpointError, load, save
from fignet_gym.simulator.config import SimulatorConfig
from fignet_gym.simulator.model import LearnedSimulator
from fignet_gym.simulator.scene import Scene
from fignet_gym.train.config import TrainConfig, load_run_config
from fignet_gym.train.evaluation import rollout_metrics
from fignet_gym.train.rundir import (
    PENDING_BEST,
    check_resume_config,
    prepare_run_folder,
    promote_best,
    rewind,
)
from fignet_gym.train.sampling import (
    WindowSampler,
    median_node_acceleration,
    mirror_asymmetric,
    mirror_y,
    rotate_about_z,
)
from fignet_gym.train.warmstart import warm_start

#: Largest global gradient norm of a step (clipped above): one impact window must not undo
#: what thousands of steps have learned.
GRAD_CLIP_NORM = 1.0
#: Steps between TensorBoard records of the training loss, learning rate and speed.
LOG_EVERY = 20
#: The weight average's decay is at most ``(1 + step) / (EMA_WARMUP + step)``: early on it forgets
#: fast, so it does not keep the initial weights.
EMA_WARMUP = 10
#: Process ``r`` seeds its window sampler and noise with ``seed + RANK_SEED_STRIDE * r``.
RANK_SEED_STRIDE = 1000
#: Validation trajectories taken from the end of the training data when no ``--valid`` is given.
DEFAULT_VALID_COUNT = 4
#: Floor of a step's wall time in the graphs-per-second readout.
_TINY_SECONDS = 1e-9


@dataclass
class TrainState:
    """Everything ``--resume`` needs besides model and optimiser weights."""

    step: int = 0
    graphs_seen: int = 0
    cpu_seconds: float = 0.0
    best_error: float = float("inf")
    history: list[dict[str, float]] = field(default_factory=list)


def init_distributed() -> tuple[int, int, torch.device]:
    """``(rank, world size, device)``; joins the process group when launched by ``torchrun``."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    local = int(os.environ.get("LOCAL_RANK", "0"))
    cuda = torch.cuda.is_available()
    device = torch.device(f"cuda:{local}" if cuda else "cpu")
    if world <= 1:
        return 0, 1, device
    if not dist.is_initialized():
        dist.init_process_group("nccl" if cuda else "gloo")
    return dist.get_rank(), dist.get_world_size(), device


def finish_distributed() -> None:
    """Leave the process group once every process is done.

    Without it a process that finishes first exits while gloo's threads still serve the others
    (rank 0 is writing the last checkpoint), and the C++ runtime aborts it (SIGABRT).
    """
    if dist.is_available() and dist.is_initialized():
        dist.barrier()
        dist.destroy_process_group()


#: What ``last.pt``'s metadata must hold for ``--resume``.
_RESUME_KEYS = ("optimizer", "scheduler", "train_state", "sampler_rng", "noise_rng")


class _Objective(nn.Module):
    """The training loss as a module's forward, so that ``DistributedDataParallel`` (which
    averages gradients of what its wrapped module's forward computed) can wrap it: ``forward(scene,
    poses)`` is ``loss(scene, poses)``; its parameters and buffers are ``sim``'s."""

    def __init__(self, sim: LearnedSimulator, loss: Callable[[Scene, Tensor], Tensor]) -> None:
        super().__init__()
        self.sim = sim
        self._loss = loss

    def forward(self, scene: Scene, poses: Tensor) -> Tensor:
        return self._loss(scene, poses)


def _still_ratio(rec: dict[str, float], q: str, at: str) -> float:
    """``rec``'s ratio of ``q`` at ``at`` ("final" or "last") to the no-motion model's. Where
    nothing moved in ``q`` (the no-motion error is exactly zero, e.g. no validation window turns
    yet) the ratio has no scale and counts 0; a missing or non-finite model error counts inf."""
    suffix = "" if at == "final" else "_last"
    ratio = rec.get(f"{q}{suffix}_ratio_still", math.nan)
    if math.isfinite(ratio):
        return ratio
    if rec.get(f"still_{q}_{at}") == 0 and math.isfinite(rec.get(f"{q}_{at}", math.nan)):
        return 0.0
    return math.inf


def selection_score(rec: dict[str, float], last_weight: float) -> float:
    """The validation score ``best.pt`` minimises: translation plus rotation error, each in units
    of the no-motion model's, at the rollout's end, plus ``last_weight`` times the same at its
    last frame; inf when any term is undefined."""
    key = sum(_still_ratio(rec, q, "final") for q in ("translation_rmse", "rotation_deg"))
    if last_weight > 0:
        key += last_weight * sum(_still_ratio(rec, q, "last") for q in ("translation_rmse", "rotation_deg"))
    return key if math.isfinite(key) else math.inf


class Trainer:
    """Trains a :class:`LearnedSimulator` on trajectory files; see the module docstring."""

    def __init__(self, sim_cfg: dict[str, Any], cfg: TrainConfig, train: list[Trajectory],
                 valid: list[Trajectory], out: Path, resume: bool = False,
                 init: str | None = None) -> None:
        self.cfg, self.out = cfg, out
        self.rank, self.world, self.device = init_distributed()
        out.mkdir(parents=True, exist_ok=True)
        if cfg.threads:
            torch.set_num_threads(cfg.threads)
        torch.manual_seed(cfg.seed)
        self.train, self.valid = train, valid
        config, blob = self._config(sim_cfg, resume)
        self.train_scenes = [build_scene(t, config.mesh_options) for t in train]
        self.valid_scenes = [build_scene(t, config.mesh_options) for t in valid]
        if cfg.mirror:
            for traj, scene in zip(train, self.train_scenes, strict=True):
                if bad := mirror_asymmetric(scene):
                    raise ValueError(f"training.mirror: object '{bad[0]}' of trajectory "
                                     f"'{traj.name}' is not symmetric under its body-frame "
                                     f"y -> -y, so its mirrored motion is not physical (set "
                                     f"training.mirror to false)")
        noise_std = cfg.noise_std
        if noise_std <= 0 and cfg.noise_fraction > 0:
            noise_std = cfg.noise_fraction * median_node_acceleration(train, self.train_scenes)
        self.noise = cfg.noise(noise_std)
        self._build(config)
        self.warm_started = init is not None and blob is None
        if self.warm_started:
            # Fine-tuning: weights and normaliser statistics from another run, this run's recipe.
            warm_start(self.sim, load_pretrained(init))
            print(f"initialised from {init}")
        self.ema = copy.deepcopy(self.sim).requires_grad_(False) if cfg.ema_decay > 0 else None
        if blob is not None:
            self._resume(blob)
        self.objective: nn.Module = _Objective(self.sim, self.loss)
        if self.world > 1:
            # Copies rank 0's weights and normaliser statistics to every process now and its
            # statistics before each step (each process accumulates its own windows' during the
            # step, as rank 0's alone were kept before); averages gradients in backward. The
            # weight average is rank 0's alone: only rank 0 validates and saves. Some configs
            # have parameters no loss reaches (one message-passing step: the object encoder feeds
            # nothing), so DDP must look for unused ones (and warns once where there are none).
            self.objective = DistributedDataParallel(self.objective, find_unused_parameters=True)
        if self.rank == 0:
            # ``noise_std``: the noise actually used (measured from the data when the training
            # config leaves it at 0).
            (out / "config.json").write_text(json.dumps(
                {"simulator": config.to_dict(), "training": asdict(cfg),
                 "noise_std": self.noise.std, "processes": self.world}, indent=2))

    def _config(self, sim_cfg: dict[str, Any], resume: bool) -> tuple[SimulatorConfig, dict[str, Any] | None]:
        """The model's config, and with ``resume`` the ``last.pt`` blob it comes from (if any)."""
        dts = {round(t.dt, 9) for t in self.train + self.valid}
        if len(dts) != 1:
            raise ValueError(f"training and validation data mix step lengths {sorted(dts)}")
        last = self.out / "last.pt"
        if resume and last.is_file():
            sim, meta = load(last)  # CheckpointError if damaged
            missing = [k for k in _RESUME_KEYS if k not in meta]
            if missing:
                raise CheckpointError(f"{last}: not a resumable run checkpoint (no {missing[0]})")
            return sim.config, {"state_dict": sim.state_dict(), "meta": meta}
        if resume:
            print(f"--resume: no {last}, starting a new run")
        # The data's own dt, not its rounding: a step spanning many learned steps (an env's 1 s
        # toss of 148 steps of 1/148 s) must divide exactly.
        return SimulatorConfig.from_dict({**sim_cfg, "dt": float(self.train[0].dt)}), None

    def _build(self, config: SimulatorConfig) -> None:
        """A fresh model, its optimiser and schedule, the window sampler and the noise source."""
        cfg = self.cfg
        self.sim = LearnedSimulator(config).to(self.device)
        self.opt = torch.optim.Adam(self.sim.parameters(), lr=cfg.lr)
        gamma = (cfg.lr_final / cfg.lr) ** (1.0 / max(cfg.steps, 1))
        self.sched = torch.optim.lr_scheduler.ExponentialLR(self.opt, gamma)
        self.state = TrainState()
        seed = cfg.seed + RANK_SEED_STRIDE * self.rank  # each process draws other windows and noise
        self.sampler = WindowSampler(self.train, self.train_scenes, config.history, cfg.still_weight, seed,
                                     unroll=cfg.unroll_steps + max(cfg.rollout_steps - 1, 0),
                                     near=cfg.near_motion_poses, near_weight=cfg.near_motion_weight,
                                     targets=max(cfg.rollout_steps, 1))
        self.gen = torch.Generator(device=self.device).manual_seed(seed)

    def _resume(self, blob: dict[str, Any]) -> None:
        """Restore weights (and their average), optimiser, schedule, progress and random streams
        from the ``last.pt`` blob."""
        last = self.out / "last.pt"
        meta = blob["meta"]
        self.sim.load_state_dict(blob["state_dict"])
        if self.ema is not None:
            self.ema.load_state_dict(meta.get("ema", blob["state_dict"]))
        try:
            self.opt.load_state_dict(meta["optimizer"])
        except ValueError as exc:
            raise ValueError(f"{last}: optimiser state from an older layout; start a new run with "
                             f"--init {last} instead of --resume ({exc})") from exc
        self.sched.load_state_dict(meta["scheduler"])
        self.state = TrainState(**meta["train_state"])
        if self.rank == 0:  # other processes continue with fresh draws
            self.sampler.rng.bit_generator.state = json.loads(meta["sampler_rng"])
            self.gen.set_state(meta["noise_rng"])
        rewind(self.out, self.state.step)  # drop records of steps a kill discarded
        print(f"resumed from {last} at step {self.state.step}")

    def check_replicas(self) -> None:
        """Raise if the processes' weights have drifted apart (they must stay identical)."""
        if self.world > 1:
            total = torch.stack([p.detach().double().sum() for p in self.sim.parameters()]).sum()
            gathered = [torch.zeros_like(total) for _ in range(self.world)]
            dist.all_gather(gathered, total)
            if any(not torch.equal(g, gathered[0]) for g in gathered):
                raise RuntimeError(f"data-parallel replicas diverged: {[g.item() for g in gathered]}")

    # -------------------------------------------------------------- one step
    def batch(self) -> tuple[Scene, Tensor]:
        """A disjoint batch of training windows: ``(scene, poses float[H + 1, O_total, 7])``."""
        picks = self.sampler.sample(self.cfg.batch_size)
        scenes, poses = [], []
        for i, t in picks:
            p = torch.as_tensor(self.train[i].poses[t:t + self.sampler.span], dtype=torch.float32)
            if self.cfg.rotate_z:
                angle = float(torch.rand((), generator=self.gen, device=self.device)) * 2 * math.pi
                p = rotate_about_z(p, angle)
            if self.cfg.mirror and float(torch.rand((), generator=self.gen, device=self.device)) < 0.5:
                p = mirror_y(p)
            scenes.append(self.train_scenes[i])
            poses.append(p)
        return Scene.batch(scenes).to(self.device), torch.cat(poses, dim=1).to(self.device)

    @property
    def _warming_up(self) -> bool:
        """Plain one-step training still (``unroll_after``): no pushforward, no rollout loss."""
        return self.state.step < self.cfg.unroll_after

    def pushforward(self, scene: Scene, poses: Tensor, k: int | None = None) -> tuple[Tensor, Tensor | None]:
        """Roll the model out for ``k`` steps (default: drawn uniformly from ``0..unroll_steps``,
        0 during the first ``unroll_after`` optimiser steps)
        from the noisy start of the window ``poses float[H + 1 + K, O, 7]``. Returns the last
        ``H + 1`` true poses and the model's own history ``float[H, O, 7]`` to use instead of
        their first ``H`` rows (``None`` when ``k = 0``: plain noise)."""
        K = self.cfg.unroll_steps
        if K <= 0:
            return poses, None
        if k is None:
            k = 0 if self._warming_up else int(
                torch.randint(0, K + 1, (), generator=self.gen, device=self.device))
        poses = poses[K - k:]
        if k == 0:
            return poses, None
        H = self.sim.config.history + 1
        hist = self.sim.pose_noise(scene, poses[:H], self.gen, self.noise)
        for j in range(k):
            nxt = self.sim.step(scene, hist, poses[H + j])
            hist = torch.cat((hist[1:], nxt[None]), 0)
        return poses[k:], hist

    def loss(self, scene: Scene, poses: Tensor) -> Tensor:
        """The simulator's loss (:meth:`LearnedSimulator.loss`) on a window from :meth:`batch`
        (``poses float[H + 1 + unroll_steps + max(rollout_steps - 1, 0), O, 7]``), after
        pushforward if configured, plus the rollout loss (:meth:`rollout_loss`) if configured."""
        poses, inputs = self.pushforward(scene, poses)
        H = self.sim.config.history + 1
        example = self.sim.training_example(scene, poses[:H + 1], self.gen, inputs, self.noise)
        loss = self.sim.loss(example, self.cfg.rigid_loss_weight,
                             vertical_weight=self.cfg.vertical_weight)
        if self.cfg.rollout_steps > 0 and not self._warming_up:
            loss = loss + self.cfg.rollout_weight * self.rollout_loss(scene, poses, inputs)
        return loss

    def rollout_loss(self, scene: Scene, poses: Tensor, inputs: Tensor | None) -> Tensor:
        """Node position errors of a rollout with gradients (``TrainConfig.rollout_steps``):
        from ``inputs float[H, O, 7]`` (pushforward's history) or the noisy first ``H`` rows of
        ``poses float[H + R, O, 7]`` (true poses), against their last ``R`` rows. Scalar."""
        H, R = self.sim.config.history + 1, self.cfg.rollout_steps
        hist = inputs if inputs is not None else self.sim.pose_noise(scene, poses[:H], self.gen,
                                                                     self.noise)
        dyn = scene.dynamic_mask[scene.node_object]
        terms = []
        for j in range(R):
            nxt = self.sim.differentiable_step(scene, hist, poses[H + j])
            err = scene.node_positions(nxt)[dyn] - scene.node_positions(poses[H + j])[dyn]
            terms.append(err.pow(2).mean() / (j + 1) ** 2)
            hist = torch.cat((hist[1:], nxt[None]), 0)
        scale = self.sim.target_norm.std.mean().to(poses.dtype)
        return torch.stack(terms).mean() / scale**2

    # -------------------------------------------------------------- loop
    def run(self, stop_after: int | None = None) -> TrainState:
        """Train until ``cfg.steps``; checkpoints on interruption (SIGINT / SIGTERM).

        ``stop_after`` ends this call after that many steps, exactly as an interruption would
        (for time-boxed runs and tests of ``--resume``).
        """
        lead = self.rank == 0
        # A resumed run hides TensorBoard events of steps after its checkpoint (a kill's leftovers).
        purge = self.state.step + 1 if self.state.step else None
        writer = SummaryWriter(str(self.out / "tb"), purge_step=purge) if lead else None
        stop = {"flag": False}

        def _stop(signum: int, _frame: object) -> None:
            stop["flag"] = True

        old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
        st = self.state
        bar = tqdm(total=self.cfg.steps, initial=st.step, desc="train", unit="step",
                   dynamic_ncols=True, disable=not lead)
        end = self.cfg.steps if stop_after is None else min(self.cfg.steps, st.step + stop_after)
        try:
            if lead and self.warm_started and st.step == 0 and not st.history:
                # The start of a fine-tuning is a candidate too: on a few real trajectories after
                # pretraining, every later checkpoint can be worse.
                self.validate(writer)
            while st.step < end and not stop["flag"]:
                # The budget is the training step itself: validation rollouts (costly for
                # node-based baselines with many edges) and checkpoint writes are not charged.
                t_start, c_start = time.perf_counter(), time.process_time()
                self.sim.train()
                scene, poses = self.batch()
                loss = self.objective(scene, poses)
                self.opt.zero_grad(set_to_none=True)
                loss.backward()  # under DistributedDataParallel: gradients averaged over processes
                torch.nn.utils.clip_grad_norm_(self.sim.parameters(), GRAD_CLIP_NORM)
                self.opt.step()
                self.sched.step()
                self._update_ema()
                st.step += 1
                st.graphs_seen += self.cfg.batch_size * self.world
                now, cnow = time.perf_counter(), time.process_time()
                # Every process does the same work, so the run's CPU time is world x this one's.
                st.cpu_seconds += (cnow - c_start) * self.world
                gps = self.cfg.batch_size * self.world / max(now - t_start, _TINY_SECONDS)
                bar.update(1)
                if lead and st.step % LOG_EVERY == 0:
                    bar.set_postfix(loss=f"{loss.item():.3g}", gps=f"{gps:.1f}")
                    writer.add_scalar("train/loss", loss.item(), st.step)
                    writer.add_scalar("train/lr", self.sched.get_last_lr()[0], st.step)
                    writer.add_scalar("train/graphs_per_s", gps, st.step)
                if lead and (st.step % self.cfg.valid_every == 0 or st.step == self.cfg.steps):
                    self.validate(writer)
                if lead and st.step % self.cfg.checkpoint_every == 0:
                    self.checkpoint()
            self.check_replicas()
        finally:
            if lead:
                self.checkpoint()
                writer.close()
            bar.close()
            for s, h in old.items():
                signal.signal(s, h)
        return st

    @torch.no_grad()
    def _update_ema(self) -> None:
        if self.ema is None:
            return
        # The usual warm-up: early on the average forgets fast, so it does not keep the init.
        decay = min(self.cfg.ema_decay, (1 + self.state.step) / (EMA_WARMUP + self.state.step))
        for e, p in zip(self.ema.parameters(), self.sim.parameters(), strict=True):
            e.lerp_(p, 1.0 - decay)
        for e, b in zip(self.ema.buffers(), self.sim.buffers(), strict=True):
            e.copy_(b)

    @property
    def model(self) -> LearnedSimulator:
        """The weights that are validated and saved as ``best.pt``: the average, if kept."""
        return self.ema if self.ema is not None else self.sim

    def validate(self, writer: Any | None = None) -> dict[str, float]:
        """Rollout errors on the first validation trajectories; keeps ``best.pt``."""
        self.model.eval()
        n = min(self.cfg.valid_trajectories, len(self.valid))
        m = rollout_metrics(self.model, self.valid[:n], self.valid_scenes[:n], horizon=self.cfg.valid_horizon)
        st = self.state
        rec = {"step": st.step, "graphs_seen": st.graphs_seen, "cpu_hours": st.cpu_seconds / 3600,
               **{k: float(v) for k, v in m.items() if isinstance(v, (int, float))}}
        rec["score"] = key = selection_score(rec, self.cfg.valid_last_weight)
        st.history.append(rec)
        with open(self.out / "curve.jsonl", "a") as fh:
            fh.write(json.dumps(rec) + "\n")
        if writer is not None:
            for k, v in rec.items():
                if k != "step":
                    writer.add_scalar(f"valid/{k}", v, st.step)
        if key < st.best_error:
            st.best_error = key
            # best.pt itself changes only with the next last.pt (rundir.promote_best).
            save(self.model, self.out / PENDING_BEST, meta={"valid": rec})
        print(f"\nstep {st.step}: " + ", ".join(f"{k}={v:.4g}" for k, v in rec.items() if k != "step"))
        return rec

    def checkpoint(self) -> None:
        """Atomically write ``last.pt`` with everything needed to resume."""
        meta = {"optimizer": self.opt.state_dict(), "scheduler": self.sched.state_dict(),
                "train_state": asdict(self.state),
                "sampler_rng": json.dumps(self.sampler.rng.bit_generator.state),
                "noise_rng": self.gen.get_state()}
        if self.ema is not None:
            meta["ema"] = self.ema.state_dict()
        save(self.sim, self.out / "last.pt", meta=meta)
        promote_best(self.out)


def train_from_files(data: str | Sequence[str], valid: str | None, config: str | None, out: str,
                     resume: bool = False, overrides: dict[str, Any] | None = None,
                     max_train: int | None = None, init: str | None = None,
                     force: bool = False) -> TrainState:
    """Load data (one file or several, pooled in order), build a :class:`Trainer` and run it.

    ``out`` must not hold a run unless ``resume`` (continue it: ``config`` must then match the
    run's, and defaults to its ``config.json``) or ``force`` (replace it).
    """
    out_dir = Path(out)
    prepare_run_folder(out_dir, resume, force)
    if resume and config is None and (out_dir / "config.json").is_file():
        config = str(out_dir / "config.json")
    sim_cfg, cfg = load_run_config(config, overrides)
    if resume:
        check_resume_config(out_dir, sim_cfg, asdict(cfg))
    files = [data] if isinstance(data, (str, Path)) else list(data)
    train_trajs = [t for f in files for t in load_trajectories(f)]
    if max_train:
        train_trajs = train_trajs[:max_train]
    valid_trajs = load_trajectories(valid) if valid else train_trajs[-DEFAULT_VALID_COUNT:]
    trainer = Trainer(sim_cfg, cfg, train_trajs, valid_trajs, out_dir, resume=resume, init=init)
    state = trainer.run()
    finish_distributed()
    return state
