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


def test_methods_do_not_import_the_harness():
    _, graph = _import_graph()
    bad = sorted((m, t) for m, targets in graph.items() if m.startswith("dbench.methods")
                 for t in targets if t == "dbench.bench" or t.startswith("dbench.bench."))
    assert bad == []


def test_every_package_has_a_docstring():
    for init in sorted((ROOT / "dbench").rglob("__init__.py")):
        assert ast.get_docstring(ast.parse(init.read_text(encoding="utf-8"))), init
