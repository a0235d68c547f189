"""A Python scene file's dictionary integrator is rendered by the rules of Mitsuba XML files
(dbench/datasets/scene_files/integrator.py plan_dict): kept where it can render dbench's
passes, unwrapped, or replaced by path with the reason; the frames say so, as a scene file's
do, and the integrator keys the renders. Sequence and transient files, which render with
dbench's own integrators, refuse another; a plugin's bare build function is treated as a file."""
from __future__ import annotations

import numpy as np
import pytest

from dbench.errors import DbenchInputError

SCENE = '''
def build(mi, width, height):
    T = mi.ScalarTransform4f
    return {{"type": "scene",
            "sensor": {{"type": "perspective", "fov": 45,
                       "to_world": T().look_at(origin=[0, 1, 4], target=[0, 0.3, 0],
                                               up=[0, 1, 0]),
                       "film": {{"type": "hdrfilm", "width": width, "height": height{film}}}}},
            "floor": {{"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(3),
                      "bsdf": {{"type": "diffuse"}}}},
            "ball": {{"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5}},
            "lamp": {{"type": "sphere", "center": [0, 0.4, 1.6], "radius": 0.3,
                     "emitter": {{"type": "area",
                                 "radiance": {{"type": "rgb", "value": [6, 6, 6]}}}}}}{integrator}}}
{extra}'''

INTEGRATORS = {"direct": {"type": "direct"},
               "path8": {"type": "path", "max_depth": 8},
               "hidden": {"type": "path", "max_depth": 8, "hide_emitters": True},
               "ptracer": {"type": "ptracer", "max_depth": 8}}


def _file(tmp_path, name: str, integrator: dict | None, extra: str = "", film: str = ""):
    path = tmp_path / f"{name}.py"
    entry = "" if integrator is None else f',\n            "integrator": {integrator!r}'
    path.write_text(SCENE.format(integrator=entry, extra=extra, film=film))
    return path


def _scene(path):
    from dbench.datasets.scenes import catalogue as scenes
    return scenes.get(str(path))


def test_the_dictionarys_integrator_renders_and_the_frames_say_which(renderer, tmp_path):
    from dbench import datasets
    cache = datasets.Cache(tmp_path / "c")
    frames, scenes = {}, {}
    for name, integrator in INTEGRATORS.items():
        sc = scenes[name] = _scene(_file(tmp_path, name, integrator))
        frames[name] = datasets.load(sc, spp=2, res=8, needs={"color"}, progress=False,
                                     cache=cache)
    render = {n: sc.scene_dict(renderer, 8)["integrator"] for n, sc in scenes.items()}
    assert render["direct"] == {"type": "direct"}
    assert render["path8"] == {"type": "path", "max_depth": 8}
    assert render["hidden"] == {"type": "path", "max_depth": 8, "hide_emitters": True}
    assert render["ptracer"] == {"type": "path", "max_depth": 8}  # replaced, with the reason
    settings = {n: f.meta["scene_file_settings"] for n, f in frames.items()}
    assert settings["direct"]["integrator"] == "direct (as in the file)"
    assert settings["direct"]["max_depth"] == "none (direct has none)"
    assert "hide_emitters true" in settings["hidden"]["max_depth"]
    assert settings["ptracer"]["integrator"].startswith("path (file: ptracer) — replaced because")
    rec = frames["ptracer"].meta["scene_file"]
    assert (rec["integrator"], rec["file_integrator"], rec["max_depth"]) == ("path", "ptracer", 8)
    # the dictionary's film names no filter: hdrfilm's Gaussian, against dbench's box
    assert settings["path8"]["filter"].startswith("box (file: gaussian) — ")
    assert settings["path8"]["sampler"] == "independent (as in the file)"
    # the renders differ where the integrators do (the lamp is in view: hidden, direct light)
    color = {n: f.color for n, f in frames.items()}
    assert not np.array_equal(color["hidden"], color["path8"])
    assert not np.array_equal(color["direct"], color["path8"])
    keys = {n: datasets.scene_fingerprint(sc, 8) for n, sc in scenes.items()}
    assert len(set(keys.values())) == 4


