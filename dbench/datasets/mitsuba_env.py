"""Choosing a Mitsuba variant without ever taking the process down (docs/mitsuba.md §1).

With only libLLVM 15 on the machine, Mitsuba's ``llvm_ad_rgb`` variant aborts the whole process
(``LLVM ERROR: Cannot select ... fminimum``) on its first kernel. That abort cannot be caught in
Python, so the LLVM check runs a tiny render in a child process; the verdict is remembered in a
small file keyed by the interpreter, Mitsuba version and ``DRJIT_LIBLLVM_PATH``.

With an NVIDIA GPU (a driver the process can see), ``cuda_ad_rgb`` is checked the same way, in
a child process with a tiny render (:func:`cuda_usable`); where no driver is visible the answer is
"no" at once, without a child. The one-pass render kernel (:mod:`dbench.datasets.render_moments`)
keeps the samples on the device and brings back only per-pixel sums, so the GPU pays no per-pass
host round trips.

``DBENCH_VARIANT`` forces a variant (``scalar_rgb`` to simulate a machine without LLVM);
``DBENCH_RENDER_DEVICE`` (``cpu`` or ``cuda``) picks the device when no variant is forced
(:func:`choose_variant`). The variant is part of every render's cache key (:func:`versions`).
"""
from __future__ import annotations

import functools
import gc
import hashlib
import json
import os
import platform
import signal
import subprocess
import sys
import threading
import warnings
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path

from ..errors import DbenchInputError, RendererUnavailableError
from .mitsuba_log import drjit_start, follow_quiet, forget, loading, route

LLVM_VARIANT = "llvm_ad_rgb"
CUDA_VARIANT = "cuda_ad_rgb"
SCALAR_VARIANT = "scalar_rgb"
#: Devices :func:`choose_variant` accepts (None: CUDA when usable, else the CPU).
DEVICES = ("cpu", "cuda")

#: A tiny render in a child process: a backend that aborts the process (LLVM 15's "Cannot
#: select", a broken CUDA driver) takes the child down, never dbench. Exit 3: no such backend.
_PROBE_TEMPLATE = r"""
import drjit as dr
if not dr.has_backend(dr.JitBackend.{backend}):
    raise SystemExit(3)
import mitsuba as mi
mi.set_variant("{variant}")
scene = mi.load_dict({{
    "type": "scene", "integrator": {{"type": "path", "max_depth": 3}},
    "sensor": {{"type": "perspective", "film": {{"type": "hdrfilm", "width": 4, "height": 4,
               "rfilter": {{"type": "box"}}}}}},
    "light": {{"type": "constant"}}, "s": {{"type": "sphere", "center": [0, 0, 5]}},
}})
img = mi.render(scene, spp=2)
assert img.shape == (4, 4, 3)
print("ok")
"""
_PROBE = _PROBE_TEMPLATE.format(backend="LLVM", variant=LLVM_VARIANT)
_CUDA_PROBE = _PROBE_TEMPLATE.format(backend="CUDA", variant=CUDA_VARIANT)
#: Where a visible NVIDIA driver shows itself; none of them: no CUDA, and no child is started.
_NVIDIA_MARKERS = ("/proc/driver/nvidia/version", "/dev/nvidiactl", "/dev/nvidia0")


#: Set by the command line for the duration of a command: the folder its ``--cache`` names, or
#: "none" under ``--no-cache`` (the probe's verdict is then kept in this process only).
PROBE_STORE_ENV = "DBENCH_PROBE_STORE"


def _state_file(name: str = "llvm") -> Path | None:
    """Where a probe's verdict is kept between processes: the command's cache folder
    (:data:`PROBE_STORE_ENV`), else ``DBENCH_CACHE`` or ``~/.cache/dbench``; None under
    ``--no-cache``, which writes nothing to disk."""
    store = os.environ.get(PROBE_STORE_ENV)
    if store == "none":
        return None
    base = Path(store or os.environ.get("DBENCH_CACHE", Path.home() / ".cache" / "dbench"))
    return base / f"{name}_probe.json"


