"""What makes a result: a cell's identity, its label, and the code versions behind it.

A benchmark cell is reused only when everything that changes its numbers matches (issue
"results that cannot be silently wrong"): the scene (its description's fingerprint), resolution,
spp, seeds, the reference spp actually used and its seed, the sample transform, the frames or
bins, the method, its *resolved* parameters (defaults included, so changing a default in code
changes the identity), the method's code version and the judge's code version.

Labels: a method run with its defaults is labelled by its name (``jbf``); with other parameters
by its name and the parameters that differ from the defaults (``jbf[radius=3]``), so two
parameter sets are two series in every table and never merged under one name.
"""
from __future__ import annotations

import hashlib
import inspect
import json
import re
from functools import lru_cache
from pathlib import Path
from typing import Any

_SAFE_FILE = re.compile(r"[A-Za-z0-9_.,=+\-\[\]]{1,96}")


def _jsonable(value: Any) -> Any:
    return json.loads(json.dumps(value, sort_keys=True, default=str))


def digest(obj: Any, length: int = 16) -> str:
    """Short sha256 of a JSON-able object (sorted keys)."""
    text = json.dumps(_jsonable(obj), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:length]


def _hash_files(paths: list[Path]) -> str:
    h = hashlib.sha256()
    for p in sorted(paths):
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()[:12]


@lru_cache(maxsize=None)
def method_version(cls: type) -> str:
    """The code version of a method class: its declared ``version`` (if any) joined with a hash
    of its source: every .py, .onnx and .json file of its package folder (weights included), and
    the top-level modules of ``dbench.methods`` it may share (``temporal.py``, ...). A class
    defined in a plugin package hashes that package's folder; one in a stand-alone file or
    top-level module (``--plugin my_method.py``) hashes that file only."""
    import dbench.methods as pkg

    source = Path(inspect.getfile(cls)).resolve()
    shared = Path(pkg.__file__).resolve().parent
    files = [source]
    outside_package = (shared not in source.parents and source.name != "__init__.py"
                       and not (source.parent / "__init__.py").is_file())
    if outside_package:
        pass  # a plugin file or top-level module (dbench --plugin x.py): that file alone
    elif source.name == "__init__.py" or source.parent.name != "methods":
        folder = source.parent
        files = [p for p in folder.rglob("*") if p.suffix in (".py", ".onnx", ".json")
                 and "__pycache__" not in p.parts]
    if shared in source.parents:
        files += [p for p in shared.glob("*.py")]
    declared = getattr(cls, "version", None)
    code = _hash_files(list(dict.fromkeys(files)))
    return f"{declared}+{code}" if declared else code


@lru_cache(maxsize=1)
def judge_version() -> str:
    """Hash of the metric code (dbench/metrics/*.py): changing how a number is computed changes
    every cell's identity."""
    import dbench.metrics as pkg

    return _hash_files(list(Path(pkg.__file__).parent.glob("*.py")))


def resolved_params(name: str, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """The method's defaults with ``overrides`` applied (JSON-normalised)."""
    from .. import methods

    cls = methods.method_class(name)
    return _jsonable({**cls.defaults, **(overrides or {})})


def label(name: str, overrides: dict[str, Any] | None = None) -> str:
    """``name`` when the resolved parameters equal the defaults, else
    ``name[key=value,...]`` listing the parameters that differ (sorted by key)."""
    from .. import methods

    defaults = _jsonable(methods.method_class(name).defaults)
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


__all__ = ["digest", "method_version", "judge_version", "resolved_params", "label",
           "file_stem", "differences"]
