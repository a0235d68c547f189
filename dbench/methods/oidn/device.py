"""``oidn`` on a device: OIDN's own CUDA device filtering torch tensors where they lie
(docs/gpu.md), or OIDN's CPU device on CPU tensors.

How pyoidn (2.5.1.0) is used, and why:

* ``pyoidn.Device.from_torch(device, stream)`` calls ``oidnNewCUDADevice(deviceIDs, streams, 1)``
  with the torch device's index and ``stream.cuda_stream``: the OIDN device runs on the same GPU
  (its primary context, which torch uses too) and queues its kernels on the current torch
  stream, so the input preparation done here with torch ops and OIDN's network are ordered on
  one stream. For CPU tensors ``pyoidn.Device(OIDN_DEVICE_TYPE_CPU)``, the device type the host
  path (``pyoidn.denoise`` on NumPy arrays) uses as well.
* ``Filter.set_image(name, tensor, OIDN_FORMAT_FLOAT3)`` with a ``torch.Tensor`` calls
  ``oidnSetSharedFilterImage`` on ``tensor.data_ptr()``: OIDN reads and writes that memory
  (device memory for CUDA tensors) with no copy. The bound tensors are staging buffers owned
  here, allocated once per (size, features, quality) and kept alive while bound.
* ``Filter.execute()`` is ``oidnExecuteFilter``, synchronous: it returns once the filter has
  finished on the device (OIDN waits on its stream). The result is cloned on the same stream
  before returning, so a later call never overwrites a tensor already handed out; a
  ``torch.cuda.synchronize()`` after the call therefore covers all of the method's work.

Input policy: the host path's (``dbench.methods.oidn``), done with torch ops on the device.
"""
from __future__ import annotations

import weakref
from typing import Any

from ...errors import DbenchInputError

#: pyoidn's OIDN_QUALITY_* codes (pyoidn/filter.py).
QUALITY_CODES = {"fast": 4, "balanced": 5, "high": 6}


def _check(device: Any, what: str) -> None:
    """Raise RuntimeError when OIDN reports an error on ``device`` (``oidnGetDeviceError``)."""
    from pyoidn.capi import oidn_Capi, oidn_ffi

    msg = oidn_ffi.new("const char**")
    code = int(oidn_Capi.oidnGetDeviceError(device._device, msg))
    if code != 0:
        text = (oidn_ffi.string(msg[0]).decode("utf-8", "replace")
                if msg[0] != oidn_ffi.NULL else "no message")
        raise RuntimeError(f"oidn: {what} failed (OIDN error {code}): {text}")


def _check_tensor(name: str, t: Any, shape: tuple[int, int]) -> None:
    if t is None:
        raise DbenchInputError(f"{name}: missing; expected a tensor of shape "
                               f"({shape[0]}, {shape[1]}, 3)")
    if tuple(t.shape) != (shape[0], shape[1], 3):
        raise DbenchInputError(f"{name}: expected shape ({shape[0]}, {shape[1]}, 3), "
                               f"got {tuple(t.shape)}")


class _Handles:
    """The native OIDN objects, released filter first (also by the runner's finalizer)."""

    def __init__(self) -> None:
        self.filter: Any = None
        self.device: Any = None

    def release_filter(self) -> None:
        if self.filter is not None:
            self.filter.release()
            self.filter = None

    def release(self) -> None:
        self.release_filter()
        if self.device is not None:
            self.device.release()
            self.device = None


