"""Training loop: one-step supervision, random-walk noise, rotation augmentation, resumable.

``fignet-gym train --data train.h5 --valid valid.h5 --config push-cpu --out runs/push``

Data-parallel training over several processes (``torchrun --nproc_per_node N -m fignet_gym train
...``; gloo on CPU, NCCL on GPUs): each process draws its own windows, gradients are averaged across
processes every step, rank 0's normaliser statistics are shared, and only rank 0 validates, logs
and writes checkpoints. The model runs on CUDA when available.

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
import signal
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from fignet_gym.data.format import Trajectory, build_scene, load_trajectories
from fignet_gym.pretrained import load_checkpoint
from fignet_gym.simulator.checkpoint import read_checkpoint
from fignet_gym.simulator.geometry import quat_mul
from fignet_gym.simulator.graph import FACE_BASE, FACE_GROUPS
from fignet_gym.simulator.model import CheckpointError, LearnedSimulator, SimulatorConfig
from fignet_gym.simulator.scene import Scene
from fignet_gym.train.rundir import (
    PENDING_BEST,
    check_resume_config,
    prepare_run_folder,
    promote_best,
    rewind,
)

# Training settings of retired experiments and the one value each still accepts (as
# ``model.RETIRED_KEYS`` for the simulator's), so that run configs that name them keep loading.
RETIRED_TRAINING_KEYS: dict[str, Any] = {"start_weight": 1.0}


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation and sampling settings (the model's own settings are in ``SimulatorConfig``).

    Attributes:
        steps: optimiser steps.
        batch_size: graphs (training windows) per step, joined into one disjoint graph.
        lr, lr_final: exponential decay from ``lr`` to ``lr_final`` over ``steps``.
        noise_fraction: training noise std as a fraction of the median per-step acceleration of
            moving dynamic nodes in the training data (used when the model's ``noise_std`` is 0).
        still_weight: sampling weight of windows in which no dynamic object moves (moving: 1 to
            11 by acceleration), unless motion happens within ``near_motion_poses`` poses before or
            after the window: those (a pusher closing in, not yet touching; an object that has
            just stopped) weigh ``near_motion_weight``, so that the model learns when contact has
            not begun yet and that an object once stopped stays put.
        rigid_loss_weight: weight of the per-object linear and angular acceleration loss terms.
        unroll_steps: pushforward training: each batch first rolls the model out for ``k`` steps
            (``k`` uniform in ``0..unroll_steps``, no gradient) from noisy inputs, then is
            supervised on the next step from its own predicted history, so that it learns to
            correct the errors it really makes, not only synthetic noise.
        unroll_after: optimiser steps of plain one-step training before pushforward (and the
            rollout loss) begin: an untrained model's own rollouts are junk states to learn from.
        rollout_steps: training through rollouts: each batch also rolls the model out for this
            many steps with gradients (:meth:`LearnedSimulator.differentiable_step`, after any
            pushforward) and adds ``rollout_weight`` times the mean squared node position error
            of step ``j`` divided by ``j`` (so that an acceleration error carried since the first
            step weighs as much as in the one-step loss), normalised like the one-step loss.
            Errors that are small per step but add up, such as a few percent of excess impulse at
            an impact, are what it supervises. 0: off. Windows are then weighted by the largest
            acceleration among the rollout's targets.
        rotate_z: random rotation of each window about the vertical axis.
        mirror: reflect half of the windows in the vertical plane y = 0 (:func:`mirror_y`), which
            is physical only when every object's mesh and centre of mass are symmetric under its
            own body-frame y -> -y (a box, a cylinder; the trainer refuses other scenes) and
            friction is isotropic.
        valid_every: steps between validation rollouts; valid_trajectories: how many;
            valid_horizon: the step at which errors are scored (``best.pt`` has the lowest sum of
            translation and rotation errors relative to the no-motion model there).
        valid_last_weight: weight in that score of the same two ratios at each validation
            trajectory's last frame (0: the horizon only). Real tosses end at rest: where the
            object stops is what a user of the simulator sees, and frame 50 alone does not
            select for it.
        checkpoint_every: steps between checkpoints of ``last.pt``.
        ema_decay: validation, ``best.pt`` and shipping use an exponential moving average of the
            weights with this decay (0: the raw weights), which smooths out the step-to-step jitter
            of rollout errors that Adam's noise causes.
        threads: torch threads (0: leave torch's default).
        seed: random seed of sampling, noise and initialisation.
    """

    steps: int = 20_000
    batch_size: int = 8
    lr: float = 1e-3
    lr_final: float = 1e-4
    noise_fraction: float = 0.5
    still_weight: float = 0.1
    near_motion_poses: int = 10
    near_motion_weight: float = 3.0
    rigid_loss_weight: float = 1.0
    unroll_steps: int = 0
    unroll_after: int = 0
    rollout_steps: int = 0
    rollout_weight: float = 1.0
    rotate_z: bool = True
    mirror: bool = False
    valid_every: int = 1000
    valid_trajectories: int = 8
    valid_horizon: int = 50
    valid_last_weight: float = 0.0
    checkpoint_every: int = 250
    ema_decay: float = 0.999
    threads: int = 0
    seed: int = 0

    def __post_init__(self) -> None:
        # Zero or negative counts would divide by zero or never validate; say what is allowed.
        for f in fields(self):
            value, lo = getattr(self, f.name), _TRAIN_MINIMUM.get(f.name, 0)
            if f.type == "bool":
                if not isinstance(value, bool):
                    raise ValueError(f"training.{f.name} must be true or false, got {value!r}")
            elif f.type == "int":
                if isinstance(value, bool) or not isinstance(value, int) or value < lo:
                    raise ValueError(f"training.{f.name} must be an integer >= {lo}, got {value!r}")
            elif (isinstance(value, bool) or not isinstance(value, (int, float))
                  or not math.isfinite(value) or value < lo
                  or (f.name in _TRAIN_POSITIVE and value <= 0)):
                rule = "> 0" if f.name in _TRAIN_POSITIVE else f">= {lo}"
                raise ValueError(f"training.{f.name} must be a finite number {rule}, got {value!r}")
        if self.ema_decay >= 1:
            raise ValueError(f"training.ema_decay must be below 1, got {self.ema_decay!r}")

    @staticmethod
    def from_dict(d: dict[str, Any]) -> TrainConfig:
        """Build from a dict; unknown keys and out-of-range values are an error, and so is a retired key
        (:data:`RETIRED_TRAINING_KEYS`) set to anything but the one value it still accepts."""
        d = dict(d)
        for key, accepted in RETIRED_TRAINING_KEYS.items():
            if key in d and d.pop(key) != accepted:
                raise ValueError(f"training config key {key!r} is a retired experiment: only "
                                 f"{key}={accepted!r} is supported (docs/experiments.md)")
        unknown = set(d) - {f.name for f in fields(TrainConfig)}
        if unknown:
            raise ValueError(f"unknown training config keys {sorted(unknown)}")
        return TrainConfig(**d)


