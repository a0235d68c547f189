"""EXR files written as another renderer would (no dbench naming), for the tests of folders of
renders (README.md, "Renders from another renderer")."""
import numpy as np
import OpenEXR


def write_exr(path, channels, origin=None):
    """Write raw channels {name: (H, W)} as float32 scanlines, ZIP-compressed; ``origin``
    (x, y): the data window's corner, where it is not (0, 0)."""
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if origin is not None:
        h, w = next(iter(channels.values())).shape
        lo = np.array(origin, np.int32)
        header["dataWindow"] = (lo, lo + np.array([w - 1, h - 1], np.int32))
        header["displayWindow"] = (np.zeros(2, np.int32), lo + np.array([w - 1, h - 1], np.int32))
    data = {k: np.ascontiguousarray(v, np.float32) for k, v in channels.items()}
    with OpenEXR.File(header, data) as f:
        f.write(str(path))


def write_rgb(path, img, prefix="", origin=None):
    """Write an (H, W, 3) image as the channels ``<prefix>R``, ``<prefix>G``, ``<prefix>B``."""
    write_exr(path, {f"{prefix}{c}": img[..., i] for i, c in enumerate("RGB")}, origin)