#: The probes whose verdicts :func:`_state_file` keeps.
PROBES = ("llvm", "cuda")


def probe_folder() -> Path | None:
    """The folder the probes keep their verdicts in (:func:`_state_file`), None when none."""
    state = _state_file()
    return state.parent if state is not None else None


def forget_probes(created: list[Path]) -> None:
    """After a refused command: remove the probes' verdicts from the folders in ``created``
    (those the command found missing, deepest first: :func:`dbench.io.missing_folders`) and
    then those folders where empty, so that a command refused before rendering leaves no cache
    folder behind (README.md, "Usage")."""
    from ..io import remove_empty

    for name in PROBES:
        state = _state_file(name)
        if state is not None and state.parent in created:
            try:
                state.unlink(missing_ok=True)
            except OSError:  # not there to remove (a file in the path, say): nothing left
                pass
    remove_empty(created)


def _probe_key() -> str:
    # the installed version from the package's metadata: importing Mitsuba here would load
    # Dr.Jit outside deferred_interrupts ("missing" is reported later)
    version = _package_versions()["mitsuba"]
    raw = f"{sys.executable}|{version}|{os.environ.get('DRJIT_LIBLLVM_PATH', '')}"
    return hashlib.sha1(raw.encode()).hexdigest()[:16]


def _probe(name: str, code: str, key: str, describe, timeout: float = 300
           ) -> tuple[bool, str]:
    """Run ``code`` in a child process once per ``key``; ``describe(exit code or None when
    it did not finish, last output line)`` words a failure. The verdict (ok, reason) is kept in
    ``_state_file(name)`` so later processes skip the child."""
    state = _state_file(name)
    try:
        if state is None:
            raise OSError("no store")
        cached = json.loads(state.read_text(encoding="utf-8"))
        if cached.get("key") == key:
            return bool(cached["ok"]), str(cached["reason"])
    except (OSError, ValueError, KeyError):
        pass
    try:
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=timeout)
        ok = proc.returncode == 0 and "ok" in proc.stdout
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
        reason = "" if ok else describe(proc.returncode, tail[0][:160])
    except (subprocess.TimeoutExpired, OSError) as exc:
        ok, reason = False, describe(None, type(exc).__name__)
    if state is None:
        return ok, reason
    try:
        state.parent.mkdir(parents=True, exist_ok=True)
        tmp = state.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps({"key": key, "ok": ok, "reason": reason}), encoding="utf-8")
        os.replace(tmp, state)
    except OSError:
        pass
    return ok, reason


#: Loaded Mitsuba scenes each loader keeps (:func:`scene_cache`). Every object a live scene
#: holds stays in Dr.Jit's registry, and each virtual call a render traces (a BSDF, emitter or
#: shape lookup) is traced for every registered object of its kind, live scene or not: with 15
#: other scenes kept alive a 64² 16-spp cornell load took 4× as long (docs/mitsuba.md §3). Two
#: covers a load (a medium scene beside its ``minus`` scene, one resolution beside another).
LIVE_SCENES = 2

#: the loaders :func:`scene_cache` made, emptied by :func:`focus`
_SCENE_CACHES: list = []
#: the scene of the last :func:`focus`
_focused: list = [None]
#: the arguments of the loads each :func:`scene_cache` loader made (:func:`forget_loads`)
_LOADS_MADE: list[set] = []


