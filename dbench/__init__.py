"""dbench: a benchmark and comparison framework for Monte Carlo rendering denoisers."""
__version__ = "0.1.0"
