"""``fignet-gym plan``: seeded episodes of a planner (or a baseline) acting in an environment.

    fignet-gym plan --env fignet_gym/Push-v2 --dynamics fignet --planner cem --episodes 50 \\
        --seed 0 --out runs/plan-fignet --videos 2

The planner plans with ``--dynamics`` (MuJoCo, or the shipped/given FIGNet model) and acts in the
environment with ``--act-dynamics`` (MuJoCo by default: "reality"). The settings go to
``OUT/run.json``; each finished episode's video (if any) is written, then its row is appended to
``OUT/episodes.jsonl`` and ``OUT/summary.json`` is rewritten, so a killed run resumes with
``--resume`` (same settings; an episode whose video was lost is run again). An existing run is
never replaced without ``--force``, and one process at a time writes to ``OUT`` (a lock).
``--videos K`` writes, for the first K episodes, the episode (left) beside what the planning
model predicted at the end of its current plan (right).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fignet_gym.atomic import output_lock, write_text
from fignet_gym.dynamics import DYNAMICS_LABELS, MujocoDynamics, make_dynamics

BASELINES = ("idle", "random")
#: Environment ids ``plan`` can act in (other packages' envs have no fignet_gym task).
ENV_NAMESPACE = "fignet_gym/"
#: A plan run folder: settings, one row per finished episode, the summary, videos.
SETTINGS, ROWS, SUMMARY, VIDEOS = "run.json", "episodes.jsonl", "summary.json", "episode_*.mp4"
#: Settings that may change on ``--resume`` (they do not change what an episode does).
RESUMABLE_CHANGES = frozenset({"threads"})
#: Suffix of a video being written (renamed into place when complete).
PARTIAL_VIDEO = ".partial.mp4"


class PlanError(ValueError):
    """A user error in the ``plan`` arguments (reported as one ``error:`` line)."""


def parse_env_kwargs(text: str, fixed: Sequence[str], why: str,
                     error: type[ValueError]) -> dict[str, Any]:
    """``--env-kwargs``' JSON object as a dict; ``error`` (one line) if it is not one or sets an
    argument of ``fixed`` (``why``: what fixes them)."""
    try:
        kwargs = json.loads(text)
    except ValueError as err:
        raise error(f"--env-kwargs: not JSON ({err}); give an object such as "
                    "'{\"goal_yaw\": 0.8}'") from None
    if not isinstance(kwargs, dict):
        raise error(f"--env-kwargs: must be a JSON object of env arguments, got {text!r}")
    if taken := sorted(set(kwargs) & set(fixed)):
        raise error(f"--env-kwargs: {', '.join(taken)} cannot be set ({why})")
    return kwargs


#: Env arguments ``plan --env-kwargs`` may not set.
PLAN_FIXED_ENV_ARGS = ("dynamics", "render_mode", "width", "height")


def check_arguments(args: argparse.Namespace) -> None:
    """:class:`PlanError` for counts out of range (the parser checks them too; this guards
    callers that build the namespace themselves)."""
    for name, low in (("episodes", 1), ("threads", 1), ("videos", 0), ("seed", 0)):
        value = getattr(args, name)
        if not isinstance(value, int) or value < low:
            raise PlanError(f"--{name} must be an integer >= {low}, got {value!r}")


def software() -> dict[str, str]:
    """Versions of the libraries whose numerics decide an episode: a planned episode is
    deterministic given its seed on one stack, but contact-rich episodes diverge between MuJoCo
    or torch versions (experiments/README.md, Planning), so a line is not resumed across them."""
    import mujoco  # deferred: versions are read only when a run starts
    import torch  # deferred: fignet-gym --help loads this module's parser, torch costs seconds

    return {"mujoco": mujoco.__version__, "torch": torch.__version__}


def _run_files(out: Path) -> list[Path]:
    if not out.is_dir():
        return []
    named = [out / n for n in (SETTINGS, ROWS, SUMMARY) if (out / n).exists()]
    return named + sorted(out.glob(VIDEOS))


def prepare_run_folder(out: Path, args: argparse.Namespace, meta: dict[str, Any]) -> list[dict[str, Any]]:
    """Make ``out`` ready for the run of ``meta`` (the settings); returns the finished rows.

    Without ``--resume`` an existing run is refused unless ``--force`` (which deletes its files).
    With ``--resume`` the stored settings must equal ``meta`` (except :data:`RESUMABLE_CHANGES`);
    episodes whose video a kill lost (a row without its video) are dropped, to be run again.
    """
    if out.exists() and not out.is_dir():
        raise PlanError(f"--out {out}: is a file; --out must be a folder")
    existing = _run_files(out)
    if existing and not args.resume:
        if not args.force:
            raise PlanError(f"--out {out}: already holds a plan run ({existing[0].name}); pass "
                            "--resume to continue it, --force to replace it, or choose another --out")
        for f in existing:
            f.unlink()
    out.mkdir(parents=True, exist_ok=True)
    for partial in out.glob("*" + PARTIAL_VIDEO):  # a video a kill cut short
        partial.unlink()
    rows: list[dict[str, Any]] = []
    if args.resume:
        _check_settings(out, meta)
        if (out / ROWS).exists():
            rows = read_rows(out / ROWS)
        kept = [r for r in rows if not _video_lost(out, r, args)]
        if len(kept) < len(rows):
            write_text(out / ROWS, "".join(json.dumps(r) + "\n" for r in kept))
            rows = kept
    write_text(out / SETTINGS, json.dumps(meta, indent=2))
    return rows


def _video_lost(out: Path, row: dict[str, Any], args: argparse.Namespace) -> bool:
    return 0 <= row["seed"] - args.seed < args.videos and not (out / f"episode_{row['seed']}.mp4").exists()


def _check_settings(out: Path, meta: dict[str, Any]) -> None:
    """:class:`PlanError` if the run in ``out`` was made with other settings than ``meta``.

    The settings are ``run.json``'s, or for runs from before it existed those ``summary.json``
    repeats."""
    stored_at = out / SETTINGS if (out / SETTINGS).exists() else out / SUMMARY
    if not stored_at.exists():
        return
    try:
        stored = json.loads(stored_at.read_text())
    except ValueError:
        raise PlanError(f"{stored_at}: not JSON; start a new run (--force) or another --out") from None
    diffs = [f"{k} {stored[k]!r} (now {v!r})" for k, v in meta.items()
             if k in stored and k not in RESUMABLE_CHANGES and stored[k] != v]
    if diffs:
        raise PlanError(f"{stored_at}: this run was made with {'; '.join(diffs)}: resume it with "
                        "the same settings, or start a new run (--force, or another --out)")


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The episode rows of ``episodes.jsonl``, dropping a partial last line (a run killed mid-append).

    The file is rewritten without that line so the next append starts on a fresh line.
    """
    text = path.read_text()
    lines = text.splitlines()
    rows: list[dict[str, Any]] = []
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:
            if i == len(lines) - 1 and not text.endswith("\n"):
                break
            raise PlanError(f"{path}: line {i + 1} is not JSON") from None
    if text and not text.endswith("\n"):  # cut mid-append, maybe just before its newline
        write_text(path, "".join(json.dumps(r) + "\n" for r in rows))
    return rows


