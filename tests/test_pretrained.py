"""The shipped pretrained simulators and the demo that uses them (the README's main job)."""

import json
import os
from pathlib import Path

import pytest

from fignet_gym import CheckpointError, available_pretrained, load_pretrained
from fignet_gym.pretrained import pretrained_dir, pretrained_path
from fignet_gym.simulator.checkpoint import load as load_checkpoint_file
from fignet_gym.train.config import PRESETS, TrainConfig


def test_shipped_models_load_offline_with_model_cards() -> None:
    assert {"push", "toss"} <= set(available_pretrained())
    for name in ("push", "toss"):
        path = pretrained_path(name)
        assert path.stat().st_size < 10e6  # "a few MB"
        sim = load_pretrained(name)
        assert sim.config.scene_type == name and not sim.training
        card = (pretrained_dir() / f"{name}.md").read_text()
        assert f'load_pretrained("{name}")' in card and "CPU hours" in card


@pytest.mark.parametrize("preset, name", [("push-finetune", "push"), ("toss-cpu", "toss"),
                                          ("cube-real", "cube-real")])
def test_presets_are_the_shipped_models_recipes(preset: str, name: str) -> None:
    shipped = load_pretrained(name).config.to_dict()
    for key, value in PRESETS[preset]["simulator"].items():
        if key == "mesh_options":
            assert all(shipped[key][k] == v for k, v in value.items())
        elif key == "gravity" and preset == "cube-real":
            # train_on_split measures gravity on the tosses it trains on; the preset rounds it.
            assert shipped[key] == pytest.approx(value, abs=5e-3), key
        else:
            assert shipped[key] == value, key
    # The training-only settings left the checkpoints; the model card records them.
    card = (pretrained_dir() / f"{name}.md").read_text()
    training = TrainConfig.from_dict(PRESETS[preset]["training"])
    assert f"(vertical weight {training.vertical_weight})" in card
    if training.noise_std > 0:
        assert f"input noise std {training.noise_std:.3g} m" in card
        assert f"rotational noise std {training.rotation_noise_std} rad" in card


def test_unknown_pretrained_name_lists_the_available_ones() -> None:
    with pytest.raises(CheckpointError, match=r"no-such-model: .*not a pretrained name \(.*push"):
        load_pretrained("no-such-model")


def test_demo_quick_run_writes_its_summary(tmp_path) -> None:
    import gymnasium as gym
    import numpy as np

    from fignet_gym.agents.ppo import load_policy
    from fignet_gym.tools.demo import DEMO_POLICY, DEMO_SEED, run_demo

    summary = run_demo(str(tmp_path), quick=True)
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert set(saved) == {"mpc"}
    for model in ("fignet", "mujoco", "ppo"):
        row = summary["mpc"]["episodes"][model][0]
        assert row["length"] == 3 and row["plan_cpu_seconds"] > 0
        assert 0.0 <= saved["mpc"]["summary"][model]["success_rate"] <= 1.0
    # push-ppo was trained on the demo's own Push-v2: the label names no other version.
    assert summary["mpc"]["labels"]["ppo"] == "PPO (trained on FIGNet)"
    # The PPO row is the shipped policy acting in MuJoCo: the same three steps, replayed here.
    policy = load_policy(DEMO_POLICY)
    env = gym.make("fignet_gym/Push-v2")
    obs, _ = env.reset(seed=DEMO_SEED)
    for _ in range(3):
        obs, *_, info = env.step(policy.predict(obs[None].astype(np.float32), deterministic=True)[0][0])
    ppo = summary["mpc"]["episodes"]["ppo"][0]
    assert ppo["position_error"] == pytest.approx(info["position_error"], abs=1e-9)
    assert ppo["orientation_error"] == pytest.approx(info["orientation_error"], abs=1e-9)
    assert (tmp_path / "push_mpc.png").stat().st_size > 1000
    assert (tmp_path / "push_mpc.mp4").stat().st_size > 1000


@pytest.mark.parametrize("kind", ["/dev/zero", "/dev/null", "fifo", "directory"])
def test_a_path_that_is_not_a_regular_file_is_one_clear_error(tmp_path: Path, kind: str) -> None:
    # Reading a device never ends (/dev/zero) or a FIFO blocks: refuse before opening, saying what
    # the path is.
    path = {"fifo": tmp_path / "pipe", "directory": tmp_path}.get(kind, Path(kind))
    if kind == "fifo":
        os.mkfifo(path)
    what = {"/dev/zero": "a device", "/dev/null": "a device", "fifo": "a FIFO",
            "directory": "a directory"}[kind]
    for load in (load_pretrained, load_checkpoint_file):
        with pytest.raises(CheckpointError) as info:
            load(path)
        message = str(info.value)
        assert message.startswith(f"{path}: is {what}") and "\n" not in message
