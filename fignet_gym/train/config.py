"""Training configuration: :class:`TrainConfig` (optimisation, noise, loss and sampling), the
presets, and the ``{"simulator": {...}, "training": {...}}`` run config they and JSON files give.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from fignet_gym.checks import Range, check_settings
from fignet_gym.simulator.model import TrainingNoise


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation, noise, loss and sampling settings (what defines the model itself is in
    ``SimulatorConfig``; none of these changes what a trained model computes).

    Attributes:
        steps: optimiser steps.
        batch_size: graphs (training windows) per step, joined into one disjoint graph.
        lr, lr_final: exponential decay from ``lr`` to ``lr_final`` over ``steps``.
        noise_std: std (m) of the random-walk training noise at the last input frame (0: set
            from the data by ``noise_fraction``).
        rotation_noise_std: std (rad) of its rotational part at the last input frame (0: the
            rotation that moves nodes at the object's RMS radius by ``noise_std``). A pushed
            object's angular velocity is set by the contact, not by inertia; rollouts drift in
            yaw much more than in position, and a model trained with position-sized rotation noise
            keeps a spurious spin instead of correcting it.
        noise_fraction: training noise std as a fraction of the median per-step acceleration of
            moving dynamic nodes in the training data (used when ``noise_std`` is 0).
        vertical_weight: loss weight of the z component of accelerations (1: the paper's plain MSE).
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
    noise_std: float = 0.0
    rotation_noise_std: float = 0.0
    noise_fraction: float = 0.5
    vertical_weight: float = 1.0
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
        check_settings(self, TRAIN_RANGES, "training.")

    def noise(self, std: float | None = None) -> TrainingNoise:
        """The input noise of this config, with ``std`` (m) in place of ``noise_std`` if given
        (the value measured from the data when ``noise_std`` is 0)."""
        return TrainingNoise(self.noise_std if std is None else std, self.rotation_noise_std)

    @staticmethod
    def from_dict(d: dict[str, Any]) -> TrainConfig:
        """Build from a dict; unknown keys and out-of-range values are an error."""
        unknown = set(d) - {f.name for f in fields(TrainConfig)}
        if unknown:
            raise ValueError(f"unknown training config keys {sorted(unknown)}")
        return TrainConfig(**d)


#: Integer training settings that must be at least 1 (the other integers: at least 0).
_TRAIN_COUNTS = ("steps", "batch_size", "valid_every", "valid_trajectories", "valid_horizon",
                 "checkpoint_every")
#: Number settings with their own range (the other numbers: finite and at least 0).
_TRAIN_NUMBERS = {"lr": Range("float", low=0, low_open=True),
                  "lr_final": Range("float", low=0, low_open=True),
                  "ema_decay": Range("float", 0, 1, high_open=True)}


def _train_ranges() -> dict[str, Range]:
    """``field -> allowed values`` of every :class:`TrainConfig` field, from its type."""
    table: dict[str, Range] = {}
    for f in fields(TrainConfig):
        if f.type == "bool":
            table[f.name] = Range("bool")
        elif f.type == "int":
            table[f.name] = Range("int", low=1 if f.name in _TRAIN_COUNTS else 0)
        else:
            table[f.name] = _TRAIN_NUMBERS.get(f.name, Range("float", low=0))
    return table


#: ``field -> allowed values`` of every :class:`TrainConfig` field (messages ``training.<field>``).
TRAIN_RANGES: dict[str, Range] = _train_ranges()


# Latent 64, 5 message-passing steps, no mesh-mesh edges (FIGNet*): cheaper per graph than the
# paper's size, so a CPU budget sees more graphs (experiments/README.md, "Speed").
_CPU_SIZE = dict(latent_size=64, message_passing_steps=5, mesh_edges=False)
# The pusher is meshed as an octagonal prism (0.4 mm from its true 4.75 mm radius): fewer faces.
_PUSH_SCENE = dict(_CPU_SIZE, collision_radius=0.01, scene_type="push", feature_clip=0.1,
                   mesh_options={"cylinder_sections": 8})
# Pushing is planar: the loss is spent on horizontal accelerations.
_PUSH_LOSS = dict(vertical_weight=0.1)
# The shipped push model's: next-step separation; small position noise, larger rotational noise.
_PUSH_MODEL = dict(_PUSH_SCENE, next_separation=True)
_PUSH_NOISE = dict(_PUSH_LOSS, noise_std=5e-5, rotation_noise_std=5e-3)

PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    # A push model from scratch on a CPU budget: the CPU size, one-step training only.
    "push-cpu": {"simulator": dict(_PUSH_SCENE),
                 "training": dict(_PUSH_LOSS, batch_size=8, valid_horizon=25)},
    # The last stage of the shipped push model (see its model card), for fine-tuning a trained
    # push model (--init): pushforward from step 0 at a low learning rate. Not for training from
    # scratch: a random model's pushforward states are junk to learn from.
    "push-finetune": {"simulator": dict(_PUSH_MODEL),
                      "training": dict(_PUSH_NOISE, batch_size=16, lr=1e-4, lr_final=1e-5, unroll_steps=6,
                                       rigid_loss_weight=3.0, valid_every=500, valid_trajectories=100,
                                       valid_horizon=25)},
    # A push model from scratch: push-finetune's model with the rigid output projection, a higher
    # learning rate and plain one-step training before pushforward (from step 1500). No shipped
    # model was trained with it (experiments/README.md, "Pushing from scratch").
    "push-scratch": {"simulator": dict(_PUSH_MODEL, rigid_output=True),
                     "training": dict(_PUSH_NOISE, steps=40_000, batch_size=16, lr=5e-4, lr_final=1e-5,
                                      unroll_steps=6,
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
    # 2 cm collision radius (~0.4 half-widths) sees every contact a step ahead (3 and 4 cm were
    # no better). The rest is toss-cpu's (5 message-passing steps, a 40k-step schedule,
    # pushforward after 5000 steps): the shipped model's recipe, which beat 3 steps and a
    # 5000-step schedule on validation. A cube is mirror symmetric: reflected windows gave
    # clearly better test errors with 8-32 tosses and level ones with 64-240 (each measured in
    # experiments/README.md, real tosses).
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
