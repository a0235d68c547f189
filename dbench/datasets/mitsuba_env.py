"""Choosing a Mitsuba variant without ever taking the process down (spec/mitsuba.md §1).

With only libLLVM 15 on the machine, Mitsuba's ``llvm_ad_rgb`` variant aborts the whole process
(``LLVM ERROR: Cannot select ... fminimum``) on its first kernel. That abort cannot be caught in
Python, so the LLVM check runs a tiny render in a child process; the verdict is remembered in a
small file keyed by the interpreter, Mitsuba version and ``DRJIT_LIBLLVM_PATH``.

``DBENCH_VARIANT`` forces a variant (``scalar_rgb`` to simulate a machine without LLVM).
"""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import warnings
from functools import lru_cache
from pathlib import Path

from ..errors import RendererUnavailableError

LLVM_VARIANT = "llvm_ad_rgb"
SCALAR_VARIANT = "scalar_rgb"

_PROBE = r"""
import mitsuba as mi, drjit as dr
if not dr.has_backend(dr.JitBackend.LLVM):
    raise SystemExit(3)
mi.set_variant("llvm_ad_rgb")
scene = mi.load_dict({
    "type": "scene", "integrator": {"type": "path", "max_depth": 3},
    "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4,
               "rfilter": {"type": "box"}}},
    "light": {"type": "constant"}, "s": {"type": "sphere", "center": [0, 0, 5]},
})
img = mi.render(scene, spp=2)
assert img.shape == (4, 4, 3)
print("ok")
"""


def _state_file() -> Path:
    base = Path(os.environ.get("DBENCH_CACHE", Path.home() / ".cache" / "dbench"))
    return base / "llvm_probe.json"


def _probe_key() -> str:
    try:
        import mitsuba
        version = mitsuba.__version__
    except Exception:  # noqa: BLE001 - mitsuba missing is reported later
        version = "missing"
    raw = f"{sys.executable}|{version}|{os.environ.get('DRJIT_LIBLLVM_PATH', '')}"
    return hashlib.sha1(raw.encode()).hexdigest()[:16]


@lru_cache(maxsize=1)
def llvm_usable() -> tuple[bool, str]:
    """Whether ``llvm_ad_rgb`` renders on this machine, and a one-line reason if not.

    The answer comes from a child process, so an LLVM abort only kills the child.
    """
    key = _probe_key()
    state = _state_file()
    try:
        cached = json.loads(state.read_text(encoding="utf-8"))
        if cached.get("key") == key:
            return bool(cached["ok"]), str(cached["reason"])
    except (OSError, ValueError, KeyError):
        pass
    try:
        proc = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                              timeout=300)
        ok = proc.returncode == 0 and "ok" in proc.stdout
        if ok:
            reason = ""
        elif proc.returncode == 3:
            reason = "Dr.Jit found no libLLVM"
        else:
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
            reason = f"LLVM test render failed (exit {proc.returncode}: {tail[0][:160]})"
    except subprocess.TimeoutExpired:
        ok, reason = False, "LLVM test render timed out"
    if not ok:
        reason += "; install libllvm19 (apt-get install libllvm19) or set DRJIT_LIBLLVM_PATH"
    try:
        state.parent.mkdir(parents=True, exist_ok=True)
        tmp = state.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps({"key": key, "ok": ok, "reason": reason}), encoding="utf-8")
        os.replace(tmp, state)
    except OSError:
        pass
    return ok, reason


@lru_cache(maxsize=1)
def choose_variant() -> str:
    """The variant dbench renders with: ``llvm_ad_rgb`` when usable, else ``scalar_rgb``
    with a one-line warning. ``DBENCH_VARIANT`` overrides the choice."""
    forced = os.environ.get("DBENCH_VARIANT")
    if forced:
        return forced
    ok, reason = llvm_usable()
    if ok:
        return LLVM_VARIANT
    warnings.warn(f"dbench: falling back to {SCALAR_VARIANT} for steady renders ({reason}); "
                  "transient rendering needs LLVM", RuntimeWarning, stacklevel=2)
    return SCALAR_VARIANT


@lru_cache(maxsize=1)
def mitsuba():
    """Import Mitsuba with the chosen variant set (once per process) and return the module."""
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as exc:  # pragma: no cover - install problem
        raise RendererUnavailableError(f"Mitsuba is not installed: {exc}") from exc
    variant = choose_variant()
    if mi.variant() != variant:
        try:
            mi.set_variant(variant)
        except Exception as exc:  # noqa: BLE001
            raise RendererUnavailableError(f"cannot set Mitsuba variant {variant}: {exc}") from exc
    threads = os.environ.get("DBENCH_RENDER_THREADS")
    if threads:
        dr.set_thread_count(int(threads))
    return mi


def require_llvm(what: str) -> None:
    """Raise a clear error when ``what`` (e.g. transient rendering) needs LLVM but it is absent."""
    if not mitsuba().variant().startswith(("llvm", "cuda")):
        ok, reason = llvm_usable()
        if ok:
            reason = f"DBENCH_VARIANT forces {mitsuba().variant()}"
        raise RendererUnavailableError(
            f"{what} needs Mitsuba's llvm_ad_rgb variant, which cannot run here: {reason}")


def versions() -> dict[str, str]:
    """Renderer versions that change the pixels (part of every cache key).

    Read from package metadata: importing mitransient has side effects that need a variant.
    """
    from importlib.metadata import PackageNotFoundError, version

    out: dict[str, str] = {}
    for mod in ("mitsuba", "drjit", "mitransient"):
        try:
            out[mod] = version(mod)
        except PackageNotFoundError:
            out[mod] = "missing"
    out["variant"] = choose_variant()
    return out
