"""Sample values that come out NaN or ±Inf: counted as 0, counted, and said (README.md, "How
renders work").

A scene holding a non-finite value (a texture's pixel, a parameter) makes Mitsuba's film hold
NaN where such a sample lands. dbench's sums count those samples as 0 (the render kernel,
:class:`~dbench.datasets.stats.PowerSums`, here the ``mi.render`` chunks of every reference
and the transient passes), so its images stay finite but are not the scene's as Mitsuba
renders it. Every loader (steady, sequence, transient) states how many there were in its
frame's ``meta``: ``nonfinite_samples`` (the noisy input), ``ref_nonfinite_samples`` (the
reference; None or absent where none was loaded) and, where either is above 0,
``nonfinite_warning``, which ``dbench run`` prints and lists in report.md's notes and a sweep
records in its cells (``input_warnings``).

The render entries this rule changed carry :data:`NONFINITE_VERSION` in their cache keys, so
an entry cached before it (no count in its meta; a sequence's or video's reference holding
NaN) is never read as a new one."""
from __future__ import annotations

from typing import Iterable

import numpy as np

#: Marker in the cache key of the render entries this rule changed: the noisy colour and the
#: reference of a steady frame, a sequence frame and a transient video (each holds its count;
#: a sequence's or video's reference, a scalar variant's steady one and the steady image of a
#: video from collector (a) held NaN or ±Inf where a sample was), and the statistics of the
#: same renders (their keys extend the colour's). Entries made before it hold no count, so a
#: run would say nothing of such samples, and such a reference fails every method: they are
#: never read as new ones. Not in a scene's fingerprint (datasets.scene_fingerprint): where no sample is
#: non-finite the numbers are the same, so every cell keeps its identity.
NONFINITE_VERSION = "zeroed-counted-1"


def zeroed(values: np.ndarray) -> tuple[np.ndarray, int]:
    """(``values`` with every NaN or ±Inf value replaced by 0, how many there were): the rule
    of the sums for a film rendered by ``mi.render`` (a reference chunk, a transient pass),
    whose non-finite pixel values each stand for at least one such sample. ``values`` itself
    is returned, unchanged, where all are finite."""
    finite = np.isfinite(values)
    n = int(finite.size - np.count_nonzero(finite))
    return (values, 0) if n == 0 else (np.where(finite, values, 0).astype(values.dtype), n)


def total(counts: Iterable[int | None]) -> int | None:
    """The sum of the counts that were made (a sequence's over its frames), None where none
    was (no frame's reference was loaded)."""
    known = [int(n) for n in counts if n is not None]
    return sum(known) if known else None


#: How a transient video's noisy count from collector (a) is made (:func:`nonfinite_text`).
PER_PATH = ("; the noisy video's once per path over its whole length, not per bin: collector "
            "(a)'s film does not keep them bin by bin")


def nonfinite_text(noisy: int | None, reference: int | None, per_path: bool = False) -> str:
    """What a render's NaN or ±Inf sample values (one per channel; a transient video's over
    all its bins; None: not counted, where no reference was loaded) mean for its
    numbers, or '' where there were none: they are counted as 0 (README.md, "How renders
    work") where Mitsuba's film would hold NaN, so the images are not the scene's as Mitsuba
    renders it. ``per_path``: the noisy count is a transient video's from collector (a), made
    in its steady image (one per path and channel, whichever bins the path's values reached,
    in the window or not) where collector (b) counts one per bin (:data:`PER_PATH`)."""
    parts = [f"{n} in the {what}" for n, what in ((noisy, "noisy image"),
                                                  (reference, "reference")) if n]
    if not parts:
        return ""
    how = PER_PATH if per_path and noisy else ""
    return (f"the renderer gave NaN or ±Inf sample values ({' and '.join(parts)}; one per "
            f"channel{how}), counted as 0 where Mitsuba's own film would hold NaN: the scene "
            f"holds a non-finite value (a texture's pixel, a parameter), which its numbers "
            f"leave out")


def note_nonfinite(meta: dict, per_path: bool = False) -> dict:
    """``meta`` (a frame's or a sequence's) with ``nonfinite_warning`` added where its
    ``nonfinite_samples`` or ``ref_nonfinite_samples`` is above 0 (:func:`nonfinite_text`;
    ``per_path`` for a transient video's from collector (a))."""
    said = nonfinite_text(meta.get("nonfinite_samples"), meta.get("ref_nonfinite_samples"),
                          per_path)
    if said:
        meta["nonfinite_warning"] = said
    return meta


__all__ = ["NONFINITE_VERSION", "PER_PATH", "nonfinite_text", "note_nonfinite", "total", "zeroed"]
