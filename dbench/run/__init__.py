"""Running cells: one method on one scene, timed and judged (``harness``, ``scoring``,
``fpenv``, ``inputs``), sequences frame by frame (``sequence_run``), the identity of a result
(``identity``) and the machine it was timed on (``machine``), and sweeps over scenes × spp ×
methods (``sweep`` and its ``sweep_*`` parts). It imports the methods, metrics, datasets and
the result writers of :mod:`dbench.report`; no method imports it (docs/architecture.md)."""