#: Smallest allowed value of the integer training settings (others: 0).
_TRAIN_MINIMUM = {"steps": 1, "batch_size": 1, "valid_every": 1, "valid_trajectories": 1,
                  "valid_horizon": 1, "checkpoint_every": 1}
#: Float training settings that must be strictly positive.
_TRAIN_POSITIVE = {"lr", "lr_final"}


# Latent 64, 5 message-passing steps, no mesh-mesh edges (FIGNet*): cheaper per graph than the
# paper's size, so a CPU budget sees more graphs (docs/experiments.md, "Speed").
_CPU_SIZE = dict(latent_size=64, message_passing_steps=5, mesh_edges=False)
# The pusher is meshed as an octagonal prism (0.4 mm from its true 4.75 mm radius): fewer faces.
_PUSH_SCENE = dict(_CPU_SIZE, collision_radius=0.01, vertical_weight=0.1, scene_type="push",
                   feature_clip=0.1, mesh_options={"cylinder_sections": 8})
# The shipped push model's: small position noise, larger rotational noise, next-step separation.
_PUSH_MODEL = dict(_PUSH_SCENE, noise_std=5e-5, rotation_noise_std=5e-3, next_separation=True)

PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    # A push model from scratch on a CPU budget: the CPU size, one-step training only.
    "push-cpu": {"simulator": dict(_PUSH_SCENE), "training": dict(batch_size=8, valid_horizon=25)},
    # The last stage of the shipped push model (see its model card), for fine-tuning a trained
    # push model (--init): pushforward from step 0 at a low learning rate. Not for training from
    # scratch: a random model's pushforward states are junk to learn from.
    "push-finetune": {"simulator": dict(_PUSH_MODEL),
                      "training": dict(batch_size=16, lr=1e-4, lr_final=1e-5, unroll_steps=6,
                                       rigid_loss_weight=3.0, valid_every=500, valid_trajectories=100,
                                       valid_horizon=25)},
    # A push model from scratch: push-finetune's model with the rigid output projection, a higher
    # learning rate and plain one-step training before pushforward (from step 1500). No shipped
    # model was trained with it (docs/experiments.md, "Pushing from scratch").
    "push-scratch": {"simulator": dict(_PUSH_MODEL, rigid_output=True),
                     "training": dict(steps=40_000, batch_size=16, lr=5e-4, lr_final=1e-5, unroll_steps=6,
                                      unroll_after=1500, rigid_loss_weight=3.0, valid_every=1000,
                                      valid_trajectories=100, valid_horizon=25)},
    # Tossing from scratch, the shipped toss model's recipe (one run of this preset; its model card
    # names the step): gravity prior, rigid output projection, pushforward (up to 3 steps) once
    # 5000 plain steps have taught the model something.
    "toss-cpu": {"simulator": dict(_CPU_SIZE, collision_radius=0.1, scene_type="toss",
                                   gravity=(0.0, 0.0, -10.0), feature_clip=3.0, rigid_output=True),
                 # Select on 50 validation tosses: fewer are too noisy to rank checkpoints.
                 "training": dict(steps=40_000, batch_size=4, lr=1e-3, lr_final=3e-5, unroll_steps=3,
                                  unroll_after=5000, valid_every=2000, valid_trajectories=50)},
    # Real tracked tosses of one 10.5 cm cube (ContactNets, ``fignet-gym import-contactnets``) at
    # the data's own dt (6.76 ms; set from the data). Gravity is a parameter of the recipe, not
    # Kubric's -10: the free flight of the training tosses fits -9.61 m/s^2 (median of per-toss
    # parabola fits, ``free_flight_gravity``), and ``train_on_split`` re-measures it on the split
    # it is given. A cube touches the floor with a corner, an edge or a face within a few mm, so a
    # 2 cm collision radius (~0.4 half-widths) sees every contact a step ahead (3 and 4 cm
    # were no better: docs/experiments.md, Issue 14, eighth round). The rest is
    # toss-cpu's (5 message-passing steps, a 40k-step schedule, pushforward after 5000 steps):
    # the shipped model's recipe, which beat 3 steps and a 5000-step schedule on validation
    # (docs/experiments.md, "Issue 14: FIGNet on real tosses", second training round). A cube
    # is mirror symmetric: reflected windows gave clearly better test errors with 8-32 tosses
    # and level ones with 64-240 (fifth round there).
    "cube-real": {"simulator": dict(_CPU_SIZE, collision_radius=0.02, scene_type="cube-real",
                                    gravity=(0.0, 0.0, -9.61), feature_clip=0.2, rigid_output=True),
                  "training": dict(steps=40_000, batch_size=16, lr=1e-3, lr_final=3e-5, unroll_steps=3,
                                   unroll_after=5000, valid_every=1000, valid_trajectories=80,
                                   valid_last_weight=1.0, mirror=True)},
    # The paper's model size (latent 128, 10 message-passing steps, mesh-mesh edges), for comparison.
    "paper": {"simulator": dict(latent_size=128, message_passing_steps=10, mesh_edges=True),
              "training": dict(batch_size=8)},
}


