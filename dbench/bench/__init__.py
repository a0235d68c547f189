"""The harness: runs methods on datasets and turns their outputs into results: one timed and
judged cell (``harness``), sweeps, sequence and transient runners, stress tests, speed benchmarks
(``speed``, ``methods/``), result identities, tables, verdicts, plots and the published report.
It imports the methods; no method imports it."""
