"""The transient scene record (:class:`TransientScene`), its time axis (:class:`Window`, in
optical path length) and the transient film. The catalogue and the loader are in
:mod:`dbench.datasets.transient.load`."""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Callable

import numpy as np

from ...data import check_count
from ...errors import DbenchInputError
from ...resolution import parse_res
from ..scenes.record import Scene
from ..scenes.build import call_build, check_film

#: Speed of light in m/s (time = OPL / c).
SPEED_OF_LIGHT = 299792458.0
TRANSIENT_BUFFERS = frozenset({"color", "albedo", "normal", "depth", "position", "emitter",
                               "stats", "reference"})


@dataclass(frozen=True)
class Window:
    """The time axis of a transient film, in optical path length (scene units)."""

    start_opl: float
    bin_width_opl: float
    bins: int

    def __post_init__(self) -> None:
        check_count("bins", self.bins)
        if not (math.isfinite(self.bin_width_opl) and self.bin_width_opl > 0):
            raise DbenchInputError(f"bin_width_opl: expected a number > 0, got "
                                   f"{self.bin_width_opl!r}")

    @property
    def end_opl(self) -> float:
        return self.start_opl + self.bins * self.bin_width_opl

    def bin_of(self, opl: float) -> int:
        """Bin index of an OPL, ``floor((opl − start)/width)`` (may fall outside [0, T))."""
        return int(math.floor((opl - self.start_opl) / self.bin_width_opl))

    def centers(self) -> np.ndarray:
        return self.start_opl + (np.arange(self.bins) + 0.5) * self.bin_width_opl

    def meta(self) -> dict:
        return {"start_opl": float(self.start_opl), "bin_width_opl": float(self.bin_width_opl),
                "bins": int(self.bins), "end_opl": float(self.end_opl),
                "units": "m (optical path length; time = OPL / c)"}


@dataclass(frozen=True, eq=False)
class TransientScene(Scene):
    """A catalogue entry of kind ``transient``.

    ``build(mi, res)`` (or ``build(mi, width, height)``, :mod:`dbench.datasets.scenes.build`)
    returns the steady scene dictionary (hdrfilm, box filter);
    :meth:`transient_dict` swaps in the transient film and integrator.

    Attributes (beyond :class:`~dbench.datasets.scenes.record.Scene`):
        window_start, window_end: the OPL window (metres), from :func:`size_window`.
        default_bins: T when ``bins`` is not given.
        integrator: ``transient_path`` or ``transient_prbvolpath``.
        steady_integrator: the steady counterpart (``path`` / ``volpath``).
        rr_depth, camera_unwarp: integrator settings.
        feature_build: ``(mi, res) -> dict`` for the AOV render (default ``build``); the fog
            scene drops the medium so the G-buffers describe the surfaces behind it.
        medium: description of the participating medium (metadata), or None.
        emission: ``"pulse"`` (a Dirac delta at OPL 0, what mitransient renders) or ``"step"``
            (a Heaviside step switched on at OPL 0): the step response is the cumulative sum
            along T of the pulse response (docs/transient.md §7 check 5), taken per rendered
            pass (:meth:`signal`), so per-bin statistics of a step scene are those of each
            path's cumulative contributions. The window (and its energy check: the last bin
            against the steady image) is the pulse's.
        minus: a scene rendered with the same seeds whose video and steady image are subtracted
            pass by pass (``scattering=multiple`` of dbench.datasets.transient.media: all
            paths minus the paths of at most one scattering vertex), or None.
    """

    window_start: float = 0.0
    window_end: float = 1.0
    default_bins: int = 200
    integrator: str = "transient_path"
    steady_integrator: str = "path"
    rr_depth: int = 5
    camera_unwarp: bool = False
    feature_build: Callable[[Any, int], dict] | None = None
    medium: dict | None = None
    emission: str = "pulse"
    minus: "TransientScene | None" = None

    def window(self, bins: int | None = None) -> Window:
        t = self.default_bins if bins is None else bins
        check_count("bins", t)
        return Window(float(self.window_start),
                      (float(self.window_end) - float(self.window_start)) / int(t), int(t))

    def scene_dict(self, mi, res) -> dict:
        """The steady scene (hdrfilm) with the steady integrator."""
        d = call_build(self.build, mi, res, f"scene {self.name}")
        check_film(d, res, f"scene {self.name}", self.build)
        d["integrator"] = {"type": self.steady_integrator, "max_depth": self.max_depth}
        return d

    def transient_dict(self, mi, res, window: Window) -> dict:
        res = parse_res(res)
        d = call_build(self.build, mi, res, f"scene {self.name}")
        # the steady renders use the build's film: refuse a wrong size here, before any
        check_film(d, res, f"scene {self.name}", self.build)
        d["sensor"]["film"] = transient_film(res.width, res.height, window)
        d["integrator"] = {"type": self.integrator, "max_depth": self.max_depth,
                           "rr_depth": self.rr_depth, "camera_unwarp": self.camera_unwarp}
        return d

    def signal(self, video: np.ndarray) -> np.ndarray:
        """The scene's signal from a rendered pulse video (..., T, C): itself for ``pulse``;
        for ``step`` its cumulative sum along T (float64 sums, float32 out)."""
        if self.emission == "step":
            return np.cumsum(video, axis=-2, dtype=np.float64).astype(np.float32)
        return video

    @property
    def needs_passes(self) -> bool:
        """Whether the signal is made from whole rendered passes (step emission, a ``minus``
        scene): per-bin statistics then come from collector (a) only."""
        return self.emission == "step" or self.minus is not None

    @property
    def emitter_meta(self) -> str:
        return ("Heaviside step at OPL 0 (cumulative sum of the pulse response along T)"
                if self.emission == "step" else "delta pulse at OPL 0")

    @property
    def feature_scene(self) -> Scene:
        """A steady Scene for the AOV render (shared by every call, so loads are cached)."""
        return _feature_scene(self)


