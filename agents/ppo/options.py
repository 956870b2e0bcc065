"""The command-line spelling of a PPO run's settings: one :class:`Option` per :class:`RunConfig` /
:class:`PPOConfig` field, from which ``fignet-gym ppo`` builds its options (the default of each is
the config's own, so no default lives twice) and a shipped policy's card writes the command that
reruns it.

Importing this module loads neither stable-baselines3 nor TensorBoard (``fignet-gym --help``).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import MISSING, dataclass, fields
from typing import Any

from fignet_gym.agents.ppo.config import DYNAMICS, OBSERVATIONS, PRECISIONS, ConfigError, PPOConfig, RunConfig


def _net_arch(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be comma-separated integers, got {text!r}") from None


@dataclass(frozen=True)
class Option:
    """One ``fignet-gym ppo`` option: ``flag`` sets the config fields ``settings`` (dotted:
    ``ppo.learning_rate``); ``invert``: a flag that turns them off (``--no-normalize``)."""

    flag: str
    settings: tuple[str, ...]
    help: str
    parse: Callable[[str], Any] | None = None
    choices: Sequence[str] | None = None
    required: bool = False
    invert: bool = False

    @property
    def dest(self) -> str:
        """The ``argparse`` attribute (its own rule: the flag without dashes, ``-`` as ``_``)."""
        return self.flag.lstrip("-").replace("-", "_")


def _o(flag: str, setting: str, help: str, **kw: Any) -> Option:
    return Option(flag, (setting,), help, **kw)


#: Every option of ``fignet-gym ppo`` that sets a config field, in ``--help`` order.
OPTIONS: tuple[Option, ...] = (
    _o("--env", "env_id", "environment id"),
    _o("--dynamics", "dynamics", "training dynamics (evaluation always runs on both)",
       choices=DYNAMICS, required=True),
    _o("--steps", "ppo.total_timesteps", "environment steps in total", parse=int, required=True),
    _o("--seed", "ppo.seed", "PPO and training-env seed", parse=int),
    _o("--simulator", "simulator", "learned simulator: pretrained name or checkpoint (default: the "
       "pretrained one of the env's scene)"),
    _o("--num-envs", "ppo.num_envs", "sub-environments stepped as one batch", parse=int),
    _o("--n-steps", "ppo.n_steps", "steps per sub-environment per update", parse=int),
    _o("--batch-size", "ppo.batch_size", "PPO minibatch", parse=int),
    _o("--n-epochs", "ppo.n_epochs", "passes over each rollout", parse=int),
    _o("--lr", "ppo.learning_rate", "Adam learning rate", parse=float),
    _o("--gamma", "ppo.gamma", "discount", parse=float),
    _o("--gae-lambda", "ppo.gae_lambda", "GAE lambda", parse=float),
    _o("--ent-coef", "ppo.ent_coef", "entropy bonus", parse=float),
    _o("--net-arch", "ppo.net_arch", "hidden sizes of policy and value MLPs", parse=_net_arch),
    _o("--log-std-init", "ppo.log_std_init", "initial log std of the Gaussian policy (exploration "
       "noise)", parse=float),
    _o("--use-sde", "ppo.use_sde", "state-dependent exploration noise (gSDE) instead of white "
       "Gaussian noise"),
    _o("--sde-sample-freq", "ppo.sde_sample_freq", "with --use-sde: new noise weights every N steps "
       "(-1: once per rollout)", parse=int),
    Option("--no-normalize", ("norm_obs", "norm_reward"), "no VecNormalize of observations and rewards",
           invert=True),
    _o("--observation", "observation", "what the policy sees: the env's observation, or it and the "
       "pushing geometry", choices=OBSERVATIONS),
    _o("--shaping", "shaping", "weight of the potential-based progress reward during training "
       "(0: none)", parse=float),
    _o("--success-bonus", "success_bonus", "extra reward of a successful step during training "
       "(0: none)", parse=float),
    _o("--curriculum", "curriculum", "goal curriculum in training: new goals on success within an "
       "episode, the goal range widening from easy to the env's own as success rises"),
    _o("--precision", "precision", "network precision of the learned training env (evaluation: "
       "float32)", choices=PRECISIONS),
    _o("--eval-every", "eval_every", "evaluate on both dynamics every N steps (0: never)", parse=int),
    _o("--eval-episodes", "eval_episodes", "episodes per periodic evaluation", parse=int),
    _o("--final-episodes", "final_episodes", "episodes per dynamics of the final evaluation", parse=int),
    _o("--checkpoint-every", "checkpoint_every", "resumable checkpoint every N steps", parse=int),
)


def _field(setting: str) -> tuple[bool, str]:
    """``(whether a PPOConfig field, its name)`` of a dotted setting (``"ppo.gamma"``)."""
    return setting.startswith("ppo."), setting.removeprefix("ppo.")


def default(setting: str) -> Any:
    """The config's default of ``setting`` (dotted: ``"ppo.gamma"``)."""
    in_ppo, name = _field(setting)
    cls = PPOConfig if in_ppo else RunConfig
    f = next(f for f in fields(cls) if f.name == name)
    return f.default_factory() if f.default is MISSING else f.default  # type: ignore[misc]


