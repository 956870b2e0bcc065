"""Nothing lost, nothing mixed: run folders and imports refuse to overwrite or mix, and the
argument values of plan, sim2real, split and the importers are checked before anything is written.

Each test reproduces a failure of the audit of the plan / sim2real / import surfaces (what it did
before is in the docstring) and checks the refusal against the files on disk: one ``error:`` line,
exit code 2, and the earlier output byte for byte unchanged.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch

from fignet_gym.atomic import OutputLockedError, lock_path, output_lock
from fignet_gym.cli import main
from fignet_gym.data.format import TrajectoryFile, load_trajectories, write_trajectories
from fignet_gym.data.generate import default_config, iter_trajectories
from fignet_gym.data.guards import MIN_MODEL_FRAMES, check_single_scene_type, scene_type
from fignet_gym.data.split import SplitError, fewest_trajectories, split_indices
from fignet_gym.data.tracked import import_contactnets

SAMPLE = Path(__file__).parent / "data" / "contactnets_sample"
#: A plan run short enough for the default test run: the idle baseline, no planning.
PLAN = ["plan", "--env", "fignet_gym/Push-v1", "--planner", "idle", "--episodes", "2"]
#: Longest wait (s) for a killed run to reach its kill point, or for a run to finish (a shared,
#: busy machine: a limit against hanging, not a timing check).
KILL_WAIT_SECONDS = 3600


def one_error_line(capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    """The captured stderr must be exactly one ``error:`` line containing every needle."""
    err = capsys.readouterr().err
    # progress bars (tqdm: "\r"-separated, with "%|") are not messages
    lines = [ln for ln in re.split(r"[\r\n]", err) if ln.strip() and "%|" not in ln]
    assert len(lines) == 1 and lines[0].startswith("error:"), err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


def parser_error(capsys: pytest.CaptureFixture[str], argv: list[str], option: str) -> None:
    """``argv`` is refused by the parser (exit 2) with a message naming ``option``."""
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}" in err and "Traceback" not in err, err


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path -> bytes)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# ----------------------------------------------------------------------------- the lock
@contextmanager
def held_by_another_process(out: Path) -> Iterator[int]:
    """A forked child holds ``output_lock(out)`` for the block; yields its pid. Leaving the block
    SIGKILLs it (the lock file stays behind, as after any crash)."""
    ready_r, ready_w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: take the lock, report, wait to be killed
        try:
            with output_lock(out):
                os.write(ready_w, b"1")
                signal.pause()
        finally:
            os._exit(0)
    os.close(ready_w)
    assert os.read(ready_r, 1) == b"1"
    os.close(ready_r)
    try:
        yield pid
    finally:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)


def test_a_second_writer_is_refused_and_a_dead_owners_lock_is_taken_over(tmp_path: Path) -> None:
    """Was: two processes on one --out appended to the same files."""
    out = tmp_path / "run"
    with held_by_another_process(out) as pid:
        with pytest.raises(OutputLockedError, match=f"run: in use by another process \\(pid {pid}"):
            with output_lock(out):
                pass
    # The owner died holding it: its lock file stays (SIGKILL runs no cleanup) but is stale.
    assert f"pid {pid}" in lock_path(out).read_text()
    with output_lock(out) as lock:
        assert lock.read_text().startswith(f"pid {os.getpid()} ")
    assert not lock_path(out).exists()  # released: the file goes with it
    assert not out.exists()  # the lock lives beside the output, never inside it


@pytest.mark.parametrize("argv", [
    [*PLAN, "--out", "{out}"],
    ["generate", "push", "--num", "1", "--out", "{out}", "--no-progress"],
    ["import-contactnets", str(SAMPLE), "--out", "{out}"],
    ["sim2real", "--data", "x.h5", "--out", "{out}", "--no-fignet"],
    ["split", "x.h5", "--out", "{out}"],
    ["mit-standin", "--num", "1", "--out", "{out}"],
    ["ppo", "--dynamics", "mujoco", "--steps", "64", "--out", "{out}"],
], ids=lambda a: a[0])
def test_every_writing_command_refuses_an_output_in_use(argv: list[str], tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    with held_by_another_process(out):
        assert main([a.replace("{out}", str(out)) for a in argv]) == 2
        one_error_line(capsys, str(out), "in use by another process")
    assert not out.exists()


# ----------------------------------------------------------------------------- plan
def _rows(out: Path) -> list[dict]:
    return [json.loads(x) for x in (out / "episodes.jsonl").read_text().splitlines()]


@pytest.fixture(scope="module")
def plan_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished two-episode plan run with a video of episode 0 (copy it before changing it)."""
    out = tmp_path_factory.mktemp("plan") / "run"
    assert main([*PLAN, "--videos", "1", "--out", str(out)]) == 0
    return out