@lru_cache(maxsize=None)
def _feature_scene(sc: TransientScene) -> Scene:
    return Scene(name=f"{sc.name}:features", kind="steady", description="AOVs",
                 build=sc.feature_build or sc.build, max_depth=sc.max_depth)


#: Largest transient film (W × H × bins RGB float32 values) dbench renders. A run holds many
#: arrays of this size (float64 statistics, the reference's chunks, the methods' outputs,
#: figures): measured with ``dbench run --method noisy --scene cornell-transient --res 16``,
#: 8000 bins (a 25 MB film) took 0.88 GB more peak memory than 100 bins, about 36× the film,
#: so this limit keeps a run near 9 GiB.
MAX_TRANSIENT_FILM_BYTES = 256 * 2**20


def max_bins(res) -> int:
    """The most time bins a transient film of size ``res`` may have
    (:data:`MAX_TRANSIENT_FILM_BYTES`)."""
    return max(1, MAX_TRANSIENT_FILM_BYTES // (parse_res(res).pixels * 3 * 4))


def check_bins(bins, res, name: str = "bins") -> int:
    """``bins`` as an int when it is an integer in [1, :func:`max_bins` (res)], else a
    DbenchInputError naming ``name``, the film's size and the valid range (before rendering)."""
    res = parse_res(res)
    top = max_bins(res)
    if isinstance(bins, (bool, np.bool_)) or not isinstance(bins, (int, np.integer)) \
            or not 1 <= bins <= top:
        need = ""
        if isinstance(bins, (int, np.integer)) and not isinstance(bins, (bool, np.bool_)) \
                and bins > top:
            need = (f" (a {res.text} film of {int(bins)} bins needs "
                    f"{res.pixels * 3 * 4 * int(bins) / 1e9:.3g} GB as RGB float32; at most "
                    f"{MAX_TRANSIENT_FILM_BYTES // 2**20} MiB)")
        raise DbenchInputError(f"{name}: expected an integer in [1, {top}] at {res.text}, got "
                               f"{bins!r}{need}")
    return int(bins)


def transient_film(width: int, height: int, window: Window) -> dict:
    return {"type": "transient_hdr_film", "width": int(width), "height": int(height),
            "rfilter": {"type": "box"}, "temporal_bins": int(window.bins),
            "start_opl": float(window.start_opl), "bin_width_opl": float(window.bin_width_opl)}
