"""A sweep on a GPU times the methods with a device path there and the others on the host
(README.md, "On a GPU"; docs/gpu.md §3): the sweep's README says which methods ran on which
device, warns when both stand side by side, and ``tables/cells.csv`` names each cell's device
and backend, as a run's report does."""
from __future__ import annotations

import json

import pandas as pd

from dbench.report import publish

MACHINE = {"cpu": "c", "cores": 2, "gpu": "NVIDIA H200", "python": "3", "platform": "p",
           "packages": {}}
CONFIG = {"labels": ["noisy", "jbf"], "methods": ["noisy", "jbf"], "scenes": ["cornell"],
          "spp": [4], "res": 16, "seeds": 2, "seed": 0, "ref_spp": 64, "repeats": 1}


def _cell(method: str, device: str, name: str, backend: str) -> dict:
    c = {"status": "ok", "scene": "cornell", "method": method, "base_method": method,
         "spp": 4, "res": 16, "n_seeds": 2, "ci_kind": "t 95 % over 2 seeds", "ref_spp": 64,
         "ref_rmse": 0.001, "time_s": 0.01, "n_nonfinite": 0, "machine": "c, 2 cores",
         "device": device, "device_name": name, "backend": backend}
    for m, v in (("rmse", 0.1), ("relmse", 0.02), ("rmse_surface", 0.05)):
        c[m], c[m + "_ci"] = v, v / 100
    return c


def _publish(tmp_path, cells) -> tuple[str, pd.DataFrame]:
    sweep = tmp_path / "results" / "sweep"
    sweep.mkdir(parents=True)
    (sweep / "sweep.json").write_text(json.dumps({"config": CONFIG, "machine": MACHINE}))
    for c in cells:
        p = sweep / "cells" / "cornell" / "00004spp" / f"{c['method']}.json"
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(c))
    text = publish.publish(tmp_path / "results").read_text(encoding="utf-8")
    return " ".join(text.split()), pd.read_csv(sweep / "tables" / "cells.csv")


def test_gpu_and_cpu_times_side_by_side_are_named(tmp_path):
    text, table = _publish(tmp_path, [_cell("noisy", "cpu", "cpu", "python"),
                                      _cell("jbf", "cuda", "NVIDIA H200", "triton")])
    assert ("methods run on cpu (1: noisy); cuda (NVIDIA H200) (1: jbf) (**times of different "
            "devices side by side: time_s compares devices as well as methods**)") in text
    got = table.set_index("method")[["device", "backend"]].to_dict("index")
    assert got == {"jbf": {"device": "cuda (NVIDIA H200)", "backend": "triton"},
                   "noisy": {"device": "cpu", "backend": "python"}}


def test_a_cpu_sweep_says_so_once(tmp_path):
    text, table = _publish(tmp_path, [_cell("noisy", "cpu", "cpu", "python"),
                                      _cell("jbf", "cpu", "cpu", "numba")])
    assert "methods run on cpu (2)" in text and "different devices" not in text
    assert set(table["device"]) == {"cpu"}