def summarize(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Aggregates of per-episode rows (see :func:`run`)."""
    steps = np.array([r["length"] for r in rows], dtype=float)
    out: dict[str, Any] = {"episodes": len(rows)}
    if rows and "is_success" in rows[0]:
        out["success_rate"] = float(np.mean([r["is_success"] for r in rows]))
    if rows and "distance" in rows[0]:  # a toss's landing error
        out["median_distance"] = float(np.median([r["distance"] for r in rows]))
        out["mean_distance"] = float(np.mean([r["distance"] for r in rows]))
        out["median_abs_yaw_error_deg"] = float(np.median([abs(r["yaw_error_deg"]) for r in rows]))
    if rows and "position_error" in rows[0]:
        out["median_position_error"] = float(np.median([r["position_error"] for r in rows]))
        out["median_orientation_error"] = float(np.median([r["orientation_error"] for r in rows]))
    if rows and "coverage" in rows[0]:
        out["median_coverage"] = float(np.median([r["coverage"] for r in rows]))
    if rows and "num_in_target" in rows[0]:
        out["mean_in_target"] = float(np.mean([r["num_in_target"] for r in rows]))
    if rows:
        out["mean_return"] = float(np.mean([r["return"] for r in rows]))
        out["seconds_per_action"] = {
            "wall": float(np.sum([r["plan_seconds"] * r["length"] for r in rows]) / steps.sum()),
            "cpu": float(np.sum([r["plan_cpu_seconds"] * r["length"] for r in rows]) / steps.sum()),
        }
        out["diverged_episodes"] = int(sum(r["diverged"] for r in rows))
    return out


def print_table(label: str, rows: list[dict[str, Any]], summary: dict[str, Any]) -> None:
    """Per-episode rows, then the summary line."""
    push = "position_error" in (rows[0] if rows else {})
    cube = "distance" in (rows[0] if rows else {})
    cover = "coverage" in (rows[0] if rows else {})
    head = ("success  pos. err (mm)  heading err (rad)" + ("  coverage" if cover else "") if push else
            "success  landing err (mm)  yaw err (deg)" if cube else "in target")
    print(f"\n{label}\n{'seed':>6s}  {'steps':>5s}  {head}  {'s/action (cpu)':>14s}")
    for r in rows:
        if push:
            body = (f"{str(r['is_success']):>7s}  {r['position_error'] * 1000:13.1f}  "
                    f"{r['orientation_error']:17.3f}" + (f"  {r['coverage']:8.3f}" if cover else ""))
        elif cube:
            body = (f"{str(r['is_success']):>7s}  {r['distance'] * 1000:17.1f}  "
                    f"{r['yaw_error_deg']:13.1f}")
        elif "num_in_target" in r:
            body = f"{r['num_in_target']:9d}"
        else:
            body = f"{'-':>9s}"
        print(f"{r['seed']:6d}  {r['length']:5d}  {body}  {r['plan_cpu_seconds']:14.3f}")
    spa = summary.get("seconds_per_action", {})
    if push:
        print(f"success {summary['success_rate']:.0%} of {summary['episodes']}, median errors "
              f"{summary['median_position_error'] * 1000:.1f} mm / "
              f"{summary['median_orientation_error']:.3f} rad"
              + (f", median coverage {summary['median_coverage']:.3f}" if cover else "") + ", "
              f"{spa.get('cpu', 0):.3f} CPU-s ({spa.get('wall', 0):.3f} s wall) per action")
    elif cube:
        print(f"success {summary['success_rate']:.0%} of {summary['episodes']}, landing error "
              f"median {summary['median_distance'] * 1000:.1f} mm (mean "
              f"{summary['mean_distance'] * 1000:.1f}), yaw error median "
              f"{summary['median_abs_yaw_error_deg']:.1f} deg, {spa.get('cpu', 0):.3f} CPU-s per "
              f"action")
    elif "mean_in_target" in summary:
        print(f"mean objects in target {summary['mean_in_target']:.2f} over {summary['episodes']}"
              f" episodes, {spa.get('cpu', 0):.3f} CPU-s per action")
    else:
        print(f"{summary['episodes']} episodes, mean return {summary.get('mean_return', 0):.2f}, "
              f"{spa.get('cpu', 0):.3f} CPU-s per action")


class SideBySide:
    """Frames of an episode (left) beside the planning model's prediction (right)."""

    def __init__(self, env_id: str, env_kwargs: dict[str, Any], width: int = 320,
                 acting: str = "mujoco") -> None:
        import gymnasium as gym  # deferred: the parser of this module loads with fignet-gym --help

        self.acting = DYNAMICS_LABELS.get(acting, acting)
        self.imagined = gym.make(env_id, render_mode="rgb_array", width=width, height=width,
                                 **env_kwargs).unwrapped
        self.imagined.reset(seed=0)
        self.frames: list[np.ndarray] = []

    def __call__(self, env: Any, planner: Any) -> None:
        """``run_episode``'s ``on_step``: grab both frames."""
        u = env.unwrapped
        left = u.render()
        pred = getattr(planner, "prediction", None)
        for attr in ("goal", "target"):
            if hasattr(u, attr):
                setattr(self.imagined, attr, np.copy(getattr(u, attr)))
        self.imagined.set_state(pred[-1] if pred is not None else u.get_state())
        right = self.imagined.render()
        self.frames.append(np.concatenate([_label(left, f"acting ({self.acting})"),
                                           _label(right, "planner's prediction")], axis=1))

    def write(self, path: Path, fps: int) -> None:
        """An mp4 of the collected frames."""
        import imageio  # deferred: only a run that writes videos needs it

        if self.frames:  # written whole, then renamed: a kill never leaves a cut video
            partial = path.with_name(path.stem + PARTIAL_VIDEO)
            imageio.mimsave(partial, self.frames, fps=fps)
            os.replace(partial, path)
        self.frames = []


def _label(frame: np.ndarray, text: str) -> np.ndarray:
    """``uint8[H, W, 3]`` with ``text`` in its top-left corner."""
    from PIL import Image, ImageDraw  # deferred: only a run that writes videos needs it

    img = Image.fromarray(frame)
    ImageDraw.Draw(img).text((6, 4), text, fill=(0, 0, 0))
    return np.asarray(img)


def fignet_env_ids() -> list[str]:
    """The registered ``fignet_gym/`` environment ids, sorted."""
    import gymnasium as gym  # deferred: loading it registers the ids; --help does not need them

    return sorted(k for k in gym.registry if k.startswith(ENV_NAMESPACE))


def unknown_env(env_id: str) -> str | None:
    """The ``--env`` error line if ``env_id`` is not a registered Gymnasium id, else ``None``."""
    import gymnasium as gym  # deferred: loading it registers the ids; --help does not need them

    ids = fignet_env_ids()
    return None if env_id in gym.registry else (
        f"--env: unknown environment {env_id!r}; use one of {ids}")


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Run the episodes, print the table, write ``OUT/summary.json``; returns the summary."""
    import gymnasium as gym  # deferred: gymnasium, torch and the envs load when a run starts,
    import torch  # deferred: not with fignet-gym --help, which builds this module's parser

    from fignet_gym.agents import IdleAgent, RandomAgent  # deferred: torch (as above)
    from fignet_gym.envs.tasks import Task  # deferred: gymnasium and MuJoCo (as above)

    check_arguments(args)
    torch.set_num_threads(args.threads)
    if unknown := unknown_env(args.env):
        raise PlanError(unknown)
    out = Path(args.out)
    extra = parse_env_kwargs(getattr(args, "env_kwargs", "{}"), PLAN_FIXED_ENV_ARGS,
                             "--act-dynamics and --videos set them", PlanError)
    env_kwargs = {"dynamics": args.act_dynamics, **extra}
    render = {"render_mode": "rgb_array", "width": 320, "height": 320} if args.videos else {}
    try:
        env = gym.make(args.env, **render, **env_kwargs)
    except TypeError as err:  # another package's env (CartPole) takes none of these arguments
        what = f"does not take all of {sorted(env_kwargs)}" if extra else "takes no dynamics= argument"
        raise PlanError(f"--env: {args.env} {what} (plannable envs: "
                        f"{fignet_env_ids()} or a user's env with dynamics= and a task): {err}"
                        ) from None
    except ValueError as err:  # an env refusing an argument (ScenePush-v0 without its file)
        raise PlanError(f"--env {args.env}: {err}") from None
    if not isinstance(getattr(env.unwrapped, "task", None), Task):
        raise PlanError(f"--env: {args.env} exposes no task to plan (env.task: a "
                        f"fignet_gym.envs.tasks.Task); {type(env.unwrapped).__name__} has none")
    if args.planner in BASELINES:
        agent: Any = (IdleAgent if args.planner == "idle" else RandomAgent)(seed=args.seed)
        label = f"{args.planner} on {args.env}"
    else:
        try:
            agent = planning_agent(
                args.env, env, args.planner, args.dynamics, args.act_dynamics, args.checkpoint,
                threads=args.threads, horizon=args.horizon, population=args.population,
                iterations=args.iterations, replan_every=args.replan_every,
                **({"seed": args.seed} if args.seed else {}),
            )
        except ValueError as err:  # a checkpoint of another scene, a bad budget
            raise PlanError(str(err)) from None
        label = f"{args.planner.upper()} planning on {args.dynamics}, acting in {args.act_dynamics}"
    config = getattr(agent, "config", None)
    meta = {"env": args.env, "planner": args.planner, "dynamics": args.dynamics,
            "act_dynamics": args.act_dynamics, "checkpoint": args.checkpoint,
            "config": config.__dict__ if config is not None else None, "seed": args.seed,
            "threads": args.threads, "software": software(),
            **({"env_kwargs": extra} if extra else {})}  # runs before the option: no key
    meta = json.loads(json.dumps(meta))  # as stored: tuples become lists
    with output_lock(out):
        rows = prepare_run_folder(out, args, meta)
        return _run_episodes(args, env, agent, label, env_kwargs, out, rows, meta)


def _run_episodes(args: argparse.Namespace, env: Any, agent: Any, label: str,
                  env_kwargs: dict[str, Any], out: Path, rows: list[dict[str, Any]],
                  meta: dict[str, Any]) -> dict[str, Any]:
    """The episodes not yet in ``rows`` (their seeds generated lazily: ``--episodes`` may be
    huge), each written as it finishes: its video (atomically), then its row."""
    from tqdm import tqdm  # deferred: only a run needs it

    # deferred: looked up when called, so a test can patch fignet_gym.agents.run_episode
    from fignet_gym.agents import run_episode

    rows_path = out / ROWS
    done = {r["seed"] for r in rows}
    first, last = args.seed, args.seed + args.episodes  # seeds [first, last)
    todo = args.episodes - sum(1 for s in done if first <= s < last)
    seeds = (s for s in range(first, last) if s not in done)
    for seed in tqdm(seeds, total=todo, desc=label, unit="episode"):
        k = seed - args.seed
        video = SideBySide(args.env, env_kwargs, acting=args.act_dynamics) if k < args.videos else None
        t0 = time.perf_counter()
        row = {"seed": seed, **run_episode(env, agent, seed=seed, on_step=video)}
        row["seconds"] = time.perf_counter() - t0
        if video is not None:  # before the row: a row on disk means its video is there too
            video.write(out / f"episode_{seed}.mp4", env.metadata["render_fps"])
        rows.append(row)
        with rows_path.open("a") as f:
            f.write(json.dumps(row) + "\n")
        summary = {**meta, **summarize(rows), "rows": sorted(rows, key=lambda r: r["seed"])}
        write_text(out / "summary.json", json.dumps(summary, indent=2))
    rows.sort(key=lambda r: r["seed"])
    summary = {**meta, **summarize(rows), "rows": rows}
    write_text(out / "summary.json", json.dumps(summary, indent=2))
    print_table(label, rows, summary)
    print(f"wrote {out / 'summary.json'}")
    return summary


def planning_agent(env_id: str, env: Any, planner: str, dynamics: str, act_dynamics: str,
                   checkpoint: str | None = None, threads: int | None = None,
                   env_kwargs: dict[str, Any] | None = None, **budget: Any) -> Any:
    """A CEM / MPPI planner for ``env`` (made from ``env_id`` with ``env_kwargs``, acting in
    ``act_dynamics``) that plans on ``dynamics`` (``"mujoco"`` or ``"fignet"``, the latter from
    ``checkpoint``); ``budget`` goes to :func:`make_planner`. ``ValueError`` for a checkpoint of
    another scene, a checkpoint with MuJoCo, or a bad budget."""
    import gymnasium as gym  # deferred: gymnasium and torch load when a run starts (--help)

    from fignet_gym.agents import make_planner  # deferred: torch, as gymnasium above

    scene = env.unwrapped.scene_type
    if dynamics == "mujoco":
        if checkpoint:
            raise ValueError("--checkpoint only applies to --dynamics fignet")
        dyn = MujocoDynamics(nthread=threads)
    else:
        # The env version's own model by default (Push-v1: push-pyramidal, Push-v2: push).
        default = getattr(env.unwrapped, "default_checkpoint", "") or None
        dyn = make_dynamics("fignet", checkpoint or default, scene)
    # An env whose scene depends on its dynamics (CubeToss: fitted MuJoCo parameters, the
    # learned model's own nominal scene) plans on the planning dynamics' scene.
    plan_model = None
    if dynamics != act_dynamics:
        own = gym.make(env_id, dynamics="mujoco" if dynamics == "mujoco" else dyn,
                       **(env_kwargs or {}))
        plan_model = own.unwrapped.model
    return make_planner(planner, dyn, scene, env=env, model=plan_model, **budget)
