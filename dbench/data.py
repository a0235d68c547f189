"""Dataset types handed from the renderer to the denoisers.

Plain dataclasses around NumPy arrays, constructible directly so that methods and tests can
run on synthetic data. Shapes use (H, W, C) with row 0 at the top; C = 3 for colour buffers.

Buffer names (used in code, files and reports): ``color``, ``albedo``, ``normal``, ``depth``,
``position``, ``emitter``, ``motion``, ``gradient``, ``emission``, ``stats``, ``reference``,
``geo_normal``, ``reflected_normal``.
``reference_var`` (the variance of the reference mean) rides along with ``reference`` for the
judge; methods never ask for it. A :class:`Sequence` is a list of Frames of one animated scene
(docs/methods/temporal.md §1).

Example:
    >>> import numpy as np
    >>> f = Frame(color=np.zeros((4, 5, 3), np.float32))
    >>> f.shape
    (4, 5)
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .errors import DbenchInputError

#: Buffers a Frame may carry, with their channel count.
FRAME_BUFFERS: dict[str, int] = {
    "color": 3,
    "albedo": 3,
    "normal": 3,
    "depth": 1,
    "position": 3,
    "reference": 3,
    "motion": 2,
    "gradient": 3,
    "emission": 3,
    "emitter": 1,
    "geo_normal": 3,
    "reflected_normal": 3,
}
#: Every name a method may list in ``needs``.
BUFFER_NAMES = tuple(FRAME_BUFFERS) + ("stats",)


#: Largest count dbench takes (spp, frames, bins, ...): counts reach Mitsuba as 32-bit integers
#: (a reference chunk's spp, the transient film's ``temporal_bins``), and a larger one would run
#: for years anyway (README.md, "How renders work": Counts).
MAX_COUNT = 2**31 - 1


def check_count(name: str, value: Any) -> int:
    """``value`` as an int when it is an integer >= 1 (spp, res, bins, frames), else a
    DbenchInputError naming ``name``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or value < 1:
        raise DbenchInputError(f"{name}: expected an integer >= 1, got {value!r}")
    return int(value)


def _check_pixel_buffers(data: Any, channels_of: dict[str, int], h: int, w: int) -> None:
    """Validate and convert, in place, every per-pixel buffer of ``data`` named in
    ``channels_of`` ({name: C}) to (h, w, C) float32; absent buffers stay None and a 2-D depth
    gains its channel axis."""
    for name, channels in channels_of.items():
        value = getattr(data, name)
        if value is None:
            continue
        value = np.asarray(value)
        if name == "depth" and value.ndim == 2:
            value = value[..., None]
        setattr(data, name, check_buffer(name, value, (h, w, channels)))


def check_buffer(name: str, array: Any, shape: tuple[int | None, ...], *, dtype=np.float32,
                 finite: bool = False) -> np.ndarray:
    """Validate one buffer and return it as a C-contiguous array of ``dtype``.

    ``shape`` may hold ``None`` for a free dimension. The error names the buffer and the
    expected shape, so a caller never has to guess which input was wrong.
    """
    if array is None:
        raise DbenchInputError(f"{name}: missing; expected an array of shape {_fmt(shape)}")
    arr = np.asarray(array)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise DbenchInputError(f"{name}: expected a numeric array of shape {_fmt(shape)}, "
                               f"got dtype {arr.dtype}")
    if arr.ndim != len(shape) or any(e is not None and e != s for e, s in zip(shape, arr.shape)):
        raise DbenchInputError(f"{name}: expected shape {_fmt(shape)}, got {tuple(arr.shape)}")
    if any(s == 0 for s in arr.shape):
        raise DbenchInputError(f"{name}: empty array of shape {tuple(arr.shape)}; "
                               f"expected {_fmt(shape)} with every dimension > 0")
    arr = np.ascontiguousarray(arr, dtype=dtype)
    if finite and not np.all(np.isfinite(arr)):
        raise DbenchInputError(f"{name}: contains NaN or Inf; expected finite values")
    return arr


