"""The learned models' HDR input helpers (dbench/methods/kernels/hdr_input.py)."""
import numpy as np
import pytest

from dbench.data import Frame
from dbench.errors import DbenchInputError
from dbench.methods.kernels.hdr_input import autoexposure, frame_spp, noise_level


def test_autoexposure_known_values_and_scaling():
    assert autoexposure(np.full((32, 32, 3), 0.36)) == pytest.approx(0.5)
    assert autoexposure(np.zeros((5, 7, 3))) == 1.0
    rng = np.random.default_rng(0)
    img = rng.gamma(1.0, 1.0, (40, 50, 3))
    assert autoexposure(img * 8.0) == pytest.approx(autoexposure(img) / 8.0, rel=1e-9)
    bad = img.copy()
    bad[3, 4] = np.nan
    bad[5, 6] = -np.inf
    assert np.isfinite(autoexposure(bad))
    # blocks: a 16x16 block average, geometric mean over the blocks
    two = np.zeros((16, 32, 3))
    two[:, :16] = 1.0
    two[:, 16:] = 4.0
    assert autoexposure(two) == pytest.approx(0.18 / 2.0)


def test_noise_level_and_frame_spp():
    assert noise_level(1) == 0.0 and noise_level(1024) == 1.0
    with pytest.raises(DbenchInputError, match="spp"):
        noise_level(0)
    f = Frame(color=np.zeros((2, 2, 3), np.float32), meta={"spp": 64})
    assert frame_spp(f) == 64 and frame_spp(f, 8) == 8
    assert frame_spp(Frame(color=np.zeros((2, 2, 3), np.float32))) is None


@pytest.mark.parametrize("shape", [(37, 45, 3), (16, 16, 3), (5, 3, 3), (130, 70, 3)])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_compiled_autoexposure_equals_the_reference(shape, dtype):
    """One image goes through the compiled block means: the same exposure as the NumPy
    reference within 1e-12 relative (edge tiles, non-finite and negative values included)."""
    from dbench.methods.kernels.hdr_input import autoexposure_reference

    rng = np.random.default_rng(sum(shape))
    c = rng.gamma(0.3, 2.0, shape).astype(dtype)
    c[0, 0, 0], c[-1, -1, 1], c[1, 1, 2] = np.nan, -2.0, np.inf
    assert autoexposure(c) == pytest.approx(autoexposure_reference(c), rel=1e-12)
    assert autoexposure(np.zeros(shape, dtype)) == autoexposure_reference(np.zeros(shape)) == 1.0
