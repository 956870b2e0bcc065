"""One episode of a planner (or a baseline) acting in an environment, with its timing."""

from __future__ import annotations

from typing import Any

import gymnasium as gym


def run_episode(
    env: gym.Env,
    planner: Any,
    seed: int | None = None,
    max_steps: int | None = None,
    on_step: Any = None,
) -> dict[str, Any]:
    """One episode acted in ``env`` with ``planner`` replanning every step.

    The planner's dynamics may differ from the environment's (plan with FIGNet, act with MuJoCo).

    Args:
        env: an environment exposing its task (``gym.make`` adds the registered time limit).
        planner: a planner or baseline (``reset``, ``bind``, ``plan``, ``last``); reset (with its
            config's seed) and bound to ``env`` first.
        seed: of ``env.reset``.
        max_steps: stop after this many steps even if the episode has not ended.
        on_step: optional ``callable(env, planner)`` called after every step (e.g. rendering).

    Returns:
        ``{"return", "length", "diverged" (the acting env's dynamics blew up), "plan_seconds"
        and "plan_cpu_seconds" (mean wall and CPU time per action), "diverged_candidates"
        (fraction of planned rollouts that diverged)}``, plus on Push ``"is_success"``,
        ``"position_error"`` (m), ``"orientation_error"`` (rad), on Toss ``"num_in_target"``, on
        CubeToss ``"is_success"``, ``"distance"`` (m) and ``"yaw_error_deg"``.
    """
    env.reset(seed=seed)
    planner.reset()
    planner.bind(env)
    total, length, seconds, cpu, bad, evaluated = 0.0, 0, 0.0, 0.0, 0, 0
    info: dict[str, Any] = {}
    done = False
    while not done and (max_steps is None or length < max_steps):
        action = planner.plan(env)
        assert planner.last is not None
        seconds += planner.last.seconds
        cpu += planner.last.cpu_seconds
        bad += planner.last.diverged
        evaluated += planner.last.evaluated
        _, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        length += 1
        done = terminated or truncated
        if on_step is not None:
            on_step(env, planner)
    out: dict[str, Any] = {
        "return": total,
        "length": length,
        "diverged": "diverged" in info,
        "plan_seconds": seconds / max(length, 1),
        "plan_cpu_seconds": cpu / max(length, 1),
        "diverged_candidates": bad / max(evaluated, 1),
    }
    if "position_error" in info:
        out["is_success"] = bool(info.get("is_success", False))
        out["position_error"] = float(info["position_error"])
        out["orientation_error"] = float(info["orientation_error"])
    if "coverage" in info:  # PushT: the fraction of the goal covered
        out["coverage"] = float(info["coverage"])
    if "num_in_target" in info:
        out["num_in_target"] = int(info["num_in_target"])
    if "distance" in info and "yaw_error_deg" in info:  # CubeToss: the landing error
        out["is_success"] = bool(info.get("is_success", False))
        out["distance"] = float(info["distance"])
        out["yaw_error_deg"] = float(info["yaw_error_deg"])
    return out
