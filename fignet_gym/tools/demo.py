"""The main job: plan with the shipped learned simulator, act in MuJoCo; no training needed.

``fignet-gym demo`` (or ``bash scripts/demo.sh``):

1. runs a few seeded ``Push-v2`` episodes in MuJoCo with a CEM planner whose model is the shipped
   FIGNet push simulator, the same episodes with the same planner whose model is MuJoCo, and the
   same episodes with the shipped PPO policy (``load_policy("push-ppo")``, trained only on FIGNet);
2. prints a table (success, final position and heading errors, CPU and wall seconds per action);
3. writes ``push_mpc.mp4`` (planning on FIGNet, planning on MuJoCo, PPO, left to right),
   ``push_mpc.png`` (distance to the goal against time) and ``summary.json``;
4. with ``--rollouts``, also compares open-loop rollouts of the shipped simulators with MuJoCo
   on fresh pushes and tosses (errors, videos and plots).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import imageio
import numpy as np
import torch

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents import PolicyAgent, make_planner, run_episode
from fignet_gym.agents.ppo import load_policy
from fignet_gym.data.generate import iter_trajectories
from fignet_gym.dynamics import DYNAMICS_LABELS, MujocoDynamics, make_dynamics
from fignet_gym.pretrained import load_pretrained
from fignet_gym.tools.plan import _label, summarize
from fignet_gym.train.evaluation import rollout_metrics
from fignet_gym.train.report import plot_curves, print_table, write_comparison_video

DEMO_SEED = 987_654  # far from the seeds of the shipped training and validation sets
#: The task of the demo's episodes.
DEMO_ENV = "fignet_gym/Push-v2"
#: The shipped PPO policy the demo shows beside the planners (trained for ``DEMO_ENV``).
DEMO_POLICY = "push-ppo"


def _task(name: str, kind: str, num: int, out: Path, videos: int, horizon: int) -> dict[str, Any]:
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
    """Same action sequence on Push-v2 with MuJoCo and with FIGNet dynamics."""
    rng = np.random.default_rng(0)
    actions = np.clip(np.array([[1.0, 0.0]]) + 0.3 * rng.normal(size=(steps, 2)), -1, 1)
    result: dict[str, Any] = {}
    for dyn in ("mujoco", "fignet"):
        env = gym.make("fignet_gym/Push-v2", dynamics=dyn)
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
    print("\n=== Push-v2, same 40 actions on both dynamics ===")
    for dyn in ("mujoco", "fignet"):
        r = result[dyn]
        print(f"{dyn:7s} return {r['return']:8.3f}   {r['steps_per_s']:7.1f} env steps/s")
    print(f"final object observation differs by {diff.max():.4f} (max abs over its first 3 entries)")
    return result


def _mpc(out: Path, episodes: int, quick: bool) -> dict[str, Any]:
    """CEM on the learned model, CEM on MuJoCo and the shipped PPO policy, all acting in MuJoCo,
    on the same seeds."""
    torch.set_num_threads(1)
    budget = {"horizon": 3, "population": 6, "iterations": 1, "replan_every": 1} if quick else {}
    max_steps = 3 if quick else None
    models = {"fignet": make_dynamics("fignet", None, "push"), "mujoco": MujocoDynamics(nthread=1)}
    policy = load_policy(DEMO_POLICY)
    # Push-v2 is Push-v1's task under isotropic friction: a policy of either version runs on it.
    if (policy.env_id.rsplit("-v", 1)[0], policy.env_kwargs) != (DEMO_ENV.rsplit("-v", 1)[0], {}):
        raise ValueError(f"{DEMO_POLICY}: trained for {policy.env_id} {policy.env_kwargs}, "
                         f"the demo runs {DEMO_ENV}")
    trained = DYNAMICS_LABELS.get(policy.config.dynamics, policy.config.dynamics)
    if policy.env_id != DEMO_ENV:
        trained += f" {policy.env_id.split('/')[-1]}"
    labels = {name: f"plans on {DYNAMICS_LABELS[name]}" for name in models}
    labels["ppo"] = f"PPO (trained on {trained})"
    agents = {name: (lambda env, dyn=dyn: make_planner("cem", dyn, "push", env=env, **budget))
              for name, dyn in models.items()}
    agents["ppo"] = lambda env: PolicyAgent(policy)
    size = 96 if quick else 320
    print(f"\n=== Push-v2: CEM planning on the shipped FIGNet push model vs on MuJoCo, and the shipped "
          f"PPO policy {DEMO_POLICY!r} (trained on {trained}), all acting in MuJoCo "
          f"({episodes} seeded episodes) ===")
    rows: dict[str, list[dict[str, Any]]] = {k: [] for k in agents}
    curves: dict[str, list[list[float]]] = {k: [] for k in agents}
    frames: dict[str, list[np.ndarray]] = {k: [] for k in agents}
    for k in range(episodes):
        seed = DEMO_SEED + k
        ends = {}
        for name, make_agent in agents.items():
            env = gym.make(DEMO_ENV, render_mode="rgb_array", width=size, height=size)
            agent = make_agent(env)
            curve: list[float] = []
            shots: list[np.ndarray] = []

            def grab(e: Any, _p: Any, curve: list[float] = curve, shots: list = shots) -> None:
                u = e.unwrapped
                curve.append(float(u.task.errors(u.get_state(), u.goal)[0]))
                shots.append(u.render())

            env.reset(seed=seed)
            start = env.unwrapped
            curve.append(float(start.task.errors(start.get_state(), start.goal)[0]))
            shots.append(start.render())
            t0 = time.perf_counter()
            row = {"seed": seed, **run_episode(env, agent, seed=seed, max_steps=max_steps,
                                               on_step=grab)}
            row["seconds"] = time.perf_counter() - t0
            rows[name].append(row)
            curves[name].append(curve)
            ends[name] = shots
            env.close()
            print(f"  seed {seed} {labels[name]:24s}: success {row['is_success']!s:5s} "
                  f"in {row['length']:2d} steps, {row['position_error'] * 1000:5.1f} mm, "
                  f"{row['orientation_error']:.3f} rad, "
                  f"{row['plan_cpu_seconds']:.4f} CPU-s per action", flush=True)
        n = max(len(v) for v in ends.values())
        for name, shots in ends.items():  # hold the last frame of the shorter episodes
            frames[name] += shots + [shots[-1]] * (n - len(shots))
    summary = {name: summarize(r) for name, r in rows.items()}
    print(f"\n{'agent':24s} {'success':>8s} {'pos. err (mm)':>14s} "
          f"{'heading (rad)':>14s} {'CPU-s/action':>13s} {'wall s/action':>14s}")
    for name, sm in summary.items():
        spa = sm["seconds_per_action"]
        ok = sum(r["is_success"] for r in rows[name])
        print(f"{labels[name]:24s} {ok:>4d}/{len(rows[name]):<3d} "
              f"{sm['median_position_error'] * 1000:14.1f} {sm['median_orientation_error']:14.3f} "
              f"{spa['cpu']:13.4f} {spa['wall']:14.4f}")
    print("(errors: medians of the final errors; success: within 1 cm and 0.2 rad)")
    video = [np.concatenate([_label(f, labels[name]) for name, f in zip(frames, step, strict=True)],
                            axis=1)
             for step in zip(*frames.values(), strict=True)]
    imageio.mimsave(out / "push_mpc.mp4", video, fps=50)
    _plot_mpc(curves, labels, out / "push_mpc.png")
    return {"summary": summary, "episodes": rows, "labels": labels}


def _plot_mpc(curves: dict[str, list[list[float]]], labels: dict[str, str], path: Path) -> None:
    """Distance from the goal against time, every episode, one colour per agent."""
    # deferred: Matplotlib's Agg backend is chosen here, when a plot is drawn, not on import
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: after the backend is chosen

    fig, ax = plt.subplots(figsize=(6, 3.5))
    for (name, eps), colour in zip(curves.items(), ("tab:blue", "tab:orange", "tab:green"), strict=False):
        for i, c in enumerate(eps):
            t = np.arange(len(c)) * 0.02
            ax.plot(t, np.array(c) * 1000, color=colour, alpha=0.8,
                    label=labels[name] if i == 0 else None)
    ax.axhline(10.0, color="grey", ls="--", lw=1, label="success (1 cm)")
    ax.set(xlabel="time (s)", ylabel="object to goal (mm)", title="Push-v2, acting in MuJoCo")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run_demo(
    out: str = "outputs/demo", quick: bool = False, episodes: int = 3, rollouts: bool = False
) -> dict[str, Any]:
    """Run the demo and write its outputs to ``out``; returns the summary.

    Args:
        out: output folder. quick: a tiny budget (tests). episodes: seeded Push-v2 episodes per
            agent (two planners, one PPO policy). rollouts: also compare open-loop rollouts with MuJoCo.
    """
    outdir = Path(out)
    outdir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    summary: dict[str, Any] = {"mpc": _mpc(outdir, 1 if quick else episodes, quick)}
    if rollouts:
        n, v = (4, 0) if quick else (16, 2)
        summary["push"] = _task("push", "push", n, outdir, v, horizon=25)
        summary["toss"] = _task("toss", "toss-simple", max(2, n // 2), outdir, min(v, 1), horizon=50)
        summary["env"] = _env_comparison(outdir)
    (outdir / "summary.json").write_text(json.dumps(summary, indent=2))
    print(f"\nwrote push_mpc.mp4, push_mpc.png and summary.json to {outdir.resolve()} "
          f"in {time.perf_counter() - t0:.0f} s")
    return summary
