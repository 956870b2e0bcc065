"""The documentation against the repository: links and paths exist, the README stays a short guide
that starts with the two set-up commands, and the layer table of docs/architecture.md is what the
code imports."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
ARCHITECTURE = ROOT / "docs" / "architecture.md"
DOCS = sorted([README, *(ROOT / "docs").glob("*.md"), *(ROOT / "fignet_gym" / "pretrained").glob("*.md"),
               ROOT / "experiments" / "README.md"])

FENCE = re.compile(r"^```.*?^```", re.S | re.M)
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
CODE_SPAN = re.compile(r"`([^`\n]+)`")
# Repository paths written in code spans start with one of these folders (run, data and output
# folders such as runs/ and data/ are the user's, not the repository's).
ENV_ID = re.compile(r"-v\d+$")  # fignet_gym/Push-v2 is an environment id, not a path
TOP = ("fignet_gym/", "docs/", "envs/", "agents/", "examples/", "scripts/", "tests/", "experiments/")


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    text = FENCE.sub("", path.read_text())
    return {_slug(m.group(1)) for m in re.finditer(r"^#+\s+(.*)$", text, re.M)}


def _links(path: Path) -> list[str]:
    return LINK.findall(FENCE.sub("", path.read_text()))


def test_slug_matches_github() -> None:
    assert _slug("Pushing: the rotation gap") == "pushing-the-rotation-gap"
    assert _slug("`SimulatorConfig`") == "simulatorconfig"
    assert _slug("Speed") == "speed"


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(doc: Path) -> None:
    missing = []
    for target in _links(doc):
        if re.match(r"^[a-z]+:", target):  # http:, https:, mailto:
            continue
        file_part, _, anchor = target.partition("#")
        dest = (doc.parent / file_part).resolve() if file_part else doc
        if not dest.exists():
            missing.append(target)
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            missing.append(f"{target} (no such heading)")
    assert not missing, f"{doc.name}: broken links {missing}"


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_repository_paths_exist(doc: Path) -> None:
    text = doc.read_text()
    paths = {tok for span in CODE_SPAN.findall(text) for tok in span.split() if tok.startswith(TOP)}
    for block in re.findall(r"^```.*?$(.*?)^```", text, re.S | re.M):
        paths |= {tok for tok in re.split(r"[\s=\"'(),]+", block) if tok.startswith(TOP)}
    paths = {p.rstrip(".,:;") for p in paths if not ENV_ID.search(p)}
    missing = sorted(p for p in paths if not _node_exists(p))
    assert not missing, f"{doc.name}: no such file {missing}"


def _node_exists(ref: str) -> bool:
    """A path, or a pytest node ``tests/x.py::test_y`` whose file defines that test."""
    path, _, name = ref.partition("::")
    if not (ROOT / path).exists():
        return False
    return not name or re.search(rf"^def {re.escape(name)}\(", (ROOT / path).read_text(), re.M) is not None


def test_readme_is_a_short_guide_starting_with_the_two_commands() -> None:
    text = README.read_text()
    assert len(text.splitlines()) <= 250
    first_block = re.search(r"^```(?:bash|sh)?\n(.*?)^```", text, re.S | re.M)
    assert first_block, "README has no code block"
    commands = [line.split("#")[0].strip() for line in first_block.group(1).splitlines()]
    commands = [c for c in commands if c]
    assert commands == ["bash scripts/demo.sh", "bash scripts/test.sh"]
    for c in commands:
        assert (ROOT / c.split()[1]).is_file()
    # Nothing before that block but the title and the description: no other command comes first.
    assert "```" not in text[: first_block.start()]


# ----------------------------------------------------------------------------- layers
def _layer_of_file(path: Path) -> str:
    rel = path.relative_to(ROOT).parts
    if rel[0] in ("envs", "agents"):
        return rel[0]
    if len(rel) == 2:  # a module directly in fignet_gym/
        stem = Path(rel[1]).stem
        return {"__init__": "fignet_gym", "__main__": "cli"}.get(stem, stem)
    return rel[1]


def _layer_of_module(name: str) -> str:
    parts = name.split(".")
    if parts[0] != "fignet_gym":
        raise ValueError(name)
    if len(parts) == 1:
        return "fignet_gym"
    return "cli" if parts[1] == "__main__" else parts[1]


def _imports(path: Path) -> list[str]:
    """Every module a file imports, at any depth (lazy imports inside functions included)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                raise AssertionError(f"{path}: relative import (the house style is absolute)")
            out.append(node.module or "")
    return out


