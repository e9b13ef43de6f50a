"""The package's import structure: every module imports alone, and no two import each other.

Both checks read ``src/qdil`` itself. The static one counts every ``import`` statement that
names a qdil module: at module level, inside functions and under ``if TYPE_CHECKING:``,
since a circle of any of them couples the modules just the same (issue 13: ``run.py`` ↔
``qd/loop.py`` ↔ ``qd/checkpoint.py`` ↔ ``tracking.py`` ↔ ``demos/io.py``). Dynamic imports
(``importlib.import_module``, the reward registry's plugin discovery) are not statements and
are not counted.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"


def modules() -> dict[str, Path]:
    """Every module of the package, by dotted name (packages by their ``__init__``)."""
    found = {}
    for path in sorted((SRC / "qdil").rglob("*.py")):
        parts = path.relative_to(SRC).with_suffix("").parts
        found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def imported(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The qdil modules that ``name`` imports anywhere in its source."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            candidates = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the package, up level - 1 packages
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            # "from pkg import mod" imports the module pkg.mod; "from mod import f", mod
            candidates = [f"{base}.{alias.name}" for alias in node.names] + [base]
        else:
            continue
        for candidate in candidates:
            while candidate and candidate not in known:  # a name inside a module
                candidate = candidate.rpartition(".")[0]
            if candidate and candidate != name:
                targets.add(candidate)
                if isinstance(node, ast.ImportFrom):
                    break  # the first match is the most specific module
    return targets


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of ``graph`` as [a, b, ..., a], or None if it is acyclic (depth-first)."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt) :], nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def test_no_two_modules_import_each_other_directly_or_through_others() -> None:
    known = modules()
    graph = {name: imported(name, path, known) for name, path in known.items()}
    assert graph["qdil.qd.loop"], "the parser found no imports: it is broken, not the package"
    cycle = find_cycle(graph)
    assert cycle is None, "import circle: " + " -> ".join(cycle or [])


def test_the_cycle_finder_finds_a_cycle_through_others() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert find_cycle(graph) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


# Import each module in a process that has imported no qdil module before: a fork of one
# interpreter that loaded only the third-party libraries (torch alone takes seconds to
# import, so one fresh interpreter per module would take minutes). Circles or missing
# imports between qdil modules show as they would in a fresh `python -c "import ..."`.
SCRIPT = """
import importlib, os, sys, traceback
for heavy in ("numpy", "torch", "lightning", "ribs", "gymnasium", "mujoco", "scipy",
              "pandas", "matplotlib", "yaml", "jsonargparse", "numba", "tqdm"):
    try:
        importlib.import_module(heavy)
    except ImportError:
        pass
assert not [m for m in sys.modules if m == "qdil" or m.startswith("qdil.")]
failed = []
for name in sys.argv[1:]:
    pid = os.fork()
    if pid == 0:
        try:
            importlib.import_module(name)
        except BaseException:
            traceback.print_exc()
            os._exit(1)
        os._exit(0)
    _, status = os.waitpid(pid, 0)
    if status:
        failed.append(name)
print("FAILED:", " ".join(failed))
sys.exit(1 if failed else 0)
"""


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")
def test_every_module_imports_alone() -> None:
    names = sorted(modules())
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, *names],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        env={**os.environ, "MPLBACKEND": "Agg"},
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    assert done.stdout.strip() == "FAILED:"


# the floors of docs/concepts, bottom up: plain data and files; physics, RL, demonstrations,
# reward models and the seats' contracts; the recipe's sections; the QD loop; what loads
# recipes, builds, scores, records, sweeps and exports runs; the commands (and the package's
# root, which registers the tasks). Every module sits on one.
FLOORS = (
    (
        "qdil.data",
        "qdil.devices",
        "qdil.files",
        "qdil.numerics",
        "qdil.provenance",
        "qdil.reductions",
        "qdil.threads",
        "qdil.timing",
        "qdil.upgrades",
    ),
    ("qdil.envs", "qdil.rl", "qdil.executors", "qdil.demos", "qdil.rewards", "qdil.seats"),
    ("qdil.config",),
    ("qdil.qd",),
    (
        "qdil.recipe",
        "qdil.recipe_load",
        "qdil.recipe_schema",
        "qdil.recipe_parts",
        "qdil.experiment",
        "qdil.finished_run",
        "qdil.run_names",
        "qdil.run",
        "qdil.evaluation",
        "qdil.tracking",
        "qdil.export",
        "qdil.sweeps",
    ),
    ("qdil.cli", "qdil"),
)


def _floor_of(name: str) -> int | None:
    """The floor of module ``name``: its longest matching package or module."""
    matches = [
        (len(package), level)
        for level, floor in enumerate(FLOORS)
        for package in floor
        if name == package or name.startswith(f"{package}.")
    ]
    return max(matches)[1] if matches else None


def test_every_module_sits_on_a_floor() -> None:
    assert [name for name in modules() if _floor_of(name) is None] == []


def test_no_floor_imports_from_a_floor_above() -> None:
    known = modules()
    reaching_up = {}
    for name, path in known.items():
        level = _floor_of(name)
        up = sorted(t for t in imported(name, path, known) if (_floor_of(t) or 0) > (level or 0))
        if up:
            reaching_up[name] = up
    assert reaching_up == {}


def test_the_package_map_names_the_floors_as_they_are() -> None:
    """docs/concepts/package.md's table lists each floor's modules, bottom up, as FLOORS."""
    import re

    page = (SRC.parent / "docs" / "concepts" / "package.md").read_text()
    rows = [line for line in page.splitlines() if re.match(r"\| \d\. ", line)]
    named = [set(re.findall(r"`(qdil[\w.]*)`", row.split("|")[2])) for row in rows]
    assert named == [set(floor) for floor in FLOORS]
