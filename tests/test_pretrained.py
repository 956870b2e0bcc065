"""The shipped pretrained simulators and the demo that uses them (the README's main job)."""

import json

import pytest

from fignet_gym import CheckpointError, available_pretrained, load_pretrained
from fignet_gym.pretrained import pretrained_dir, pretrained_path


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
    from fignet_gym.train.training import PRESETS

    shipped = load_pretrained(name).config.to_dict()
    for key, value in PRESETS[preset]["simulator"].items():
        if key == "mesh_options":
            assert all(shipped[key][k] == v for k, v in value.items())
        elif key == "gravity" and preset == "cube-real":
            # train_on_split measures gravity on the tosses it trains on; the preset rounds it.
            assert shipped[key] == pytest.approx(value, abs=5e-3), key
        else:
            assert shipped[key] == value, key


def test_unknown_pretrained_name_lists_the_available_ones() -> None:
    with pytest.raises(CheckpointError, match="available: .*push"):
        load_pretrained("no-such-model")


def test_demo_quick_run_writes_its_summary(tmp_path) -> None:
    from fignet_gym.tools.demo import run_demo

    summary = run_demo(str(tmp_path), quick=True)
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert set(saved) == {"mpc"}
    for model in ("fignet", "mujoco"):
        row = summary["mpc"]["episodes"][model][0]
        assert row["length"] == 3 and row["plan_cpu_seconds"] > 0
        assert 0.0 <= saved["mpc"]["summary"][model]["success_rate"] <= 1.0
    assert (tmp_path / "push_mpc.png").stat().st_size > 1000
    assert (tmp_path / "push_mpc.mp4").stat().st_size > 1000