def _source_files() -> list[Path]:
    return sorted(p for d in ("fignet_gym", "envs", "agents") for p in (ROOT / d).rglob("*.py"))


def _layer_table() -> dict[str, set[str]]:
    """``docs/architecture.md``'s table: layer -> the layers it may import."""
    known = {_layer_of_file(p) for p in _source_files()}
    table: dict[str, set[str]] = {}
    section = ARCHITECTURE.read_text().split("## Layers", 1)[1].split("\n## ", 1)[0]
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 2:
            continue
        layers = [t for t in CODE_SPAN.findall(cells[0]) if t in known]
        allowed = {t for t in CODE_SPAN.findall(cells[1]) if t in known}
        for layer in layers:
            table[layer] = allowed
    return table


def test_layer_table_covers_every_package() -> None:
    table = _layer_table()
    assert {_layer_of_file(p) for p in _source_files()} == set(table)


def test_code_imports_only_what_the_layer_table_allows() -> None:
    table = _layer_table()
    bad = []
    for path in _source_files():
        src = _layer_of_file(path)
        for mod in _imports(path):
            if mod.split(".")[0] != "fignet_gym":
                continue
            dst = _layer_of_module(mod)
            if dst != src and dst not in table[src]:
                bad.append(f"{path.relative_to(ROOT)} ({src}) imports {mod} ({dst})")
    assert not bad, "\n".join(bad)


def test_rl_stack_only_where_the_table_allows() -> None:
    gym_layers = {"registration", "envs", "agents", "tools"}
    sb3_files = {"envs/sb3.py"} | {str(p.relative_to(ROOT)) for p in (ROOT / "agents" / "ppo").glob("*.py")}
    bad = []
    for path in _source_files():
        rel = str(path.relative_to(ROOT))
        for mod in _imports(path):
            top = mod.split(".")[0]
            if top == "gymnasium" and _layer_of_file(path) not in gym_layers:
                bad.append(f"{rel} imports {mod}")
            if top == "stable_baselines3" and rel not in sb3_files:
                bad.append(f"{rel} imports {mod}")
    assert not bad, "\n".join(bad)


def _cli_examples(path: Path) -> list[str]:
    """``fignet-gym ...`` command lines of a document's code blocks (continuations joined)."""
    out = []
    for block in re.findall(r"^```(?:bash|sh)\n(.*?)^```", path.read_text(), re.S | re.M):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split(" #")[0].strip()
            if line.startswith("fignet-gym "):
                out.append(line)
    return out


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_cli_examples_parse(doc: Path) -> None:
    import shlex

    from fignet_gym.cli import build_parser

    parser = build_parser()
    bad = []
    for line in _cli_examples(doc):
        try:
            parser.parse_args(shlex.split(line)[1:])
        except SystemExit:
            bad.append(line)
    assert not bad, f"{doc.name}: commands that do not parse {bad}"


def test_readme_shows_cli_examples() -> None:
    assert len(_cli_examples(README)) >= 5


def test_cli_doc_lists_every_command_and_no_other() -> None:
    import argparse

    from fignet_gym.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    listed = re.findall(r"^\| `fignet-gym ([a-z0-9-]+)`", (ROOT / "docs" / "cli.md").read_text(), re.M)
    assert sorted(listed) == sorted(sub.choices)
