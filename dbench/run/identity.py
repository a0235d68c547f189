"""What makes a result: a cell's identity, its label, and the code versions behind it.

A benchmark cell is reused only when everything that changes its numbers matches (issue
"results that cannot be silently wrong"): the scene (its description's fingerprint), resolution,
spp, seeds, the reference spp actually used and its seed, the feature buffers' spp where it is
not the default 64 (:func:`dbench.datasets.feature_identity`), the sample transform, the frames or
bins, the method, its *resolved* parameters (defaults included, so changing a default in code
changes the identity), the method's code version and the judge's code version.

Labels: a method run with its defaults is labelled by its name (``jbf``); with other parameters
by its name and the parameters that differ from the defaults (``jbf[radius=3]``), so two
parameter sets are two series in every table and never merged under one name.
"""
from __future__ import annotations

import ast
import hashlib
import inspect
import json
import re
import types
from functools import lru_cache
from pathlib import Path
from typing import Any

#: the ``dbench`` package folder (this file is dbench/run/identity.py)
_PACKAGE_ROOT = Path(__file__).resolve().parents[1]
_SAFE_FILE = re.compile(r"[A-Za-z0-9_.,=+\-\[\]]{1,96}")


def _jsonable(value: Any) -> Any:
    return json.loads(json.dumps(value, sort_keys=True, default=str))


def digest(obj: Any, length: int = 16) -> str:
    """Short sha256 of a JSON-able object (sorted keys)."""
    text = json.dumps(_jsonable(obj), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:length]


def code_text(path: Path) -> bytes:
    """What of a file decides the numbers: a Python file's syntax tree without its docstrings
    (``ast.dump``: comments, formatting and line numbers are not in it), any other file's
    bytes (ONNX weights, JSON metadata). So documentation and formatting edits keep a method's
    identity, and any change to what runs changes it. A Python file is decoded as Python
    decodes it (from bytes: a ``# -*- coding: latin-1 -*-`` line, a byte-order mark); one that
    does not parse (a template in a plugin's folder, never imported) counts by its bytes."""
    if path.suffix != ".py":
        return path.read_bytes()
    tree = _parsed(path)
    if tree is None:
        return path.read_bytes()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                and body and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return ast.dump(tree).encode()


def _parsed(path: Path) -> ast.Module | None:
    """The syntax tree of the Python file ``path`` read as bytes (so its coding declaration or
    byte-order mark is honoured, as ``import`` honours it), or None when it does not parse."""
    try:
        return ast.parse(path.read_bytes(), str(path))
    except (SyntaxError, ValueError):
        return None


