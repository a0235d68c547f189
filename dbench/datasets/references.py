"""Reference settings shared by the steady, sequence and transient loaders: the default spp
(``DBENCH_REF_SPP``), the reference seed and the reference entries of a frame's ``meta``."""
from __future__ import annotations

import os

import numpy as np

from ..data import MAX_COUNT
from ..errors import DbenchInputError

DEFAULT_REFERENCE_SPP = 4096
#: Largest seed: Mitsuba takes a render's seed as an unsigned 32-bit integer (``mi.render``
#: refuses -1 and 2**32), so a seed outside [0, MAX_SEED] is not a seed a render could have used.
MAX_SEED = 2**32 - 1
#: Fewest and most reference spp: the reference's variance is the spread of its chunks, and one
#: sample is one chunk, whose spread reads as zero (a "noise-free" reference); Mitsuba's spp is a
#: signed 32-bit integer.
MIN_REF_SPP, MAX_REF_SPP = 2, MAX_COUNT


def seed_problem(seed, n_seeds: int = 1) -> str:
    """'' when ``seed`` … ``seed + n_seeds − 1`` all lie in [0, :data:`MAX_SEED`], else the
    words that say the valid range."""
    top = MAX_SEED - max(int(n_seeds), 1) + 1
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) \
            or not 0 <= seed <= top:
        extra = f" with --seeds {n_seeds}" if n_seeds > 1 else ""
        return (f"expected an integer in [0, {top}]{extra} (render seeds are unsigned 32-bit), "
                f"got {seed!r}")
    return ""


def check_seed(seed, n_seeds: int = 1, name: str = "--seed") -> int:
    """``seed`` as an int (:func:`seed_problem`); DbenchInputError naming ``name`` and the valid
    range otherwise."""
    problem = seed_problem(seed, n_seeds)
    if problem:
        raise DbenchInputError(f"{name}: {problem}")
    return int(seed)


def ref_spp_problem(value) -> str:
    """'' when ``value`` is an integer in [:data:`MIN_REF_SPP`, :data:`MAX_REF_SPP`], else the
    words that say the valid range and why 1 is not in it."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or not MIN_REF_SPP <= value <= MAX_REF_SPP:
        return (f"expected an integer in [{MIN_REF_SPP}, {MAX_REF_SPP}] (the reference's "
                f"variance is the spread of its chunks, and 1 spp is one chunk), got {value!r}")
    return ""


def check_ref_spp(value, name: str = "--ref-spp") -> int:
    """``value`` as an int (:func:`ref_spp_problem`); DbenchInputError naming ``name``."""
    problem = ref_spp_problem(value)
    if problem:
        raise DbenchInputError(f"{name}: {problem}")
    return int(value)


def reference_spp() -> int:
    """``DBENCH_REF_SPP`` (an integer in [2, 2³¹ − 1], the range of ``--ref-spp``), else
    :data:`DEFAULT_REFERENCE_SPP`; DbenchInputError naming the variable otherwise, so a bad
    value is one line and exit 2 before anything renders."""
    text = os.environ.get("DBENCH_REF_SPP", "").strip()
    if not text:
        return DEFAULT_REFERENCE_SPP
    try:
        value = int(text)
    except ValueError:
        value = text
    if ref_spp_problem(value):  # (the text, a str, is never valid: the words show it as given)
        raise DbenchInputError(f"DBENCH_REF_SPP: {ref_spp_problem(text)}; "
                               f"unset it for {DEFAULT_REFERENCE_SPP}")
    return value


def check_render_args(spp, seed, ref_spp) -> int:
    """Check a load's ``spp`` (an integer >= 1), ``seed`` (:func:`check_seed`) and ``ref_spp``
    (None for the default, else an integer in [2, 2³¹ − 1]: the reference's variance comes from
    the spread of its chunks, and one chunk has none); DbenchInputError naming the first that
    is not, before anything renders. Returns the seed as an int: a float seed would key the
    cache as its integer part while the render hashed the float."""
    from ..data import check_count

    check_count("spp", spp)
    seed = check_seed(seed, name="seed")
    if ref_spp is not None:
        check_ref_spp(ref_spp, "ref_spp")
    return seed


def check_ref_seed(ref_seed: int | None) -> int:
    """The reference seed: 0 for None, else an integer in [0, :data:`MAX_SEED`]
    (DbenchInputError)."""
    if ref_seed is None:
        return 0
    return check_seed(ref_seed, name="ref_seed")


def reference_meta(ref_spp: int, ref_seed: int, reference_var) -> dict:
    """``ref_spp``, ``ref_seed`` and ``ref_rmse`` = sqrt(mean(reference_var)) for ``meta``
    (``reference_var`` one array or a list of them, e.g. a sequence's frames)."""
    if isinstance(reference_var, (list, tuple)):
        total = sum(float(np.asarray(v, np.float64).sum()) for v in reference_var)
        count = sum(int(np.asarray(v).size) for v in reference_var)
        mean_var = total / max(count, 1)
    else:
        mean_var = float(np.mean(np.asarray(reference_var, np.float64)))
    return {"ref_spp": int(ref_spp), "ref_seed": int(ref_seed),
            "ref_rmse": float(np.sqrt(max(mean_var, 0.0)))}
