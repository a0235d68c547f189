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


def machine_label() -> str:
    """"<cpu>, <n> cores": what a sweep cell and run record, so that timings measured on
    different machines are never compared unknowingly."""
    return f"{cpu_name()}, {os.cpu_count()} cores"


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

    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "platform": platform.platform(), "gpu": gpu, "packages": packages,
            "memory": advice_text()}