def _flag_text(value: Any) -> str:
    return ",".join(str(v) for v in value) if isinstance(value, tuple) else str(value)


def add_options(parser: argparse.ArgumentParser) -> None:
    """Add :data:`OPTIONS` to ``parser``, each defaulting to the config's value."""
    for o in OPTIONS:
        if o.invert or isinstance(default(o.settings[0]), bool):
            parser.add_argument(o.flag, action="store_true", help=o.help)
            continue
        value = default(o.settings[0])
        kw: dict[str, Any] = {"help": o.help, "choices": o.choices, "required": o.required}
        if o.parse is not None:
            kw["type"] = o.parse
        if not o.required:
            kw["default"] = value
            kw["help"] += f" (default: {_flag_text(value)})"
        parser.add_argument(o.flag, **kw)


def config_from_args(args: argparse.Namespace) -> RunConfig:
    """The :class:`RunConfig` of parsed ``fignet-gym ppo`` options; ``ValueError`` naming the option
    of a setting out of range."""
    run: dict[str, Any] = {}
    ppo: dict[str, Any] = {}
    for o in OPTIONS:
        value = getattr(args, o.dest)
        for setting in o.settings:
            in_ppo, name = _field(setting)
            (ppo if in_ppo else run)[name] = (not value) if o.invert else value
    flag = {s: o.flag for o in OPTIONS for s in o.settings}
    try:
        return RunConfig(**run, ppo=PPOConfig(**ppo))
    except ConfigError as err:
        setting = err.setting if err.setting in flag else f"ppo.{err.setting}"
        raise ValueError(f"{flag.get(setting, err.setting)} {err.detail}") from None


def command_line(cfg: RunConfig, out: str) -> tuple[list[str], list[str]]:
    """``fignet-gym ppo`` arguments that rerun ``cfg`` into ``out`` (required options and those off
    their default), and the settings of ``cfg`` that no option sets and that differ from the
    config's defaults (a rerun would not have them)."""
    values = cfg.to_json()
    flat = {**{k: v for k, v in values.items() if k != "ppo"},
            **{f"ppo.{k}": v for k, v in values["ppo"].items()}}
    args: list[str] = []
    unset: list[str] = []
    for o in OPTIONS:
        value = flat[o.settings[0]]
        value = tuple(value) if isinstance(value, list) else value
        if o.invert:
            args += [o.flag] if not any(flat[s] for s in o.settings) else []
            if len({flat[s] for s in o.settings}) > 1:  # one flag cannot set them apart
                unset += [s for s in o.settings if not flat[s]]
        elif isinstance(value, bool):
            args += [o.flag] if value else []
        elif o.required or value != default(o.settings[0]):
            args += [o.flag, _flag_text(value)]
    covered = {s for o in OPTIONS for s in o.settings}
    unset += [k.removeprefix("ppo.") for k, v in flat.items() if k not in covered
              and (tuple(v) if isinstance(v, list) else v) != default(k)]
    return [*args, "--out", out], unset