def load_run_config(spec: str | None, overrides: dict[str, Any] | None = None
                    ) -> tuple[dict[str, Any], TrainConfig]:
    """Config from a preset name or a JSON file ``{"simulator": {...}, "training": {...}}``."""
    if spec is None:
        raw: dict[str, Any] = {"simulator": {}, "training": {}}
    elif spec in PRESETS:
        raw = json.loads(json.dumps(PRESETS[spec]))
    else:
        path = Path(spec)
        if not path.is_file():
            raise ValueError(f"config {spec!r} is neither a preset ({', '.join(PRESETS)}) nor a file")
        try:
            raw = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise ValueError(f"{path}: not a readable JSON config ({exc})") from None
        if not isinstance(raw, dict) or not all(isinstance(raw.get(k, {}), dict)
                                                for k in ("simulator", "training")):
            raise ValueError(f'{path}: expected {{"simulator": {{...}}, "training": {{...}}}}')
    for key, val in (overrides or {}).items():
        section, _, name = str(key).partition(".")
        if section not in ("simulator", "training") or not name:
            raise ValueError(f"override {key!r}: keys are 'simulator.<field>' or 'training.<field>'")
        raw.setdefault(section, {})[name] = val
    return raw.get("simulator", {}), TrainConfig.from_dict(raw.get("training", {}))


