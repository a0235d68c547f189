"""ColorVideoVDP (Mantiuk et al. 2024, the ``cvvdp`` package) on linear HDR videos
(README.md, "Metrics").

:func:`cvvdp_jod` scores an output video against its reference in JOD (just-objectionable
differences): 10 means no visible difference, one JOD less means that 75 % of observers would
pick the better of the two, and heavy distortions go below 0. Higher is better. The package does all the vision modelling
(colour, contrast sensitivity, masking, temporal channels, pooling); this module only checks the
buffers, puts dbench's radiance on the display and calls it.

* Display: the package's ``standard_hdr_linear`` model (its ``display_models.json``): a 30-inch
  4K HDR monitor seen from 0.75 m (75.4 pixels per degree), peak 1500 cd/m², contrast 10⁶, 10 lux
  ambient, linear BT.709 input (Mitsuba's linear sRGB primaries).
* Luminance: ``L = WHITE_NITS · 2^EV · x`` cd/m², so that the value the LDR metrics' tone map
  shows as display white (``x · 2^EV = 1``, dbench/metrics/tonemapping.py) is the HDR reference
  white of ITU-R BT.2408, 203 cd/m²; highlights up to the peak (7.4× that white) stay visible and
  the display model clips above it. One fixed scale for the scene, never fitted to the frames, so
  output and reference, and every frame, meet the same display (a per-frame scale would hide the
  brightness pumping the metric is there to see).
* Frame rate: ``fps`` (dbench's sequences carry none; the sequence runner uses
  :data:`DEFAULT_FPS`).
* Non-finite output: NaN. The reference must be finite. Deterministic: one PyTorch thread on
  the CPU, the package's own parameters.
* The package runs offline: its parameters and look-up tables ship inside it
  (``pycvvdp/vvdp_data``, read through an explicit path so that ``CVVDP_PATH`` cannot swap them);
  tests/metrics/test_video_quality.py runs it with the network blocked.

Example:
    >>> import numpy as np
    >>> from dbench.metrics.video_quality import cvvdp_jod
    >>> ref = np.full((4, 32, 32, 3), 0.3)
    >>> round(cvvdp_jod(ref, ref, fps=30), 3)
    10.0
"""
from __future__ import annotations

import functools
import math
import threading
import warnings
from typing import Any

import numpy as np

from ..data import check_buffer
from ..errors import DbenchInputError
from .tonemapping import check_ev

#: The package's display model used by default (see the module docstring).
CVVDP_DISPLAY = "standard_hdr_linear"
#: cd/m² of a linear value 2^-EV: ITU-R BT.2408's HDR reference (diffuse) white.
WHITE_NITS = 203.0
#: Frame rate of a sequence that states none: the low end of real-time rendering, where the
#: frame-to-frame artefacts of temporal denoisers (flicker, ghosting) last longest on screen.
DEFAULT_FPS = 30.0
#: Largest frames × pixels scored by default in sequence cells (24 frames of 128 × 128 px).
#: The cost grows with frames × pixels, about 0.5 s there on one core (README.md, "Metrics"),
#: and would reach tens of seconds per method and seed at 720p, so larger sequences get the
#: metric only when asked for.
AUTO_MAX_SAMPLES = 24 * 128 * 128
#: One-line definition for reports.
CVVDP_DEFINITION = (
    "cvvdp: ColorVideoVDP 0.5.7 (Mantiuk et al. 2024) quality in JOD (10 = no visible "
    "difference, higher is better) of the video after the warm-up, display 'standard_hdr_linear' "
    f"(4K 30-inch HDR, 1500 cd/m² peak, 75.4 ppd), luminance {WHITE_NITS:g}·2^EV·x cd/m², "
    f"{DEFAULT_FPS:g} fps")

#: Smallest height and width the package's pyramid accepts (1-px frames have no band).
MIN_SIDE = 2

_LOCK = threading.Lock()


@functools.lru_cache(maxsize=4)
def _metric(display: str):
    """The package's metric object for ``display`` on the CPU, built once per process."""
    import os

    import torch
    with warnings.catch_warnings():
        # torchvision's compiled image I/O is not used (only its Gaussian blur, plain PyTorch),
        # so the warning that it cannot be loaded says nothing about this metric.
        warnings.simplefilter("ignore")
        import pycvvdp
    data = os.path.join(os.path.dirname(pycvvdp.__file__), "vvdp_data")
    names = _display_names(data)
    if display not in names:
        raise DbenchInputError(f"display: unknown ColorVideoVDP display model {display!r}; "
                               f"expected one of {', '.join(sorted(names))}")
    return pycvvdp.cvvdp(display_name=display, quiet=True, device=torch.device("cpu"),
                         config_paths=[data])


def _display_names(data_dir: str) -> set[str]:
    import json
    import os

    with open(os.path.join(data_dir, "display_models.json"), encoding="utf-8") as f:
        return set(json.load(f))


def _check_video(name: str, x: Any, shape: tuple[int | None, ...]) -> np.ndarray:
    arr = np.asarray(x) if x is not None else None
    if arr is not None and np.iscomplexobj(arr):
        raise DbenchInputError(f"{name}: expected a real (T, H, W, 3) linear video, got dtype "
                               f"{arr.dtype}")
    return check_buffer(name, arr, shape, dtype=np.float64)


