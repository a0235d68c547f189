"""Small denoisers the tests run through the harness (importable from every test folder: pytest
puts ``tests/`` on ``sys.path`` for ``tests/conftest.py``)."""
from scipy.ndimage import uniform_filter

from dbench.denoiser import Denoiser


class Blur(Denoiser):
    """A 3 × 3 box blur of the colour: a steady method that helps and never fails."""
    name = "blur"
    kinds = {"steady"}
    needs = {"color"}
    defaults = {}

    def denoise(self, data):
        return uniform_filter(data.color, size=(3, 3, 1))
