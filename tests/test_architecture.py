"""The shape of the package: no import circles, no method reaching into the harness, and every
package saying what it is for."""
from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _import_graph():
    spec = importlib.util.spec_from_file_location("import_cycles",
                                                  ROOT / "scripts" / "import_cycles.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    return tool, tool.graph(ROOT)


def test_no_import_cycles():
    tool, graph = _import_graph()
    assert tool.cycles(graph) == []


#: The rooms of the package, top to bottom (docs/architecture.md, "Rooms"): a module may import
#: its own room and the rooms below its layer, never a room above it or beside it.
LAYERS = (("__main__",), ("cli",), ("studies",), ("speed", "stress", "learn"), ("run",), ("report",),
          ("registry",), ("plugins",), ("synthetic", "datasets"), ("methods", "metrics"),
          ("denoiser", "device", "data", "io", "memory", "options", "resolution", "errors"))


def room_shapes(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "dbench"


def test_imports_flow_down_the_rooms():
    _, graph = _import_graph()
    layer = {room: i for i, rooms in enumerate(LAYERS) for room in rooms}
    bad = []
    for m, targets in graph.items():
        a = room_shapes(m)
        for t in targets:
            b = room_shapes(t)
            if a == b or a == "dbench":
                continue
            assert a in layer and b in layer, f"{m} -> {t}: a room no layer names"
            base = len(LAYERS) - 1  # the core modules import one another (no cycles, above)
            if layer[a] > layer[b] or (layer[a] == layer[b] != base):
                bad.append((m, t))
    assert sorted(bad) == []


def test_rooms_hold_at_most_15_modules_side_by_side():
    for folder in [ROOT / "dbench"] + sorted(p for p in (ROOT / "dbench").rglob("*")
                                               if p.is_dir() and p.name != "__pycache__"):
        mods = [p for p in folder.glob("*.py") if p.name != "__init__.py"]
        assert len(mods) <= 15, (folder, len(mods))


def test_every_package_has_a_docstring():
    for init in sorted((ROOT / "dbench").rglob("__init__.py")):
        assert ast.get_docstring(ast.parse(init.read_text(encoding="utf-8"))), init


def test_no_file_over_500_lines():
    long = [(str(p.relative_to(ROOT)), n) for base in ("dbench", "tests", "scripts")
            for p in sorted((ROOT / base).rglob("*.py"))
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > 500]
    assert long == []


def test_no_module_imports_another_packages_private_name():
    """``from X import _name`` only inside X's own package (dbench/ and its subpackages)."""
    import ast
    bad = []
    for p in sorted((ROOT / "dbench").rglob("*.py")):
        here = p.relative_to(ROOT).with_suffix("").parts
        package = here[:-1] if here[-1] != "__init__" else here[:-1]
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and any(a.name.startswith("_") and
                                                        not a.name.startswith("__")
                                                        for a in node.names):
                if node.level:
                    base = package[:len(package) - node.level + 1]
                    target = base + tuple((node.module or "").split(".")) if node.module else base
                else:
                    target = tuple((node.module or "").split("."))
                # the target's package (the module itself when it is a package)
                if target[:len(package)] != package:
                    bad.append(f"{p.relative_to(ROOT)}: {ast.unparse(node)}")
    assert bad == [], "\n".join(bad)
