"""The settings of a PPO run: :class:`PPOConfig` (stable-baselines3's) and :class:`RunConfig` (the run's).

Every setting is checked when the config is built, against the range it may take (the table
:data:`PPO_RANGES`), so a bad value is refused before a run folder is written rather than deep inside
stable-baselines3 after the first update.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from fignet_gym.checks import Range, SettingError, check_settings

#: The environment a run trains on unless told otherwise: the current Push version.
PUSH_ID = "fignet_gym/Push-v2"
#: Training dynamics a run accepts (the env's ``dynamics=`` names).
DYNAMICS = ("mujoco", "fignet")
#: Network precisions of the learned training env (``FIGNetDynamics(precision=)``).
PRECISIONS = ("float32", "bfloat16")
#: More sub-environments than this would only exhaust memory (each holds its own ``MjData`` and,
#: for the learned dynamics, its share of one graph); 1024 is 30x the recipe's batch.
MAX_NUM_ENVS = 1024
#: Steps per sub-environment between updates: beyond this the rollout buffer alone is gigabytes.
MAX_N_STEPS = 100_000
#: Seeds are NumPy / torch seeds: 32-bit.
MAX_SEED = 2**32 - 1
#: ``log_std_init`` range: e^-20 is no exploration at all, e^2 = 7.4 times the action range.
LOG_STD_RANGE = (-20.0, 2.0)
#: Largest hidden layer: a policy for a 2-D action needs nothing near this.
MAX_LAYER = 8192
#: Observation kinds a run may give its policy (:mod:`~fignet_gym.agents.ppo.features`).
OBSERVATIONS = ("env", "push-features")
#: Largest progress-shaping weight: beyond it the shaping dwarfs the env's own reward.
MAX_SHAPING = 100.0
#: Largest success bonus: a few hundred steps of the env's largest per-step cost.
MAX_BONUS = 1000.0


#: The error of a setting outside its range (``setting``: the field, which the CLI maps to its
#: option; ``detail``: ``"must be ..., got ..."``); the name the CLI imports.
ConfigError = SettingError

#: ``field -> allowed values`` of every :class:`PPOConfig` field but ``net_arch``.
PPO_RANGES: dict[str, Range] = {
    "total_timesteps": Range("int", low=1),
    "num_envs": Range("int", 1, MAX_NUM_ENVS),
    "n_steps": Range("int", 1, MAX_N_STEPS),
    "batch_size": Range("int", low=1),  # and at most n_steps * num_envs
    "n_epochs": Range("int", 1, 1000),
    "learning_rate": Range("float", 0, 1, low_open=True),
    "gamma": Range("float", 0, 1),
    "gae_lambda": Range("float", 0, 1),
    "clip_range": Range("float", 0, 1, low_open=True),
    "ent_coef": Range("float", 0, 1),
    "log_std_init": Range("float", *LOG_STD_RANGE),
    "use_sde": Range("bool"),
    "sde_sample_freq": Range("int", low=1, also=(-1,)),
    "seed": Range("int", 0, MAX_SEED),
    "torch_threads": Range("int", low=1, none_ok=True),
}
#: One hidden layer's size in ``net_arch``.
_LAYER = Range("int", 1, MAX_LAYER)
#: ``field -> allowed values`` of the scalar :class:`RunConfig` fields (``env_id``, ``simulator``,
#: ``norm_obs`` and ``norm_reward`` are not checked here).
RUN_RANGES: dict[str, Range] = {
    "precision": Range("str", choices=PRECISIONS),
    "curriculum": Range("bool"),
    "observation": Range("str", choices=OBSERVATIONS),
    "shaping": Range("float", 0, MAX_SHAPING),
    "success_bonus": Range("float", 0, MAX_BONUS),
    "dynamics": Range("str", choices=DYNAMICS),
    "eval_every": Range("int", low=0),
    "checkpoint_every": Range("int", low=1),
    "eval_episodes": Range("int", low=1),
    "final_episodes": Range("int", low=1),
}


@dataclass(frozen=True)
class PPOConfig:
    """PPO settings (stable-baselines3 names; rollout buffer ``n_steps * num_envs``).

    The defaults are the recipe ``fignet-gym ppo`` runs.

    Args:
        total_timesteps: environment steps in total (over all sub-environments).
        num_envs: sub-environments stepped as one batch.
        n_steps: steps per sub-environment between updates.
        batch_size: minibatch size (at most ``n_steps * num_envs``).
        n_epochs: passes over the rollout buffer per update.
        learning_rate, gamma, gae_lambda, clip_range, ent_coef: PPO's usual meanings.
        net_arch: hidden layer sizes of the policy and value MLPs.
        log_std_init: initial log standard deviation of the Gaussian policy's actions.
        use_sde: state-dependent exploration noise (gSDE) instead of independent Gaussian noise.
        sde_sample_freq: with gSDE, draw new noise weights every this many steps (-1: once per
            rollout).
        seed: of PPO and the environments.
        torch_threads: torch threads during training; ``None``: 1 when the dynamics is not MuJoCo
            (a learned model in this process: policy and simulator would fight over the same
            cores, and the small policy gains nothing from more), else torch's current setting.

    Raises:
        ConfigError: a setting outside its range (:data:`PPO_RANGES`; ``batch_size`` at most
            ``n_steps * num_envs``, ``net_arch`` one or more sizes in ``[1, MAX_LAYER]``).
    """

    total_timesteps: int = 200_000
    num_envs: int = 32
    n_steps: int = 64
    batch_size: int = 256
    n_epochs: int = 10
    learning_rate: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    net_arch: tuple[int, ...] = (256, 256)
    log_std_init: float = -1.0
    use_sde: bool = False
    sde_sample_freq: int = -1
    seed: int = 0
    torch_threads: int | None = None

    def __post_init__(self) -> None:
        check_settings(self, PPO_RANGES)
        if self.batch_size > self.n_steps * self.num_envs:
            raise ConfigError(
                "batch_size",
                f"must be at most the rollout buffer n_steps * num_envs = "
                f"{self.n_steps * self.num_envs}, got {self.batch_size}",
            )
        arch = self.net_arch
        if not (isinstance(arch, tuple) and arch and all(_LAYER.accepts(n) for n in arch)):
            raise ConfigError("net_arch", f"must be one or more integers in [1, {MAX_LAYER}], got {arch!r}")


@dataclass(frozen=True)
class RunConfig:
    """Everything that defines a PPO run (saved as ``config.json``).

    Args:
        env_id: registered fignet_gym environment id (default: the current Push version).
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
        observation: what the policy sees: ``"env"`` (the env's observation) or
            ``"push-features"`` (it and the pushing geometry,
            :func:`~fignet_gym.agents.ppo.features.push_features`).
        shaping: weight of the potential-based progress reward added during training
            (:class:`~fignet_gym.agents.ppo.features.ProgressShaping`; 0: none).
        success_bonus: extra reward of a successful step during training
            (:class:`~fignet_gym.agents.ppo.features.SuccessBonus`; 0: none). Evaluation and the
            logged returns always use the env's own reward.
        curriculum: train with a goal curriculum (:mod:`~fignet_gym.agents.ppo.curriculum`: goals
            resampled on success within an episode, the goal range widening from easy to the
            env's own with success); evaluation always has the env's own goals.
        precision: the learned simulator's network precision in the training env
            (``"bfloat16"``: about 1.4x the env steps per CPU-second; ``docs/ppo.md``); every
            evaluation runs it in float32.
    """

    env_id: str = PUSH_ID
    dynamics: str = "mujoco"
    ppo: PPOConfig = field(default_factory=PPOConfig)
    simulator: str | None = None
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    norm_obs: bool = True
    norm_reward: bool = True
    eval_every: int = 50_000
    eval_episodes: int = 32
    final_episodes: int = 50
    checkpoint_every: int = 20_000
    observation: str = "env"
    shaping: float = 0.0
    success_bonus: float = 0.0
    curriculum: bool = False
    precision: str = "float32"

    def __post_init__(self) -> None:
        check_settings(self, RUN_RANGES)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dictionary (``net_arch`` as a list)."""
        return asdict(self)

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> RunConfig:
        """Inverse of :meth:`to_json`; settings added since a config was saved take their old
        values (``use_sde``: off)."""
        known = {f.name for f in fields(PPOConfig)}
        ppo = {**asdict(PPOConfig()), "use_sde": False, "sde_sample_freq": -1,
               **{k: v for k, v in data["ppo"].items() if k in known}}
        ppo["net_arch"] = tuple(ppo["net_arch"])
        names = {f.name for f in fields(cls)}
        return cls(**{**{k: v for k, v in data.items() if k in names}, "ppo": PPOConfig(**ppo)})
