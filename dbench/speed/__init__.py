"""Speed figures (``dbench bench``): same-run ratios and medians for the render statistics
(``timing``, ``transient_render``, ``transient_collectors``), scene files (``files``), video
metrics (``video_metrics``), methods on the GPU (``gpu``), the temporal methods at 720p
(``sequence``), and one module per method whose fast path is timed against its reference
(``jbf``, ``statistical``, ``nca``, ``autoencoder``: ``dbench bench <name>`` adds their
figures; ``python -m dbench.speed.jbf`` runs one alone). Printing, never tests."""