def _fmt(shape: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"


#: Sample transforms of the statistics (docs/methods/statistical.md §3), checked by :func:`check_transform`.
TRANSFORMS = ("identity", "box-cox", "yeo-johnson")

#: λ accepted by the transforms. The spec's sweep range is [0.25, 1.5]; beyond |λ| = 3 the cubes
#: of transformed radiance overflow float64 for bright pixels (λ = 300 gave Inf moments).
LAM_RANGE = (-3.0, 3.0)


def check_transform(transform: str, lam: float) -> None:
    """A known transform and a λ it accepts (DbenchInputError naming the problem otherwise)."""
    if transform not in TRANSFORMS:
        raise DbenchInputError(f"transform: unknown {transform!r}; expected one of {TRANSFORMS}")
    if isinstance(lam, bool) or not isinstance(lam, (int, float, np.integer, np.floating)) \
            or not np.isfinite(lam):
        raise DbenchInputError(f"lam: expected a finite number, got {lam!r}")
    if transform != "identity" and not LAM_RANGE[0] <= lam <= LAM_RANGE[1]:
        raise DbenchInputError(f"lam: {lam} is outside [{LAM_RANGE[0]}, {LAM_RANGE[1]}] "
                               "(larger |λ| overflows the moments of bright samples)")
    if transform == "box-cox" and lam <= 0:
        # Rendered samples are often exactly 0, where Box-Cox with λ ≤ 0 is undefined (§3).
        raise DbenchInputError(f"lam: Box-Cox needs λ > 0 on rendered samples (zeros occur), "
                               f"got {lam}")


@dataclass
class SampleStats:
    """Per-pixel, per-channel statistics of the transformed samples (docs/methods/statistical.md §4).

    Attributes:
        n: (H, W, C) sample count per pixel and channel; given one number, a read-only
            broadcast of it (no per-pixel copy), so write to a copy, never to ``n``.
        mean: (H, W, C) mean μ of the transformed samples.
        var_mean: (H, W, C) variance of the mean σ²/n (σ² unbiased; 0 where σ² is zero or n < 2).
        m3: (H, W, C) biased third central moment of the transformed samples.
        transform: ``"identity"``, ``"box-cox"`` or ``"yeo-johnson"``.
        lam: λ of the transform (ignored by ``identity``).
        diagnostics: counters such as ``n_clamped``, ``n_nonfinite``.
    """

    n: np.ndarray
    mean: np.ndarray
    var_mean: np.ndarray
    m3: np.ndarray
    transform: str = "box-cox"
    lam: float = 0.5
    diagnostics: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_transform(self.transform, self.lam)
        mean = np.asarray(self.mean)
        if mean.ndim < 1:
            raise DbenchInputError("stats.mean: expected an array, (H, W, C) for images or "
                                   f"(H, W, T, C) for transient data, got {tuple(mean.shape)}")
        shape = tuple(mean.shape)
        self.mean = check_buffer("stats.mean", mean, shape, dtype=np.float64)
        if np.ndim(self.n) == 0:
            # one count for every pixel (a render at a fixed spp) stays one value, read-only and
            # broadcast to the shape: a copy would be 8 bytes a value (39 MB at 128² × 100 bins,
            # whose first touch cost 0.27 s on a virtual machine, next to a 0.3 s render)
            one = (1,) * len(shape)
            self.n = np.broadcast_to(check_buffer("stats.n", np.reshape(self.n, one), one,
                                                  dtype=np.float64), shape)
        else:
            self.n = check_buffer("stats.n", self.n, shape, dtype=np.float64)
        self.var_mean = check_buffer("stats.var_mean", self.var_mean, shape, dtype=np.float64)
        self.m3 = check_buffer("stats.m3", self.m3, shape, dtype=np.float64)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(self.mean.shape)

    @property
    def theta(self) -> np.ndarray:
        """Skew-corrected mean θ̂ = μ + M3 / (6 σ² n), with the correction 0 where σ² = 0.

        σ² n = var_mean · n², so the correction is M3 / (6 var_mean n²) (docs/methods/statistical.md §4).
        """
        denom = 6.0 * self.var_mean * self.n * self.n
        corr = np.divide(self.m3, denom, out=np.zeros_like(self.m3), where=denom > 0)
        return self.mean + corr


@dataclass
class Frame:
    """One steady image and the buffers rendered with it.

    Attributes:
        color: (H, W, 3) float32 linear noisy radiance (the mean of the samples).
        albedo: (H, W, 3) float32 or None.
        normal: (H, W, 3) float32 world-space shading normal (0 where nothing is hit) or None.
        depth: (H, W, 1) float32 distance along the camera ray (0 where nothing is hit) or None.
        position: (H, W, 3) float32 world position or None.
        stats: SampleStats of the same samples as ``color`` or None.
        reference: (H, W, 3) float32 high-spp image or None.
        meta: scene, spp, seed, render timings and other settings; sequence frames add
            ``frame`` (index) and ``camera`` (``to_world`` 4×4 camera→world, ``origin``, ``fov``,
            ``fov_axis``, ``width``, ``height``; docs/methods/temporal.md §1).
        motion: (H, W, 2) float32 sequence frames only: offset in pixels (x right, y down) from
            each pixel to where its surface point was in the previous frame (docs/methods/temporal.md
            §3.1); NaN where there is no previous position (no hit, behind the previous camera).
        gradient: (H, W, 3) float32 sequence frames only (A-SVGF): the scene state of this frame
            rendered from the previous camera with the previous frame's random numbers
            (docs/methods/svgf.md §6.4); equal to ``color`` on the first frame.
        emission: (H, W, 3) float32 sequence frames only: radiance emitted by the surfaces the
            colour samples' primary rays hit (0 off lights), so filters can keep lights out of
            the demodulated illumination.
        emitter: (H, W, 1) float32 in [0, 1]: the fraction of the pixel's footprint (box
            filter) whose primary ray, directly or after reflections in smooth mirrors, sees
            an emitter sending radiance > 0 toward the camera (an area light's front, or the
            environment where the ray escapes); 0 on surfaces, fractional on a light's edge
            (dbench.datasets.emitter). Or None.
        reference_var: (H, W, 3) float32 ≥ 0, the variance of ``reference`` (the mean) per pixel
            and channel, estimated from K independent chunks of the reference render
            (docs/judging.md §2), or None. Comes with ``reference``; ``meta["ref_rmse"]`` =
            sqrt(mean(reference_var)).
        geo_normal: (H, W, 3) float32 sequence frames only (PSR G-buffers): the world-space
            geometric (face) normal of the surface ``normal`` describes, or None.
        reflected_normal: (H, W, 3) float32 sequence frames only (PSR G-buffers): ``normal``,
            replaced on glossy surfaces of roughness < 0.4 by the shading normal of what their
            mirror direction hits (seed 001 §1.2.1), or None.
        judged_lights: (H, W, 1) float32, 1 on the pixels the judge counts as lights where the
            frame has no ``emitter`` buffer (a folder of renders: the rule its
            ``meta["surface_pixels"]`` states, docs/formats.md), or None. Scoring only: no
            method reads it.
    """

    color: np.ndarray
    albedo: np.ndarray | None = None
    normal: np.ndarray | None = None
    depth: np.ndarray | None = None
    position: np.ndarray | None = None
    stats: SampleStats | None = None
    reference: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    motion: np.ndarray | None = None
    gradient: np.ndarray | None = None
    emission: np.ndarray | None = None
    emitter: np.ndarray | None = None
    reference_var: np.ndarray | None = None
    geo_normal: np.ndarray | None = None
    reflected_normal: np.ndarray | None = None
    judged_lights: np.ndarray | None = None

    kind = "steady"

    def __post_init__(self) -> None:
        color = np.asarray(self.color) if self.color is not None else None
        if color is None or color.ndim != 3:
            raise DbenchInputError("color: expected shape (H, W, 3), got "
                                   f"{None if color is None else tuple(color.shape)}")
        h, w = color.shape[:2]
        _check_pixel_buffers(self, FRAME_BUFFERS, h, w)
        if self.reference_var is not None:
            self.reference_var = check_buffer("reference_var", self.reference_var, (h, w, 3))
        if self.judged_lights is not None:
            self.judged_lights = check_buffer("judged_lights", self.judged_lights, (h, w, 1))
        if self.stats is not None and self.stats.shape != (h, w, 3):
            raise DbenchInputError(f"stats: expected shape (H, W, 3) = ({h}, {w}, 3), "
                                   f"got {self.stats.shape}")

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.color.shape[:2])

    def has(self, buffer: str) -> bool:
        return getattr(self, buffer, None) is not None

    def with_buffers(self, **buffers: Any) -> "Frame":
        """A copy with some buffers replaced (validated again)."""
        return replace(self, **buffers)


