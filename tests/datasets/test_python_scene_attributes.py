"""A Python scene file's optional module attributes (README.md, "Python scene files") are
checked when the file is resolved: a value that is not a number of the stated kind is refused
in one line naming the attribute (exit 2) before anything renders, where it used to end in an
internal error (``ev = "bright"``), be refused only after the renders (``ev = nan``), or be cut
to an integer without a word (``frames = 2.7``, ``bins = 2.5``)."""
from __future__ import annotations

import pytest

from dbench.errors import DbenchInputError

SCENE = '''
def build(mi, width, height):
    T = mi.ScalarTransform4f
    return {"type": "scene",
            "sensor": {"type": "perspective", "fov": 45,
                       "to_world": T().look_at(origin=[0, 1, 4], target=[0, 0.3, 0],
                                               up=[0, 1, 0])},
            "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(3),
                      "bsdf": {"type": "diffuse"}},
            "lamp": {"type": "sphere", "center": [0, 0.4, 1.6], "radius": 0.3,
                     "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 6}}}}

def camera(i):
    return [0, 1, 4], [0, 0.3, 0]
'''
TRANSIENT = 'kind = "transient"\nwindow_start = 1.0\nwindow_end = 9.0\n'

BAD = {"ev-text": ('ev = "bright"\n', "ev is 'bright'"),
       "ev-none": ("ev = None\n", "ev is None"),
       "ev-nan": ('ev = float("nan")\n', "ev is nan"),
       "ev-huge": ("ev = 1e6\n", "ev is 1000000.0; give a number of stops in [-1074, 1023]"),
       "kind": ('kind = "video"\n', "kind is 'video'; give one of steady, sequence"),
       "depth": ("max_depth = 2.5\n", "max_depth is 2.5; give an integer"),
       "frames-text": ('kind = "sequence"\nframes = "many"\n', "frames is 'many'"),
       "frames-fraction": ('kind = "sequence"\nframes = 2.7\n', "frames is 2.7"),
       "frames-zero": ('kind = "sequence"\nframes = 0\n',
                       "frames is 0; give an integer in [1, 2147483647]"),
       "frames-huge": ('kind = "sequence"\nframes = 10**12\n', "frames is 1000000000000"),
       "bins-fraction": (TRANSIENT + "bins = 2.5\n",
                         "bins is 2.5; give an integer in [1, 2147483647]"),
       "window-text": (TRANSIENT + 'window_start = "x"\n', "window_start is 'x'"),
       "window-order": (TRANSIENT + "window_end = 0.5\n",
                        "window_end is 0.5; give a length greater than window_start (1.0)"),
       "window-missing": ('kind = "transient"\nwindow_start = 1.0\n',
                          "a transient scene needs window_end"),
       "integrator": (TRANSIENT + 'integrator = "transient_volpath"\n',
                      "integrator is 'transient_volpath'; give transient_path or "
                      "transient_prbvolpath"),
       "integrator-number": (TRANSIENT + "integrator = 5\n", "integrator is 5")}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_module_attribute_is_refused_naming_it(renderer, tmp_path, case):
    from dbench.datasets.scenes import catalogue as scenes
    extra, said = BAD[case]
    path = tmp_path / f"{case}.py"
    path.write_text(SCENE + extra)
    with pytest.raises(DbenchInputError) as err:
        scenes.get(str(path))
    assert said in str(err.value) and str(path) in str(err.value), str(err.value)


