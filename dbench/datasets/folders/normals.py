"""How a folder's normal image is encoded: signed (n in [−1, 1]) or unsigned (n·0.5 + 0.5).

Both hypotheses are tested against what a normal is, a unit vector (README.md, "Renders from
another renderer"). Over the pixels each hypothesis calls valid (finite, and not the encoding
of "nothing hit": all-zero when signed, all-zero or 0.5 grey, which decodes to 0, when
unsigned) the median of |‖n‖ − 1| is taken as stored (signed) and of |‖2n − 1‖ − 1| (unsigned):

* one hypothesis fits (median ≤ :data:`FIT`) and the other is at least :data:`CLEAR` times
  farther from unit length: that encoding is chosen;
* otherwise (neither fits, or both are alike) nothing is guessed: the normals are used as
  stored and a warning says so, naming the file and both figures, and how to declare the
  encoding in ``dataset.json`` (``"normal_encoding": "signed"`` or ``"unsigned"``) or on the
  command line (``dbench run --normal-encoding``).

A declaration wins over the detection, and ``--normal-encoding`` over ``dataset.json``: the
command line is the user's word for this run, and a dataset one cannot edit (read-only, shared)
must still be usable when its ``dataset.json`` is wrong. The text says which declared it and,
when the two disagree, what ``dataset.json`` said (README.md, "Renders from another renderer").

The median, not the mean, decides: a share of background pixels stored as 0.5 grey, or a few
antialiased edge pixels whose averaged normals are short, move a mean past any threshold (an
unsigned image with a tenth of its pixels 0.5 grey has a mean deviation of 0.106 when decoded,
past a mean threshold of 0.1) while the median of the bulk stays near 0. Typical separations:
unit normals spread over a hemisphere and stored unsigned have a median |‖n‖ − 1| of 0.21 when
read as stored and 0 when decoded; signed normals that all face one octant keep unit length as
stored (0) and decode to 0.23.

Example:
    >>> import numpy as np
    >>> n = np.array([[[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]]], np.float32)
    >>> decide(n * 0.5 + 0.5, "v_0004.nrm.exr").encoding
    'unsigned'
    >>> decide(n, "v_0004.nrm.exr").encoding
    'signed'
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: A hypothesis fits when the median |‖n‖ − 1| of its decoded normals is at most this.
FIT = 0.15
#: The chosen hypothesis's median deviation must be this many times smaller than the other's.
CLEAR = 2.0
ENCODINGS = ("signed", "unsigned")


@dataclass(frozen=True)
class NormalEncoding:
    """The decision: ``encoding`` (what :func:`dbench.datasets.folders.exr_layers.decode_normals` is
    given), the two median deviations (NaN without a valid pixel), ``text`` for
    ``meta["normal_encoding"]`` and ``warning`` ("" or a sentence for
    ``meta["normal_warning"]``)."""

    encoding: str
    signed_dev: float
    unsigned_dev: float
    text: str
    warning: str = ""


def _median_dev(v: np.ndarray) -> float:
    if v.shape[0] == 0:
        return float("nan")
    return float(np.median(np.abs(np.linalg.norm(v, axis=-1) - 1.0)))


def deviations(normal: np.ndarray) -> tuple[float, float]:
    """(median |‖n‖ − 1| as stored, median |‖2n − 1‖ − 1| decoded) over each hypothesis's valid
    pixels of an (H, W, 3) normal image (module docstring)."""
    n = np.asarray(normal, np.float64).reshape(-1, 3)
    n = n[np.isfinite(n).all(axis=-1) & np.any(n != 0, axis=-1)]
    decoded = 2.0 * n - 1.0
    # 0.5 grey decodes to the zero vector: "nothing hit" in an unsigned file, not a normal
    decoded = decoded[np.linalg.norm(decoded, axis=-1) > 1e-3]
    return _median_dev(n), _median_dev(decoded)


def _figures(signed: float, unsigned: float) -> str:
    return f"median |‖n‖−1| {signed:.2f} as stored, {unsigned:.2f} decoded as 2n−1"


def decide(normal: np.ndarray, source: str) -> NormalEncoding:
    """Detect the encoding of ``normal`` (from the file ``source``, named in the texts)."""
    signed, unsigned = deviations(normal)
    figures = _figures(signed, unsigned)
    if not (np.isfinite(signed) or np.isfinite(unsigned)):
        return NormalEncoding("signed", signed, unsigned,
                              f"signed [−1,1], used as stored ({source} holds no normal: "
                              "every pixel is zero or not finite)")
    s = signed if np.isfinite(signed) else np.inf
    u = unsigned if np.isfinite(unsigned) else np.inf
    if u <= FIT and s >= CLEAR * u and s > u:
        return NormalEncoding("unsigned", signed, unsigned,
                              f"unsigned [0,1] → 2n−1 ({figures}; detected on {source})")
    if s <= FIT and u >= CLEAR * s and u > s:
        return NormalEncoding("signed", signed, unsigned,
                              f"signed [−1,1], used as stored ({figures}; detected on "
                              f"{source})")
    why = "neither is near unit length" if min(s, u) > FIT else "both are alike"
    return NormalEncoding(
        "signed", signed, unsigned,
        f"undecided, used as stored ({figures}; on {source})",
        f"normals in {source} fit neither encoding clearly ({figures}: {why}); they are used "
        "as stored, which may be wrong: declare \"normal_encoding\": \"signed\" or "
        "\"unsigned\" in dataset.json, or pass --normal-encoding")


#: Who declared an encoding, as :func:`declared` names it: ``dataset.json`` or the option.
BY_FILE, BY_OPTION = "dataset.json", "--normal-encoding"


def declared(encoding: str, normal: np.ndarray | None = None, source: str = "",
             by: str = BY_FILE, overrides: str | None = None) -> NormalEncoding:
    """The encoding ``by`` declares (:data:`BY_FILE` or :data:`BY_OPTION`, which wins over the
    ``overrides`` declaration of ``dataset.json``, named in the text when it differs); with the
    image, the figures are stated too, and a declaration the pixels clearly contradict gets a
    warning (the declaration still wins)."""
    text = ("unsigned [0,1] → 2n−1" if encoding == "unsigned" else
            "signed [−1,1], used as stored") + (
        " (declared in dataset.json" if by == BY_FILE else f" (given by {by}" + (
            f", over dataset.json's {overrides!r}" if overrides not in (None, encoding) else ""))
    if normal is None:
        return NormalEncoding(encoding, float("nan"), float("nan"), text + ")")
    signed, unsigned = deviations(normal)
    found = decide(normal, source)
    text += f"; {_figures(signed, unsigned)} on {source})"
    warning = ""
    if not found.warning and found.encoding != encoding:
        says = "dataset.json declares" if by == BY_FILE else f"{by} gives"
        warning = (f"{says} {encoding} normals, but {source} looks "
                   f"{found.encoding} ({_figures(signed, unsigned)}); "
                   + ("the declaration is used" if by == BY_FILE else f"{by} is used"))
    return NormalEncoding(encoding, signed, unsigned, text, warning)


def resolve(declared_as: str | None, image: np.ndarray | None, source: str = "",
            given: str | None = None) -> NormalEncoding | None:
    """The encoding of a folder's normals: ``given`` (``--normal-encoding``), else
    ``declared_as`` (``dataset.json``), else detected on ``image``, the first normal image of
    the view (read from ``source``); None without a normal image and without a declaration."""
    if given is not None:
        return declared(given, image, source, BY_OPTION, declared_as)
    if image is None:
        return None if declared_as is None else declared(declared_as)
    return declared(declared_as, image, source) if declared_as else decide(image, source)