class OIDNRunner:
    """An OIDN device and RT filter kept across calls, with the staging tensors bound to it.

    The device is re-created when the tensors' device or the current CUDA stream changes; the
    filter (and its staging tensors) when the image size, the feature set, the quality or
    ``clean_aux`` change. ``device_builds`` and ``filter_builds`` count the (re)creations.
    """

    def __init__(self) -> None:
        self._h = _Handles()
        self._finalizer = weakref.finalize(self, self._h.release)
        self.device_key: tuple | None = None
        self.filter_key: tuple | None = None
        self.device_builds = 0
        self.filter_builds = 0
        self._stream: Any = None  # keeps the torch stream (and so its handle) alive
        self._images: dict[str, Any] = {}

    @property
    def filter(self) -> Any:
        return self._h.filter

    def close(self) -> None:
        """Release the filter and the device now (they are released at collection anyway)."""
        self._h.release()
        self._images = {}
        self.device_key = self.filter_key = None

    def _ensure_device(self, tdev: Any) -> str:
        import pyoidn
        import torch

        if tdev.type == "cuda":
            index = tdev.index if tdev.index is not None else torch.cuda.current_device()
            stream = torch.cuda.current_stream(index)
            key: tuple = ("cuda", int(index), int(stream.cuda_stream))
        elif tdev.type == "cpu":
            stream, key = None, ("cpu",)
        else:
            raise DbenchInputError(f"oidn: the device path runs on CUDA or CPU tensors, "
                                   f"got {tdev.type!r}")
        if key == self.device_key:
            return key[0]
        self.close()
        if key[0] == "cuda":
            if not pyoidn.Device.is_cuda_available(key[1]):
                raise RuntimeError(f"oidn: OIDN's CUDA device does not support CUDA device "
                                   f"{key[1]} ({torch.cuda.get_device_name(key[1])})")
            dev = pyoidn.Device.from_torch(torch.device("cuda", key[1]), stream)
        else:
            dev = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
        self._h.device = dev
        _check(dev, f"{key[0]} device creation")
        dev.commit()
        _check(dev, f"{key[0]} device commit")
        self.device_key, self._stream = key, stream
        self.device_builds += 1
        return key[0]

    def _ensure_filter(self, key: tuple, tdev: Any) -> None:
        import pyoidn
        import torch

        if key == self.filter_key and self._h.filter is not None:
            return
        self._h.release_filter()
        self._images = {}
        self.filter_key = None
        (h, w), names, quality, clean_aux = key
        dev = self._h.device
        flt = pyoidn.Filter(dev, pyoidn.OIDN_FILTER_TYPE_RT)
        self._h.filter = flt
        _check(dev, "filter creation")
        images = {n: torch.empty((h, w, 3), dtype=torch.float32, device=tdev)
                  for n in (*names, "output")}
        for name, t in images.items():
            flt.set_image(name, t, pyoidn.OIDN_FORMAT_FLOAT3)
            _check(dev, f"binding the {name} image")
        flt.set_bool("hdr", True)
        flt.set_bool("cleanAux", bool(clean_aux))
        flt.set_quality(QUALITY_CODES[quality])
        flt.commit()
        _check(dev, "filter commit")
        self._images, self.filter_key = images, key
        self.filter_builds += 1

    def run(self, frame: Any, features: str, quality: str, clean_aux: bool
            ) -> tuple[Any, dict[str, Any]]:
        """OIDN on a :class:`~dbench.device.DeviceFrame`: ((H, W, 3) float32 tensor on the
        frame's device, settings)."""
        import torch

        color = frame.color
        if color is None or color.ndim != 3 or color.shape[2] != 3 or min(color.shape[:2]) == 0:
            raise DbenchInputError(f"color: expected a tensor of shape (*, *, 3), got "
                                   f"{None if color is None else tuple(color.shape)}")
        h, w = int(color.shape[0]), int(color.shape[1])
        names = ("color",) + {"none": (), "albedo": ("albedo",),
                              "albedo+normal": ("albedo", "normal")}[features]
        for name in names[1:]:
            _check_tensor(name, getattr(frame, name), (h, w))
        clean = bool(clean_aux and len(names) > 1)
        kind = self._ensure_device(color.device)
        self._ensure_filter(((h, w), names, quality, clean), color.device)
        img = self._images
        f32 = torch.float32
        # the host path's input policy, written into the bound staging tensors
        torch.nan_to_num(color.to(f32), nan=0.0, posinf=0.0, neginf=0.0,
                         out=img["color"]).clamp_(min=0.0)
        if "albedo" in img:
            torch.nan_to_num(frame.albedo.to(f32), nan=0.0, posinf=1.0, neginf=0.0,
                             out=img["albedo"]).clamp_(0.0, 1.0)
        if "normal" in img:
            torch.nan_to_num(frame.normal.to(f32), nan=0.0, posinf=0.0, neginf=0.0,
                             out=img["normal"]).clamp_(-1.0, 1.0)
        self._h.filter.execute()  # synchronous (oidnExecuteFilter)
        _check(self._h.device, "filter execution")
        settings = dict(oidn_device=kind, backend=f"oidn-{kind}", quality=quality,
                        features=features, clean_aux=clean)
        return img["output"].clone(), settings


__all__ = ["OIDNRunner", "QUALITY_CODES"]
