"""The command line as one package: ``fignet-gym ppo``'s options are the run config's (one default
per setting, every field spelled once), its card command reruns any config, and a user's mistake in
any command group takes the one error path (one ``error:`` line, exit 2)."""

from __future__ import annotations

import shlex
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from fignet_gym.agents.ppo.config import PPOConfig, RunConfig
from fignet_gym.agents.ppo.options import OPTIONS, command_line, config_from_args
from fignet_gym.cli import build_parser, main

#: Config fields no ``fignet-gym ppo`` option sets, on purpose (a card lists them when they differ).
NO_OPTION = {"env_kwargs", "ppo.clip_range", "ppo.torch_threads", "ppo"}


def _parse(argv: list[str]) -> RunConfig:
    return config_from_args(build_parser().parse_args(["ppo", *argv, "--out", "unused"]))


def test_every_config_field_has_exactly_one_option_or_is_listed() -> None:
    settings = [s for o in OPTIONS for s in o.settings]
    assert len(settings) == len(set(settings))  # no field set by two options
    every = {f.name for f in fields(RunConfig)} | {f"ppo.{f.name}" for f in fields(PPOConfig)}
    assert set(settings) | NO_OPTION == every and not set(settings) & NO_OPTION
    assert len({o.flag for o in OPTIONS}) == len(OPTIONS)


def test_options_left_out_are_the_configs_defaults() -> None:
    cfg = _parse(["--dynamics", "fignet", "--steps", "1000"])
    assert cfg == RunConfig(dynamics="fignet", ppo=PPOConfig(total_timesteps=1000))
    assert cfg.eval_every == RunConfig.eval_every  # the default the old parser wrote twice


def _random_config(rng: np.random.Generator) -> RunConfig:
    num_envs, n_steps = int(rng.integers(1, 64)), int(rng.integers(1, 128))
    ppo = PPOConfig(
        total_timesteps=int(rng.integers(1, 10**7)), num_envs=num_envs, n_steps=n_steps,
        batch_size=int(rng.integers(1, num_envs * n_steps + 1)), n_epochs=int(rng.integers(1, 20)),
        learning_rate=float(rng.uniform(1e-5, 1e-2)), gamma=float(rng.uniform(0.9, 1)),
        gae_lambda=float(rng.uniform(0.8, 1)), ent_coef=float(rng.uniform(0, 0.1)),
        net_arch=tuple(int(n) for n in rng.integers(1, 512, size=rng.integers(1, 4))),
        log_std_init=float(rng.uniform(-3, 1)), use_sde=bool(rng.integers(2)),
        sde_sample_freq=int(rng.choice([-1, 4, 16])), seed=int(rng.integers(0, 2**31)))
    return RunConfig(
        env_id=str(rng.choice(["fignet_gym/Push-v2", "fignet_gym/PushT-v0"])),
        dynamics=str(rng.choice(["mujoco", "fignet"])), ppo=ppo,
        simulator=[None, "push"][int(rng.integers(2))], norm_obs=(norm := bool(rng.integers(2))),
        norm_reward=norm, eval_every=int(rng.integers(0, 10**5)), eval_episodes=int(rng.integers(1, 64)),
        final_episodes=int(rng.integers(1, 100)), checkpoint_every=int(rng.integers(1, 10**5)),
        observation=str(rng.choice(["env", "push-features"])), shaping=float(rng.uniform(0, 5)),
        success_bonus=float(rng.uniform(0, 5)), curriculum=bool(rng.integers(2)),
        precision=str(rng.choice(["float32", "bfloat16"])))


@pytest.mark.parametrize("seed", range(25))
def test_the_command_a_card_writes_reruns_the_config(seed: int) -> None:
    cfg = _random_config(np.random.default_rng(seed))
    argv, unset = command_line(cfg, "runs/x")
    assert unset == []
    assert config_from_args(build_parser().parse_args(["ppo", *shlex.split(shlex.join(argv))])) == cfg


def test_a_setting_no_option_carries_is_named_by_the_card() -> None:
    cfg = RunConfig(ppo=PPOConfig(clip_range=0.1), norm_obs=False)
    _, unset = command_line(cfg, "runs/x")
    assert unset == ["norm_obs", "clip_range"]


@pytest.mark.parametrize("argv, message", [
    (["ppo", "--dynamics", "mujoco", "--steps", "10", "--lr", "5", "--out", "{tmp}/r"],
     "error: --lr must be a number in (0, 1], got 5.0"),
    (["ppo", "--dynamics", "mujoco", "--steps", "10", "--batch-size", "9999", "--out", "{tmp}/r"],
     "error: --batch-size must be at most the rollout buffer n_steps * num_envs = 2048, got 9999"),
    (["plan", "--env", "fignet_gym/Push-v2", "--out", "{tmp}/file.txt"],
     "error: --out {tmp}/file.txt: is a file; --out must be a folder"),
    (["show", "{tmp}/file.txt"], "error: {tmp}/file.txt: "),
    (["train", "--data", "{tmp}/none.h5", "--out", "{tmp}/run", "--set", "[1]"],
     "error: --set: expected a JSON object"),
    (["ppo-table", "{tmp}"], "error: "),
])
def test_a_mistake_in_any_group_is_one_error_line(argv: list[str], message: str, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "file.txt").write_text("not a folder, not HDF5")
    assert main([a.replace("{tmp}", str(tmp_path)) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(message.replace("{tmp}", str(tmp_path))) and "\n" not in err, err
    assert not (tmp_path / "r").exists() and not (tmp_path / "run").exists()
