"""The layout docs/design.md draws: which package may import which, no import circle, the size limits.

The import graph is read here from the source with :mod:`ast` (every ``import``
and ``from ... import``, also those inside functions), independently of how the
packages import each other at run time; the rule is read from the table between
``<!-- layout-map -->`` markers in docs/design.md.
"""

from __future__ import annotations

import ast
import re
from collections import Counter
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("pris_cosim", "estimation")
#: ``python -m pris_cosim`` runs the command line: the package's ``__main__`` belongs to it.
OWNED_ELSEWHERE = {"pris_cosim.__main__": "pris_cosim.cli"}
MAX_MODULES_PER_FOLDER = 20
MAX_LINES = 1000
MAX_PREFIX_FAMILY = 2


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for pkg in PACKAGES for p in sorted((REPO / pkg).rglob("*.py"))}


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The project modules ``name`` imports (a ``from P import m`` of a submodule counts as ``P.m``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    base = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = base[: len(base) - node.level + 1]
                mod = ".".join(anchor + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            for alias in node.names:
                full = f"{mod}.{alias.name}"
                out.add(full if full in known else mod)
        elif isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
    return {m for m in out if m in known and m != name}


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    known = set(mods)
    return {name: _imports(name, path, known) for name, path in mods.items()}


def _script_graph() -> dict[str, set[str]]:
    """The benchmarks' scripts, which import each other by name (their folder is on the path)."""
    scripts = {p.stem: p for p in sorted((REPO / "benchmarks").glob("*.py"))}
    return {f"benchmarks.{name}": {f"benchmarks.{m}" for m in _imports(name, path, set(scripts))}
            for name, path in scripts.items()}


def _layout_map() -> dict[str, set[str]]:
    text = (REPO / "docs" / "design.md").read_text(encoding="utf-8")
    block = text.split("<!-- layout-map -->", 1)[1].split("<!-- /layout-map -->", 1)[0]
    rows = [line for line in block.splitlines() if line.startswith("| `")]
    units = [re.findall(r"`([\w.]+)`", row.split("|")[1])[0] for row in rows]
    rule: dict[str, set[str]] = {}
    for unit, row in zip(units, rows):
        allowed = row.split("|")[3]
        names: set[str] = set()
        if "every package" in allowed:
            names.update(units)
        for top in re.findall(r"every `([\w.]+)` package", allowed):
            names.update(u for u in units if u == top or u.startswith(top + "."))
        names.update(re.findall(r"(?<!every )`([\w.]+)`", allowed))
        rule[unit] = names - {unit}
    return rule


def _unit(module: str, units: set[str]) -> str | None:
    module = OWNED_ELSEWHERE.get(module, module)
    best = None
    for u in units:
        if (module == u or module.startswith(u + ".")) and (best is None or len(u) > len(best)):
            best = u
    return best


def test_the_map_names_every_package_and_its_rule_holds() -> None:
    rule = _layout_map()
    units = set(rule)
    assert {"pris_cosim", "estimation", "pris_cosim.circuits", "estimation.diagnosis"} <= units
    bad = []
    for module, deps in _graph().items():
        u = _unit(module, units)
        assert u is not None, f"{module} belongs to no package of the map in docs/design.md"
        for d in deps:
            v = _unit(d, units)
            if v != u and v not in rule[u]:
                bad.append(f"{module} ({u}) imports {d} ({v})")
    assert not bad, "imports the map does not allow:\n" + "\n".join(sorted(bad))


def test_estimation_builds_on_pris_cosim_never_the_reverse() -> None:
    back = [(m, d) for m, deps in _graph().items() if m.startswith("pris_cosim") for d in deps
            if d.startswith("estimation")]
    assert not back


def test_no_import_circle_between_modules() -> None:
    graph = {**_graph(), **_script_graph()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    circles: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                circles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert not circles, f"import circles: {circles}"


def _folders() -> list[Path]:
    roots = [REPO / p for p in (*PACKAGES, "tests", "benchmarks", "scripts")]
    return [d for r in roots for d in [r, *sorted(r.rglob("*"))] if d.is_dir() and "__pycache__" not in d.parts
            and not any(part.startswith(".") for part in d.relative_to(REPO).parts)]


@pytest.mark.parametrize("limit", [MAX_MODULES_PER_FOLDER])
def test_no_folder_holds_more_than_twenty_modules(limit: int) -> None:
    crowded = {str(d.relative_to(REPO)): n for d in _folders()
               if (n := len([p for p in d.glob("*.py") if p.name != "__init__.py"])) > limit}
    assert not crowded, crowded


def test_no_module_over_a_thousand_lines() -> None:
    long = {str(p.relative_to(REPO)): n for d in _folders() for p in d.glob("*.py")
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert not long, long


def test_no_family_of_three_modules_sharing_a_name_prefix() -> None:
    families = {}
    for pkg in PACKAGES:
        for d in [REPO / pkg, *sorted((REPO / pkg).rglob("*"))]:
            if not d.is_dir() or "__pycache__" in d.parts:
                continue
            stems = [p.stem for p in d.glob("*.py") if not p.stem.startswith("__")]
            count = Counter(s.strip("_").split("_")[0] for s in stems)
            families.update({f"{d.relative_to(REPO)}/{k}_*": n for k, n in count.items() if n > MAX_PREFIX_FAMILY})
    assert not families, families