def cvvdp_jod(output: Any, reference: Any, fps: float = DEFAULT_FPS,
              display: str = CVVDP_DISPLAY, ev: float = 0.0) -> float:
    """ColorVideoVDP quality of ``output`` against ``reference`` in JOD (README.md, "Metrics").

    Args:
        output: (T, H, W, 3) linear HDR video, the reference's shape; may hold NaN/Inf.
        reference: (T, H, W, 3) linear HDR video, finite.
        fps: frames per second (finite, > 0); ignored for T = 1 (scored as an image).
        display: a display model of the package (default :data:`CVVDP_DISPLAY`).
        ev: the scene's exposure in stops, as for the tone map; luminance is
            ``WHITE_NITS · 2^ev · x`` cd/m².

    Returns:
        JOD (10 = identical, higher is better); NaN when ``output`` is not finite.

    Raises:
        DbenchInputError: naming ``output``, ``reference``, ``fps``, ``display`` or ``ev``.
    """
    ref = _check_video("reference", reference, (None, None, None, 3))
    if not np.all(np.isfinite(ref)):
        raise DbenchInputError("reference: contains NaN or Inf; expected finite values of "
                               f"shape (T, H, W, 3) = {ref.shape}")
    if min(ref.shape[1:3]) < MIN_SIDE:
        raise DbenchInputError(f"reference: expected (T, H, W, 3) with H, W >= {MIN_SIDE} "
                               f"(ColorVideoVDP's smallest frame), got {ref.shape}")
    out = _check_video("output", output, ref.shape)
    try:
        rate = float(fps)
    except (TypeError, ValueError):
        raise DbenchInputError(f"fps: expected a finite number > 0, got {fps!r}") from None
    if not (math.isfinite(rate) and rate > 0):
        raise DbenchInputError(f"fps: expected a finite number > 0, got {fps!r}")
    scale = WHITE_NITS * 2.0 ** check_ev(ev)
    if not isinstance(display, str):
        raise DbenchInputError(f"display: expected a display model name, got {display!r}")
    metric = _metric(display)
    if not np.all(np.isfinite(out)):
        return float("nan")
    import torch

    peak = float(metric.display_photometry.get_peak_luminance())
    # The display shows nothing outside [0, peak] (the package clips each channel there);
    # clipping first keeps float32 finite for outputs near the float range.
    test_t = torch.from_numpy(np.clip(out * scale, 0.0, peak).astype(np.float32))
    ref_t = torch.from_numpy(np.clip(ref * scale, 0.0, peak).astype(np.float32))
    frames = ref.shape[0]
    with _LOCK, torch.no_grad():
        threads = torch.get_num_threads()
        # One thread: the figure cannot depend on the machine's core count, and PyTorch's
        # OpenMP team no longer waits on threads that FLIP's and numba's pools keep busy
        # (on 2 shared cores, 24 frames of 64² took 2.5-6 s with two threads, 0.37 s with one).
        torch.set_num_threads(1)
        try:
            if frames == 1:
                jod, _ = metric.predict(test_t[0], ref_t[0], dim_order="HWC",
                                        frames_per_second=0)
            else:
                jod, _ = metric.predict(test_t, ref_t, dim_order="FHWC",
                                        frames_per_second=rate)
        finally:
            torch.set_num_threads(threads)
    value = float(jod)
    return value if math.isfinite(value) else float("nan")


def scored_frames(n_frames: int, warmup: int) -> slice:
    """The frames a sequence's ``cvvdp`` covers: those after the warm-up, as the sequence's
    other means (dbench/run/sequence_run.py); all of them when there are no more than that."""
    return slice(int(warmup), None) if n_frames > warmup else slice(0, None)


def use_cvvdp(frames: int, height: int, width: int, wanted: bool | None = None) -> bool:
    """Whether a sequence cell scores ``cvvdp``: ``wanted`` when given, else only when
    frames × height × width <= :data:`AUTO_MAX_SAMPLES` (``frames`` the scored ones)."""
    if wanted is not None:
        return bool(wanted)
    return int(frames) * int(height) * int(width) <= AUTO_MAX_SAMPLES


def sequence_cvvdp(outputs: list, references: list, warmup: int, ev: float = 0.0,
                   fps: float = DEFAULT_FPS, wanted: bool | None = None) -> dict[str, float]:
    """``{"cvvdp": JOD}`` of a sequence's (H, W, 3) output frames against its references over
    :func:`scored_frames`, or ``{}`` when :func:`use_cvvdp` says no; NaN for frames under
    :data:`MIN_SIDE` px."""
    if len(outputs) != len(references):
        raise DbenchInputError(f"outputs: expected {len(references)} frames, got {len(outputs)}")
    if not references:
        return {}
    keep = scored_frames(len(references), warmup)
    refs = references[keep]
    h, w = np.shape(refs[0])[:2]
    if not use_cvvdp(len(refs), h, w, wanted):
        return {}
    if min(h, w) < MIN_SIDE:
        return {"cvvdp": float("nan")}
    try:
        out, ref = np.stack(outputs[keep]), np.stack(refs)
    except ValueError as e:
        raise DbenchInputError(f"outputs: expected frames of the references' shape "
                               f"{np.shape(refs[0])}: {e}") from None
    return {"cvvdp": cvvdp_jod(out, ref, fps=fps, ev=ev)}


__all__ = ["cvvdp_jod", "use_cvvdp", "sequence_cvvdp", "scored_frames", "CVVDP_DISPLAY", "WHITE_NITS", "DEFAULT_FPS",
           "AUTO_MAX_SAMPLES", "CVVDP_DEFINITION", "MIN_SIDE"]
