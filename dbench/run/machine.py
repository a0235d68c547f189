"""The machine a result was measured on: CPU, cores, GPU and package versions."""
from __future__ import annotations

import os
import platform
from functools import lru_cache
from typing import Any


@lru_cache(maxsize=1)
def cpu_name() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what ``platform`` knows."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return cpu


#: cgroup files of a CPU quota: v2's "QUOTA PERIOD" (or "max PERIOD"), v1's two files
_CPU_MAX = "/sys/fs/cgroup/cpu.max"
_CFS = ("/sys/fs/cgroup/cpu/cpu.cfs_quota_us", "/sys/fs/cgroup/cpu/cpu.cfs_period_us")


def _read(path: str) -> str:
    try:
        with open(path, encoding="ascii", errors="replace") as fh:
            return fh.read().strip()
    except OSError:
        return ""


def _quota_cores() -> int | None:
    """The cores a cgroup CPU quota allows (its quota over its period, rounded up), None
    where no quota is set or readable."""
    v2 = _read(_CPU_MAX).split()
    quota, period = (v2 if len(v2) == 2 else [_read(f) for f in _CFS])
    try:
        q, p = int(quota), int(period)
    except ValueError:  # "max", missing files: no quota
        return None
    return max(1, -(-q // p)) if q > 0 and p > 0 else None


def usable_cores() -> int:
    """The cores this process may run on: the CPUs of its affinity mask (``taskset``, a
    container's cpuset) and at most its cgroup CPU quota (``docker --cpus``), where
    ``os.cpu_count()`` counts the machine's. A method's threads share these, so its time
    depends on them, not on the machine's count."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not Linux
        n = os.cpu_count() or 1
    quota = _quota_cores()
    return max(1, min(n, quota) if quota else n)


def cores_text() -> str:
    """``2 cores``, or ``2 of 16 cores`` where the process may use fewer than the machine has
    (:func:`usable_cores`), worded as a run's report words its recorded machine
    (:func:`dbench.report.formats.cores_text`)."""
    from ..report.formats import cores_text as worded  # loads pandas: only when called

    return worded(usable_cores(), os.cpu_count())


def machine_label() -> str:
    """"<cpu>, <n> cores" (``<n> of <m> cores`` where this process may use only n of the
    machine's m: :func:`usable_cores`): what a sweep cell and run record, so that timings
    measured on different machines are never compared unknowingly."""
    return f"{cpu_name()}, {cores_text()}"


def machine_info() -> dict[str, Any]:
    """CPU, core count and package versions, printed in every report."""
    cpu = cpu_name()
    from importlib.metadata import PackageNotFoundError, version

    packages = {}
    for pkg in ("dbench", "mitsuba", "drjit", "mitransient", "numpy", "numba", "torch",
                "pyoidn", "flip-evaluator", "scikit-image", "onnxruntime"):
        try:
            packages[pkg] = version(pkg)
        except PackageNotFoundError:
            packages[pkg] = "missing"
    try:
        import torch
        gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "none"
    except Exception:  # noqa: BLE001
        gpu = "unknown"
    from ..memory import advice_text

    return {"cpu": cpu, "cores": os.cpu_count(), "usable_cores": usable_cores(),
            "python": platform.python_version(),
            "platform": platform.platform(), "gpu": gpu, "packages": packages,
            "memory": advice_text()}