def scene_cache(maxsize: int = LIVE_SCENES, loads: bool = True):
    """``functools.lru_cache(maxsize)`` for a function that returns loaded Mitsuba objects (a
    scene, its batch or transient form, a scene file's objects, a collector holding one),
    registered so that :func:`focus` drops them. A load with arguments it was called with
    before (its objects dropped meanwhile) runs without Mitsuba's warnings, which the first
    load showed and kept (:func:`dbench.datasets.mitsuba_log.loading`): a sweep reads a scene
    file when it checks its scenes and again for its renders, after other scenes' (README.md,
    "Usage"). ``loads=False``: a function of objects loaded already (a collector of a loaded
    scene), whose arguments a record of calls would keep alive past :func:`focus`."""
    def wrap(fn):
        # the arguments of every load made (descriptions: scenes, sizes, paths)
        loaded_before: set = set()
        _LOADS_MADE.append(loaded_before)

        @functools.wraps(fn)
        def load(*args, **kwargs):
            key = (args, tuple(sorted(kwargs.items())))
            with loading(key in loaded_before):
                out = fn(*args, **kwargs)
            loaded_before.add(key)
            return out

        cached = lru_cache(maxsize=maxsize)(load if loads else fn)
        _SCENE_CACHES.append(cached)
        return cached
    return wrap


def forget_loads() -> None:
    """A command starts: its loads are first loads again, whose warnings are forwarded and kept
    in its own log (:func:`scene_cache`), and its sweep's workers inherit its own lines alone
    (:func:`dbench.datasets.mitsuba_log.forget`)."""
    for made in _LOADS_MADE:
        made.clear()
    forget()


def focus(scene) -> None:
    """Say that renders of ``scene`` (a hashable identity: the Scene a load renders) come next:
    where it differs from the last one, the loaded objects of every :func:`scene_cache` are
    dropped, so that the next renders trace their virtual calls over this scene's objects alone
    (:data:`LIVE_SCENES`)."""
    if _focused[0] is not None and _focused[0] != scene:
        for cached in _SCENE_CACHES:
            cached.cache_clear()
        gc.collect()
    _focused[0] = scene


def _llvm_failure(code: int | None, last: str) -> str:
    reason = ("LLVM test render timed out" if code is None
              else "Dr.Jit found no libLLVM" if code == 3
              else f"LLVM test render failed (exit {code}: {last})")
    return reason + "; install libllvm19 (apt-get install libllvm19) or set DRJIT_LIBLLVM_PATH"


@lru_cache(maxsize=1)
def llvm_usable() -> tuple[bool, str]:
    """Whether ``llvm_ad_rgb`` renders on this machine, and a one-line reason if not.

    The answer comes from a child process, so an LLVM abort only kills the child.
    """
    return _probe("llvm", _PROBE, _probe_key(), _llvm_failure)


def _cuda_failure(code: int | None, last: str) -> str:
    return ("CUDA test render timed out" if code is None
            else "Dr.Jit found no CUDA device" if code == 3
            else f"CUDA test render failed (exit {code}: {last})")


def _nvidia_driver() -> str | None:
    """The visible NVIDIA driver's version line ("" when only its device files show), or None
    when none is visible (``CUDA_VISIBLE_DEVICES`` empty or ``-1`` hides every GPU)."""
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    if visible is not None and visible.strip() in ("", "-1"):
        return None
    for marker in _NVIDIA_MARKERS:
        if os.path.exists(marker):
            try:
                return Path(_NVIDIA_MARKERS[0]).read_text(encoding="utf-8").splitlines()[0]
            except (OSError, IndexError):
                return ""
    return None


@lru_cache(maxsize=1)
def cuda_usable() -> tuple[bool, str]:
    """Whether ``cuda_ad_rgb`` renders here, and a one-line reason if not.

    No visible NVIDIA driver: "no" at once. Otherwise a child process renders a tiny scene
    (a CUDA or OptiX failure only ends the child); the verdict is remembered per interpreter,
    Mitsuba version, host, driver and ``CUDA_VISIBLE_DEVICES``."""
    driver = _nvidia_driver()
    if driver is None:
        return False, "no NVIDIA driver visible"
    raw = "|".join([_probe_key(), platform.node(), driver,
                    os.environ.get("CUDA_VISIBLE_DEVICES", "")])
    key = hashlib.sha1(raw.encode()).hexdigest()[:16]
    return _probe("cuda", _CUDA_PROBE, key, _cuda_failure, timeout=120)


