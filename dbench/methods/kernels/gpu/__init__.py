"""GPU kernels of the methods, written once in Triton (docs/gpu.md).

One kernel source serves two places: compiled for CUDA when its tensors are on a GPU, and run by
Triton's interpreter when they are on the CPU, which is how the tests on machines without a GPU
prove every kernel equal to its method's readable reference (:mod:`.runtime`). Files:
``runtime`` (the launcher), ``bilateral`` (the JBF/Welch window of ``jbf`` and ``statistical``),
``guide`` (the window's guide planes built on the device), ``temporal`` (reprojection,
accumulation and TAA of the temporal methods), ``svgf`` (SVGF's temporal pass, variance and
à-trous) and ``asvgf`` (A-SVGF's gradient strata)."""
