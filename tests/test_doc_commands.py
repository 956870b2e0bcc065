"""The real-pushing commands of ``docs/sim2real.md`` run as written, in order, on the shipped
sample: only the data folder and the budgets are swapped for small ones (a command the docs
change must still run; a documented recipe that a smaller data set refuses, or a rerun that
needs ``--resume`` the docs do not show, fails here)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from fignet_gym.cli import main

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "sim2real.md"
SAMPLE = Path(__file__).parent / "data" / "mit_sample"
#: How the docs' commands end the path of a folder of raw MIT pushes (the shared ABS set, or a
#: placeholder); each is replaced by the shipped sample.
DOC_PUSH_FOLDERS = ("mit-push-abs/pushes", "path/to/pushes")
#: The sections whose code blocks are run, in the docs' order.
SECTIONS = ("## Real pushes (MIT Pushing): import protocol and geometry",
            "## Real pushes (MIT Pushing on ABS)", "## A stand-in pushing set")
#: Budgets swapped for tiny ones (option -> value); every other option stays as written.
SMALL = {"--budget": "2", "--num": "8", "--fit-evaluations": "3", "--fit-trajectories": "2",
         "--pretrain": "4", "--pretrain-budget": "2", "--episodes": "1"}
#: A planner's budget cut to a few candidates (``plan`` takes the last of a repeated option).
TINY_PLAN = ["--horizon", "2", "--population", "4", "--iterations", "1"]
TINY_TRAINING = ('{"training.valid_every": 1, "training.batch_size": 1, '
                 '"training.valid_trajectories": 1}')


def _commands(section: str) -> list[list[str]]:
    """The ``fignet-gym`` command lines (continuations joined) of one section's bash blocks."""
    text = DOC.read_text()
    start = text.index(section)
    end = text.find("\n## ", start + len(section))
    body = text[start:end if end > 0 else None]
    out = []
    for block in re.findall(r"^```bash\n(.*?)^```", body, re.S | re.M):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split(" #")[0].strip()
            if line.startswith("fignet-gym "):
                out.append(shlex.split(line)[1:])
    return out


def _small(argv: list[str]) -> list[str]:
    """``argv`` on the sample, with :data:`SMALL` budgets and every ``--sizes`` list ``all``."""
    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        if a.endswith(DOC_PUSH_FOLDERS):  # the docs' folders of raw pushes: never read here
            a = str(SAMPLE)
        if a in SMALL:
            out += [a, SMALL[a]]
            i += 2
            continue
        if a == "--sizes":  # the sample's training split holds 2 pushes: every size is "all"
            i += 1
            while i < len(argv) and not argv[i].startswith("--"):
                i += 1
            out += ["--sizes", "all"]
            continue
        out.append(a)
        i += 1
    if out[0] == "sim2real":  # tiny fits and training (the last of a repeated option wins)
        out += ["--fit-evaluations", "3", "--fit-trajectories", "2", "--set", TINY_TRAINING]
    if out[0] == "plan":
        out += TINY_PLAN
    if out[0] == "evaluate":
        out += ["--videos", "0"]
    return out


def test_the_documented_real_push_commands_run_as_written(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    ran = []
    for section in SECTIONS:
        commands = _commands(section)
        assert commands, f"{DOC.name}: no commands under {section!r}"
        for argv in commands:
            small = _small(argv)
            assert main(small) == 0, f"failed as documented: fignet-gym {shlex.join(argv)}"
            ran.append(small[0])
    assert ran.count("sim2real") >= 4 and "import-mit" in ran and "check-mit" in ran
    assert "sim2real-compare" in ran and (tmp_path / "runs" / "s2r_abs_compare" / "compare.md").is_file()
    assert ran.count("evaluate") >= 3 and ran.count("plan") == 2
    assert (tmp_path / "runs" / "s2r_abs" / "table.md").is_file()
    assert (tmp_path / "runs" / "s2r_abs_scratch" / "results.json").is_file()