def _hash_files(paths: list[Path]) -> str:
    h = hashlib.sha256()
    for p in sorted(paths):
        h.update(p.name.encode())
        if p.suffix == ".py":
            h.update(code_text(p))
        else:  # the same bytes as code_text, read in pieces: a plugin's weights may be large
            with p.open("rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
    return h.hexdigest()[:12]


def _module_file(root: Path, name: str) -> Path | None:
    """The file of module ``name`` (dotted, under the package folder ``root``), or None."""
    parts = name.split(".")[1:]
    base = root.joinpath(*parts)
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if parts and candidate.is_file():
            return candidate.resolve()
    return None


def _imported_files(path: Path, root: Path) -> set[Path]:
    """The files of the ``dbench`` modules that the Python file ``path`` imports (every import
    statement, those inside functions included), with the ``__init__.py`` of each package on
    the way, since importing a module runs them."""
    rel = path.relative_to(root.parent).with_suffix("").parts
    package = list(rel[:-1])
    names: set[str] = set()
    for node in ast.walk(_parsed(path) or ast.Module(body=[], type_ignores=[])):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            names.add(mod)
            names.update(f"{mod}.{a.name}" for a in node.names)
    out: set[Path] = set()
    for name in names:
        if name.split(".")[0] != root.name:
            continue
        parts = name.split(".")
        for i in range(2, len(parts) + 1):
            f = _module_file(root, ".".join(parts[:i]))
            if f is not None:
                out.add(f)
    return out


def method_files(cls: type) -> list[Path]:
    """The files behind a method's numbers, sorted: every .py, .onnx and .json file of its
    package folder (weights included), the top-level modules of ``dbench.methods`` it may share
    (``guards.py``, ``checks.py``, ...) and every module of ``dbench.methods`` those files
    import, directly or through one another (shared kernels such as
    ``dbench/methods/kernels/``, or the steps of another method it reuses). A class defined in a
    plugin package gives every file of that package's folder (whatever the folder is called
    and whatever its files hold: weights in any format; not ``__pycache__`` nor hidden files)
    and the modules of its top-level package that those import (``from ..common import x``),
    README.md "Add your own denoiser"; one in a stand-alone file or top-level module
    (``--plugin my_method.py``) that file and the modules beside it that it imports; a
    plugin's class adds the files of the classes it inherits from."""
    wrapped = getattr(cls, "wrapped", None)  # NAME+gate: the gate's files and the method's
    if wrapped is not None:
        return sorted(set(method_files(wrapped)) | set(_package_files(inspect.getfile(cls))))
    own = source_file(cls)  # None: a class with no file (unsourced_classes)
    files = set(_package_files(str(own))) if own is not None else set()
    import dbench.methods as pkg

    if own is None or Path(pkg.__file__).resolve().parent not in own.parents:
        # a plugin's class runs the code of the classes it inherits from too (a built-in
        # method's): theirs count (dbench's own classes import their bases, traced above)
        for base in cls.__mro__[1:]:
            base_file = source_file(base)
            if base.__module__ not in ("builtins", "dbench.denoiser") and base_file is not None:
                files |= set(_package_files(str(base_file)))
    return sorted(files)


def source_file(cls: type) -> Path | None:
    """The file ``cls`` was defined in, or None where it has none to read: a class typed at a
    prompt, in a notebook cell or in ``python -c`` (``__main__`` without a file, or with a
    name such as ``<stdin>`` that is no file)."""
    try:
        path = Path(inspect.getfile(cls))
    except (TypeError, OSError):
        return None
    return path.resolve() if path.is_file() else None


def unsourced_classes(cls: type) -> list[type]:
    """The classes behind a method's numbers that have no :func:`source_file`: ``cls`` and
    the classes it inherits from (the method a ``NAME+gate`` wraps, and its), bar dbench's
    base class."""
    classes = list(cls.__mro__) + list(getattr(getattr(cls, "wrapped", None), "__mro__", ()))
    return [k for k in dict.fromkeys(classes)
            if k.__module__ not in ("builtins", "dbench.denoiser") and source_file(k) is None]


def _stable(value: Any) -> str:
    """``value`` as the same text in every process: sets sorted (their order follows the
    string hash, another in every process) and no object addresses."""
    if isinstance(value, (set, frozenset)):
        return "{" + ",".join(sorted(_stable(v) for v in value)) + "}"
    if isinstance(value, (list, tuple)):
        return "(" + ",".join(_stable(v) for v in value) + ")"
    if isinstance(value, dict):
        return "{" + ",".join(sorted(f"{_stable(k)}:{_stable(v)}" for k, v in value.items())) + "}"
    return re.sub(r" at 0x[0-9A-Fa-f]+", "", repr(value))


def _code_parts(obj: Any, module: str, seen: set[int]) -> list[str]:
    """What of ``obj`` (a class, function or code object of the module ``module``) decides what
    it computes: a class's name and attributes, a function's compiled code (bytecode, constants
    and the names it uses, nested functions included) and defaults, and the functions, classes
    and plain constants of ``module`` that the code uses by name, each once."""
    if id(obj) in seen:
        return []
    seen.add(id(obj))
    if isinstance(obj, type):
        out = [obj.__qualname__]
        for name, value in sorted(vars(obj).items()):
            if name not in ("__dict__", "__weakref__", "__module__", "__doc__", "__qualname__"):
                out += [name] + (_code_parts(value, module, seen) or [_stable(value)])
        return out
    if isinstance(obj, (staticmethod, classmethod)):
        return _code_parts(obj.__func__, module, seen)
    if isinstance(obj, property):
        return [p for f in (obj.fget, obj.fset, obj.fdel) if f is not None
                for p in _code_parts(f, module, seen)]
    if not isinstance(obj, types.FunctionType):
        return []
    out, names, todo = [_stable((obj.__defaults__, obj.__kwdefaults__))], set(), [obj.__code__]
    while todo:
        code = todo.pop()
        out += [code.co_code.hex(), _stable(code.co_names), _stable(code.co_varnames)]
        out += [_stable(c) for c in code.co_consts if not isinstance(c, types.CodeType)]
        todo += [c for c in code.co_consts if isinstance(c, types.CodeType)]
        names |= set(code.co_names)
    for name in sorted(names):  # what the code reaches in its module by name
        value = obj.__globals__.get(name)
        if isinstance(value, (type, types.FunctionType)) and value.__module__ == module:
            out += [name, *_code_parts(value, module, seen)]
        elif isinstance(value, (bool, int, float, complex, str, bytes, tuple, frozenset)):
            out += [name, _stable(value)]
    return out


def _unsourced_version(classes: list[type]) -> str:
    """``source-unknown-`` and a hash of :func:`_code_parts` of ``classes`` (compiled code:
    it changes with the Python version too), so a cell is reused only by the same code."""
    seen: set[int] = set()
    parts = [p for k in classes for p in _code_parts(k, k.__module__, seen)]
    return "source-unknown-" + hashlib.sha256("\n".join(parts).encode()).hexdigest()[:12]


def _package_files(source_file: str) -> list[Path]:
    """:func:`method_files` of the class defined in ``source_file``."""
    import dbench.methods as pkg

    source = Path(source_file).resolve()
    shared = Path(pkg.__file__).resolve().parent
    files = [source]
    outside_package = (shared not in source.parents and source.name != "__init__.py"
                       and not (source.parent / "__init__.py").is_file())
    if outside_package:  # a plugin file or top-level module (dbench --plugin x.py): that file
        files += _sibling_imports(source)  # and the modules beside it that it imports
    elif shared not in source.parents:  # a plugin package: its folder, whatever it holds
        files = _plugin_package_files(source.parent)
    elif source.name == "__init__.py" or source.parent != shared:
        folder = source.parent
        files = [p for p in folder.rglob("*") if p.suffix in (".py", ".onnx", ".json")
                 and "__pycache__" not in p.parts]
    if shared in source.parents:
        files += [p for p in shared.glob("*.py")]
        root = _PACKAGE_ROOT
        todo = [p.resolve() for p in files if p.suffix == ".py"]
        seen = set(todo)
        while todo:
            for f in _imported_files(todo.pop(), root):
                if shared in f.parents and f not in seen:
                    seen.add(f)
                    todo.append(f)
                    files.append(f)
    return sorted(dict.fromkeys(p.resolve() for p in files))


def _plugin_package_files(folder: Path) -> list[Path]:
    """Every file under a plugin package's ``folder`` (its weights too, whatever their format:
    a changed ``weights.pt`` changes the numbers as a changed module does), bar ``__pycache__``
    and hidden files, and the modules of its top-level package that the Python files import,
    directly or through one another (``from ..common import SCALE`` in ``mylab/methods/``)."""
    files = {p.resolve() for p in folder.rglob("*") if p.is_file()
             and "__pycache__" not in p.relative_to(folder).parts and p.suffix != ".pyc"
             and not any(part.startswith(".") for part in p.relative_to(folder).parts)}
    top = folder
    while (top.parent / "__init__.py").is_file():
        top = top.parent
    todo = [p for p in files if p.suffix == ".py"]
    while todo:
        for f in _imported_files(todo.pop(), top):
            if f not in files:
                files.add(f)
                todo.append(f)
    return sorted(files)


def _sibling_imports(source: Path) -> list[Path]:
    """The modules in ``source``'s folder that it imports (``import helper``, ``from helper
    import x``, and in a namespace package ``from .helper import x``), and those they import
    in turn: a stand-alone plugin's helpers. A package beside it (``helpers/__init__.py``)
    counts as a plugin package does, whole (:func:`_plugin_package_files`)."""
    found, todo = [], [source]
    while todo:
        current = todo.pop()
        tree = _parsed(current) or ast.Module(body=[], type_ignores=[])
        for node in ast.walk(tree):
            folder = source.parent  # an absolute import: a module beside the plugin file
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level:
                names = [node.module] if node.module else []
            elif isinstance(node, ast.ImportFrom):  # relative: a namespace package's module
                ups = [current.parent, *current.parent.parents]
                if node.level > len(ups):
                    continue
                folder = ups[node.level - 1]
                names = [node.module] if node.module else [a.name for a in node.names]
            else:
                continue
            for name in names:
                f = folder / f"{name.split('.')[0]}.py"
                package = folder / name.split(".")[0]
                if not f.is_file() and (package / "__init__.py").is_file():
                    found += [p for p in _plugin_package_files(package) if p not in found]
                elif f.is_file() and f.resolve() != source and f.resolve() not in found:
                    found.append(f.resolve())
                    todo.append(f.resolve())
    return found


def device_only(path: Path) -> bool:
    """Whether a method file runs only on a device (docs/gpu.md §2): the GPU kernels
    (``dbench/methods/kernels/gpu/``) and the device paths (``device.py``, ``*_device.py``).
    A host call never executes them, so they are no part of a CPU result. Only dbench's own
    methods are split so; a plugin's files all count."""
    import dbench.methods as pkg

    if Path(pkg.__file__).resolve().parent not in Path(path).resolve().parents:
        return False
    parts = Path(path).parts
    in_gpu_kernels = any(parts[i:i + 3] == ("methods", "kernels", "gpu")
                         for i in range(len(parts) - 2))
    return in_gpu_kernels or path.name == "device.py" or path.name.endswith("_device.py")


@lru_cache(maxsize=None)
def method_version(cls: type, device: str = "cpu") -> str:
    """The code version of a method class on ``device``: its declared ``version`` (if any)
    joined with a hash of :func:`method_files` (its package folder, the shared top-level modules
    of ``dbench.methods`` and every module of ``dbench.methods`` they import), each as
    :func:`code_text` reads it. On the CPU the :func:`device_only` files are left out: a change
    to a GPU kernel is no change to a CPU cell's numbers; on a device they count. Classes with
    no file (:func:`unsourced_classes`: typed in a notebook or ``python -c``) add
    ``source-unknown-`` and a hash of their compiled code (:func:`_unsourced_version`)."""
    declared = getattr(cls, "version", None)
    files = method_files(cls)
    if device == "cpu":
        files = [f for f in files if not device_only(f)]
    unsourced = unsourced_classes(cls)
    code = "+".join(([_hash_files(files)] if files or not unsourced else [])
                    + ([_unsourced_version(unsourced)] if unsourced else []))
    return f"{declared}+{code}" if declared else code


@lru_cache(maxsize=1)
def judge_version() -> str:
    """Hash of the code that turns a method's output into a cell's numbers, as
    :func:`code_text` reads it: the metrics (dbench/metrics/*.py), the pixels they are judged
    over (dbench/run/scoring.py: surfaces, lights) and a sequence's protocol
    (dbench/run/sequence_run.py: which frames are averaged and timed, t_rmse and tpsnr).
    Changing how a number is computed changes every cell's identity; a docstring or a comment
    does not."""
    import dbench.metrics as pkg

    run = Path(__file__).parent
    return _hash_files(sorted(Path(pkg.__file__).parent.glob("*.py"))
                       + [run / "scoring.py", run / "sequence_run.py"])


def resolved_params(name: str, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """The method's defaults with ``overrides`` applied (JSON-normalised): an integer given
    where the default is a float is that float (``beta=10`` is the default ``10.0``, the
    same numbers and so the same identity)."""
    from .. import registry

    cls = registry.method_class(name)
    given = {k: float(v) if isinstance(cls.defaults.get(k), float) and isinstance(v, int)
             and not isinstance(v, bool) else v for k, v in (overrides or {}).items()}
    return _jsonable({**cls.defaults, **given})


def label(name: str, overrides: dict[str, Any] | None = None) -> str:
    """``name`` when the resolved parameters equal the defaults, else
    ``name[key=value,...]`` listing the parameters that differ (sorted by key)."""
    from .. import registry

    defaults = _jsonable(registry.method_class(name).defaults)
    params = resolved_params(name, overrides)
    diff = {k: v for k, v in params.items() if defaults.get(k, object()) != v}
    if not diff:
        return name
    return f"{name}[" + ",".join(f"{k}={json.dumps(v, sort_keys=True) if not isinstance(v, str) else v}"
                                 for k, v in sorted(diff.items())) + "]"


def file_stem(label_: str) -> str:
    """A file name for a label: the label itself when it is made of safe characters, else the
    method name and a hash of the label."""
    if _SAFE_FILE.fullmatch(label_) and not label_.startswith("."):
        return label_
    base = re.sub(r"[^A-Za-z0-9_\-]", "_", label_.split("[", 1)[0])[:40] or "method"
    return f"{base}@{digest(label_, 10)}"


def changed_during_sweep(method: str, planned: dict[str, Any] | None,
                         now: dict[str, Any]) -> str:
    """``""`` when ``now``, a cell's identity as the process about to score it finds it, is the
    one the sweep planned (``planned``; None: nothing planned, as from the Python API), else the
    line that refuses the cell: a plugin's file edited while ``dbench sweep --workers N`` runs
    is read by a worker after the sweep hashed it, and its numbers would be filed under the old
    code's identity (README.md, the ``dbench sweep`` paragraph). The error cell is computed
    again by the next run of the sweep."""
    if planned is None or digest(planned) == digest(now):
        return ""
    keys = differences(planned, now)
    what = (f"its code changed during the sweep (method_version {planned['method_version']} "
            f"-> {now['method_version']})" if keys == ["method_version"] else
            f"its cell's identity changed during the sweep (differs in {', '.join(keys[:6])})")
    return f"{method}: {what}; not scored: run the sweep again"


def differences(old: dict[str, Any], new: dict[str, Any], prefix: str = "") -> list[str]:
    """Dotted keys whose values differ between two identity dicts."""
    out = []
    for k in sorted(set(old) | set(new)):
        a, b = old.get(k), new.get(k)
        if isinstance(a, dict) and isinstance(b, dict):
            out += differences(a, b, f"{prefix}{k}.")
        elif _jsonable(a) != _jsonable(b):
            out.append(f"{prefix}{k}")
    return out


__all__ = ["digest", "code_text", "method_files", "method_version", "judge_version", "resolved_params", "label",
           "file_stem", "differences", "changed_during_sweep"]
