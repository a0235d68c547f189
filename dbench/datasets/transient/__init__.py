"""Transient (time-resolved) renders through mitransient: the scene record and its time window, the media, the render, the in-integrator statistics collectors and the loader (docs/transient.md)."""
