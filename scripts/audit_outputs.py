"""Audit of run folders and imports: does a command refuse to overwrite, mix or half-write?

    python scripts/audit_outputs.py [--tree PATH] [--only NAME ...] [--json OUT]

Runs ``python -m fignet_gym`` on crafted inputs, each in a fresh temporary folder, with the
``fignet_gym`` package of ``--tree`` (default: this checkout; an older checkout measures
"before"). Each case is classified by what happened on disk and on stderr:

``clear``      exit 2, one ``error:`` line naming what it must name, the old files unchanged
``unclear``    refused, but the message does not name the option or file at fault (or misleads)
``silent``     accepted (exit 0) although it is wrong, or a refusal of something else
``data lost``  earlier output deleted or replaced, or two runs mixed in one folder
``debris``     refused, but files left where they do not belong
``traceback``  a Python traceback
``crash``      killed by a signal, out of memory, or the time limit
``ok``         the valid case works
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "tests" / "data" / "contactnets_sample"
MIT_PUSH = next(iter(sorted(Path("/work/shared/data/mit-push-abs/pushes").glob("*.h5"))), None)
PLAN = ["plan", "--env", "fignet_gym/Push-v1", "--planner", "idle", "--episodes", "1"]
TREE = ROOT
#: Memory limit (MB) of every command: a runaway allocation ends as MemoryError, not a swap storm.
MEM_MB = 3000


def cli(argv: list[str], cwd: Path, timeout: float = 600, background: bool = False
        ) -> tuple[int | None, str] | subprocess.Popen:
    """Exit code (``None``: killed by the time limit) and stderr of ``fignet-gym argv``."""
    import resource

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (MEM_MB << 20, MEM_MB << 20))

    env = {**os.environ, "PYTHONPATH": str(TREE), "OMP_NUM_THREADS": "1", "MUJOCO_GL": "egl"}
    cmd = [sys.executable, "-m", "fignet_gym", *argv]
    if background:
        return subprocess.Popen(cmd, cwd=cwd, env=env, preexec_fn=limit, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True)
    try:
        p = subprocess.run(cmd, cwd=cwd, env=env, preexec_fn=limit, capture_output=True, text=True,
                           timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, "timeout"
    return p.returncode, p.stderr


def refusal(rc: int | None, err: str, *needles: str) -> str:
    """``clear`` / ``unclear`` / ``silent`` / ``traceback`` / ``crash`` of a refusal expected to
    name ``needles``."""
    if rc is None or rc < 0 or "MemoryError" in err:
        return "crash"
    if "Traceback" in err:
        return "traceback"
    if rc == 0:
        return "silent"
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip() and "%|" not in ln]
    ok = lines and any(ln.startswith(("error:", "fignet-gym")) for ln in lines)
    if not ok:
        return "traceback"
    return "clear" if all(n in err for n in needles) else "unclear"


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def fake_plan_run(out: Path, planner: str = "idle", rows: int = 3) -> None:
    """A plan run folder as ``plan`` writes it (rows of seeds 0..rows-1)."""
    out.mkdir(parents=True)
    row = {"length": 75, "return": -1.0, "plan_seconds": 0.0, "plan_cpu_seconds": 0.0,
           "diverged": False, "is_success": False, "position_error": 0.04, "orientation_error": 0.3}
    rs = [{"seed": k, **row} for k in range(rows)]
    (out / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rs))
    meta = {"env": "fignet_gym/Push-v1", "planner": planner, "dynamics": "mujoco",
            "act_dynamics": "mujoco", "checkpoint": None, "config": None, "threads": 1}
    (out / "summary.json").write_text(json.dumps({**meta, "episodes": rows, "rows": rs}))


# ----------------------------------------------------------------------------- cases
def case_plan_overwrite(d: Path) -> str:
    fake_plan_run(d / "run")
    before = snapshot(d / "run")
    rc, err = cli([*PLAN, "--out", "run"], d)
    if snapshot(d / "run").get("episodes.jsonl") != before["episodes.jsonl"]:
        return "data lost"
    return refusal(rc, err, "--resume", "--force")


def case_plan_resume_other_planner(d: Path) -> str:
    fake_plan_run(d / "run", planner="cem")
    rc, err = cli([*PLAN, "--episodes", "4", "--out", "run", "--resume"], d)
    return refusal(rc, err, "planner")


def case_plan_env_cartpole(d: Path) -> str:
    rc, err = cli(["plan", "--env", "CartPole-v1", "--out", "run"], d)
    out = refusal(rc, err, "--env")
    return "debris" if out == "clear" and (d / "run").exists() else out


def case_plan_threads_0(d: Path) -> str:
    return refusal(*cli([*PLAN, "--threads", "0", "--out", "run"], d), "--threads")


def case_plan_videos_negative(d: Path) -> str:
    return refusal(*cli([*PLAN, "--videos", "-1", "--out", "run"], d), "--videos")


def case_plan_episodes_1e12(d: Path) -> str:
    rc, err = cli([*PLAN[:-1], str(10**12), "--out", "run"], d, timeout=240)
    rows = d / "run" / "episodes.jsonl"
    if rc is None and rows.exists() and rows.read_text().strip():
        return "ok"  # it plays episodes (stopped by the time limit)
    return refusal(rc, err)


def case_plan_lost_video(d: Path) -> str:
    rc, err = cli([*PLAN, "--videos", "1", "--out", "run"], d)
    assert rc == 0, err
    (d / "run" / "episode_0.mp4").unlink()  # a kill after the row, before the video
    rc, err = cli([*PLAN, "--videos", "1", "--out", "run", "--resume"], d)
    if rc != 0:
        return refusal(rc, err)
    return "ok" if (d / "run" / "episode_0.mp4").exists() else "data lost"


def case_plan_two_writers(d: Path) -> str:
    slow = ["--videos", "50"]  # rendering makes an episode last seconds: the runs overlap
    first = cli([*PLAN[:-1], "50", *slow, "--out", "run"], d, background=True)
    for _ in range(1200):  # wait until the first has started writing
        if (d / "run").exists() or first.poll() is not None:
            break
        time.sleep(0.5)
    rc, err = cli([*PLAN[:-1], "3", *slow, "--out", "run", "--resume"], d)
    first.send_signal(signal.SIGTERM)  # the first would go on for 50 episodes
    first.wait()
    seeds = [json.loads(x)["seed"] for x in (d / "run" / "episodes.jsonl").read_text().splitlines()]
    if len(seeds) != len(set(seeds)):
        return "data lost"  # mixed: both appended the same episodes
    return refusal(rc, err, "in use")


def _sim2real_started(d: Path) -> list[str]:
    assert cli(["import-contactnets", str(SAMPLE), "--out", "cube.h5"], d)[0] == 0
    argv = ["sim2real", "--data", "cube.h5", "--out", "run", "--fractions", "0.5", "0.25", "0.25",
            "--sizes", "5", "--budget", "3"]
    cli(argv, d)  # size 5 > 2 training trajectories: stops after the split
    return argv


def case_sim2real_resume_other_budget(d: Path) -> str:
    argv = _sim2real_started(d)
    rc, err = cli([*argv[:-1], "4", "--resume"], d)
    return refusal(rc, err, "--budget")


def _mixed(d: Path) -> None:
    assert cli(["import-contactnets", str(SAMPLE), "--out", "cube.h5"], d)[0] == 0
    assert cli(["generate", "push", "--num", "2", "--out", "push.h5", "--no-progress",
                "--workers", "1", "--duration", "0.4"], d)[0] == 0
    code = ("import sys; from fignet_gym.data.format import load_trajectories as L, "
            "write_trajectories as W; W('mixed.h5', L('cube.h5') + L('push.h5'))")
    subprocess.run([sys.executable, "-c", code], cwd=d, env={**os.environ, "PYTHONPATH": str(TREE)},
                   check=True)


def case_sim2real_mixed_scenes(d: Path) -> str:
    _mixed(d)
    rc, err = cli(["sim2real", "--data", "mixed.h5", "--out", "run", "--no-fignet", "--fit-evaluations",
                   "2", "--fit-trajectories", "1"], d)
    return refusal(rc, err, "scene")


def case_split_mixed_scenes(d: Path) -> str:
    _mixed(d)
    return refusal(*cli(["split", "mixed.h5", "--out", "s"], d), "scene")


def _replaced(d: Path, argv: list[str]) -> str:
    (d / "old.h5").write_bytes(b"precious")
    rc, err = cli(argv, d)
    if (d / "old.h5").read_bytes() != b"precious":
        return "data lost"
    return refusal(rc, err, "--force")


def case_import_contactnets_existing_out(d: Path) -> str:
    return _replaced(d, ["import-contactnets", str(SAMPLE), "--out", "old.h5"])


def case_import_mit_existing_out(d: Path) -> str:
    return _replaced(d, ["import-mit", str(MIT_PUSH), "--out", "old.h5"])


def case_mit_standin_non_empty(d: Path) -> str:
    assert cli(["mit-standin", "--num", "1", "--seed", "0", "--out", "s"], d)[0] == 0
    rc, err = cli(["mit-standin", "--num", "1", "--seed", "1", "--out", "s"], d)
    if rc == 0:
        seeds = {json.loads(p.read_text())["standin"]["seed"] for p in (d / "s").glob("*.json")}
        return "silent" if len(seeds) > 1 else "ok"
    return refusal(rc, err, "--force")


def _contactnets_dir(d: Path) -> Path:
    src = d / "cn"
    shutil.copytree(SAMPLE, src)
    return src


def case_import_two_frame_toss(d: Path) -> str:
    src = _contactnets_dir(d)
    code = ("import torch; x = torch.load('cn/tosses_processed/55.pt'); "
            "torch.save(x[:, :2].clone(), 'cn/tosses_processed/9.pt')")
    subprocess.run([sys.executable, "-c", code], cwd=d, check=True)
    rc, err = cli(["import-contactnets", str(src), "--out", "cube.h5"], d)
    return refusal(rc, err, "9.pt")


def case_import_contactnets_copy(d: Path) -> str:
    src = _contactnets_dir(d)
    shutil.copy(src / "tosses_processed" / "229.pt", src / "tosses_processed" / "900.pt")
    return refusal(*cli(["import-contactnets", str(src), "--out", "cube.h5"], d), "900.pt", "229.pt")


def case_import_mit_copy(d: Path) -> str:
    (d / "src").mkdir()
    shutil.copy(MIT_PUSH, d / "src" / MIT_PUSH.name)
    copy = f"{MIT_PUSH.stem}_rep=1{MIT_PUSH.suffix}"  # the same push under another name
    shutil.copy(MIT_PUSH, d / "src" / copy)
    return refusal(*cli(["import-mit", "src", "--out", "mit.h5"], d), copy, MIT_PUSH.name)


def case_import_mit_negative_friction(d: Path) -> str:
    return refusal(*cli(["import-mit", str(MIT_PUSH), "--out", "mit.h5", "--friction", "-1"], d),
                   "--friction")


def case_split_fractions_nan(d: Path) -> str:
    assert cli(["import-contactnets", str(SAMPLE), "--out", "cube.h5"], d)[0] == 0
    return refusal(*cli(["split", "cube.h5", "--out", "s", "--fractions", "nan", "0.5", "0.5"], d),
                   "--fractions")


def case_split_three_trajectories(d: Path) -> str:
    code = ("from fignet_gym.data.format import load_trajectories as L, write_trajectories as W; "
            "W('three.h5', L('cube.h5')[:3])")
    assert cli(["import-contactnets", str(SAMPLE), "--out", "cube.h5"], d)[0] == 0
    subprocess.run([sys.executable, "-c", code], cwd=d, env={**os.environ, "PYTHONPATH": str(TREE)},
                   check=True)
    rc, err = cli(["split", "three.h5", "--out", "s"], d)
    return refusal(rc, err, "at least 4")  # 0.6/0.2/0.2 of 3 leaves no test trajectory; 4 do


def case_import_out_is_a_folder(d: Path) -> str:
    (d / "folder").mkdir()
    rc, err = cli(["import-contactnets", str(SAMPLE), "--out", "folder"], d)
    out = refusal(rc, err, "folder")
    return "debris" if (d / "folder.incomplete").exists() else out


def case_split_out_is_a_file(d: Path) -> str:
    assert cli(["import-contactnets", str(SAMPLE), "--out", "cube.h5"], d)[0] == 0
    (d / "afile").write_text("mine")
    rc, err = cli(["split", "cube.h5", "--out", "afile", "--fractions", "0.5", "0.25", "0.25"], d)
    out = refusal(rc, err, "afile")
    return "debris" if (d / ".afile.tmp").exists() else out


CASES: dict[str, Callable[[Path], str]] = {
    name[len("case_"):]: fn for name, fn in globals().items() if name.startswith("case_")}


def main() -> None:
    global TREE
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", default=str(ROOT), help="checkout whose fignet_gym package to audit")
    ap.add_argument("--only", nargs="*", help="case names")
    ap.add_argument("--json", help="write {case: outcome} here")
    args = ap.parse_args()
    TREE = Path(args.tree).resolve()
    results = {}
    for name, fn in CASES.items():
        if args.only and name not in args.only:
            continue
        with tempfile.TemporaryDirectory(prefix="audit-") as tmp:
            t0 = time.time()
            try:
                results[name] = fn(Path(tmp))
            except (AssertionError, subprocess.CalledProcessError) as err:
                results[name] = f"setup failed ({err})"
            print(f"{name:40s} {results[name]:12s} {time.time() - t0:6.1f} s", flush=True)
        if args.json:
            Path(args.json).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.default_int_handler)
    main()
