"""The simulator core and the trainer show their structure at the top of each file: no import
hides in a function body, and the simulator's modules import each other without a cycle."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "fignet_gym"
TOP_LEVEL_ONLY = sorted([*(ROOT / "simulator").glob("*.py"), ROOT / "pretrained" / "__init__.py",
                         *(ROOT / "train" / name for name in ("config.py", "sampling.py", "warmstart.py",
                                                             "trainer.py", "real.py", "ship.py",
                                                             "synthetic.py", "synthetic_push.py"))])


def _function_imports(path: Path) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for inner in ast.walk(node):
                if isinstance(inner, (ast.Import, ast.ImportFrom)):
                    found.append(f"{path.name}:{inner.lineno}")
    return found


@pytest.mark.parametrize("path", TOP_LEVEL_ONLY, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_no_import_inside_a_function(path: Path) -> None:
    assert _function_imports(path) == []


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
