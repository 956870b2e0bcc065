"""The one table-driven validator (:mod:`fignet_gym.checks`) and every config's table of it.

The per-config cases below are written out by hand, not derived from the tables: each field gets
values just inside and just outside its bounds (and of the wrong kind), so a bound flipped, opened
or dropped in a table fails here. A field added to a table without a case here fails too.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import pytest

from fignet_gym.agents.planners import CEM_RANGES, MPPI_RANGES, CEMConfig, MPPIConfig
from fignet_gym.agents.ppo.config import PPO_RANGES, RUN_RANGES, ConfigError, PPOConfig, RunConfig
from fignet_gym.checks import Range, SettingError, check_settings, check_value
from fignet_gym.simulator.config import CONFIG_BOUNDS, MESH_BOUNDS, SimulatorConfig, check_config
from fignet_gym.simulator.scene import MeshOptions
from fignet_gym.train.config import TRAIN_RANGES, TrainConfig

NAN, INF = float("nan"), float("inf")


def below(x: float) -> float:
    """The float just below ``x``."""
    return math.nextafter(x, -INF)


def above(x: float) -> float:
    """The float just above ``x``."""
    return math.nextafter(x, INF)


# ----------------------------------------------------------------------------- Range and check_settings
@pytest.mark.parametrize(("allowed", "words"), [
    (Range("int", low=1), "an integer >= 1"),
    (Range("int", 1, 1024), "an integer in [1, 1024]"),
    (Range("int", 0, 2**32 - 1), "an integer in [0, 4294967295]"),
    (Range("int", low=0, low_open=True), "an integer > 0"),
    (Range("int", high=5), "an integer <= 5"),
    (Range("int"), "an integer"),
    (Range("float", 0, 1, low_open=True), "a number in (0, 1]"),
    (Range("float", 0, 1, high_open=True), "a number in [0, 1)"),
    (Range("float", 0, 1, low_open=True, high_open=True), "a number in (0, 1)"),
    (Range("float", -20.0, 2.0), "a number in [-20, 2]"),
    (Range("float", 1e-6, 1e4), "a number in [1e-06, 10000]"),
    (Range("float", low=0), "a finite number >= 0"),
    (Range("float", low=0, low_open=True), "a finite number > 0"),
    (Range("float", high=1, high_open=True), "a finite number < 1"),
    (Range("float"), "a finite number"),
    (Range("str", choices=("float32", "bfloat16")), "one of ('float32', 'bfloat16')"),
    (Range("str"), "a string"),
    (Range("bool"), "true or false"),
    (Range("int", low=1, none_ok=True), "None or an integer >= 1"),
    (Range("int", low=1, also=(-1,)), "-1 or an integer >= 1"),
])
def test_words(allowed: Range, words: str) -> None:
    assert allowed.words() == words


@pytest.mark.parametrize(("allowed", "good", "bad"), [
    # integers: not bools, not floats (not even integral ones), closed bounds by default
    (Range("int", 1, 3), [1, 2, 3], [0, 4, True, False, 2.0, None, "2"]),
    (Range("int", 1, 3, low_open=True, high_open=True), [2], [1, 3]),
    (Range("int", low=1, also=(-1,)), [-1, 1, 10**12], [0, -2, -1.0]),
    # numbers: ints and floats, finite, not bools
    (Range("float", 0, 1), [0, 0.0, 1, 1.0, 0.5], [below(0.0), above(1.0), NAN, True, False, "0.5", None]),
    (Range("float", 0, 1, low_open=True), [above(0.0), 1.0], [0, 0.0]),
    (Range("float", 0, 1, high_open=True), [0.0, below(1.0)], [1, 1.0]),
    (Range("float", low=0), [0.0, 1e300], [INF, -INF, NAN, below(0.0)]),
    (Range("float"), [-1e300, 0, 1e300], [INF, -INF, NAN]),
    # None only where allowed
    (Range("int", low=1, none_ok=True), [None, 1], [0, 1.0]),
    (Range("float", low=0, none_ok=True), [None, 0.0], [NAN]),
    # choices: of the kind, and nothing else
    (Range("str", choices=("a", "b")), ["a", "b"], ["c", "", None, 1]),
    (Range("int", choices=(2, 4)), [2, 4], [3, 2.0, True]),
    (Range("str"), ["", "push"], [None, 1, b"push"]),
    (Range("bool"), [True, False], [0, 1, None, "true"]),
])
def test_range_accepts(allowed: Range, good: list[Any], bad: list[Any]) -> None:
    for value in good:
        assert allowed.accepts(value), value
        check_value("x", value, allowed)
    for value in bad:
        assert not allowed.accepts(value), value
        with pytest.raises(SettingError, match=r"^x must be "):
            check_value("x", value, allowed)


class _Obj:
    a = 1
    b = 0.5
    c = "face"


def test_check_settings_names_the_first_bad_field() -> None:
    table = {"a": Range("int", low=1), "b": Range("float", 0, 1, low_open=True),
             "c": Range("str", choices=("face", "node"))}
    check_settings(_Obj(), table)
    obj = _Obj()
    obj.b, obj.c = float("nan"), "edge"
    with pytest.raises(SettingError) as info:
        check_settings(obj, table, "training.")
    err = info.value
    assert isinstance(err, ValueError)
    assert (err.setting, err.detail) == ("b", "must be a number in (0, 1], got nan")
    assert str(err) == "training.b must be a number in (0, 1], got nan"
    obj.b = 1.0
    with pytest.raises(SettingError, match=r"^c must be one of \('face', 'node'\), got 'edge'$"):
        check_settings(obj, table)
    check_settings(obj, {})  # an empty table checks nothing
    with pytest.raises(AttributeError):
        check_settings(obj, {"missing": Range("int")})


@pytest.mark.parametrize("kw", [dict(kind="integer"), dict(kind="bool", low=0), dict(kind="str", high=1),
                                dict(kind="int", low=0, choices=(1,)), dict(kind="float", low=2, high=1)])
def test_a_malformed_range_is_refused(kw: dict[str, Any]) -> None:
    with pytest.raises(ValueError):
        Range(**kw)


def test_config_error_is_the_setting_error() -> None:
    """The PPO CLI catches ``ConfigError`` and reads ``setting`` / ``detail``."""
    assert issubclass(ConfigError, SettingError)
    with pytest.raises(ConfigError) as info:
        PPOConfig(gamma=2)
    assert (info.value.setting, info.value.detail) == ("gamma", "must be a number in [0, 1], got 2")


# ----------------------------------------------------------------------------- every config's table
#: ``field -> (values accepted, values refused)``, by hand.
Cases = dict[str, tuple[list[Any], list[Any]]]

_UNIT_CLOSED = ([0, 0.0, 1.0], [below(0.0), above(1.0), NAN, True])
_UNIT_OPEN_LOW = ([above(0.0), 1, 1.0], [0, 0.0, above(1.0), INF, True])
_COUNT = ([1, 10**9], [0, 1.0, True, None])

PPO_CASES: Cases = {
    "total_timesteps": _COUNT,
    "num_envs": ([1, 1024], [0, 1025, 2.0]),
    "n_steps": ([1, 100_000], [0, 100_001]),
    "batch_size": ([1, 10**6], [0, 16.0, True]),
    "n_epochs": ([1, 1000], [0, 1001]),
    "learning_rate": _UNIT_OPEN_LOW,
    "gamma": _UNIT_CLOSED,
    "gae_lambda": _UNIT_CLOSED,
    "clip_range": _UNIT_OPEN_LOW,
    "ent_coef": _UNIT_CLOSED,
    "log_std_init": ([-20, 2.0], [below(-20.0), above(2.0), -INF]),
    "use_sde": ([True, False], [1, 0, "true"]),
    "sde_sample_freq": ([-1, 1, 64], [0, -2, -1.0, True]),
    "seed": ([0, 2**32 - 1], [-1, 2**32, 0.0]),
    "torch_threads": ([None, 1], [0, 1.0]),
}
RUN_CASES: Cases = {
    "precision": (["float32", "bfloat16"], ["float16", None]),
    "curriculum": ([True, False], [1, None]),
    "observation": (["env", "push-features"], ["features", ""]),
    "shaping": ([0, 100.0], [below(0.0), above(100.0), NAN]),
    "success_bonus": ([0.0, 1000], [below(0.0), above(1000.0), INF]),
    "dynamics": (["mujoco", "fignet"], ["bullet", None]),
    "eval_every": ([0, 10**9], [-1, 0.0]),
    "checkpoint_every": _COUNT,
    "eval_episodes": _COUNT,
    "final_episodes": _COUNT,
}
_TRAIN_COUNTS = ("steps", "batch_size", "valid_every", "valid_trajectories", "valid_horizon",
                 "checkpoint_every")
_TRAIN_INTS = ("near_motion_poses", "unroll_steps", "unroll_after", "rollout_steps", "threads", "seed")
_TRAIN_NUMBERS = ("noise_std", "rotation_noise_std", "noise_fraction", "vertical_weight", "still_weight",
                  "near_motion_weight", "rigid_loss_weight", "rollout_weight", "valid_last_weight")
TRAIN_CASES: Cases = {
    **{name: _COUNT for name in _TRAIN_COUNTS},
    **{name: ([0, 10**9], [-1, 0.0, False]) for name in _TRAIN_INTS},
    **{name: ([0, 0.0, 1e300], [below(0.0), INF, NAN, True]) for name in _TRAIN_NUMBERS},
    "lr": ([above(0.0), 1], [0, 0.0, NAN, True]),
    "lr_final": ([above(0.0), 1.0], [0.0, -1e-3, INF]),
    "ema_decay": ([0, 0.999, below(1.0)], [below(0.0), 1, 1.0, NAN]),
    "rotate_z": ([True, False], [1, "yes"]),
    "mirror": ([True, False], [0, None]),
}
SIM_CASES: Cases = {
    "dt": ([1e-6, 10.0], [below(1e-6), above(10.0), -1.0, NAN, True]),
    "history": ([1, 16], [0, 17, 2.0, None]),
    "latent_size": ([1, 4096], [0, 4097, "big"]),
    "hidden_size": ([None, 1, 8192], [0, 8193, 64.0]),
    "message_passing_steps": ([1, 64], [0, 65, True]),
    "collision_radius": ([1e-6, 100], [below(1e-6), above(100.0), 0]),
    "feature_clip": ([0, 1e4], [below(0.0), above(1e4), INF]),
}
MESH_CASES: Cases = {
    "sphere_subdivisions": ([0, 5], [-1, 6, 1.0]),
    "cylinder_sections": ([3, 256], [2, 257]),
    "capsule_rings": ([1, 64], [0, 65]),
    "box_subdivisions": ([0, 5], [-1, 6, True]),
    "plane_half_size": ([1e-3, 1e5], [below(1e-3), above(1e5), NAN]),
    "plane_cells": ([1, 256], [0, 257, 1.0]),
}
_SAMPLING_CASES: Cases = {
    "horizon": ([1, 10**6], [0, 1.0, True]),
    "population": ([2, 10**6], [1, 2.0]),
    "iterations": ([1, 100], [0, 1.5]),
    "replan_every": ([1, 100], [0, 1.0]),
    "noise_std": ([above(0.0), 1e300], [0, 0.0, INF, NAN]),
    "noise_correlation": ([0, 0.0, below(1.0)], [below(0.0), 1, 1.0, NAN]),
}
CEM_CASES: Cases = {**_SAMPLING_CASES, "elites": ([1, 10**6], [0, 2.0]),
                    "min_std": ([0, 0.0, 1e300], [below(0.0), INF])}
MPPI_CASES: Cases = {**_SAMPLING_CASES, "temperature": ([above(0.0), 1e300], [0, 0.0, NAN])}

#: One row per config class: its table, its hand cases, how to build it with one field set (the
#: other fields leave room for the cross-field checks), and the message prefix.
CONFIGS: dict[str, tuple[Any, Cases, Callable[[str, Any], Any], str]] = {
    "PPOConfig": (PPO_RANGES, PPO_CASES,
                  lambda k, v: PPOConfig(**{"n_steps": 100_000, "num_envs": 1024, k: v}), ""),
    "RunConfig": (RUN_RANGES, RUN_CASES, lambda k, v: RunConfig(**{k: v}), ""),
    "TrainConfig": (TRAIN_RANGES, TRAIN_CASES, lambda k, v: TrainConfig(**{k: v}), "training."),
    "SimulatorConfig": (CONFIG_BOUNDS, SIM_CASES, lambda k, v: SimulatorConfig(**{k: v}), ""),
    "MeshOptions": (MESH_BOUNDS, MESH_CASES,
                    lambda k, v: SimulatorConfig(mesh_options=MeshOptions(**{k: v})), "mesh_options."),
    "CEMConfig": (CEM_RANGES, CEM_CASES,
                  lambda k, v: CEMConfig(**{"horizon": 10**6, "population": 10**6, "elites": 1, k: v}), ""),
    "MPPIConfig": (MPPI_RANGES, MPPI_CASES,
                   lambda k, v: MPPIConfig(**{"horizon": 10**6, "population": 10**6, k: v}), ""),
}


@pytest.mark.parametrize("config", CONFIGS)
def test_every_field_of_a_table_has_cases(config: str) -> None:
    table, cases, _, _ = CONFIGS[config]
    assert set(cases) == set(table)
    assert all(isinstance(r, Range) for r in table.values())


def _check_field(config: str, name: str) -> None:
    _, cases, build, prefix = CONFIGS[config]
    good, bad = cases[name]
    for value in good:
        build(name, value)
    for value in bad:
        with pytest.raises(SettingError) as info:
            build(name, value)
        assert info.value.setting == name, (name, value, str(info.value))
        assert str(info.value).startswith(f"{prefix}{name} must be "), str(info.value)
        assert str(info.value).endswith(f", got {value!r}"), str(info.value)


@pytest.mark.parametrize("name", PPO_CASES)
def test_ppo_config_table(name: str) -> None:
    _check_field("PPOConfig", name)


@pytest.mark.parametrize("name", RUN_CASES)
def test_run_config_table(name: str) -> None:
    _check_field("RunConfig", name)


@pytest.mark.parametrize("name", TRAIN_CASES)
def test_train_config_table(name: str) -> None:
    _check_field("TrainConfig", name)


@pytest.mark.parametrize("name", SIM_CASES)
def test_simulator_config_table(name: str) -> None:
    _check_field("SimulatorConfig", name)


@pytest.mark.parametrize("name", MESH_CASES)
def test_mesh_options_table(name: str) -> None:
    _check_field("MeshOptions", name)


@pytest.mark.parametrize("name", CEM_CASES)
def test_cem_config_table(name: str) -> None:
    _check_field("CEMConfig", name)


@pytest.mark.parametrize("name", MPPI_CASES)
def test_mppi_config_table(name: str) -> None:
    _check_field("MPPIConfig", name)


# ----------------------------------------------------------------------------- checks across fields
def _refused(build: Callable[[], Any], setting: str, needle: str) -> None:
    with pytest.raises(SettingError) as info:
        build()
    assert info.value.setting == setting and needle in str(info.value), str(info.value)


def test_cross_field_and_composite_checks() -> None:
    PPOConfig(num_envs=2, n_steps=8, batch_size=16)
    _refused(lambda: PPOConfig(num_envs=2, n_steps=8, batch_size=17), "batch_size", "n_steps * num_envs = 16")
    PPOConfig(net_arch=(1, 8192))
    for arch in [(), (0,), (8193,), [64], (64, 2.0), (True,)]:
        _refused(lambda arch=arch: PPOConfig(net_arch=arch), "net_arch", repr(arch))
    CEMConfig(horizon=3, replan_every=3, population=4, elites=4)
    _refused(lambda: CEMConfig(horizon=3, replan_every=4), "replan_every", "got 4")
    _refused(lambda: MPPIConfig(horizon=3, replan_every=4), "replan_every", "got 4")
    _refused(lambda: CEMConfig(population=4, elites=5), "elites", "got 5")
    SimulatorConfig(gravity=(-1e3, 0, 1e3))
    for g in [above(1e3), below(-1e3), NAN, True, "9.8"]:
        _refused(lambda g=g: SimulatorConfig(gravity=(0.0, 0.0, g)), "gravity", f"got {g!r}")
    _refused(lambda: SimulatorConfig(gravity=(0.0, -9.8)), "gravity", "3 entries")
    for flag in ("mesh_edges", "object_nodes", "next_separation", "rigid_output", "canonical_frame"):
        _refused(lambda flag=flag: SimulatorConfig(**{flag: 1}), flag, "true or false")
    _refused(lambda: SimulatorConfig(scene_type=None), "scene_type", "a string")
    SimulatorConfig(collision="node")
    _refused(lambda: SimulatorConfig(collision="edge"), "collision", "'edge'")
    check_config(SimulatorConfig())
