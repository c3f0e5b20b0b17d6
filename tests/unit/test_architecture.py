"""The layers hold: no import cycles between files, no project imports hidden inside functions (except in
command-line entry files, where lazy imports keep start-up fast), and modules one can read in one sitting.
The layer contract itself is checked by `lint-imports` (pyproject.toml), which .ci/run runs."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import grimp
import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("reconswarm", "agent", "simworld", "monitor", "reconswarm_bringup")
ENTRY_FILES = ("cli.py", "__main__.py")


def _sources() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def test_no_import_cycles_between_files():
    g = grimp.build_graph(*PACKAGES)
    cycles = sorted({tuple(sorted((a, b))) for a in g.modules for b in g.find_modules_directly_imported_by(a)
                     if g.chain_exists(importer=b, imported=a)})
    assert cycles == []


def _nested_project_imports(path: Path) -> list[str]:
    tree = ast.parse(path.read_text())
    found = []
    for fn in ast.walk(tree):
        if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        for node in ast.walk(fn):
            if isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            found += [f"{path.relative_to(ROOT)}:{node.lineno} {n}" for n in names if n.split(".")[0] in PACKAGES]
    return found


def test_no_function_level_project_imports_outside_entry_files():
    hidden = [hit for p in _sources() if not p.name.startswith(ENTRY_FILES) and not p.name.startswith("cli_")
              for hit in _nested_project_imports(p)]
    assert hidden == []


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_modules_are_readable_in_one_sitting(path: Path):
    assert len(path.read_text().splitlines()) < 400


def _layer_map() -> str:
    """The layer map of docs/architecture.md: the code block under its "## Layers" heading."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    return text.split("## Layers", 1)[1].split("```", 2)[1]


def _unmapped() -> list[str]:
    block, missing = _layer_map(), []
    # reconswarm/'s subpackages: one entry each (`   net/  ...` up to the next entry), naming its modules as words;
    # a subpackage's own subpackages indented two more (`     wire/  ...`, its entry `net/wire`).
    entries: dict[str, str] = {}
    top = current = None
    for line in block.split(" reconswarm/ ", 1)[1].splitlines():
        head = re.match(r"^( {3}| {5})(\w+)/\s", line)
        if head and len(head.group(1)) == 3:
            top = current = head.group(2)
        elif head:
            current = f"{top}/{head.group(2)}"
        if current is not None:
            entries[current] = entries.get(current, "") + line + "\n"
    for p in _sources():
        rel = p.relative_to(ROOT)
        if p.name.startswith("__"):
            continue
        if rel.parts[0] == "reconswarm" and len(rel.parts) >= 3:
            if not re.search(rf"\b{p.stem}\b", entries.get("/".join(rel.parts[1:-1]), "")):
                missing.append(str(rel))
        elif not re.search(rf"\b{re.escape(p.name)}\b", block):
            missing.append(str(rel))
    return missing


def test_the_layer_map_names_every_module():
    assert _unmapped() == []
