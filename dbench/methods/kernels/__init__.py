"""Numerical kernels shared by several methods, named for what they compute: the joint bilateral
base weights and their accumulation (``bilateral``: ``jbf``, ``statistical``, the transient
baselines) and the Welch pair tests evaluated inside those loops (``welch``). A kernel imports no
method and nothing of the harness."""
