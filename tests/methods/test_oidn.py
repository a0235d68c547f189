"""OIDN baseline: shapes, input policy, quality option, denoising effect."""
import numpy as np
import pytest

from dbench import registry
from dbench.data import Frame
from dbench.errors import DbenchInputError


def _frame(h=48, w=48, seed=0, noise=0.2):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    clean = np.repeat((0.3 + 0.2 * np.sin(x / 6.0) * np.cos(y / 9.0))[..., None], 3, 2)
    color = clean + noise * rng.standard_normal(clean.shape)
    albedo = np.full((h, w, 3), 0.7)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1
    return Frame(color=color.clip(0), albedo=albedo, normal=normal,
                 depth=np.ones((h, w, 1)), reference=clean)


def test_reduces_error_on_noisy_smooth_image():
    f = _frame()
    out = registry.get("oidn").denoise(f)
    assert out.dtype == np.float32 and out.shape == f.color.shape
    err = lambda a: np.sqrt(((a - f.reference) ** 2).mean())
    assert err(out) < 0.5 * err(f.color)


@pytest.mark.parametrize("features", ["albedo+normal", "albedo", "none"])
@pytest.mark.parametrize("quality", ["high", "fast"])
def test_options(features, quality):
    out = registry.get("oidn", features=features, quality=quality).denoise(_frame(16, 24))
    assert out.shape == (16, 24, 3) and np.all(np.isfinite(out))


def test_bad_options_and_missing_buffers():
    with pytest.raises(DbenchInputError, match="quality"):
        registry.get("oidn", quality="ultra")
    with pytest.raises(DbenchInputError, match="albedo"):
        registry.get("oidn").denoise(Frame(color=np.zeros((8, 8, 3))))


def test_non_finite_and_negative_input_give_finite_output():
    f = _frame(24, 24)
    color = f.color.copy()
    color[5, 5] = np.nan
    color[6, 6] = np.inf
    color[7, 7] = -3
    out = registry.get("oidn").denoise(f.with_buffers(color=color))
    assert np.all(np.isfinite(out))
    # the NaN pixel does not poison its neighbourhood
    assert np.abs(out[3:9, 3:9] - f.reference[3:9, 3:9]).max() < 1.0


@pytest.mark.parametrize("shape", [(1, 1), (1, 17), (13, 7)])
def test_tiny_and_odd_sizes(shape):
    f = _frame(*shape)
    out = registry.get("oidn").denoise(f)
    assert out.shape == f.color.shape and np.all(np.isfinite(out))
