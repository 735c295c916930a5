"""The package's structure (docs/design.md, "Package layout"): no import cycle, small modules,
and the commands that need no solver do not import it."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "woundsweep"
MAX_LINES = 500
HEAVY = ("dolfinx", "ufl", "petsc4py", "gmsh", "xgboost", "matplotlib")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path, *, everywhere: bool) -> set[str]:
    """The woundsweep names ``path`` imports: each module, and each ``module.name`` of a
    from-import; at module level, or ``everywhere`` (inside functions too)."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text())
    found: set[str] = set()
    for node in ast.walk(tree) if everywhere else tree.body:
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.startswith("woundsweep"))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                target = f"{base}.{node.module}" if node.module else base
            else:
                target = node.module or ""
            if not target.startswith("woundsweep"):
                continue
            found.add(target)
            found.update(f"{target}.{a.name}" for a in node.names)
    return found


def _module_imports(path: Path) -> set[str]:
    """The woundsweep modules ``path`` imports when it is loaded (module level only: imports
    inside functions run later and cannot form a cycle at import time)."""
    name = _module_name(path)
    found = _imports(path, everywhere=False)
    # Importing a.b.c runs the __init__ of a and a.b first, unless they are packages of this
    # module (already being imported when it runs).
    parents = {m.rsplit(".", k)[0] for m in found for k in range(1, m.count(".") + 1)}
    return found | {p for p in parents if not name.startswith(p + ".")}


def _graph() -> dict[str, set[str]]:
    modules = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    return {name: _module_imports(p) & set(modules) - {name} for name, p in modules.items()}


def test_import_graph_has_no_cycle() -> None:
    graph = _graph()
    assert "woundsweep.physics.stages" in graph and graph["woundsweep.physics.stages"]
    state: dict[str, int] = {}  # 1 on the stack, 2 done

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycle = path[path.index(nxt) :] + [nxt] if nxt in path else [node, nxt]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if nxt not in state:
                visit(nxt, [*path, nxt])
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [name])


# The layers, bottom first (docs/design.md, "Layers"): a module imports from its own package
# or from a lower layer, never sideways or up. Top-level modules sit in the layer named here.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("core", "__init__"),
    ("config",),
    ("mesh", "contact", "solver", "store"),
    ("physics",),
    ("execution", "studies", "analysis", "viz", "verify"),
    ("cli", "clitypes", "commands", "__main__"),
)
RANK = {unit: rank for rank, units in enumerate(LAYERS) for unit in units}


def _unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def test_imports_run_down_the_layers() -> None:
    modules = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    assert {_unit(m) for m in modules} - {"__version__"} <= set(RANK)
    upward = []
    for name, path in sorted(modules.items()):
        for target in sorted(_imports(path, everywhere=True)):
            src, dst = _unit(name), _unit(target)
            # The root package holds only `__version__`, which every layer may read.
            if target == "woundsweep" or dst == "__version__" or src == dst:
                continue
            if RANK[dst] >= RANK[src] and not (RANK[src] == RANK["cli"] == RANK[dst]):
                upward.append(f"{name} -> {target}")
    assert upward == []


def test_modules_are_small() -> None:
    sizes = {_module_name(p): len(p.read_text().splitlines()) for p in PACKAGE.rglob("*.py")}
    assert len(sizes) > 40
    assert {m: n for m, n in sizes.items() if n > MAX_LINES} == {}


def test_commands_without_the_solver_do_not_import_it(tmp_path: Path) -> None:
    """`--help`, `generate` and `status` load neither DOLFINx nor gmsh, XGBoost or matplotlib."""
    path = PACKAGE.parent / "sweeps" / "demo.yaml"
    run = tmp_path / "run"
    code = (
        "import json, sys\n"
        "from woundsweep.cli import main\n"
        f"codes = [main(['--help']), main(['generate', {str(path)!r}, '--out', {str(run)!r}]),"
        f" main(['status', {str(run)!r}])]\n"
        f"print(json.dumps([codes, sorted(m for m in {HEAVY!r} if m in sys.modules)]))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    ).stdout
    codes, loaded = json.loads(out.strip().splitlines()[-1])
    assert codes == [0, 0, 0]
    assert loaded == []
