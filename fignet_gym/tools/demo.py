"""The main job: the shipped pretrained simulators against MuJoCo, no training needed.

``fignet-gym demo`` (or ``bash scripts/demo.sh``):

1. generates fresh held-out pushes and tosses with MuJoCo (seeds never used in training);
2. rolls out the shipped learned simulators from their first poses, all scenes in one batch;
3. prints errors against MuJoCo and against the no-motion and constant-velocity references;
4. writes side-by-side videos (MuJoCo left, FIGNet right), error plots and ``summary.json``;
5. runs the ``Push-v0`` environment on both dynamics with the same actions and compares them.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

DEMO_SEED = 987_654  # far from the seeds of the shipped training and validation sets


def _task(name: str, kind: str, num: int, out: Path, videos: int, horizon: int) -> dict[str, Any]:
    from fignet_gym.data.generate import iter_trajectories
    from fignet_gym.pretrained import load_pretrained
    from fignet_gym.train.evaluation import (
        plot_curves,
        print_table,
        rollout_metrics,
        write_comparison_video,
    )

    sim = load_pretrained(name)
    print(f"\n=== {name}: {num} fresh MuJoCo '{kind}' trajectories (seed {DEMO_SEED}) ===")
    t0 = time.perf_counter()
    trajs = list(iter_trajectories(kind, num, DEMO_SEED, workers=1))
    print(f"generated in {time.perf_counter() - t0:.1f} s")
    res = rollout_metrics(sim, trajs, horizon=horizon)
    print_table(res)
    plot_curves(res, out / f"{name}_errors.png")
    for i in range(videos):
        write_comparison_video(sim, trajs[i], out / f"{name}_{i}.mp4")
    return {k: v for k, v in res.items() if not k.endswith("_curve")}


def _env_comparison(out: Path, steps: int = 40) -> dict[str, Any]:
    """Same action sequence on Push-v0 with MuJoCo and with FIGNet dynamics."""
    import gymnasium as gym

    import fignet_gym.envs  # noqa: F401 - registers the environments

    rng = np.random.default_rng(0)
    actions = np.clip(np.array([[1.0, 0.0]]) + 0.3 * rng.normal(size=(steps, 2)), -1, 1)
    result: dict[str, Any] = {}
    for dyn in ("mujoco", "fignet"):
        env = gym.make("fignet_gym/Push-v0", dynamics=dyn)
        obs, _ = env.reset(seed=0)
        t0 = time.perf_counter()
        total = 0.0
        for a in actions:
            obs, reward, term, trunc, _info = env.step(a.astype(np.float32))
            total += float(reward)
            if term or trunc:
                break
        result[dyn] = {"return": total, "final_obs": np.asarray(obs).round(4).tolist(),
                       "steps_per_s": steps / (time.perf_counter() - t0)}
        env.close()
    diff = np.abs(np.array(result["mujoco"]["final_obs"][:3]) - np.array(result["fignet"]["final_obs"][:3]))
    print("\n=== Push-v0, same 40 actions on both dynamics ===")
    for dyn in ("mujoco", "fignet"):
        r = result[dyn]
        print(f"{dyn:7s} return {r['return']:8.3f}   {r['steps_per_s']:7.1f} env steps/s")
    print(f"final object observation differs by {diff.max():.4f} (max abs over its first 3 entries)")
    return result


def run_demo(out: str = "outputs/demo", quick: bool = False) -> dict[str, Any]:
    """Run the demo and write its outputs to ``out``; returns the summary."""
    outdir = Path(out)
    outdir.mkdir(parents=True, exist_ok=True)
    n, v = (4, 0) if quick else (16, 2)
    summary = {
        "push": _task("push", "push", n, outdir, v, horizon=25),
        "toss": _task("toss", "toss-simple", max(2, n // 2), outdir, min(v, 1), horizon=50),
    }
    summary["env"] = _env_comparison(outdir)
    (outdir / "summary.json").write_text(json.dumps(summary, indent=2))
    print(f"\nwrote videos, plots and summary.json to {outdir.resolve()}")
    return summary
