"""One-off studies behind published pages (results/temporal_study, results/temporal_targets,
results/transient*, results/temporal): each module runs with ``python -m dbench.studies.<name>``,
imports whatever it needs, and is imported by nothing else in the package."""