# ----------------------------------------------------------------------------- data statistics
def node_accelerations(traj: Trajectory, scene: Scene) -> Tensor:
    """Per-step finite-difference accelerations of dynamic nodes, ``float[T-2, N_dyn, 3]``."""
    poses = torch.as_tensor(traj.poses, dtype=torch.float32)
    x = scene.node_positions(poses)[:, scene.dynamic_mask[scene.node_object]]
    return x[2:] - 2 * x[1:-1] + x[:-2]


def median_node_acceleration(trajs: list[Trajectory], scenes: list[Scene]) -> float:
    """Median acceleration norm (m/step^2) of moving dynamic nodes: the data's motion scale."""
    norms = []
    for traj, scene in zip(trajs, scenes, strict=True):
        a = node_accelerations(traj, scene).norm(dim=-1).flatten()
        norms.append(a[a > 1e-7])
    allnorms = torch.cat(norms)
    if allnorms.numel() == 0:
        raise ValueError("trajectories have no motion: no acceleration scale to measure")
    return float(allnorms.median())


class WindowSampler:
    """Draws training windows ``float[H + 1, O, 7]`` weighted towards contact events, reproducibly.

    A window's weight is ``1 + min(a / a_ref, accel_cap)``, where ``a`` is the window's largest
    dynamic-node acceleration and ``a_ref`` the median over moving windows. Contact onsets (a pusher
    starting an object, an impact) are a few windows per trajectory but carry most of what a model
    must learn. A window in which no dynamic object moves weighs ``still_weight``, or
    ``near_weight`` if motion happens within ``near`` poses before or after it. Without the
    approach windows a model learns that a pusher within the collision radius always moves the
    object, and starts it too early; without the settling windows, that a slowly sliding object
    keeps sliding (a rollout's small excess velocity after a glancing push then never dies out).
    """

    def __init__(self, trajs: list[Trajectory], scenes: list[Scene], history: int,
                 still_weight: float, seed: int, accel_cap: float = 10.0, unroll: int = 0,
                 near: int = 0, near_weight: float = 1.0, targets: int = 1) -> None:
        self.trajs, self.scenes, self.span = trajs, scenes, history + 2 + unroll
        if not 1 <= targets <= unroll + 1:
            raise ValueError(f"targets must be in 1..{unroll + 1}, got {targets}")
        index, weight, accel = [], [], []
        for i, (traj, scene) in enumerate(zip(trajs, scenes, strict=True)):
            poses = traj.poses
            dyn = scene.dynamic_mask.numpy()
            moved = np.abs(np.diff(poses[:, dyn, :3], axis=0)).max(axis=(1, 2)) > 1e-6
            acc = node_accelerations(traj, scene).norm(dim=-1).amax(dim=-1).numpy()  # [T-2]
            for t in range(poses.shape[0] - self.span + 1):
                index.append((i, t))
                # The acceleration of target pose p is acc[p - 2]; the last target is t + span - 1.
                end_acc = t + self.span - 2
                accel.append(float(acc[end_acc - targets:end_acc].max()))
                end = t + self.span - 1
                if moved[t:end].any():
                    weight.append(-1.0)
                else:
                    close = moved[end:end + near].any() or moved[max(t - near, 0):t].any()
                    weight.append(near_weight if close else still_weight)
        if not index:
            raise ValueError(f"no trajectory has the {self.span} poses a training window needs")
        self.index = np.asarray(index)
        w, a = np.asarray(weight), np.asarray(accel)
        moving = w < 0
        a_ref = float(np.median(a[moving])) if moving.any() else 1.0
        w[moving] = 1.0 + np.minimum(a[moving] / max(a_ref, 1e-12), accel_cap)
        self.prob = w / w.sum()
        self.rng = np.random.default_rng(seed)

    def sample(self, count: int) -> list[tuple[int, int]]:
        """``count`` (trajectory, start) pairs."""
        picks = self.rng.choice(len(self.index), size=count, p=self.prob)
        return [tuple(map(int, self.index[p])) for p in picks]