def test_plan_refuses_an_existing_run_without_resume_or_force(plan_run: Path, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """Was: ``plan`` without ``--resume`` deleted episodes.jsonl (3 rows became 1) and left the
    old videos beside the new summary."""
    out = tmp_path / "run"
    shutil.copytree(plan_run, out)
    before = snapshot(out)
    assert main([*PLAN, "--episodes", "1", "--out", str(out)]) == 2
    one_error_line(capsys, str(out), "--resume", "--force")
    assert snapshot(out) == before
    assert main([*PLAN, "--episodes", "1", "--out", str(out), "--force"]) == 0
    assert [r["seed"] for r in _rows(out)] == [0]
    assert not (out / "episode_0.mp4").exists()  # the old run's video went with it


def _with(argv: list[str], change: list[str]) -> list[str]:
    """``argv`` with the options of ``change`` (pairs) replaced or added."""
    argv = list(argv)
    for opt, value in zip(change[::2], change[1::2], strict=True):
        if opt in argv:
            argv[argv.index(opt) + 1] = value
        else:
            argv += [opt, value]
    return argv


@pytest.mark.parametrize("change,needle", [
    (["--planner", "random"], "planner 'idle' (now 'random')"),
    (["--env", "fignet_gym/Push-v2"], "env 'fignet_gym/Push-v1' (now 'fignet_gym/Push-v2')"),
    (["--seed", "7"], "seed 0 (now 7)"),
    (["--dynamics", "fignet"], "dynamics 'mujoco' (now 'fignet')"),
])
def test_plan_resume_refuses_other_settings(plan_run: Path, tmp_path: Path, change: list[str],
                                            needle: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Was: ``--resume`` with another planner or env labelled the old rows with the new settings."""
    out = tmp_path / "run"
    shutil.copytree(plan_run, out)
    before = snapshot(out)
    assert main(_with([*PLAN, "--videos", "1", "--out", str(out), "--resume"], change)) == 2
    one_error_line(capsys, "run.json", needle)
    assert snapshot(out) == before


def test_plan_resume_refuses_another_mujoco(plan_run: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """A line's episodes are reproducible only on one MuJoCo / torch: a resume on another
    stack would mix two samples under one label."""
    out = tmp_path / "run"
    shutil.copytree(plan_run, out)
    settings = json.loads((out / "run.json").read_text())
    assert settings["software"]["mujoco"] == mujoco.__version__
    settings["software"]["mujoco"] = "3.2.0"
    (out / "run.json").write_text(json.dumps(settings))
    before = snapshot(out)
    assert main([*PLAN, "--videos", "1", "--out", str(out), "--resume"]) == 2
    one_error_line(capsys, "run.json", "'3.2.0'")
    assert snapshot(out) == before


def test_plan_resume_accepts_other_threads_and_more_episodes(plan_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    shutil.copytree(plan_run, out)
    assert main([*PLAN, "--episodes", "3", "--videos", "1", "--out", str(out), "--resume",
                 "--threads", "2"]) == 0
    assert [r["seed"] for r in _rows(out)] == [0, 1, 2]
    assert json.loads((out / "run.json").read_text())["threads"] == 2


def test_plan_resume_recovers_a_video_a_kill_lost(plan_run: Path, tmp_path: Path) -> None:
    """Was: a kill between an episode's row and its video lost the video for good (the resumed
    run skipped the episode). Now the video is written first; and a run killed the old way (a
    row without its video) or mid-video (a partial file) gets the episode run again."""
    out = tmp_path / "run"
    shutil.copytree(plan_run, out)
    rows = _rows(out)
    video = (out / "episode_0.mp4").read_bytes()
    (out / "episode_0.mp4").unlink()  # what the kill left
    (out / "episode_0.partial.mp4").write_bytes(video[: len(video) // 2])
    assert main([*PLAN, "--videos", "1", "--out", str(out), "--resume"]) == 0
    again = _rows(out)
    assert sorted(r["seed"] for r in again) == [0, 1]  # each episode once
    strip = lambda r: {k: v for k, v in r.items() if "seconds" not in k}  # noqa: E731
    assert [strip(r) for r in sorted(again, key=lambda r: r["seed"])] == [strip(r) for r in rows]
    assert (out / "episode_0.mp4").stat().st_size > 0
    assert not list(out.glob("*.partial.mp4"))


def test_plan_refuses_other_packages_envs_before_writing(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """Was: ``TypeError`` from ``gym.make('CartPole-v1', dynamics=...)``."""
    out = tmp_path / "run"
    assert main(["plan", "--env", "CartPole-v1", "--out", str(out)]) == 2
    one_error_line(capsys, "--env", "CartPole-v1", "takes no dynamics= argument", "fignet_gym/Push-v1")
    assert not out.exists()


@pytest.mark.parametrize("option,value", [("--threads", "0"), ("--videos", "-1"), ("--episodes", "0"),
                                          ("--seed", "-1"), ("--episodes", "1.5")])
def test_plan_counts_are_checked_by_the_parser(option: str, value: str, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """Was: ``--threads 0`` and ``--videos -1`` accepted."""
    parser_error(capsys, ["plan", "--out", str(tmp_path / "run"), option, value], option)
    assert not (tmp_path / "run").exists()


def test_plan_with_a_huge_episode_count_never_builds_the_seed_list(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Was: ``--episodes 1000000000000`` built the whole seed list first (MemoryError)."""
    import fignet_gym.agents as agents

    episode = agents.run_episode
    played: list[int] = []

    class Enough(Exception):
        pass

    def two_then_stop(env, agent, seed=None, **kw):  # noqa: ANN001, ANN202
        if len(played) == 2:
            raise Enough
        played.append(seed)
        return episode(env, agent, seed=seed, max_steps=3, **kw)

    monkeypatch.setattr(agents, "run_episode", two_then_stop)
    out = tmp_path / "run"
    with pytest.raises(Enough):
        main([*PLAN[:-1], str(10**12), "--seed", "5", "--out", str(out)])
    assert played == [5, 6] and [r["seed"] for r in _rows(out)] == [5, 6]


# ----------------------------------------------------------------------------- sim2real
@pytest.fixture(scope="module")
def cube_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cube") / "cube.h5"
    import_contactnets(SAMPLE, path)
    return path


def test_sim2real_resume_refuses_another_fignet_recipe(cube_file: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str],
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """Was: ``--resume`` ignored ``--budget``, ``--config``, ``--set`` and ``--init``: one table
    compared sizes trained with different recipes, and no recipe was recorded."""
    from fignet_gym.train import sim2real

    out = tmp_path / "run"
    argv = ["sim2real", "--data", str(cube_file), "--out", str(out), "--fractions", "0.5", "0.25",
            "0.25", "--sizes", "5", "--budget", "3", "--set", '{"training.lr": 1e-4}']
    assert main(argv) == 2  # size 5 > the 2 training trajectories: refused, nothing written
    one_error_line(capsys, "size 5 exceeds")
    assert not out.exists()
    argv[argv.index("5")] = "2"

    def killed(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        raise sim2real.Sim2RealError("killed after recording run.json")

    with monkeypatch.context() as m:  # a run stopped right after recording its plan
        m.setattr(sim2real, "write_split", killed)
        assert main(argv) == 2
    one_error_line(capsys, "killed after")
    recipe = json.loads((out / "run.json").read_text())["recipe"]
    assert recipe == {"config": "cube-real", "budget": 3, "set": {"training.lr": 1e-4}, "init": None}
    before = snapshot(out)
    for change, needle in ((["--budget", "4"], "--budget 3 (now 4)"),
                           (["--config", "toss-cpu"], "--config 'cube-real' (now 'toss-cpu')"),
                           (["--set", "{}"], "--set {'training.lr': 0.0001} (now {})"),
                           (["--init", "toss"], "--init None (now 'toss')")):
        assert main([*_with(argv, change), "--resume"]) == 2
        one_error_line(capsys, "run.json", needle)
        assert snapshot(out) == before


def _pushes(n: int) -> list:
    return list(iter_trajectories("push", n, seed=3, config=default_config("push")))


def test_sim2real_and_split_refuse_a_file_mixing_scene_types(cube_file: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """Was: both ran to a table on cube tosses mixed with pushes."""
    mixed = tmp_path / "mixed.h5"
    write_trajectories(mixed, [*load_trajectories(cube_file), *_pushes(2)])
    assert check_single_scene_type(cube_file) == "toss"
    out = tmp_path / "run"
    assert main(["sim2real", "--data", str(mixed), "--out", str(out), "--no-fignet"]) == 2
    one_error_line(capsys, "--data", "mixed.h5", "mixes scene types", "'toss-55'", "a push")
    assert not out.exists()
    assert main(["split", str(mixed), "--out", str(out)]) == 2
    one_error_line(capsys, "mixed.h5", "mixes scene types")
    assert not out.exists() and not list(tmp_path.glob(".run*"))


def test_scene_type_is_read_from_the_structure_not_the_metadata(cube_file: Path) -> None:
    push = _pushes(1)[0]
    toss = load_trajectories(cube_file)[0]
    assert scene_type(push.kinds) == "push" and scene_type(toss.kinds) == "toss"
    push.metadata.clear()  # metadata says nothing: the kinematic pusher still tells
    assert scene_type(push.kinds) == "push"


# ----------------------------------------------------------------------------- importers
def _contactnets_copy(tmp_path: Path) -> Path:
    src = tmp_path / "cn"
    shutil.copytree(SAMPLE, src)
    return src


@pytest.mark.parametrize("cmd", ["import-contactnets", "import-mit"])
def test_importers_refuse_an_existing_out_unless_force(cmd: str, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """Was: both silently replaced an existing --out."""
    out = tmp_path / "old.h5"
    out.write_bytes(b"precious")
    src = str(SAMPLE) if cmd == "import-contactnets" else str(tmp_path / "nothing-needed")
    assert main([cmd, src, "--out", str(out)]) == 2
    one_error_line(capsys, "old.h5", "--force")
    assert out.read_bytes() == b"precious"
    if cmd == "import-contactnets":
        assert main([cmd, src, "--out", str(out), "--force"]) == 0
        assert len(TrajectoryFile(out)) == 4


def test_import_into_a_folder_is_refused_and_leaves_nothing_beside_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Was: ``import-contactnets --out /tmp`` left ``/tmp.incomplete`` at the filesystem root."""
    folder = tmp_path / "folder"
    folder.mkdir()
    assert main(["import-contactnets", str(SAMPLE), "--out", str(folder)]) == 2
    one_error_line(capsys, "folder", "is a directory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder"]


def test_a_toss_too_short_for_a_model_is_refused_at_import(tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Was: a 2-frame toss passed import-contactnets, then sim2real died in sysid
    (``TypeError: iteration over a 0-d array``)."""
    src = _contactnets_copy(tmp_path)
    x = torch.load(src / "tosses_processed" / "55.pt", weights_only=True)
    for frames in (2, MIN_MODEL_FRAMES - 1):
        torch.save(x[:, :frames].clone(), src / "tosses_processed" / "9.pt")
        out = tmp_path / "cube.h5"
        assert main(["import-contactnets", str(src), "--out", str(out)]) == 2
        one_error_line(capsys, "9.pt", f"{frames} poses", f"at least {MIN_MODEL_FRAMES}")
        assert not out.exists()
    with pytest.warns(UserWarning, match="skipped.*9.pt"):
        assert import_contactnets(src, tmp_path / "cube.h5", skip_bad=True) == 4
    torch.save(x[:, :MIN_MODEL_FRAMES].clone(), src / "tosses_processed" / "9.pt")
    assert import_contactnets(src, tmp_path / "ok.h5") == 5  # the fewest frames allowed


def test_a_copied_toss_is_refused_naming_both_files(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """Was: a byte-identical copy under another name was imported, so a split could put the
    same toss in training and test."""
    src = _contactnets_copy(tmp_path)
    shutil.copy(src / "tosses_processed" / "229.pt", src / "tosses_processed" / "900.pt")
    out = tmp_path / "cube.h5"
    assert main(["import-contactnets", str(src), "--out", str(out)]) == 2
    one_error_line(capsys, "900.pt", "copy of", "229.pt")
    assert not out.exists()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert import_contactnets(src, out, skip_bad=True) == 4
    assert any("900.pt" in str(w.message) and "229.pt" in str(w.message) for w in caught)
    # a near copy (one pose moved by 1 mm) is another toss
    x = torch.load(src / "tosses_processed" / "229.pt", weights_only=True).clone()
    x[0, 40, 0] += 1e-3 / 0.0524
    torch.save(x, src / "tosses_processed" / "900.pt")
    assert import_contactnets(src, tmp_path / "near.h5") == 5


def test_a_copied_mit_push_is_refused_naming_both_files(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    from test_mit_importer import _write_raw

    src = tmp_path / "src"
    src.mkdir()
    first = _write_raw(src, "abs", "rect1", 0)
    copy = src / first.name.replace("t=0.349", "t=0.350")
    shutil.copy(first, copy)
    out = tmp_path / "mit.h5"
    assert main(["import-mit", str(src), "--out", str(out)]) == 2
    one_error_line(capsys, copy.name, "copy of", first.name)
    assert not out.exists()


@pytest.mark.parametrize("argv,option", [
    (["import-mit", "x", "--out", "o.h5", "--friction", "-1"], "--friction"),
    (["import-mit", "x", "--out", "o.h5", "--friction", "nan"], "--friction"),
    (["import-mit", "x", "--out", "o.h5", "--duration", "-1"], "--duration"),
    (["split", "x.h5", "--out", "s", "--fractions", "nan", "0.5", "0.5"], "--fractions"),
    (["sim2real", "--data", "x.h5", "--out", "s", "--fractions", "0.5", "-0.25", "0.75"], "--fractions"),
])
def test_nonsense_values_are_refused_by_the_parser(argv: list[str], option: str,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """Was: ``--friction -1`` written into every imported MJCF; ``--fractions nan 0.5 0.5`` ended
    in ``cannot convert float NaN to integer`` naming no option."""
    parser_error(capsys, argv, option)


def test_mit_standin_refuses_a_folder_that_is_not_empty(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """Was: a second stand-in into the same folder mixed two seeds' pushes silently."""
    out = tmp_path / "standin"
    out.mkdir()
    (out / "motion_surface=abs_shape=rect1_a=0_v=20_i=0.000_s=0.500_t=0.000_rep=0000.json").write_text("{}")
    before = snapshot(out)
    assert main(["mit-standin", "--num", "1", "--seed", "3", "--out", str(out)]) == 2
    one_error_line(capsys, "standin", "not empty", "--force")
    assert snapshot(out) == before
    assert main(["mit-standin", "--num", "1", "--seed", "3", "--out", str(out), "--force"]) == 0
    files = list(out.iterdir())
    assert len(files) == 1 and json.loads(files[0].read_text())["standin"]["seed"] == 3


# ----------------------------------------------------------------------------- split
def test_split_fractions_must_be_finite_and_the_error_names_the_option() -> None:
    with pytest.raises(SplitError, match="--fractions.*finite"):
        split_indices(10, (float("nan"), 0.5, 0.5))
    with pytest.raises(SplitError, match="--fractions"):
        split_indices(10, (float("inf"), -np.inf, 1.0))


def test_fewest_trajectories_matches_a_brute_force_search() -> None:
    """The number a too-small split asks for is the first that works (searched by brute force)."""
    def brute(f: tuple[float, float, float]) -> int:
        for n in range(1, 10_000):
            try:
                split_indices(n, f)
                return n
            except SplitError:
                continue
        raise AssertionError(f)

    rng = np.random.default_rng(0)
    cases = [(0.6, 0.2, 0.2), (0.5, 0.25, 0.25), (0.9, 0.05, 0.05), (0.98, 0.01, 0.01)]
    cases += [tuple(x / x.sum()) for x in rng.uniform(0.02, 1, (30, 3))]
    for f in cases:
        assert fewest_trajectories(f) == brute(f), f
    assert fewest_trajectories((1.0, 0.0, 0.0)) is None


def test_split_of_too_few_trajectories_states_how_many_are_needed(cube_file: Path, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """Was: "3 are too few ... need at least 3"."""
    three = tmp_path / "three.h5"
    write_trajectories(three, load_trajectories(cube_file)[:3])
    assert main(["split", str(three), "--out", str(tmp_path / "s")]) == 2
    line = one_error_line(capsys, "three.h5", "3 trajectories are too few", "test (0 < 1)")
    assert "need at least 4 trajectories" in line
    with pytest.raises(SplitError, match="no number of trajectories is enough"):
        split_indices(3, (1.0, 0.0, 0.0))


def test_split_into_a_file_is_refused_and_leaves_no_temporary_folder(
        cube_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Was: ``split --out afile`` failed after writing and left ``.afile.tmp/`` behind."""
    afile = tmp_path / "afile"
    afile.write_text("mine")
    assert main(["split", str(cube_file), "--out", str(afile), "--fractions", "0.5", "0.25", "0.25"]) == 2
    one_error_line(capsys, "afile", "must be a folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"] and afile.read_text() == "mine"


# ----------------------------------------------------------------------------- kill and resume
def _cli_process(argv: list[str], cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return subprocess.Popen([sys.executable, "-m", "fignet_gym", *argv], cwd=cwd, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _kill_when(proc: subprocess.Popen, ready: Callable[[], bool], what: str) -> None:
    """SIGKILL ``proc`` as soon as ``ready()`` (polled); fails if it ends first."""
    deadline = time.monotonic() + KILL_WAIT_SECONDS
    while not ready():
        assert proc.poll() is None, f"ended before {what}: {proc.stderr.read()[-2000:]}"
        assert time.monotonic() < deadline, f"never reached {what}"
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL


def _run(argv: list[str], cwd: Path) -> None:
    proc = _cli_process(argv, cwd)
    _, err = proc.communicate(timeout=KILL_WAIT_SECONDS)
    assert proc.returncode == 0, err[-3000:]


TIMING_KEYS = ("seconds", "cpu", "wall")


def _untimed(obj: object) -> object:
    """``obj`` without the keys of wall or CPU times (they differ between any two runs)."""
    if isinstance(obj, dict):
        return {k: _untimed(v) for k, v in obj.items() if not any(t in k for t in TIMING_KEYS)}
    if isinstance(obj, list):
        return [_untimed(v) for v in obj]
    return obj


@pytest.mark.slow
def test_plan_killed_at_any_episode_resumes_to_the_uninterrupted_run(tmp_path: Path) -> None:
    """SIGKILL while episodes are being written (after the first row), then ``--resume``: the
    same rows, each once, and every video (was: a kill between a row and its video lost it)."""
    argv = ["plan", "--env", "fignet_gym/Push-v1", "--planner", "cem", "--episodes", "3",
            "--videos", "3", "--horizon", "2", "--population", "4", "--iterations", "1",
            "--replan-every", "1"]
    _run([*argv, "--out", "straight"], tmp_path)
    killed = tmp_path / "killed"
    rows = killed / "episodes.jsonl"
    proc = _cli_process([*argv, "--out", "killed"], tmp_path)
    _kill_when(proc, lambda: rows.exists() and rows.read_text().count("\n") >= 1, "a row")
    _run([*argv, "--out", "killed", "--resume"], tmp_path)
    a, b = (json.loads((tmp_path / r / "summary.json").read_text()) for r in ("straight", "killed"))
    assert _untimed(a) == _untimed(b)
    assert sorted(r["seed"] for r in _rows(killed)) == [0, 1, 2]  # each episode once
    for k in range(3):
        assert (killed / f"episode_{k}.mp4").stat().st_size > 0
    assert not list(killed.glob("*.partial.mp4"))


@pytest.mark.slow
def test_sim2real_killed_while_training_resumes_to_the_uninterrupted_run(cube_file: Path,
                                                                         tmp_path: Path) -> None:
    """SIGKILL once FIGNet training has started, then ``--resume`` with the same recipe: the same
    results as a run never killed, with the recipe recorded."""
    tiny = json.dumps({"training.valid_every": 1, "training.batch_size": 1,
                       "training.valid_trajectories": 1, "training.checkpoint_every": 2})
    argv = ["sim2real", "--data", str(cube_file), "--fractions", "0.5", "0.25", "0.25",
            "--fit-evaluations", "4", "--fit-trajectories", "2", "--sizes", "2", "--budget", "6",
            "--set", tiny, "--no-polish"]
    _run([*argv, "--out", "straight"], tmp_path)
    proc = _cli_process([*argv, "--out", "killed"], tmp_path)
    _kill_when(proc, lambda: (tmp_path / "killed" / "fignet_2" / "curve.jsonl").exists(), "training")
    _run([*argv, "--out", "killed", "--resume"], tmp_path)
    a, b = (json.loads((tmp_path / r / "results.json").read_text()) for r in ("straight", "killed"))
    assert b["run"]["recipe"] == {"config": "cube-real", "budget": 6, "set": json.loads(tiny),
                                  "init": None}
    for key in ("mujoco_nominal", "mujoco_fitted", "fit"):
        assert _untimed(a[key]) == _untimed(b[key])
    _assert_close(_untimed(a["fignet"]["2"]), _untimed(b["fignet"]["2"]))


def _assert_close(a: object, b: object, where: str = "") -> None:
    """Nested JSON values equal, numbers to float32-level rounding (rel 1e-5)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for k in a:
            _assert_close(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_close(x, y, f"{where}[{i}]")
    elif isinstance(a, float):
        assert b == pytest.approx(a, rel=1e-5, nan_ok=True), where
    else:
        assert a == b, where
