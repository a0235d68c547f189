"""A plugin file registering one steady Scene object whose film line is given (README.md,
"Python scene files"): the source the refusal tests write with ``PLUGIN.format(film=...)``."""

PLUGIN = '''from dbench.datasets.scenes.record import Scene, register_scene


def _build(mi, res):
    d = mi.cornell_box()
    {film}
    return d


register_scene(Scene(name="my-room", kind="steady", description="x", build=_build))
'''
