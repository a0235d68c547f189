"""The history of a temporal method on a device (docs/temporal.md): the checked input tensors, two
alternating history buffers, the reprojection and TAA launches of
:mod:`dbench.methods.kernels.gpu.temporal`, shared by ``accumulate``, ``svgf`` and ``asvgf``'s
device paths (:mod:`dbench.methods.accumulate.device`, :mod:`dbench.methods.svgf.device`).

Nothing here converts image data to NumPy: the camera origin is host metadata (Python floats),
every pixel buffer stays a tensor on the frame's device.
"""
from __future__ import annotations

from typing import Any

import triton

from ..kernels.gpu.runtime import cdiv
from ..kernels.gpu.temporal import BASE, block_for, reproject_kernel, taa_kernel
from .params import EPS_F, FALLBACK_KERNEL



def device_buffer(frame: Any, name: str, h: int, w: int, c: int, required: bool = True,
                  why: str = ""):
    """The (H, W, C) float32 contiguous tensor ``name`` of a DeviceFrame (``depth`` may be
    (H, W)); None when absent and not ``required``. Errors name the buffer (and ``why``)."""
    import torch

    from ...errors import DbenchInputError

    t = frame.buffers.get(name)
    if t is None:
        if required:
            raise DbenchInputError(f"{name}: missing{why}; expected an array of shape "
                                   f"({h}, {w}, {c})")
        return None
    if name == "depth" and t.dim() == 2:
        t = t.unsqueeze(-1)
    if tuple(t.shape) != (h, w, c):
        raise DbenchInputError(f"{name}: expected shape ({h}, {w}, {c}), got {tuple(t.shape)}")
    return t.to(torch.float32).contiguous()


#: The buffers the temporal methods' device paths read: {name: (channels, required)}.
SEQUENCE_BUFFERS = {"color": (3, True), "albedo": (3, True), "depth": (1, True),
                    "normal": (3, True), "position": (3, True), "motion": (2, False),
                    "emission": (3, False)}


def sequence_buffers(frame: Any, names) -> tuple[int, int, dict[str, Any]]:
    """(H, W, {name: tensor or None}) for ``names`` of :data:`SEQUENCE_BUFFERS`, each checked
    by :func:`device_buffer`; H and W are the colour's, which must be (H, W, 3)."""
    from ...errors import DbenchInputError

    color = frame.buffers.get("color")
    if color is None or color.dim() != 3 or color.shape[2] != 3:
        raise DbenchInputError("color: expected shape (H, W, 3), got "
                               f"{None if color is None else tuple(color.shape)}")
    h, w = int(color.shape[0]), int(color.shape[1])
    return h, w, {n: device_buffer(frame, n, h, w, SEQUENCE_BUFFERS[n][0],
                                   required=SEQUENCE_BUFFERS[n][1]) for n in names}


def camera_origin(meta: Any) -> tuple[float, float, float] | None:
    """``meta["camera"]["origin"]`` as three Python floats (host metadata, as ``frame_geometry``
    reads it), None when absent or not finite."""
    import math

    from ...errors import DbenchInputError

    cam = (meta or {}).get("camera") if isinstance(meta, dict) else None
    if not isinstance(cam, dict) or cam.get("origin") is None:
        return None
    o = cam["origin"]
    vals = [float(v) for v in (o.reshape(-1).tolist() if hasattr(o, "reshape") else o)]
    if len(vals) != 3:
        raise DbenchInputError(f"meta['camera']['origin']: expected 3 numbers, got {len(vals)}")
    return tuple(vals) if all(math.isfinite(v) for v in vals) else None


