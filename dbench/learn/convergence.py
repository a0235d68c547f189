"""Do the learned denoisers converge? Their error against the noisy input's over the whole spp
range users run, on the steady catalogue and on scenes no network was trained or tuned on.

    python -m dbench.learn.convergence [--res 64] [--spp 1,4,16,64,256,1024] [--ref-spp 4096]
        [--old-nca PATH --old-autoencoder PATH] [--weights LABEL=METHOD:PATH ...] [--nca-steps K]
        [--out results/learned_convergence.md]

For every scene and spp: relMSE (ε = 1e-2) of each method divided by the noisy input's relMSE
(< 1: the method helps), the log-log slope of each method's relMSE from 16 to 1024 spp (least
squares; negative: its error falls as samples are added), and the checks of the convergence
issue. ``--old-*`` adds rows for earlier weights (ONNX files) under ``nca (old)`` and
``autoencoder (old)``.

Scenes: the steady catalogue (``EVAL_SCENES``) and ``OUTSIDE_SCENES``: the XML scene
``examples/scenes/gold-glass-lamp.xml`` (gold floor, glass, a small visible lamp) and two
procedural scenes of another family (``family_seed`` 1) than the training set's (0).

The reference's own error is stated: the mean over pixels of its variance (``reference_var``)
relative to the noisy input's squared error at the highest spp.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..run import fpenv

EVAL_SCENES = ("cornell", "mirrors", "caustic", "textured", "fireflies")
XML_SCENE = Path(__file__).resolve().parents[2] / "examples" / "scenes" / "gold-glass-lamp.xml"
OUTSIDE_FAMILY = (1, (0, 1))  # family_seed, indices
SPPS = (1, 4, 16, 64, 256, 1024)
METHODS = ("noisy", "nca", "autoencoder", "nca+gate", "autoencoder+gate", "oidn", "oidn+gate")


def outside_scenes() -> list[Any]:
    """Scenes outside the catalogue and the training family: the XML scene (when the source
    tree is there) and two procedural scenes of family 1."""
    from ..datasets.scenes import get
    from .scenes import training_scene

    family, indices = OUTSIDE_FAMILY
    out = [get(str(XML_SCENE))] if XML_SCENE.exists() else []
    for i in indices:
        sc = training_scene(i, family)
        out.append(sc)
    return out


def _scene_label(sc: Any) -> str:
    name = getattr(sc, "name", str(sc))
    return f"{name} (family 1)" if name.startswith("train-") else name


def rows(scenes: Sequence[Any], spps: Sequence[int] = SPPS, res: int = 64,
         ref_spp: int = 4096, methods: dict[str, tuple[str, dict]] | None = None,
         cache=None, seed: int = 0) -> list[dict[str, Any]]:
    """{scene, spp, method, relmse, rmse, ref_share} per scene, spp and method label;
    ``methods`` maps labels to (registered name, parameters)."""
    from .. import datasets, metrics
    from .. import methods as registry

    methods = methods or {m: (m, {}) for m in METHODS}
    out = []
    for sc in scenes:
        for spp in spps:
            frame = datasets.load(sc, spp=spp, res=res, seed=seed, ref_spp=ref_spp,
                                  needs={"color", "albedo", "normal", "depth", "reference",
                                         "stats", "emitter"}, cache=cache, progress=False)
            ref_var = float(np.mean(frame.reference_var)) if frame.reference_var is not None \
                else float("nan")
            for label, (name, params) in methods.items():
                m = registry.get(name, **params)
                m.reset()
                den = fpenv.denoise(m, frame)
                vals = metrics.compute_all(den, frame.reference, names=["rmse", "relmse"])
                out.append({"scene": _scene_label(sc), "spp": int(spp), "method": label,
                            "relmse": float(vals["relmse"]), "rmse": float(vals["rmse"]),
                            "ref_var": ref_var})
    return out


def _get(rows_: list[dict], scene: str, spp: int, method: str, key: str = "relmse") -> float:
    for r in rows_:
        if r["scene"] == scene and r["spp"] == spp and r["method"] == method:
            return r[key]
    return float("nan")


def slope(rows_: list[dict], scene: str, method: str, lo: int = 16, hi: int = 1024) -> float:
    """Least-squares slope of log relMSE against log spp over the spp in [lo, hi]."""
    pts = [(r["spp"], r["relmse"]) for r in rows_ if r["scene"] == scene
           and r["method"] == method and lo <= r["spp"] <= hi and r["relmse"] > 0]
    if len(pts) < 2:
        return float("nan")
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def markdown(rows_: list[dict], settings: dict[str, Any]) -> str:
    scenes = list(dict.fromkeys(r["scene"] for r in rows_))
    spps = sorted({r["spp"] for r in rows_})
    methods = [m for m in dict.fromkeys(r["method"] for r in rows_) if m != "noisy"]
    head = "| scene | spp | noisy relMSE | " + " | ".join(methods) + " |"
    lines = ["# Learned denoisers over the spp range", "",
             f"Generated by `python -m dbench.learn.convergence` ({settings['when']}): "
             f"{settings['res']} px, references at {settings['ref_spp']} spp, noisy seed 0. "
             "Each method's relMSE (ε = 1e-2, linear HDR) divided by the noisy input's: below "
             "1 the method helps, **bold** where it is worse than its input. Catalogue scenes "
             f"({', '.join(EVAL_SCENES)}) and scenes outside it and the training family "
             "(`gold-glass-lamp.xml`: gold floor, glass, a small visible lamp; two procedural "
             "scenes of family 1).", "",
             head, "|---|---:|---:|" + "---:|" * len(methods)]
    for s in scenes:
        for spp in spps:
            base = _get(rows_, s, spp, "noisy")
            cells = []
            for m in methods:
                v = _get(rows_, s, spp, m) / base
                cells.append(f"**{v:.3g}**" if v > 1 else f"{v:.3g}")
            lines.append(f"| {s} | {spp} | {base:.4g} | " + " | ".join(cells) + " |")
    lines += ["", "## Log-log slope of relMSE from 16 to 1024 spp", "",
              "| scene | noisy | " + " | ".join(methods) + " |",
              "|---|---:|" + "---:|" * len(methods)]
    for s in scenes:
        vals = [slope(rows_, s, m) for m in ["noisy"] + methods]
        lines.append(f"| {s} | " + " | ".join(f"{v:.2f}" for v in vals) + " |")
    lines += ["", "## Checks", ""] + checks(rows_) + [""]
    top = max(spps)
    shares = []
    for s in scenes:
        ref_var = _get(rows_, s, top, "noisy", "ref_var")
        noisy_mse = _get(rows_, s, top, "noisy", "rmse") ** 2
        shares.append(f"{s} {ref_var / noisy_mse:.0%}")
    lines += [f"The references' own error (mean variance of the reference over the noisy input's "
              f"MSE at {top} spp): {', '.join(shares)}. It is part of every measured error at "
              "that spp, the noisy input's included.", ""]
    return "\n".join(lines)


def checks(rows_: list[dict]) -> list[str]:
    """Below the noisy input at every spp; negative slope from 16 to 1024 spp."""
    scenes = list(dict.fromkeys(r["scene"] for r in rows_))
    spps = sorted({r["spp"] for r in rows_})
    methods = [m for m in dict.fromkeys(r["method"] for r in rows_) if m != "noisy"]
    out = []
    for m in methods:
        worse = [(s, n) for s in scenes for n in spps
                 if _get(rows_, s, n, m) >= _get(rows_, s, n, "noisy")]
        flat = [s for s in scenes if not slope(rows_, s, m) < 0]
        out.append(f"- `{m}`: below the noisy input in {len(scenes) * len(spps) - len(worse)}/"
                   f"{len(scenes) * len(spps)} cells"
                   + (f" (not: {', '.join(f'{s} {n}' for s, n in worse)})" if worse else "")
                   + f"; slope negative on {len(scenes) - len(flat)}/{len(scenes)} scenes"
                   + (f" (not: {', '.join(flat)})" if flat else "") + ".")
    return out


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--res", type=int, default=64)
    p.add_argument("--spp", default=",".join(map(str, SPPS)))
    p.add_argument("--ref-spp", type=int, default=4096)
    p.add_argument("--old-nca", default=None)
    p.add_argument("--old-autoencoder", default=None)
    p.add_argument("--weights", action="append", default=[], metavar="LABEL=METHOD:PATH",
                   help="more columns: METHOD (nca or autoencoder) with the ONNX file PATH "
                        "under LABEL, e.g. 'autoencoder (no gate)=autoencoder:old.onnx'")
    p.add_argument("--nca-steps", type=int, action="append", default=[],
                   help="a column of the shipped nca with this fixed step count")
    p.add_argument("--out", default="results/learned_convergence.md")
    args = p.parse_args(argv)
    from .. import datasets
    from ..io import write_json, write_text

    methods = {m: (m, {}) for m in METHODS}
    if args.old_nca:
        methods["nca (old)"] = ("nca", {"weights": args.old_nca})
    if args.old_autoencoder:
        methods["autoencoder (old)"] = ("autoencoder", {"weights": args.old_autoencoder})
    for spec in args.weights:
        label, _, rest = spec.partition("=")
        method, _, path = rest.partition(":")
        if not label or method not in ("nca", "autoencoder") or not path:
            from ..errors import DbenchInputError
            raise DbenchInputError(f"--weights: expected LABEL=nca:PATH or "
                                   f"LABEL=autoencoder:PATH, got {spec!r}")
        methods[label] = (method, {"weights": path})
    for k in args.nca_steps:
        methods[f"nca ({k} step{'s' if k != 1 else ''})"] = ("nca", {"iterations": k})
    scenes = list(EVAL_SCENES) + outside_scenes()
    spps = [int(s) for s in args.spp.split(",")]
    data = rows(scenes, spps, args.res, args.ref_spp, methods, cache=datasets.Cache())
    settings = {"res": args.res, "ref_spp": args.ref_spp, "spp": spps,
                "when": time.strftime("%Y-%m-%d %H:%M")}
    out = Path(args.out)
    write_text(out, markdown(data, settings))
    write_json(out.with_suffix(".json"), {"settings": settings, "rows": data})
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