@dataclass
class Sequence:
    """Frames of one animated scene, in order (docs/methods/temporal.md §1).

    Every frame is a :class:`Frame` of the same (H, W) carrying the same buffers; sequence
    buffers (``motion``, ``gradient``, ``emission``) and the camera (``meta["camera"]``) live on
    the frames.
    Sequence methods are run with ``reset()`` and then ``denoise(frame)`` for each frame in order.

    Attributes:
        frames: the frames, index 0 first.
        meta: scene, spp, seed, resolution, frame count and render timings.

    Example:
        >>> import numpy as np
        >>> s = Sequence([Frame(color=np.zeros((4, 5, 3))) for _ in range(3)])
        >>> len(s), s.shape, s.kind
        (3, (4, 5), 'sequence')
    """

    frames: list[Frame]
    meta: dict[str, Any] = field(default_factory=dict)

    kind = "sequence"

    def __post_init__(self) -> None:
        self.frames = list(self.frames)
        if not self.frames:
            raise DbenchInputError("frames: expected a non-empty list of Frame objects")
        for i, f in enumerate(self.frames):
            if not isinstance(f, Frame):
                raise DbenchInputError(f"frames[{i}]: expected a Frame, got {type(f).__name__}")
            if f.shape != self.frames[0].shape:
                raise DbenchInputError(f"frames[{i}].color: expected shape (H, W, 3) = "
                                       f"{self.frames[0].shape + (3,)}, got {f.color.shape}")

    @property
    def shape(self) -> tuple[int, int]:
        return self.frames[0].shape

    def __len__(self) -> int:
        return len(self.frames)

    def __iter__(self):
        return iter(self.frames)

    def __getitem__(self, index: int) -> Frame:
        return self.frames[index]

    def has(self, buffer: str) -> bool:
        """Whether every frame carries ``buffer``."""
        return all(f.has(buffer) for f in self.frames)


