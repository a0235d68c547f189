"""Import graph of the ``dbench`` package and its cycles.

    python scripts/import_cycles.py            # prints the cycles; exit status 1 when there are any

Every ``import`` / ``from ... import`` statement counts, and every ``importlib.import_module``
or ``__import__`` of a module named by a string constant, those inside functions included (a
function-level import that breaks a circle at run time is still a circle in the design); only
imports under ``if TYPE_CHECKING:`` are left out. An edge goes to the deepest module of the
package that the statement names (``from .x import y`` with ``y`` a submodule: ``x.y``). A cycle
is a strongly connected component of more than one module.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path


def modules(root: Path, package: str = "dbench") -> dict[str, Path]:
    """Dotted module name → file, for every ``.py`` file of ``root/package``."""
    out = {}
    for p in sorted((root / package).rglob("*.py")):
        if "__pycache__" in p.parts:
            continue
        parts = list(p.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _type_checking_only(tree: ast.AST) -> set[int]:
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for sub in node.body:
                skip.update(id(n) for n in ast.walk(sub))
    return skip


def imports(name: str, path: Path, mods: dict[str, Path]) -> set[str]:
    """The modules of ``mods`` that module ``name`` (file ``path``) imports."""
    tree = ast.parse(path.read_text(), str(path))
    skip = _type_checking_only(tree)
    here = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    out: set[str] = set()

    def add(target: str) -> None:
        parts = target.split(".")
        while parts:
            candidate = ".".join(parts)
            if candidate in mods:
                if candidate != name:
                    out.add(candidate)
                return
            parts.pop()

    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(alias.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[:len(here) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            for alias in node.names:
                sub = f"{mod}.{alias.name}"
                add(sub if sub in mods else mod)
        elif isinstance(node, ast.Call) and _dynamic_import(node):
            # importlib.import_module("dbench.x") / __import__("dbench.x"): an import all the
            # same, which a cycle through it must not hide behind
            add(node.args[0].value)
    return out


def _dynamic_import(node: ast.Call) -> bool:
    """A call importing a module named by a string constant: ``importlib.import_module(...)``,
    ``import_module(...)`` or ``__import__(...)``."""
    f = node.func
    name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
    return (name in ("import_module", "__import__") and bool(node.args)
            and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str))


def graph(root: Path, package: str = "dbench") -> dict[str, set[str]]:
    mods = modules(root, package)
    return {m: imports(m, p, mods) for m, p in mods.items()}


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(g.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(g) + 100))
    for v in sorted(g):
        if v not in index:
            visit(v)
    return sorted(found)


def main(argv: list[str]) -> int:
    root = Path(argv[0]) if argv else Path(__file__).resolve().parent.parent
    g = graph(root)
    found = cycles(g)
    print(f"{len(g)} modules, {sum(len(v) for v in g.values())} import edges, "
          f"{len(found)} cycle(s)")
    for comp in found:
        members = set(comp)
        print("cycle: " + ", ".join(comp))
        for m in comp:
            for t in sorted(g[m] & members):
                print(f"    {m} -> {t}")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
