"""The benchmark commands run from the command line and report what they measure."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterator

import pytest

from fignet_gym.cli import main


def test_bench_collision_finds_more_contacts_at_a_larger_radius(capsys: pytest.CaptureFixture) -> None:
    assert main(["bench", "collision", "--radii", "0.005", "0.02", "--repeats", "1"]) == 0
    counts: dict[str, list[int]] = {}
    for name, n in re.findall(r"^(\w+).*?d_c [\d.]+:\s+(\d+) contacts", capsys.readouterr().out, re.M):
        counts.setdefault(name, []).append(int(n))
    assert set(counts) == {"pile", "push"}
    assert all(0 < a < b for a, b in counts.values())  # every pair within 5 mm is within 20 mm


def test_bench_envs_rows_and_a_bad_option(capsys: pytest.CaptureFixture) -> None:
    assert main(["bench", "envs", "--envs", "push", "--dynamics", "mujoco", "--nums", "2",
                 "--seconds", "0.1"]) == 0
    rows = re.findall(r"^\| push \| mujoco \| (single|vector) \| (\d+) \| ([\d.]+) \|",
                      capsys.readouterr().out, re.M)
    assert [(m, int(n)) for m, n, _ in rows] == [("single", 1), ("vector", 2)]
    assert all(float(r) > 0 for *_, r in rows)
    with pytest.raises(SystemExit) as exit_:
        main(["bench", "envs", "--bogus"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == "fignet-gym: error: unrecognized arguments: --bogus"


@pytest.mark.parametrize("sub, args, key", [
    ("step", ["--batch", "1"], "step"),
    ("shipped", ["--batch", "1"], "shipped"),
    ("rollout", ["--batch", "1", "--steps", "2"], "rollout"),
    ("ppo", ["--setting", "2", "4", "8", "1"], "ppo"),
])
def test_each_bench_subcommand_writes_its_figures(sub: str, args: list[str], key: str, tmp_path) -> None:
    out = tmp_path / "bench.json"
    assert main(["bench", sub, *args, "--repeats", "1", "--threads", "1", "--json", str(out)]) == 0
    times = list(_timings(json.loads(out.read_text())[key]))
    assert times and all(math.isfinite(t) and t > 0 for t in times)


#: Key endings of the benchmarks' times and rates.
TIMED = ("_ms", "seconds", "_per_s", "per_cpu_second", "_per_scene", "gflops")


def _timings(tree: object, name: str = "") -> Iterator[float]:
    """Every number in a benchmark's JSON whose key says it is a time or a rate."""
    if isinstance(tree, dict):
        for k, v in tree.items():
            yield from _timings(v, k)
    elif isinstance(tree, list):
        for v in tree:
            yield from _timings(v, name)
    elif isinstance(tree, (int, float)) and not isinstance(tree, bool) and (
            name.endswith(TIMED) or name in ("total", "network")):
        yield float(tree)
