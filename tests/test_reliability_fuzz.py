"""Issue 16, slow: thousands of random and hostile actions over every env x dynamics pair, the
batched vector environment and the SB3 adapter.

Invariants: a hostile action (NaN, inf, wrong shape, not numeric) raises ``ValueError`` and
changes no state; a finite action of any size (clipped) steps and yields finite observations and
rewards; an episode that ended is reset. ``python -m pytest -m slow tests/test_reliability_fuzz.py
-s`` prints the counts.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.envs.sb3 import SB3VecEnvAdapter

ENV_IDS = ["fignet_gym/Push-v2", "fignet_gym/Toss-v0"]
#: Valid steps per case (a learned Toss step is 75 learned steps: fewer of those).
VALID_STEPS = {("fignet_gym/Push-v2", "mujoco"): 400, ("fignet_gym/Push-v2", "fignet"): 200,
               ("fignet_gym/Toss-v0", "mujoco"): 60, ("fignet_gym/Toss-v0", "fignet"): 12}
HOSTILE_PER_VALID = 4


def hostile_action(rng: np.random.Generator, shape: tuple[int, ...]) -> Any:
    """An action every environment must refuse (``ValueError``), drawn from several families."""
    kind = int(rng.integers(7))
    if kind == 0:
        a = rng.uniform(-1, 1, shape)
        a[tuple(rng.integers(0, s) for s in shape)] = rng.choice([np.nan, np.inf, -np.inf])
        return a
    if kind == 1:
        return np.full(shape, np.nan)
    if kind == 2:
        return rng.uniform(-1, 1, shape[:-1] + (shape[-1] + int(rng.integers(1, 3)),))
    if kind == 3:
        return rng.uniform(-1, 1, (*shape, 1))
    if kind == 4:
        return np.full(shape, "x").tolist()  # not numeric
    if kind == 5:
        return rng.uniform(-1, 1, shape[:-1])  # a missing axis
    return None


def valid_action(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """A finite action: mostly in range, sometimes huge or tiny (must be clipped, not refused)."""
    kind = int(rng.integers(4))
    if kind == 0:
        return rng.uniform(-1, 1, shape)
    if kind == 1:
        return rng.choice([-1e30, 1e30, -1e300, 1e300], shape)
    if kind == 2:
        return rng.uniform(-5, 5, shape).astype(np.float32)
    return np.where(rng.random(shape) < 0.5, -1.0, 1.0)


def snapshot(envs: list[Any]) -> list[tuple]:
    return [(e.data.qpos.copy(), e.data.qvel.copy(), e.data.mocap_pos.copy(), e.data.time,
             getattr(e, "released", None)) for e in envs]


def same(a: list[tuple], b: list[tuple]) -> bool:
    return all(all(np.array_equal(x, y) for x, y in zip(p, q, strict=True))
               for p, q in zip(a, b, strict=True))


def fuzz(step: Any, envs: list[Any], shape: tuple[int, ...], valid_steps: int, rng: np.random.Generator,
         reset: Any, counts: Counter) -> None:
    """Interleave valid and hostile actions through ``step``; check every invariant."""
    done_valid = 0
    while done_valid < valid_steps:
        if rng.random() < HOSTILE_PER_VALID / (HOSTILE_PER_VALID + 1):
            before = snapshot(envs)
            with pytest.raises(ValueError):
                step(hostile_action(rng, shape))
            assert same(before, snapshot(envs)), "a refused action changed state"
            counts["hostile refused, state unchanged"] += 1
            continue
        obs, reward, ended = step(valid_action(rng, shape))
        assert np.isfinite(obs).all() and np.isfinite(reward).all(), "NaN or inf leaked"
        counts["valid stepped, finite"] += 1
        done_valid += 1
        if np.any(ended):
            counts["episodes ended"] += int(np.sum(ended))
            reset()


def _single(env_id: str, dynamics: str, rng: np.random.Generator, counts: Counter) -> None:
    env = gym.make(env_id, dynamics=dynamics)
    base = env.unwrapped
    env.reset(seed=int(rng.integers(1000)))

    def step(a: Any) -> tuple:
        obs, r, term, trunc, _ = env.step(a)
        return obs, np.asarray(r), term or trunc

    fuzz(step, [base], env.action_space.shape, VALID_STEPS[(env_id, dynamics)], rng,
         lambda: env.reset(), counts)


def _vector(env_id: str, dynamics: str, rng: np.random.Generator, counts: Counter,
            sb3: bool) -> None:
    venv = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point",
                        dynamics=dynamics)
    inner = venv.unwrapped
    if sb3:
        sbv = SB3VecEnvAdapter(venv)
        sbv.seed(int(rng.integers(1000)))
        sbv.reset()

        def step(a: Any) -> tuple:
            obs, r, dones, _ = sbv.step(a)
            return obs, r, np.zeros_like(dones)  # SB3 resets finished sub-environments itself
    else:
        venv.reset(seed=int(rng.integers(1000)))

        def step(a: Any) -> tuple:
            obs, r, term, trunc, _ = venv.step(a)
            return obs, r, np.zeros_like(term)  # NEXT_STEP autoreset
    fuzz(step, inner.envs, inner.action_space.shape, VALID_STEPS[(env_id, dynamics)] // 2, rng,
         lambda: None, counts)


@pytest.mark.slow
@pytest.mark.parametrize("dynamics", ["mujoco", "fignet"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_fuzz_actions(env_id: str, dynamics: str) -> None:
    rng = np.random.default_rng(16)
    counts: Counter = Counter()
    _single(env_id, dynamics, rng, counts)
    single = dict(counts)
    _vector(env_id, dynamics, rng, counts, sb3=False)
    _vector(env_id, dynamics, rng, counts, sb3=True)
    print(f"\n{env_id} {dynamics}: single {single}; all (single + vector + SB3) {dict(counts)}")
    assert counts["hostile refused, state unchanged"] > 0 and counts["valid stepped, finite"] > 0
