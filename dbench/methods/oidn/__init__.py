"""``oidn``: Intel Open Image Denoise (RT filter, HDR) through the pyoidn binding.

The professional baseline every other method is measured against (docs/methods/oidn.md;
docs/metrics.md §2.5 for CPU timings). Inputs: color + albedo + normal by default.

Input policy (documented finite result): OIDN needs non-negative finite HDR color, albedo in
[0, 1] and normals in [-1, 1]. Non-finite color pixels are replaced by 0 and negative values by
0 before the call; albedo and normal are clipped to their ranges and their non-finite values
set to 0. The output is therefore finite everywhere, and a NaN never reaches OIDN.

Device path (``denoise_device``, :mod:`.device`): the same policy with torch ops on the frame's
device, then OIDN's CUDA device filtering the tensors in GPU memory (OIDN's CPU device for CPU
tensors); the OIDN device and filter are kept on the instance between calls.
"""
from __future__ import annotations

import numpy as np

from ...data import check_buffer
from ...errors import DbenchInputError
from ...denoiser import Denoiser, register

QUALITIES = ("high", "balanced", "fast")
FEATURE_SETS = ("albedo+normal", "albedo", "none")
#: The buffers each feature set reads besides the colour: an instance needs what its
#: ``features`` read, so ``features=none`` runs on colour-only renders.
FEATURE_NEEDS = {"albedo+normal": {"albedo", "normal"}, "albedo": {"albedo"}, "none": set()}


def oidn_denoise(color: np.ndarray, albedo: np.ndarray | None = None,
                 normal: np.ndarray | None = None, quality: str = "high",
                 clean_aux: bool = True) -> np.ndarray:
    """Denoise an (H, W, 3) linear HDR image with OIDN; albedo/normal (H, W, 3) optional.

    Returns float32 (H, W, 3). ``clean_aux`` tells OIDN the features are noise-free (dbench's
    AOVs are rendered at 64 spp with a box filter); normals need albedo (an OIDN rule).
    """
    import pyoidn

    if quality not in QUALITIES:
        raise DbenchInputError(f"quality: expected one of {QUALITIES}, got {quality!r}")
    color = check_buffer("color", color, (None, None, 3))
    h, w = color.shape[:2]
    color = np.where(np.isfinite(color), np.maximum(color, 0.0), 0.0).astype(np.float32)
    aux = {}
    if albedo is not None:
        aux["albedo"] = np.clip(np.nan_to_num(check_buffer("albedo", albedo, (h, w, 3)),
                                              nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
        if normal is not None:
            aux["normal"] = np.clip(np.nan_to_num(check_buffer("normal", normal, (h, w, 3)),
                                                  nan=0.0, posinf=0.0, neginf=0.0), -1.0, 1.0)
    elif normal is not None:
        raise DbenchInputError("normal: OIDN uses normals only together with albedo")
    out = pyoidn.denoise(color, aux.get("albedo"), aux.get("normal"), hdr=True,
                         clean_aux=bool(clean_aux and aux), quality=quality)
    return np.ascontiguousarray(out, dtype=np.float32)


@register("oidn")
class OIDN(Denoiser):
    """Intel Open Image Denoise, RT filter in HDR mode.

    Parameters: ``quality`` (high | balanced | fast), ``features`` (albedo+normal | albedo |
    none), ``clean_aux`` (features are noise-free). An instance needs the colour and the
    buffers its ``features`` read (``needs`` below is the default's).
    """

    kinds = {"steady"}
    needs = {"color", "albedo", "normal"}
    defaults = dict(quality="high", features="albedo+normal", clean_aux=True)
    #: ``denoise_device``: OIDN's own CUDA device on the tensors (:mod:`.device`).
    device_backend = "oidn-cuda"

    def __init__(self, **params):
        super().__init__(**params)
        if self.params["features"] not in FEATURE_SETS:
            raise DbenchInputError(f"features: expected one of {FEATURE_SETS}, "
                                   f"got {self.params['features']!r}")
        if self.params["quality"] not in QUALITIES:
            raise DbenchInputError(f"quality: expected one of {QUALITIES}, "
                                   f"got {self.params['quality']!r}")
        self.needs = {"color"} | FEATURE_NEEDS[self.params["features"]]
        #: What the last call ran on: ``oidn_device`` ("cuda" | "cpu"), quality, features.
        self.last_settings: dict = {}
        self._runner = None  # the device path's cached OIDN device and filter

    def applies_to(self, kind: str, available: set[str] | None = None) -> tuple[bool, str]:
        """As every method's, and where the features are what is missing, the setting that
        runs on the colour alone (README.md, "Renders from another renderer")."""
        ok, why = super().applies_to(kind, available)
        if not ok and available is not None and "color" in available \
                and kind in self.kinds and self.params["features"] != "none":
            why += f"; --param {self.name}.features=none runs on the colour alone"
        return ok, why

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["_runner"] = None  # native handles stay with the process that made them
        return state

    def denoise_device(self, data):
        """OIDN on a :class:`~dbench.device.DeviceFrame`: CUDA tensors are filtered by OIDN's
        CUDA device in GPU memory on the current torch stream, CPU tensors by OIDN's CPU device;
        synchronous (the result is ready on return). Equal to :meth:`denoise` on the CPU
        (tests/methods/test_oidn_device.py)."""
        from .device import OIDNRunner

        if self._runner is None:
            self._runner = OIDNRunner()
        p = self.params
        out, self.last_settings = self._runner.run(data, p["features"], p["quality"],
                                                   p["clean_aux"])
        return out

    def denoise(self, data) -> np.ndarray:
        self.check_input(data)
        features = self.params["features"]
        albedo = data.albedo if features != "none" else None
        normal = data.normal if features == "albedo+normal" else None
        h, w = data.color.shape[:2]
        if features != "none":
            check_buffer("albedo", albedo, (h, w, 3))  # a missing buffer raises, naming it
        if features == "albedo+normal":
            check_buffer("normal", normal, (h, w, 3))
        self.last_settings = dict(oidn_device="cpu", backend="pyoidn-numpy",
                                  quality=self.params["quality"], features=features,
                                  clean_aux=bool(self.params["clean_aux"] and albedo is not None))
        return oidn_denoise(data.color, albedo, normal, quality=self.params["quality"],
                            clean_aux=self.params["clean_aux"])
