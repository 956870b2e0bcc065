"""The core imports no RL stack, and env ids are registered whichever package is imported first.

Each check runs in a fresh interpreter: this test process has long imported Gymnasium and
stable-baselines3 itself.
"""

import json
import subprocess
import sys

import pytest

RL_STACK = ("gymnasium", "stable_baselines3")


def run_fresh(code: str) -> dict:
    """Run ``code`` in a new interpreter; it prints one JSON object as its last line."""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("module", ["fignet_gym", "fignet_gym.simulator"])
def test_core_import_loads_no_rl_stack(module: str) -> None:
    loaded = run_fresh(f"""
import json, sys
import {module}
print(json.dumps({{"rl": [m for m in {RL_STACK!r} if m in sys.modules],
                  "torch": "torch" in sys.modules}}))
""")
    assert loaded == {"rl": [], "torch": True}  # torch: the import really ran the core


@pytest.mark.parametrize("first, second", [("fignet_gym", "gymnasium"), ("gymnasium", "fignet_gym")])
def test_env_ids_are_registered_in_either_import_order(first: str, second: str) -> None:
    out = run_fresh(f"""
import json, sys
import {first}
import {second}
import gymnasium as gym
env = gym.make("fignet_gym/Push-v2", dynamics="mujoco")
obs, _ = env.reset(seed=0)
print(json.dumps({{"ids": sorted(k for k in gym.registry if k.startswith("fignet_gym/")),
                  "obs": list(obs.shape), "sb3": "stable_baselines3" in sys.modules}}))
""")
    from fignet_gym.registration import ENV_SPECS

    assert out["ids"] == sorted(ENV_SPECS) and "fignet_gym/Push-v2" in out["ids"]
    assert len(out["obs"]) == 1 and out["obs"][0] > 0
    assert not out["sb3"]  # making an env does not load stable-baselines3 either
