"""Benchmark of the Push and Toss environments with MuJoCo and learned dynamics.

``fignet-gym bench envs [--envs push toss] [--nums 1 16 64] [--seconds 3] [--threads 1]``

For each environment and dynamics it reports environment steps per second of a single environment
(``gym.make``) and of the batched vector environment at each ``N`` (``gym.make_vec(...,
vectorization_mode="vector_entry_point")``), plus the cost of one batched learned step per scene
relative to a single-scene step (``FIGNetDynamics.step_many`` on N ``MjData``; the issue's target is
at most 1/5 at N = 64). A Toss step is ``settle_steps`` learned steps, so rates are also given
in simulated 0.02-s frames (learned steps) per second.

The learned model is the shipped pretrained one when available (``fignet_gym.load_pretrained``),
else an untrained model of the training preset's size (``push-cpu`` / ``toss-cpu``) whose output
statistics are set small so that it moves objects little: cost depends on the graph (nodes,
contacts, network size), not on the weights, but a model that flings objects apart finds fewer
contacts and would look cheaper.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import torch

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.pretrained import available_pretrained, load_pretrained
from fignet_gym.simulator.model import LearnedSimulator, SimulatorConfig
from fignet_gym.train.config import PRESETS

ENV_IDS = {"push": "fignet_gym/Push-v2", "toss": "fignet_gym/Toss-v1"}


@dataclass
class Row:
    """One measurement: environment, dynamics, vectorisation, rates."""

    env: str
    dynamics: str
    mode: str  # "single" or "vector"
    num_envs: int
    env_steps_per_s: float
    frames_per_s: float  # simulated 0.02-s frames (learned steps) per second


def learned_model(kind: str, checkpoint: str | None) -> tuple[Any, str]:
    """The simulator to benchmark for ``kind`` and a description of where it came from."""
    if checkpoint:
        return load_pretrained(checkpoint), f"checkpoint {checkpoint}"
    if kind in available_pretrained():
        return load_pretrained(kind), f"pretrained '{kind}'"
    cfg = SimulatorConfig.from_dict(PRESETS[f"{kind}-cpu"]["simulator"])
    sim = LearnedSimulator(cfg).eval()
    sim.target_norm.accumulate(torch.randn(1000, 3, dtype=torch.float64) * 1e-4)
    return (
        sim,
        f"untrained '{kind}-cpu' preset (latent {cfg.latent_size}, "
        f"{cfg.message_passing_steps} message-passing steps)",
    )


def _timed(fn: Callable[[], int], seconds: float, max_calls: int) -> float:
    """Calls ``fn`` (returning work units done) after one warm-up call until ``seconds`` passed;
    returns units per second."""
    fn()
    units, start, calls = 0, time.perf_counter(), 0
    while calls < max_calls and (calls == 0 or time.perf_counter() - start < seconds):
        units += fn()
        calls += 1
    return units / (time.perf_counter() - start)


def bench_single(env_id: str, kwargs: dict[str, Any], seconds: float) -> float:
    """Environment steps per second of one ``gym.make`` environment (random actions, autoreset)."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    env.action_space.seed(0)

    def step() -> int:
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        if term or trunc:
            env.reset()
        return 1

    rate = _timed(step, seconds, 10_000)
    env.close()
    return rate


def bench_vector(env_id: str, num: int, kwargs: dict[str, Any], seconds: float) -> float:
    """Environment steps per second (summed over sub-environments) of the batched vector env."""
    venv = gym.make_vec(env_id, num_envs=num, vectorization_mode="vector_entry_point", **kwargs)
    venv.reset(seed=0)
    venv.action_space.seed(0)

    def step() -> int:
        venv.step(venv.action_space.sample())
        return num

    rate = _timed(step, seconds, 10_000)
    venv.close()
    return rate


def bench_batched_step(
    env_id: str, kwargs: dict[str, Any], nums: list[int], seconds: float
) -> dict[int, float]:
    """Seconds per scene of one batched learned step (``step_many``) for each ``N``."""
    env = gym.make(env_id, **kwargs).unwrapped
    dyn, model = env.dynamics, env.model
    frame_skip = round(dyn.dt / model.opt.timestep)
    out = {}
    for n in nums:
        datas = []
        for i in range(n):
            env.reset(seed=i)
            env._apply_action(np.zeros(env.action_space.shape))  # a toss: an object in flight
            d = mujoco.MjData(model)
            mujoco.mj_copyData(d, model, env.data)
            datas.append(d)

        def step(datas: list[mujoco.MjData] = datas) -> int:
            dyn.step_many(model, datas, frame_skip)
            return 1

        out[n] = 1.0 / _timed(step, seconds, 200) / n
    return out


def run(args: argparse.Namespace) -> dict[str, Any]:
    """``fignet-gym bench envs``: env steps per second, single and vectorised; the rows."""

    rows: list[Row] = []
    ratios: dict[str, dict[int, float]] = {}
    sources: dict[str, str] = {}
    for kind in args.envs:
        env_id = ENV_IDS[kind]
        ckpt = getattr(args, f"checkpoint_{kind}")
        for dyn in args.dynamics:
            kwargs: dict[str, Any] = {"dynamics": dyn}
            if dyn == "fignet":
                sim, sources[kind] = learned_model(kind, ckpt)
                kwargs["checkpoint"] = sim
            probe = gym.make(env_id, **kwargs).unwrapped
            per_step = round(
                probe.frame_skip * probe.model.opt.timestep / 0.02
            )  # learned steps per env step
            probe.close()
            rate = bench_single(env_id, kwargs, args.seconds)
            rows.append(Row(kind, dyn, "single", 1, rate, rate * per_step))
            print(f"{kind:5s} {dyn:7s} single      {rate:10.2f} env steps/s", flush=True)
            for n in args.nums:
                rate = bench_vector(env_id, n, kwargs, args.seconds)
                rows.append(Row(kind, dyn, "vector", n, rate, rate * per_step))
                print(f"{kind:5s} {dyn:7s} vector N={n:<3d} {rate:10.2f} env steps/s", flush=True)
            if dyn == "fignet":
                cost = bench_batched_step(
                    env_id, kwargs, sorted(set([1] + args.nums)), args.seconds
                )
                ratios[kind] = {n: cost[n] / cost[1] for n in cost}
                for n in cost:
                    print(
                        f"{kind:5s} learned step N={n:<3d} {cost[n] * 1e3:8.2f} ms/scene "
                        f"(x{ratios[kind][n]:.3f} of single)",
                        flush=True,
                    )

    print(
        "\n| env | dynamics | mode | N | env steps/s | 0.02-s frames/s |\n|---|---|---|---|---|---|"
    )
    for r in rows:
        print(
            f"| {r.env} | {r.dynamics} | {r.mode} | {r.num_envs} | {r.env_steps_per_s:.1f} | "
            f"{r.frames_per_s:.1f} |"
        )
    if ratios:
        print("\nPer-scene cost of a batched learned step relative to one scene:")
        for kind, rat in ratios.items():
            print(
                f"  {kind} ({sources[kind]}): "
                + ", ".join(f"N={n}: {v:.3f}" for n, v in rat.items())
            )
    result = {
        "rows": [r.__dict__ for r in rows],
        "batched_ratio": ratios,
        "models": sources,
        "threads": args.threads,
    }
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)
    return result

