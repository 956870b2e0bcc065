"""PPO-loop throughput: environment steps per CPU-second of ``PPO.learn`` (rollouts and updates),
the figure that bounds how many steps a PPO run can afford (``fignet-gym bench ppo``)."""

from __future__ import annotations

import statistics
import time
from dataclasses import replace
from typing import Any

from fignet_gym.agents.ppo.config import PPOConfig, RunConfig
from fignet_gym.agents.ppo.run import _new_model, _train_env, torch_threads


def ppo_throughput(cfg: RunConfig, iterations: int = 3) -> dict[str, Any]:
    """Time ``iterations`` PPO iterations (rollout of ``num_envs * n_steps`` steps, then the
    update) of ``cfg`` after one untimed warm-up iteration, on one torch thread.

    Returns:
        ``{"dynamics", "num_envs", "n_steps", "batch_size", "n_epochs", "steps", "cpu_seconds",
        "steps_per_cpu_second", "rollout_fraction"}``; ``rollout_fraction`` is the share of the
        CPU time spent collecting experience (the rest is PPO's update).
    """
    if iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {iterations}")
    p = cfg.ppo
    per_iter = p.num_envs * p.n_steps
    cfg = replace(cfg, ppo=replace(p, total_timesteps=per_iter))
    with torch_threads(1):
        vec, _ = _train_env(cfg)
        model = _new_model(cfg, vec)
        model.learn(total_timesteps=per_iter)  # warm-up: first graphs, allocator, caches
        rollout = 0.0
        original = model.collect_rollouts

        def timed_collect(*args: Any, **kwargs: Any) -> bool:
            nonlocal rollout
            t0 = time.process_time()
            try:
                return original(*args, **kwargs)
            finally:
                rollout += time.process_time() - t0

        model.collect_rollouts = timed_collect  # type: ignore[method-assign]
        t0 = time.process_time()
        model.learn(total_timesteps=iterations * per_iter, reset_num_timesteps=False)
        cpu = time.process_time() - t0
        vec.close()
    steps = iterations * per_iter
    return {"dynamics": cfg.dynamics, "num_envs": p.num_envs, "n_steps": p.n_steps,
            "batch_size": p.batch_size, "n_epochs": p.n_epochs, "steps": steps,
            "cpu_seconds": cpu, "steps_per_cpu_second": steps / cpu,
            "rollout_fraction": rollout / cpu}


#: The arms of :func:`ppo_throughput_table`: (label, training dynamics, network precision).
ARMS = (("MuJoCo", "mujoco", "float32"), ("FIGNet float32", "fignet", "float32"),
        ("FIGNet bfloat16", "fignet", "bfloat16"))


def ppo_throughput_table(env_id: str, num_envs: int, n_steps: int, batch_size: int, n_epochs: int,
                         repeats: int = 3, iterations: int = 2) -> tuple[str, list[dict[str, Any]]]:
    """:func:`ppo_throughput` of every arm of :data:`ARMS` on one PPO setting, ``repeats`` times
    in turn (arms interleaved, so a busy core slows all alike); the table of medians and the rows.
    """
    rows: dict[str, list[dict[str, Any]]] = {label: [] for label, _, _ in ARMS}
    ppo = PPOConfig(num_envs=num_envs, n_steps=n_steps, batch_size=batch_size, n_epochs=n_epochs)
    for _ in range(repeats):
        for label, dyn, precision in ARMS:
            cfg = RunConfig(env_id=env_id, dynamics=dyn, ppo=ppo, precision=precision, eval_every=0)
            rows[label].append(ppo_throughput(cfg, iterations))
    lines = [f"PPO loop on {env_id}: {num_envs} envs x {n_steps} steps per update, minibatch "
             f"{batch_size}, {n_epochs} epochs; one torch thread; medians of {repeats}",
             "| training dynamics | env steps per CPU-second | x MuJoCo | rollout share of CPU |",
             "|---|---|---|---|"]
    out = []
    mj = statistics.median(r["steps_per_cpu_second"] for r in rows["MuJoCo"])
    for label, reps in rows.items():
        rate = statistics.median(r["steps_per_cpu_second"] for r in reps)
        share = statistics.median(r["rollout_fraction"] for r in reps)
        lines.append(f"| {label} | {rate:,.0f} | {rate / mj:.2f} | {share:.0%} |")
        out.append({"arm": label, "steps_per_cpu_second": rate, "rollout_fraction": share,
                    "repeats": reps})
    return "\n".join(lines), out
