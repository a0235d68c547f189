"""Which feature buffers a folder's series of spp uses (README.md, "Renders from another
renderer"; docs/formats.md §1).

A feature (:data:`FEATURES`) of a noisy spp comes from that spp's own files or, failing that,
from the reference's (OIDN training sets may store clean features once). A feature that some
spp of the series have and others lack, while the reference has none, is left out at every spp:
a method that reads it would run with it on some rows and without it on others, and its rows
would no longer compare across the series. Refusing the folder instead would also refuse the
methods that read no feature. Leaving it out is said, never silent: ``meta["feature_warning"]``
names the spp that lack which buffer and how to complete them, and each file left unread is in
``meta["layers_ignored"]`` with the reason. Per-pixel statistics (``.stats.npz``, or a variance
image) that some spp lack are left out of the whole series in the same way
(:func:`stats_left_out`). A feature that some spp have and the others take
from the reference is used (the rows then differ in their features' noise, which the loads that
read it say in ``meta["feature_warning"]``).

Example:
    >>> gaps({4: {"color", "albedo"}, 16: {"color"}})
    {'albedo': (16,)}
    >>> left_out({"albedo": (16,)}, set(), "v", {"albedo": "alb"})[:80]
    'albedo missing at spp 16, and not in the reference: albedo left out at every spp'
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

#: Buffers that come from an spp's own files or, failing that, from the reference's.
FEATURES = ("albedo", "normal", "depth", "position", "emitter", "motion")


def _spps(values) -> str:
    return ", ".join(map(str, values))


def gaps(own: Mapping[int, set[str]]) -> dict[str, tuple[int, ...]]:
    """{feature: the spp that lack it} for every feature that some spp of the series hold in
    their own files and others do not; ``own``: {spp: the buffers of that spp's own files}."""
    out = {}
    for b in FEATURES:
        lacking = tuple(s for s in sorted(own) if b not in own[s])
        if lacking and len(lacking) < len(own):
            out[b] = lacking
    return out


def left_out(found: Mapping[str, tuple[int, ...]], ref: set[str], view: str,
             tags: Mapping[str, str]) -> str:
    """"" or the warning for the features of ``found`` (:func:`gaps`) that the reference
    (``ref``: the buffers of its files) lacks, which are left out at every spp; ``tags``:
    {feature: the tag of its one-buffer file}, for the files that would complete them."""
    out = {b: s for b, s in found.items() if b not in ref}
    if not out:
        return ""
    it = "it" if len(out) == 1 else "them"
    files = ", ".join(f"{view}_ref.{tags[b]}.exr" for b in out)
    return ("; ".join(f"{b} missing at spp {_spps(s)}" for b, s in out.items())
            + f", and not in the reference: {', '.join(out)} left out at every spp, so that "
            f"the series' rows stay comparable (methods that need {it} are skipped, the others "
            f"run without {it}); to use {it}, add the missing files at those spp, or once for "
            f"the reference ({files})")


def left_out_files(found: Mapping[str, tuple[int, ...]], ref: set[str],
                   slot: Mapping[str, object]) -> list[str]:
    """``meta["layers_ignored"]`` lines for the left-out features (:func:`left_out`) that the
    loaded spp's own files hold; ``slot``: {buffer: Layer} of that spp's files."""
    return [f"{slot[b].file.name}: {b} left out at every spp (missing at spp {_spps(s)}, "
            "and not in the reference)" for b, s in found.items() if b not in ref and b in slot]


def mixed(found: Mapping[str, tuple[int, ...]], ref: set[str], loaded: set[str],
          ref_files: Mapping[str, str]) -> str:
    """"" or the warning for the ``loaded`` features of ``found`` that the spp lacking them
    take from the reference (``ref_files``: {feature: its file}) while the others use their
    own."""
    parts = [f"{b} at spp {_spps(s)} comes from the reference ({ref_files[b]}), at the other "
             "spp from their own files" for b, s in found.items() if b in ref and b in loaded]
    if not parts:
        return ""
    return "; ".join(parts) + (": the series' rows differ in the noise of their features "
                               "(a feature-using method's rows do not compare across spp)")


def stats_left_out(lacking: Sequence[int], view: str) -> str:
    """The warning for per-pixel statistics (a ``.stats.npz`` or a ``.var.exr``) that the spp
    ``lacking`` do not have while others do: left out at every spp, as a feature would be."""
    return (f"statistics (.stats.npz or .var.exr) missing at spp {_spps(lacking)}: left out at "
            "every spp, so that the series' rows stay comparable (methods that need them are "
            f"skipped); to use them, add a {view}_<spp>.stats.npz or .var.exr at those spp")


def non_finite(buffers: dict, files: dict) -> str:
    """What ``meta["feature_warning"]`` says of feature buffers holding NaN or ±Inf values
    (another renderer's depth or position where a pixel sees no surface, a broken normal),
    '' when none does: the methods read them as they are (their outputs stay finite), and the
    user learns that the buffers hold them."""
    said = []
    for b in FEATURES:
        if b in buffers:
            bad = int(np.count_nonzero(~np.isfinite(buffers[b])))
            if bad:
                said.append(f"{b}: {bad} values NaN or Inf in {files[b]}")
    return "; ".join(said)


__all__ = ["FEATURES", "gaps", "left_out", "left_out_files", "mixed", "non_finite",
           "stats_left_out"]
