"""Why a PPO push policy fails: roll it out on MuJoCo Push-v1 and classify every episode.

    python scripts/ppo_diagnose.py RUN [--checkpoint] [--episodes 100] [--out RUN/diagnosis]

Episode ``k`` is seeded ``10000 + k`` (the runs' evaluation episodes). Per step it records the
position and heading errors, whether the tip touches the object (a MuJoCo contact between the
``tip`` and ``object`` geoms) and the reward terms; a failure is classified as

* ``never_touched``: no contact in the whole episode;
* ``heading_off``: ends within the position tolerance with the heading outside;
* ``passed_through``: was within the position tolerance at some step, ends outside it;
* ``lost_contact``: ends outside, last contact 10 or more steps before the end;
* ``pushing_at_timeout``: ends outside while still (or recently) touching the object.

Writes ``diagnosis.json`` (counts, per-episode records) and ``diagnosis.png`` (error curves).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
from stable_baselines3 import PPO

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents.ppo.eval import EVAL_SEED
from fignet_gym.agents.ppo.policy import NormalizedPolicy, load_normalizer, load_run_policy, run_transform
from fignet_gym.agents.ppo.rundir import CHECKPOINT, MODEL, NORMALIZER, saved_config
from fignet_gym.atomic import write_text

#: A contact this many steps before the end or fewer counts as "still pushing".
RECENT = 10


def load(run: Path, checkpoint: bool) -> NormalizedPolicy:
    """The run's final policy, or its last checkpoint's."""
    if not checkpoint:
        return load_run_policy(run)
    cfg = saved_config(run)
    transform = run_transform(cfg.env_id, cfg.env_kwargs, cfg.observation)
    return NormalizedPolicy(PPO.load(run / CHECKPOINT / MODEL, device="cpu"),
                            load_normalizer(run / CHECKPOINT / NORMALIZER), transform)


def touching(env: gym.Env) -> bool:
    """Whether the tip and the object are in contact (MuJoCo's contact list)."""
    u = env.unwrapped
    tip = mujoco.mj_name2id(u.model, mujoco.mjtObj.mjOBJ_GEOM, "tip")
    obj = mujoco.mj_name2id(u.model, mujoco.mjtObj.mjOBJ_GEOM, "object")
    pairs = {(int(c.geom1), int(c.geom2)) for c in u.data.contact[: u.data.ncon]}
    return (tip, obj) in pairs or (obj, tip) in pairs


def episode(env: gym.Env, policy: NormalizedPolicy, seed: int) -> dict:
    """One deterministic episode; its per-step record and final class."""
    obs, _ = env.reset(seed=seed)
    u = env.unwrapped
    start_yaw = float(abs(np.arctan2(obs[13], obs[12])))  # goal_rel_yaw: the turn the task asks
    pos, yaw, contact, rewards = [], [], [], []
    done, info = False, {}
    while not done:
        action, _ = policy.predict(obs[None], deterministic=True)
        obs, r, term, trunc, info = env.step(action[0])
        pos.append(info["position_error"])
        yaw.append(info["orientation_error"])
        contact.append(touching(env))
        rewards.append({k: v for k, v in info.items() if k.startswith("reward_")})
        done = term or trunc
    tol_p = u.task.success_position
    n = len(pos)
    touched = np.flatnonzero(contact)
    if info["is_success"]:
        kind = "success"
    elif not len(touched):
        kind = "never_touched"
    elif pos[-1] < tol_p:
        kind = "heading_off"
    elif min(pos) < tol_p:
        kind = "passed_through"
    elif touched[-1] < n - RECENT:
        kind = "lost_contact"
    else:
        kind = "pushing_at_timeout"
    return {"seed": seed, "kind": kind, "length": n, "position_error": pos, "orientation_error": yaw,
            "contact": contact, "first_contact": int(touched[0]) if len(touched) else None,
            "contact_fraction": float(np.mean(contact)),
            "goal_distance": float(np.hypot(*(u.goal[:2]))),
            "goal_yaw_change": start_yaw,
            "reward_terms": {k: float(np.mean([r[k] for r in rewards])) for k in rewards[0]}}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", type=Path)
    p.add_argument("--checkpoint", action="store_true", help="the last checkpoint, not policy.zip")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--out", type=Path, default=None)
    a = p.parse_args()
    out = a.out or a.run / "diagnosis"
    out.mkdir(parents=True, exist_ok=True)
    cfg = saved_config(a.run)
    env = gym.make(cfg.env_id, **{**cfg.env_kwargs, "dynamics": "mujoco"})
    policy = load(a.run, a.checkpoint)
    eps = [episode(env, policy, EVAL_SEED + k) for k in range(a.episodes)]
    kinds = [e["kind"] for e in eps]
    counts = {k: kinds.count(k) for k in sorted(set(kinds))}
    succ = [e for e in eps if e["kind"] == "success"]
    summary = {
        "run": str(a.run), "episodes": a.episodes, "counts": counts,
        "success_length_mean": float(np.mean([e["length"] for e in succ])) if succ else None,
        "first_contact_mean": float(np.mean([e["first_contact"] for e in eps
                                             if e["first_contact"] is not None])),
        "contact_fraction_mean": float(np.mean([e["contact_fraction"] for e in eps])),
        "success_by_goal_distance": {
            f"{lo}-{lo + 1} cm": float(np.mean([e["kind"] == "success" for e in eps
                                                if lo <= 100 * e["goal_distance"] < lo + 1] or [np.nan]))
            for lo in (2, 3, 4)},
        "reward_terms_per_step": {k: float(np.mean([e["reward_terms"][k] for e in eps]))
                                  for k in eps[0]["reward_terms"]},
    }
    print(json.dumps(summary, indent=1))
    write_text(out / "diagnosis.json", json.dumps({**summary, "episodes_detail": eps}))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    colors = {"success": "g", "never_touched": "k", "heading_off": "orange", "passed_through": "m",
              "lost_contact": "r", "pushing_at_timeout": "b"}
    for e in eps:
        c = colors[e["kind"]]
        ax[0].plot(1000 * np.array(e["position_error"]), c, alpha=0.3, lw=0.8)
        ax[1].plot(e["orientation_error"], c, alpha=0.3, lw=0.8)
    ax[0].axhline(10, ls="--", c="gray")
    ax[1].axhline(0.2, ls="--", c="gray")
    ax[0].set(xlabel="step", ylabel="position error (mm)", title="position error per episode")
    ax[1].set(xlabel="step", ylabel="heading error (rad)", title="heading error")
    ax[2].bar(list(counts), list(counts.values()), color=[colors[k] for k in counts])
    ax[2].tick_params(axis="x", rotation=30)
    ax[2].set(title=f"episode outcome ({a.episodes} MuJoCo episodes)")
    fig.tight_layout()
    fig.savefig(out / "diagnosis.png", dpi=80)


if __name__ == "__main__":
    main()
