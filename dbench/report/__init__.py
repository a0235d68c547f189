"""Everything that writes or reads results: the cell files (``cells``), verdicts and tables,
plots and figures, the run report of ``dbench run`` (``run_report``, its terminal headline
``headline``/``terminal`` and its output folder ``run_output``), the published sweep report of
``dbench report`` (``publish``), the HTML viewer (``html``, ``viewer/``) and reference
comparisons (``refcompare``). It computes nothing it reports: numbers come from the cells
(docs/architecture.md)."""
