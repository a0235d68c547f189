import numpy as np
import pytest

from dbench import registry
from dbench.data import Frame


def test_identity_returns_a_float32_copy():
    color = np.random.default_rng(0).random((5, 7, 3))
    f = Frame(color=color)
    out = registry.get("noisy").denoise(f)
    assert out.dtype == np.float32 and out.shape == (5, 7, 3)
    np.testing.assert_array_equal(out, color.astype(np.float32))
    out[0, 0, 0] = 99
    assert f.color[0, 0, 0] != 99


def test_non_finite_input_is_shown_as_is():
    color = np.ones((3, 3, 3), np.float32)
    color[1, 1] = np.nan
    out = registry.get("noisy").denoise(Frame(color=color))
    assert np.isnan(out[1, 1]).all() and np.isfinite(np.delete(out.reshape(-1, 3), 4, 0)).all()


@pytest.mark.parametrize("shape", [(1, 1, 3), (1, 13, 3), (17, 1, 3)])
def test_any_size(shape):
    assert registry.get("noisy").denoise(Frame(color=np.zeros(shape))).shape == shape


def test_something_other_than_a_frame_is_refused_naming_the_method():
    """A bare array is one DbenchInputError naming the method and what it takes, not an
    AttributeError from inside it (Denoiser.check_input)."""
    import numpy as np
    import pytest

    from dbench import registry
    from dbench.errors import DbenchInputError

    for name in ("noisy", "oidn"):
        with pytest.raises(DbenchInputError, match=rf"^{name}: expected a dbench Frame"):
            registry.get(name).denoise(np.zeros((4, 4, 3), np.float32))
