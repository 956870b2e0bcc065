"""The library shows its structure at the top of each file: an import inside a function body is
there on purpose, and says why on its line or the line above (``# deferred: <reason>``: a heavy or
optional stack that some importers must not pay for, an import cycle, a PEP 562 lazy name). The
simulator core and the trainer have none at all, and the simulator's modules import each other
without a cycle."""

import ast
from pathlib import Path

import pytest

CHECKOUT = Path(__file__).resolve().parents[1]
ROOT = CHECKOUT / "fignet_gym"
#: Every module of the library: the core, and the env and agent packages installed beside it.
LIBRARY = sorted(p for name in ("fignet_gym", "envs", "agents") for p in (CHECKOUT / name).rglob("*.py"))
#: What marks a function-level import as meant; the reason follows it on the same line.
DEFERRED = "# deferred:"
TOP_LEVEL_ONLY = sorted([*(ROOT / "simulator").glob("*.py"), ROOT / "pretrained" / "__init__.py",
                         *(ROOT / "train" / name for name in ("config.py", "sampling.py", "warmstart.py",
                                                             "trainer.py", "real.py", "ship.py",
                                                             "synthetic.py", "synthetic_push.py"))])


def _says_why(line: str) -> bool:
    """``line`` carries a ``# deferred: <reason>`` comment with a reason."""
    at = line.find(DEFERRED)
    return at >= 0 and bool(line[at + len(DEFERRED):].strip())


def _function_imports(source: str, where: str = "", allow_deferred: bool = False) -> list[str]:
    """``where:line`` of each import inside a function body of ``source``; with
    ``allow_deferred``, only those whose lines, or the comment line just above, do not say why
    (:func:`_says_why`)."""
    lines = source.splitlines()
    found = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for inner in ast.walk(node):
                if not isinstance(inner, (ast.Import, ast.ImportFrom)):
                    continue
                own = lines[inner.lineno - 1:inner.end_lineno]
                above = lines[inner.lineno - 2].strip() if inner.lineno > 1 else ""
                if allow_deferred and (any(_says_why(t) for t in own)
                                       or (above.startswith("#") and _says_why(above))):
                    continue
                found.add(inner.lineno)
    return [f"{where}:{n}" for n in sorted(found)]


@pytest.mark.parametrize("path", TOP_LEVEL_ONLY, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_no_import_inside_a_function(path: Path) -> None:
    assert _function_imports(path.read_text(), path.name) == []


@pytest.mark.parametrize("path", LIBRARY, ids=lambda p: str(p.relative_to(CHECKOUT)))
def test_a_function_level_import_says_why_it_is_deferred(path: Path) -> None:
    """Anywhere in the library, an import inside a function carries ``# deferred: <reason>``."""
    where = str(path.relative_to(CHECKOUT))
    bare = _function_imports(path.read_text(), where, allow_deferred=True)
    assert not bare, (f"{', '.join(bare)}: move these imports to the top of the file, or say why "
                      f"they wait ('{DEFERRED} <reason>' on the line or the line above)")


def test_the_import_check_sees_the_whole_library_and_a_bare_import() -> None:
    names = {str(p.relative_to(CHECKOUT)) for p in LIBRARY}
    assert {"fignet_gym/cli/__init__.py", "fignet_gym/cli/data.py", "envs/__init__.py", "envs/push.py",
            "agents/__init__.py", "agents/ppo/run.py"} <= names
    code = ("import os\n\n\ndef f():\n    import json\n\n    # deferred: a reason\n    import math\n"
            "    import sys  # deferred: a reason\n    import re  # deferred:\n\n\n"
            "class A:\n    def g(self):\n        from pathlib import Path\n")
    assert _function_imports(code, "m.py", allow_deferred=True) == ["m.py:5", "m.py:10", "m.py:15"]
    assert _function_imports(code, "m.py") == ["m.py:5", "m.py:8", "m.py:9", "m.py:10", "m.py:15"]


def test_simulator_modules_import_each_other_without_a_cycle() -> None:
    graph = {}
    for path in (ROOT / "simulator").glob("*.py"):
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("fignet_gym.simulator."):
                deps.add(node.module.rsplit(".", 1)[1])
        graph[path.stem] = deps
    assert "model" in graph["checkpoint"]  # the parse sees the imports
    done: set[str] = set()

    def visit(name: str, stack: tuple[str, ...]) -> None:
        assert name not in stack, f"import cycle: {' -> '.join((*stack, name))}"
        if name in done:
            return
        for dep in graph.get(name, ()):
            visit(dep, (*stack, name))
        done.add(name)

    for name in graph:
        visit(name, ())


def test_the_planners_load_no_rl_stack() -> None:
    """``import fignet_gym.agents`` (the planners) loads neither stable-baselines3 nor
    TensorBoard; the PPO names it re-exports come from :mod:`fignet_gym.agents.ppo` on first use."""
    import subprocess
    import sys

    code = ("import sys, fignet_gym.agents as a; "
            "bad = [m for m in ('stable_baselines3', 'tensorboard', 'torch.utils.tensorboard') "
            "if m in sys.modules]; assert not bad, bad; "
            "from fignet_gym.agents import load_policy; import fignet_gym.agents.ppo as p; "
            "assert load_policy is p.load_policy and 'stable_baselines3' in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_a_second_copy_on_the_path_is_refused_in_one_line(tmp_path: Path) -> None:
    """A copy of the core first on ``PYTHONPATH`` with this checkout installed: ``fignet_gym``
    comes from the copy, ``fignet_gym.envs`` / ``.agents`` from the installed tree. The import
    says so (MixedInstallError naming both) instead of mixing them; the unit check accepts a
    checkout's and a wheel's layout."""
    import shutil
    import subprocess
    import sys

    import fignet_gym

    shutil.copytree(ROOT, tmp_path / "fignet_gym", ignore=shutil.ignore_patterns("*.pt", "*.zip",
                                                                                "__pycache__"))
    for name in ("envs", "agents"):
        run = subprocess.run([sys.executable, "-c", f"import fignet_gym.{name}"], capture_output=True,
                             cwd=tmp_path,
                             text=True, env={**__import__("os").environ, "PYTHONPATH": str(tmp_path)})
        assert run.returncode != 0
        last = run.stderr.strip().splitlines()[-1]
        assert last.startswith("fignet_gym.MixedInstallError:") and str(tmp_path) in last, last
    core = Path(fignet_gym.__file__).resolve().parent
    fignet_gym.check_same_install(str(core.parent / "envs" / "__init__.py"), "envs")  # a checkout
    fignet_gym.check_same_install(str(core / "envs" / "__init__.py"), "envs")  # a wheel
    with pytest.raises(fignet_gym.MixedInstallError, match="two copies"):
        fignet_gym.check_same_install(str(tmp_path / "envs" / "__init__.py"), "envs")
