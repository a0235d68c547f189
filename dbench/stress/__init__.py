"""The numerical stress matrix (``dbench stress``, results/stress.md): adversarial cases
(``cases``), the runner judging each method on each (``runner``), the same cases on the methods'
device forms (``device``) and the harness contract cases (``contract``)."""