class DeviceHistory:
    """A temporal method's state on a device: two alternating (5 + ``planes``, H, W) float32
    history buffers (module docstring), the previous frame's camera origin and plane layout,
    the previous TAA output, and work tensors reused from frame to frame (nothing of the history
    is allocated per frame once the size is known)."""

    def __init__(self, planes: int, tau_d: float, tau_n: float) -> None:
        self.planes, self.tau_d, self.tau_n = int(planes), float(tau_d), float(tau_n)
        self.bufs = None
        self.device = None
        self._work: dict[str, Any] = {}
        self.reset()

    def reset(self) -> None:
        """Forget the history (the buffers stay allocated)."""
        self.i = 0
        self.has_prev = False
        self.origin = None
        self.layout = None
        self.taa_has = False
        self.ti = 0

    def work(self, name: str, shape: tuple[int, ...], dtype=None, device=None):
        """The reusable tensor ``name`` (stale values; a new one when the shape changed)."""
        import torch

        dtype = dtype or torch.float32
        t = self._work.get(name)
        if t is None or tuple(t.shape) != tuple(shape) or t.dtype != dtype:
            t = self._work[name] = torch.empty(shape, dtype=dtype, device=device or self.device)
        return t

    def begin(self, h: int, w: int, device) -> tuple[Any, Any]:
        """(previous buffer, buffer of this frame), allocated for an (h, w) frame on ``device``
        (a new size or device starts without history)."""
        import torch

        shape = (BASE + self.planes, h, w)
        if (self.bufs is None or tuple(self.bufs[0].shape) != shape
                or self.bufs[0].device != device):
            self.bufs = [torch.zeros(shape, dtype=torch.float32, device=device)
                         for _ in range(2)]
            self._work = {}
            self.reset()
        self.device = device
        return self.bufs[self.i], self.bufs[1 - self.i]

    def params(self):
        """(12,) float64 on the device: τ_d, τ_n, ε_f and the 3×3 fallback kernel."""
        import torch

        par = self._work.get("par")
        if par is None:
            vals = [self.tau_d, self.tau_n, EPS_F] + [float(v) for v in FALLBACK_KERNEL.ravel()]
            par = self._work["par"] = torch.tensor(vals, dtype=torch.float64, device=self.device)
        return par

    def reproject(self, depth, normal, position, motion, r: int, layout: Any, flag=None):
        """Write this frame's geometry into its buffer and reproject the previous buffer's
        planes 5 … 5 + r − 1 (:data:`reproject_kernel`, one launch). Returns (previous buffer,
        this frame's buffer, reprojected (r, H, W), status (H, W) uint8, whether there was a
        history: a previous frame of this size and ``layout``, and motion vectors)."""
        import torch

        h, w = depth.shape[:2]
        prev, new = self.begin(h, w, depth.device)
        fetched = self.work("fetched", (r, h, w))
        status = self.work("status", (h, w), torch.uint8)
        has = self.has_prev and motion is not None and self.layout == layout
        origin = self.origin if has else None
        par = self.params()
        blk = block_for(h * w, depth.device)
        reproject_kernel[(cdiv(h * w, blk),)](
            depth, normal, position, motion if motion is not None else normal, prev, new,
            fetched, status, flag if flag is not None else par, par,
            *(origin if origin is not None else (0.0, 0.0, 0.0)), h, w,
            HAS_HIST=bool(has), HAS_ORIGIN=origin is not None, R=r,
            RP=triton.next_power_of_2(r), N_PLANE=5, FLAG=flag is not None, BLOCK=blk)
        return prev, new, fetched, status, has

    def commit(self, origin, layout: Any) -> None:
        """This frame's buffer becomes the previous one."""
        self.i = 1 - self.i
        self.has_prev = True
        self.origin = origin
        self.layout = layout

    def taa_flag(self, want: bool, device):
        """A zeroed (1,) int32 flag the reprojection sets when some status > 0 (TAA's "the
        method's history did not restart"), or None when TAA is off."""
        import torch

        if not want:
            return None
        flag = self.work("flag", (1,), torch.int32, device)
        flag.zero_()
        return flag

    def taa(self, out, motion, alpha: float, flag):
        """``out`` (H, W, 3) after :data:`taa_kernel` against the previous TAA output (none on
        the first frame, without motion, with α = 1 or where the flag is 0: ``out`` itself, as
        ``HistoryDenoiser._with_taa``). Returns a new (H, W, 3) tensor; keeps a copy."""
        import torch

        h, w = out.shape[:2]
        shape = (2, h, w, 3)
        keep = self._work.get("taa")
        if keep is None or tuple(keep.shape) != shape:
            keep = self._work["taa"] = torch.empty(shape, dtype=torch.float32,
                                                   device=out.device)
            self.taa_has = False
        use = flag
        if not self.taa_has or motion is None or float(alpha) == 1.0:
            use = self.work("no-flag", (1,), torch.int32, out.device)
            use.zero_()
        res = torch.empty_like(out)
        blk = block_for(h * w, out.device)
        taa_kernel[(cdiv(h * w, blk),)](out, keep[self.ti], motion if motion is not None else out,
                                        use, res, keep[1 - self.ti], float(alpha), h, w,
                                        BLOCK=blk)
        self.ti = 1 - self.ti
        self.taa_has = True
        return res


__all__ = ["DeviceHistory", "camera_origin", "device_buffer"]