def rotate_about_z(poses: Tensor, angle: float) -> Tensor:
    """Rotate whole-scene poses ``float[..., O, 7]`` about the world z axis through the origin."""
    c, s = math.cos(angle), math.sin(angle)
    rot = poses.new_tensor([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    qz = poses.new_tensor([math.cos(angle / 2), 0, 0, math.sin(angle / 2)])
    return torch.cat((poses[..., :3] @ rot.T, quat_mul(qz.expand_as(poses[..., 3:]), poses[..., 3:])), -1)


def mirror_y(poses: Tensor) -> Tensor:
    """Reflect whole-scene poses ``float[..., O, 7]`` in the world plane ``y = 0``.

    With ``M = diag(1, -1, 1)`` a pose ``(p, R)`` becomes ``(M p, M R M)``, i.e. quaternion
    ``(w, x, y, z) -> (w, -x, y, -z)``. For an object symmetric under its body-frame ``M``
    (:func:`mirror_asymmetric`), the posed mesh is the mirror image of the original one, so a
    reflected trajectory is the mirror image of a physical one.
    """
    sign = poses.new_tensor([1.0, -1.0, 1.0, 1.0, -1.0, 1.0, -1.0])
    return poses * sign


def mirror_asymmetric(scene: Scene, tol: float = 1e-4) -> list[str]:
    """Names of the objects of ``scene`` whose body-frame mesh or centre of mass is not symmetric
    under ``y -> -y`` (within ``tol`` times the object's size): :func:`mirror_y` would turn them
    into shapes that do not exist."""
    bad = []
    for o, name in enumerate(scene.object_names):
        v = scene.ref_vertices[scene.node_object == o].double()
        size = float((v.amax(0) - v.amin(0)).norm()) or 1.0
        flipped = v * v.new_tensor([1.0, -1.0, 1.0])
        gap = torch.cdist(flipped, v).amin(dim=1).max()  # Scene refuses empty meshes
        if float(gap) > tol * size or abs(float(scene.object_com[o, 1])) > tol * size:
            bad.append(name)
    return bad


# ----------------------------------------------------------------------------- trainer
def _face_columns(config: SimulatorConfig) -> list[tuple[str, int]]:
    """Face-feature columns of ``config`` as ``(group, index within group)``, in layout order."""
    cols = [("base", i) for i in range(FACE_BASE)]
    for group in config.face_groups:
        cols += [(group.name, i) for i in range(group.size)]
    return cols


def warm_start(sim: LearnedSimulator, source: LearnedSimulator) -> None:
    """Copy ``source``'s weights and normaliser statistics into ``sim``.

    The architectures must match, except that ``sim`` may add optional face feature groups
    (``graph.FACE_GROUPS``): the face encoder's input columns for a new group start at zero, so
    the warm-started model computes exactly what ``source`` did, and the new columns' normaliser
    statistics start as those of the group's ``stats_from`` base columns (of the same scale).
    """
    own, src = sim.state_dict(), source.state_dict()
    if set(own) != set(src):
        raise ValueError(f"cannot warm-start: parameters differ ({sorted(set(own) ^ set(src))[:4]} ...)")
    new_cols, old_cols = _face_columns(sim.config), _face_columns(source.config)
    if not set(old_cols) <= set(new_cols):
        raise ValueError("cannot warm-start: the source has face features this model lacks")
    # For each of this model's face columns: the source column it copies, or (for a new group)
    # the source column its statistics start from, with its weights zeroed.
    stats_from = {g.name: g.stats_from for g in FACE_GROUPS}
    pick = [old_cols.index(c) if c in old_cols else stats_from[c[0]] + c[1] for c in new_cols]
    fresh = torch.tensor([c not in old_cols for c in new_cols])
    widen = {"net.enc.face.first.weight", "norms.face.total", "norms.face.total_sq"}
    for key, value in src.items():
        target = own[key]
        if target.shape == value.shape and (key not in widen or not fresh.any()):
            target.copy_(value)
        elif key in widen and value.shape[-1] == len(old_cols) and target.shape[-1] == len(new_cols):
            cols = value[..., pick].clone()
            if key.startswith("net."):
                cols[..., fresh] = 0.0
            target.copy_(cols)
        else:
            raise ValueError(f"cannot warm-start {key}: shape {tuple(value.shape)} -> {tuple(target.shape)}")


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
    import os

    import torch.distributed as dist

    world = int(os.environ.get("WORLD_SIZE", "1"))
    local = int(os.environ.get("LOCAL_RANK", "0"))
    cuda = torch.cuda.is_available()
    device = torch.device(f"cuda:{local}" if cuda else "cpu")
    if world <= 1:
        return 0, 1, device
    if not dist.is_initialized():
        dist.init_process_group("nccl" if cuda else "gloo")
    return dist.get_rank(), dist.get_world_size(), device


#: What ``last.pt``'s metadata must hold for ``--resume``.
_RESUME_KEYS = ("optimizer", "scheduler", "train_state", "sampler_rng", "noise_rng")


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
        torch.manual_seed(cfg.seed)  # the same initial weights in every process
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
        if config.noise_std <= 0 and cfg.noise_fraction > 0:
            scale = median_node_acceleration(train, self.train_scenes)
            config = replace(config, noise_std=cfg.noise_fraction * scale)
        self._build(config)
        self.warm_started = init is not None and blob is None
        if self.warm_started:
            # Fine-tuning: weights and normaliser statistics from another run, this run's recipe.
            warm_start(self.sim, load_checkpoint(init))
            print(f"initialised from {init}")
        self.ema = copy.deepcopy(self.sim).requires_grad_(False) if cfg.ema_decay > 0 else None
        if blob is not None:
            self._resume(blob)
        self._broadcast(self.sim.state_dict().values())
        if self.ema is not None:
            self._broadcast(self.ema.state_dict().values())
        if self.rank == 0:
            (out / "config.json").write_text(json.dumps(
                {"simulator": config.to_dict(), "training": asdict(cfg), "processes": self.world},
                indent=2))

    def _config(self, sim_cfg: dict[str, Any], resume: bool) -> tuple[SimulatorConfig, dict[str, Any] | None]:
        """The model's config, and with ``resume`` the ``last.pt`` blob it comes from (if any)."""
        dts = {round(t.dt, 9) for t in self.train + self.valid}
        if len(dts) != 1:
            raise ValueError(f"training and validation data mix step lengths {sorted(dts)}")
        last = self.out / "last.pt"
        if resume and last.is_file():
            config, state_dict, meta = read_checkpoint(last)  # CheckpointError if damaged
            missing = [k for k in _RESUME_KEYS if k not in meta]
            if missing:
                raise CheckpointError(f"{last}: not a resumable run checkpoint (no {missing[0]})")
            return config, {"state_dict": state_dict, "meta": meta}
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
        seed = cfg.seed + 1000 * self.rank  # each process draws different windows and noise
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
        self.sim.load_state_dict(self.sim.upgrade_state_dict(blob["state_dict"]))
        if self.ema is not None:
            self.ema.load_state_dict(self.sim.upgrade_state_dict(meta.get("ema", blob["state_dict"])))
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

    # -------------------------------------------------------------- data parallelism
    def _broadcast(self, tensors: Any) -> None:
        """Copy rank 0's values of ``tensors`` to every process (no-op in one process)."""
        if self.world > 1:
            import torch.distributed as dist

            for t in tensors:
                dist.broadcast(t.data, 0)

    def _average_gradients(self) -> None:
        if self.world > 1:
            import torch.distributed as dist

            for p in self.sim.parameters():
                if p.grad is None:
                    p.grad = torch.zeros_like(p)
                dist.all_reduce(p.grad)
                p.grad /= self.world

    def check_replicas(self) -> None:
        """Raise if the processes' weights have drifted apart (they must stay identical)."""
        if self.world > 1:
            import torch.distributed as dist

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
        hist = self.sim.pose_noise(scene, poses[:H], self.gen)
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
        example = self.sim.training_example(scene, poses[:H + 1], self.gen, inputs)
        loss = self.sim.loss(example, self.cfg.rigid_loss_weight)
        if self.cfg.rollout_steps > 0 and not self._warming_up:
            loss = loss + self.cfg.rollout_weight * self.rollout_loss(scene, poses, inputs)
        return loss

    def rollout_loss(self, scene: Scene, poses: Tensor, inputs: Tensor | None) -> Tensor:
        """Node position errors of a rollout with gradients (``TrainConfig.rollout_steps``):
        from ``inputs float[H, O, 7]`` (pushforward's history) or the noisy first ``H`` rows of
        ``poses float[H + R, O, 7]`` (true poses), against their last ``R`` rows. Scalar."""
        H, R = self.sim.config.history + 1, self.cfg.rollout_steps
        hist = inputs if inputs is not None else self.sim.pose_noise(scene, poses[:H], self.gen)
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
        from torch.utils.tensorboard import SummaryWriter
        from tqdm import tqdm

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
                # pretraining, every later checkpoint can be worse (docs/experiments.md, Issue 14).
                self.validate(writer)
            while st.step < end and not stop["flag"]:
                # The budget is the training step itself: validation rollouts (costly for
                # node-based baselines with many edges) and checkpoint writes are not charged.
                t_start, c_start = time.perf_counter(), time.process_time()
                self.sim.train()
                scene, poses = self.batch()
                loss = self.loss(scene, poses)
                self.opt.zero_grad(set_to_none=True)
                loss.backward()
                self._average_gradients()
                torch.nn.utils.clip_grad_norm_(self.sim.parameters(), 1.0)
                self.opt.step()
                if self.world > 1 and self.sim.target_norm.calls < self.sim.target_norm.max_accumulations:
                    self._broadcast(b for name, b in self.sim.named_buffers())
                self.sched.step()
                self._update_ema()
                st.step += 1
                st.graphs_seen += self.cfg.batch_size * self.world
                now, cnow = time.perf_counter(), time.process_time()
                # Every process does the same work, so the run's CPU time is world x this one's.
                st.cpu_seconds += (cnow - c_start) * self.world
                gps = self.cfg.batch_size * self.world / max(now - t_start, 1e-9)
                bar.update(1)
                if lead and st.step % 20 == 0:
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
        decay = min(self.cfg.ema_decay, (1 + self.state.step) / (10 + self.state.step))
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
        from fignet_gym.train.evaluation import rollout_metrics

        self.model.eval()
        n = min(self.cfg.valid_trajectories, len(self.valid))
        m = rollout_metrics(self.model, self.valid[:n], self.valid_scenes[:n], horizon=self.cfg.valid_horizon)
        st = self.state
        rec = {"step": st.step, "graphs_seen": st.graphs_seen, "cpu_hours": st.cpu_seconds / 3600,
               **{k: float(v) for k, v in m.items() if isinstance(v, (int, float))}}
        # Translation and rotation both count, each in units of the no-motion model's error.
        key = rec.get("translation_rmse_ratio_still", math.inf) + rec.get("rotation_deg_ratio_still",
                                                                          math.inf)
        if self.cfg.valid_last_weight > 0:
            key += self.cfg.valid_last_weight * (
                rec.get("translation_rmse_last_ratio_still", math.inf)
                + rec.get("rotation_deg_last_ratio_still", math.inf))
        if not math.isfinite(key):
            key = math.inf
        rec["score"] = key
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
            self.model.save(self.out / PENDING_BEST, meta={"valid": rec})
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
        self.sim.save(self.out / "last.pt", meta=meta)
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
    valid_trajs = load_trajectories(valid) if valid else train_trajs[-4:]
    trainer = Trainer(sim_cfg, cfg, train_trajs, valid_trajs, out_dir, resume=resume, init=init)
    return trainer.run()