def test_wrappers_a_missing_integrator_and_the_modules_max_depth(renderer, tmp_path):
    moment = _scene(_file(tmp_path, "moment", {"type": "moment",
                                               "a": {"type": "path", "max_depth": 5}}))
    plan = moment.integrator_plan
    assert plan.render == {"type": "path", "max_depth": 5} and plan.file_integrator == \
        "moment(path)" and "moment unwrapped" in plan.notes[0]
    assert moment.scene_dict(renderer, 8)["integrator"] == {"type": "path", "max_depth": 5}
    none = _scene(_file(tmp_path, "none", None)).integrator_plan
    assert none.render == {"type": "path", "max_depth": 8} and none.file_integrator is None
    assert "names no integrator" in none.notes[0]
    over = _scene(_file(tmp_path, "over", {"type": "path", "max_depth": 8, "hide_emitters": True},
                        extra="max_depth = 2\n"))
    assert over.integrator_plan.render == {"type": "path", "max_depth": 2, "hide_emitters": True}
    assert over.max_depth == 2 and "the module's max_depth" in over.integrator_plan.notes[-1]
    direct = _scene(_file(tmp_path, "direct3", {"type": "direct"}, extra="max_depth = 3\n"))
    assert direct.integrator_plan.render == {"type": "direct"}
    assert "does not apply" in direct.integrator_plan.notes[-1]
    with pytest.raises(DbenchInputError, match=r"bogus\.py: Mitsuba could not load it: "
                                               r"integrator no_such_integrator"):
        _scene(_file(tmp_path, "bogus", {"type": "no_such_integrator"}))


SEQUENCE = '''kind = "sequence"
frames = 2

def camera(i):
    return (0.1 * i, 1.0, 4.0), (0, 0.3, 0)
'''

TRANSIENT = '''kind = "transient"
window_start, window_end = 2.0, 10.0
bins = 4
'''


@pytest.mark.parametrize("extra", [SEQUENCE, TRANSIENT], ids=["sequence", "transient"])
def test_sequence_and_transient_files_refuse_an_integrator_they_would_not_render(
        renderer, tmp_path, extra):
    for name, integrator in [("direct", {"type": "direct"}),
                             ("hidden", {"type": "path", "max_depth": 8, "hide_emitters": True})]:
        with pytest.raises(DbenchInputError, match=rf"{name}\.py: build\(\)'s dictionary sets "
                                                   r".*(direct|hide_emitters on its path).* "
                                                   r"remove the dictionary's integrator"):
            _scene(_file(tmp_path, name, integrator, extra=extra))
    sc = _scene(_file(tmp_path, "fine", {"type": "path", "max_depth": 5}, extra=extra))
    assert sc.kind in ("sequence", "transient") and sc.max_depth == 5
    # their frames carry no record to say which of two depths renders: two are refused
    with pytest.raises(DbenchInputError, match=r"twice\.py: max_depth 3 in the module and 5 in "
                                               r"build\(\)'s integrator; give one"):
        _scene(_file(tmp_path, "twice", {"type": "path", "max_depth": 5},
                     extra=extra + "max_depth = 3\n"))
    same = _scene(_file(tmp_path, "same", {"type": "path", "max_depth": 5},
                        extra=extra + "max_depth = 5\n"))
    assert same.max_depth == 5


def test_a_plugin_build_function_renders_its_dictionarys_integrator(renderer, tmp_path):
    from dbench import datasets
    from dbench.datasets.scenes.build import plugin_build
    from dbench.datasets.scenes.record import Scene

    def build(mi, res):
        d = mi.cornell_box()
        d["sensor"]["film"].update(width=res.width, height=res.height)
        d["integrator"] = {"type": "direct"}
        return d

    sc = Scene(name="direct-box", kind="steady", description="x",
               build=plugin_build(build, "direct-box"))
    assert sc.scene_dict(renderer, 8)["integrator"] == {"type": "direct"}
    frame = datasets.load(sc, spp=1, res=8, needs={"color"}, progress=False,
                          cache=datasets.Cache(tmp_path / "c"))
    assert frame.meta["scene_file"]["integrator"] == "direct"
    assert frame.meta["scene_file_settings"]["integrator"] == "direct (as in the file)"
    # mi.cornell_box's film states a Gaussian filter, which dbench replaces
    assert frame.meta["scene_file_settings"]["filter"].startswith("box (file: gaussian)")
