"""The benchmark commands run from the command line and report what they measure."""

from __future__ import annotations

import re

import pytest

from fignet_gym.cli import main


def test_bench_collision_finds_more_contacts_at_a_larger_radius(capsys: pytest.CaptureFixture) -> None:
    assert main(["bench-collision", "--radii", "0.005", "0.02", "--repeats", "1"]) == 0
    counts: dict[str, list[int]] = {}
    for name, n in re.findall(r"^(\w+).*?d_c [\d.]+:\s+(\d+) contacts", capsys.readouterr().out, re.M):
        counts.setdefault(name, []).append(int(n))
    assert set(counts) == {"pile", "push"}
    assert all(0 < a < b for a, b in counts.values())  # every pair within 5 mm is within 20 mm


def test_bench_envs_rows_and_a_bad_option(capsys: pytest.CaptureFixture) -> None:
    assert main(["bench-envs", "--envs", "push", "--dynamics", "mujoco", "--nums", "2",
                 "--seconds", "0.1"]) == 0
    rows = re.findall(r"^\| push \| mujoco \| (single|vector) \| (\d+) \| ([\d.]+) \|",
                      capsys.readouterr().out, re.M)
    assert [(m, int(n)) for m, n, _ in rows] == [("single", 1), ("vector", 2)]
    assert all(float(r) > 0 for *_, r in rows)
    assert main(["bench-envs", "--bogus"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == "fignet-gym bench-envs: error: unrecognized arguments: --bogus"