@lru_cache(maxsize=4)
def choose_variant(device: str | None = None) -> str:
    """The variant dbench renders with on ``device``.

    ``DBENCH_VARIANT`` overrides everything. ``"cuda"``: ``cuda_ad_rgb``, or
    RendererUnavailableError with the probe's reason. ``"cpu"``: ``llvm_ad_rgb`` when usable,
    else ``scalar_rgb`` with a one-line warning. None: ``cuda_ad_rgb`` where :func:`cuda_usable`
    says yes, else as ``"cpu"``."""
    forced = os.environ.get("DBENCH_VARIANT")
    if forced:
        return forced
    if device is not None and device not in DEVICES:
        raise DbenchInputError(f"render device: expected one of {DEVICES}, got {device!r}")
    if device in (None, "cuda"):
        ok, reason = cuda_usable()
        if ok:
            return CUDA_VARIANT
        if device == "cuda":
            raise RendererUnavailableError(f"cannot render on cuda: {reason}")
    ok, reason = llvm_usable()
    if ok:
        return LLVM_VARIANT
    warnings.warn(f"dbench: falling back to {SCALAR_VARIANT} for steady renders ({reason}); "
                  "transient rendering needs LLVM", RuntimeWarning, stacklevel=2)
    return SCALAR_VARIANT


def current_variant() -> str:
    """:func:`choose_variant` for ``DBENCH_RENDER_DEVICE`` (unset: the default device), the
    variant :func:`mitsuba` sets and :func:`versions` records."""
    return choose_variant(os.environ.get("DBENCH_RENDER_DEVICE") or None)


@contextmanager
def deferred_interrupts():
    """Ctrl-C and SIGTERM wait until the block has ended, then arrive as they would have.

    Importing Dr.Jit and Mitsuba and setting the variant start native thread pools and JIT
    back-ends; an interrupt raised in the Python code between those steps left them half made:
    it surfaced as "cannot set Mitsuba variant" (exit 3), as a NameError, or as a crash while the
    interpreter shut down ("PyThreadState_Get: the function must be called with the GIL held").
    Inside the block a signal is only noted; afterwards the handlers in force before it
    (dbench's command handlers, Python's default) get it. Main thread only."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived: list[int] = []
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    for sig, handler in previous.items():
        if handler not in (signal.SIG_IGN, None):
            signal.signal(sig, lambda signum, frame: arrived.append(signum))
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)
        for sig in dict.fromkeys(arrived):
            signal.raise_signal(sig)


@lru_cache(maxsize=1)
def mitsuba():
    """Import Mitsuba with the chosen variant set (once per process) and return the module.
    An interrupt during the import waits until it is done (:func:`deferred_interrupts`)."""
    variant = current_variant()  # its probes run in child processes: interruptible
    # Dr.Jit's start-up warnings (an unusable kernel cache) go to the run's files as Mitsuba's
    # do, shown unless --quiet
    with deferred_interrupts(), drjit_start():
        try:
            import drjit as dr
            import mitsuba as mi
        except ImportError as exc:  # pragma: no cover - install problem
            raise RendererUnavailableError(f"Mitsuba is not installed: {exc}") from exc
        if mi.variant() != variant:
            try:
                mi.set_variant(variant)
            except Exception as exc:  # noqa: BLE001
                raise RendererUnavailableError(
                    f"cannot set Mitsuba variant {variant}: {exc}") from exc
        follow_quiet()  # Dr.Jit's later lines: errors alone under --quiet
        route(mi)  # Mitsuba's warnings: kept in the run's files, shown unless --quiet
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
    """Renderer versions that change the pixels (part of every cache key), and the variant."""
    return {**_package_versions(), "variant": current_variant()}


@functools.lru_cache(maxsize=1)
def _package_versions() -> dict[str, str]:
    """Read from package metadata once a process (importing mitransient has side effects that
    need a variant; parsing the metadata took 1.5 ms, at every render's cache key)."""
    from importlib.metadata import PackageNotFoundError, version

    out: dict[str, str] = {}
    for mod in ("mitsuba", "drjit", "mitransient"):
        try:
            out[mod] = version(mod)
        except PackageNotFoundError:
            out[mod] = "missing"
    return out
