"""Speed of single methods' fast paths against their references (printing; not tests).
``dbench bench <method>`` adds the figures of a module named after the method here
(``benchmark(height, width, repeats)``); ``python -m dbench.bench.methods.jbf`` (or
``statistical``) runs one alone.
They live with the harness, so a method never imports it."""
