"""EXR files written as another renderer would (no dbench naming), for the tests of folders of
renders (README.md, "Renders from another renderer")."""
import numpy as np
import OpenEXR


def write_exr(path, channels):
    """Write raw channels {name: (H, W)} as float32 scanlines, ZIP-compressed."""
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    data = {k: np.ascontiguousarray(v, np.float32) for k, v in channels.items()}
    with OpenEXR.File(header, data) as f:
        f.write(str(path))


def write_rgb(path, img, prefix=""):
    """Write an (H, W, 3) image as the channels ``<prefix>R``, ``<prefix>G``, ``<prefix>B``."""
    write_exr(path, {f"{prefix}{c}": img[..., i] for i, c in enumerate("RGB")})