#: Per-pixel buffers of a TransientFrame (constant along time), with their channel count.
TRANSIENT_PIXEL_BUFFERS: dict[str, int] = {"albedo": 3, "normal": 3, "depth": 1, "position": 3,
                                           "steady": 3, "emitter": 1}
#: Per-pixel, per-bin buffers of a TransientFrame, (H, W, T, 3).
TRANSIENT_VIDEO_BUFFERS = ("color", "reference", "reference_var")


@dataclass
class TransientFrame:
    """One time-resolved render: a video of T time bins (docs/transient.md §6).

    The time axis is optical path length (OPL, scene units, metres): bin t covers
    ``[start_opl + t·bin_width_opl, start_opl + (t+1)·bin_width_opl)``; time = OPL / c.

    Attributes:
        color: (H, W, T, 3) float32 linear noisy radiance per bin (mean of the samples; no
            division by the bin width, so summing over T gives the steady image of the paths
            inside the window).
        stats: SampleStats of shape (H, W, T, 3): per-bin statistics, each path's summed
            contribution to a bin being one sample (bins a path never reaches are samples of
            g(0)); docs/methods/statistical.md §11.1. Or None.
        albedo, normal: (H, W, 3) float32 from a steady AOV render of the same camera, or None.
        depth: (H, W, 1) float32 camera distance (0 where nothing is hit) or None.
        position: (H, W, 3) float32 world position or None.
        reference: (H, W, T, 3) float32 high-spp video with the same window, or None.
        steady: (H, W, 3) float32 steady image of the same samples (all path lengths, also those
            outside the window), or None.
        non_zero: (H, W, T, 3) int32 number of samples (paths) with a non-zero value in the bin,
            0 ≤ non_zero ≤ n, or None.
        meta: ``start_opl``, ``bin_width_opl``, ``bins`` (= T), ``units`` and whatever the renderer
            adds (scene, spp, ``energy_fraction``, ...). Missing time-axis entries default to
            start 0, width 1, units "bins".
        emitter: (H, W, 1) float32 in [0, 1]: fraction of the pixel footprint whose primary ray
            sees an emitter with radiance > 0 toward the camera (steady render of the same
            camera, as for the features; :class:`Frame`), or None.
        reference_var: (H, W, T, 3) float32 ≥ 0, the variance of ``reference`` (the mean) per
            pixel, bin and channel from K independent chunks (docs/judging.md §2), or None.
        total_var: (H, W, 3) float64 ≥ 0, the variance of the mean of the per-path sums over
            the window's bins (the noisy time-integrated image's own variance, from the same
            samples as ``stats``; below Σ_t Var because a path's bins are anti-correlated), or
            None.

    Example:
        >>> import numpy as np
        >>> v = TransientFrame(color=np.zeros((4, 5, 6, 3), np.float32),
        ...                    meta={"start_opl": 3.5, "bin_width_opl": 0.02})
        >>> v.shape, v.bins, v.kind, round(v.end_opl, 2)
        ((4, 5), 6, 'transient', 3.62)
    """

    color: np.ndarray
    stats: SampleStats | None = None
    albedo: np.ndarray | None = None
    normal: np.ndarray | None = None
    depth: np.ndarray | None = None
    position: np.ndarray | None = None
    reference: np.ndarray | None = None
    steady: np.ndarray | None = None
    non_zero: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    emitter: np.ndarray | None = None
    reference_var: np.ndarray | None = None
    total_var: np.ndarray | None = None

    kind = "transient"

    def __post_init__(self) -> None:
        color = np.asarray(self.color) if self.color is not None else None
        if color is None or color.ndim != 4:
            raise DbenchInputError("color: expected shape (H, W, T, 3), got "
                                   f"{None if color is None else tuple(color.shape)}")
        self.color = check_buffer("color", color, (None, None, None, 3))
        h, w, t = self.color.shape[:3]
        if self.reference is not None:
            self.reference = check_buffer("reference", self.reference, (h, w, t, 3))
        if self.reference_var is not None:
            self.reference_var = check_buffer("reference_var", self.reference_var, (h, w, t, 3))
        _check_pixel_buffers(self, TRANSIENT_PIXEL_BUFFERS, h, w)
        if self.non_zero is not None:
            self.non_zero = check_buffer("non_zero", self.non_zero, (h, w, t, 3), dtype=np.int32)
        if self.total_var is not None:
            self.total_var = check_buffer("total_var", self.total_var, (h, w, 3),
                                          dtype=np.float64)
            if np.any(self.total_var < 0):
                raise DbenchInputError("total_var: negative values; expected a variance ≥ 0")
        if self.stats is not None and self.stats.shape != (h, w, t, 3):
            raise DbenchInputError(f"stats: expected shape (H, W, T, 3) = ({h}, {w}, {t}, 3), "
                                   f"got {self.stats.shape}")
        meta = dict(self.meta)
        bins = meta.setdefault("bins", t)
        if bins != t:
            raise DbenchInputError(f"meta.bins: expected T = {t} (color has shape "
                                   f"{tuple(self.color.shape)}), got {bins!r}")
        meta.setdefault("start_opl", 0.0)
        meta.setdefault("bin_width_opl", 1.0)
        meta.setdefault("units", "bins")
        width = meta["bin_width_opl"]
        if not (isinstance(width, (int, float, np.floating, np.integer)) and np.isfinite(width)
                and width > 0):
            raise DbenchInputError(f"meta.bin_width_opl: expected a finite number > 0, got "
                                   f"{width!r}")
        self.meta = meta

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.color.shape[:2])

    @property
    def bins(self) -> int:
        return int(self.color.shape[2])

    @property
    def start_opl(self) -> float:
        return float(self.meta["start_opl"])

    @property
    def bin_width_opl(self) -> float:
        return float(self.meta["bin_width_opl"])

    @property
    def end_opl(self) -> float:
        return self.start_opl + self.bins * self.bin_width_opl

    @property
    def time_axis(self) -> np.ndarray:
        """(T,) optical path length at the centre of each bin."""
        return self.start_opl + (np.arange(self.bins) + 0.5) * self.bin_width_opl

    def has(self, buffer: str) -> bool:
        return getattr(self, buffer, None) is not None

    def with_buffers(self, **buffers: Any) -> "TransientFrame":
        """A copy with some buffers replaced (validated again)."""
        return replace(self, **buffers)