def test_good_attributes_are_kept_and_a_refusal_exits_2_before_rendering(renderer, tmp_path,
                                                                         capsys):
    from dbench.cli import main
    from dbench.datasets.scenes import catalogue as scenes
    path = tmp_path / "seq.py"
    path.write_text(SCENE + 'kind = "sequence"\nframes = 3\nev = 1\n')
    sc = scenes.get(str(path))
    assert (sc.n_frames, sc.ev) == (3, 1.0)
    path = tmp_path / "pulse.py"
    path.write_text(SCENE + TRANSIENT + "bins = 7\n")
    sc = scenes.get(str(path))
    assert (sc.default_bins, sc.window_start, sc.window_end) == (7, 1.0, 9.0)
    path = tmp_path / "nan.py"
    path.write_text(SCENE + 'ev = float("nan")\n')
    assert main(["run", "--method", "noisy", "--scene", str(path), "--spp", "1", "--res", "8",
                 "--ref-spp", "16", "--quiet", "--cache", str(tmp_path / "c"),
                 "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert "ev is nan" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "c").exists() and not (tmp_path / "run").exists()


SEQUENCE = 'kind = "sequence"\nframes = 3\n'
FUNCTIONS = {
    "camera-none": ("def camera(i):\n    return None\n", "camera(0) returned None"),
    "camera-raises": ("def camera(i):\n    raise ValueError('no pose')\n",
                      "camera(0) failed: ValueError: no pose"),
    "camera-three": ("def camera(i):\n    return [0, 1, 4], [0, 0, 0], [0, 1, 0]\n",
                     "give (origin, target), two points"),
    "camera-late": ("def camera(i):\n    return ([0, 1, 4], [0, 0, 0]) if i < 2 else None\n",
                    "camera(2) returned None"),
    # a vertical view: look_at's roll is undefined (NaN), rendered as a black sequence
    "camera-vertical": ("def camera(i):\n    return [0, 5, 0], [0, 0, 0]\n", "not vertical"),
    "camera-still": ("def camera(i):\n    return [0, 1, 4], [0, 1, 4]\n",
                     "two different finite points"),
    "lights-key": ("def lights(i):\n    return {'lmap': (1, 1, 1)}\n",
                   "lights(0)'s key is 'lmap'; give a shape key of build()'s dictionary: "
                   "floor, lamp"),
    "lights-colour": ("def lights(i):\n    return {'lamp': 'red'}\n",
                      "lights(0)['lamp'] is 'red'; give (r, g, b)"),
    "lights-nan": ("def lights(i):\n    return {'lamp': (1, float('nan'), 1)}\n",
                   "three finite numbers"),
    "lights-raises": ("def lights(i):\n    return {'lamp': (1, 1, 1)}[i]\n",
                      "lights(0) failed: KeyError: 0"),
    "lights-negative": ("def lights(i):\n    return {'lamp': (1, -1, 1)}\n",
                        "three finite numbers >= 0"),
    # the lamp's own emitter taken away: no frame would have light (refused after the renders)
    "lights-dark": ("def lights(i):\n    return {'lamp': (0, 0, 0)}\n"
                    "_build = build\ndef build(mi, width, height):\n"
                    "    d = _build(mi, width, height)\n    del d['lamp']['emitter']\n"
                    "    return d\n", "no frame has an emitter"),
    # called for every render of a frame: unseeded random numbers gave the noisy images and
    # the reference of one frame different scenes
    "camera-random": ("import random\ndef camera(i):\n"
                      "    return [random.uniform(-1, 1), 1, 4], [0, 0, 0]\n",
                      "camera(0) returned another value when called again"),
    "lights-random": ("import random\ndef lights(i):\n"
                      "    return {'lamp': (random.random() + 1, 1, 1)}\n",
                      "lights(0) returned another value when called again"),
}


@pytest.mark.parametrize("case", sorted(FUNCTIONS))
def test_a_sequence_files_camera_and_lights_are_checked_for_every_frame(renderer, tmp_path,
                                                                        case):
    """camera(i) and lights(i) used to fail inside the render (an internal error, exit 1) or,
    for a vertical view, render a black sequence refused as unlit; they are called for every
    frame when the file is resolved and refused naming the frame."""
    from dbench.datasets.scenes import catalogue as scenes
    code, said = FUNCTIONS[case]
    path = tmp_path / f"{case}.py"
    still = "def camera(i):\n    return [0, 1, 4], [0, 0.3, 0]\n"
    path.write_text(SCENE.replace("def camera", "def _unused") + SEQUENCE + code
                    + ("" if "camera" in case else still))
    with pytest.raises(DbenchInputError) as err:
        scenes.get(str(path))
    assert said in str(err.value) and str(path) in str(err.value), str(err.value)


@pytest.mark.parametrize("where", ["module", "build"])
def test_a_scene_file_that_sets_the_variant_is_refused_and_the_variant_kept(renderer, tmp_path,
                                                                            where):
    """mi.set_variant("scalar_rgb") at the top of a scene file, as Mitsuba's tutorials begin,
    switched the process to scalar_rgb: its renders were made there while the cache keys, the
    cells and the report named llvm_ad_rgb. The variant is put back and the file refused."""
    from dbench.datasets.scenes import catalogue as scenes
    mine = renderer.variant()
    other = "scalar_rgb" if mine != "scalar_rgb" else "llvm_ad_rgb"
    if other not in renderer.variants():
        pytest.skip(f"{other} is not compiled into this Mitsuba")
    path = tmp_path / f"{where}.py"
    if where == "module":
        path.write_text(f"import mitsuba\nmitsuba.set_variant({other!r})\n" + SCENE)
        said = "the file set Mitsuba's variant"
    else:
        path.write_text(SCENE.replace("    T = mi.ScalarTransform4f",
                                      f"    mi.set_variant({other!r})\n"
                                      f"    T = mi.ScalarTransform4f"))
        said = "build(mi, 8, 8) set Mitsuba's variant"
    with pytest.raises(DbenchInputError) as err:
        scenes.get(str(path))
    assert f"{said} to {other}, but dbench renders in {mine}" in str(err.value)
    assert renderer.variant() == mine


def test_a_sequence_sees_through_the_sensors_fov_or_focal_length(renderer, tmp_path):
    """A sequence file's frames took the sensor's "fov" or 39.3°: a 24 mm focal length
    rendered at 39.3° instead of the 71.6° a steady file (and Mitsuba) gives it, without a
    word. They now take the field of view a steady file's sensor gives, and a sensor that is
    no perspective camera is refused."""
    from dbench.datasets.scenes import catalogue as scenes
    from dbench.resolution import focal_fov

    def sequence(name, sensor_entry):
        path = tmp_path / f"{name}.py"
        path.write_text(SCENE.replace('"type": "perspective", "fov": 45,', sensor_entry)
                        + SEQUENCE)
        return scenes.get(str(path))

    steady = tmp_path / "steady.py"
    steady.write_text(SCENE.replace('"fov": 45,', '"focal_length": "24mm",'))
    wide = scenes.get(str(steady)).scene_dict(renderer, 16)["sensor"]["fov"]
    focal = sequence("focal", '"type": "perspective", "focal_length": "24mm",')
    assert focal.fov == pytest.approx(wide)
    assert wide == pytest.approx(71.59, abs=0.01)
    assert sequence("fov", '"type": "perspective", "fov": 30,').fov == 30
    neither = sequence("neither", '"type": "perspective",')
    assert neither.fov == pytest.approx(focal_fov("50mm", None))
    with pytest.raises(DbenchInputError, match="build\\(\\)'s sensor type is 'thinlens'; "
                                               "give \"perspective\""):
        sequence("lens", '"type": "thinlens", "aperture_radius": 0.1, "fov": 45,')
