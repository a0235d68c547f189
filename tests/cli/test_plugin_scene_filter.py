"""A plugin's Scene renders its build's film as it is; one whose reconstruction filter is not a
box (hdrfilm's default is a Gaussian) exits 2 before anything renders, in one line naming the
scene, its file and the entry to write; with that entry it renders (dbench/datasets/scenes/
build.py check_box_filter; README.md, "Python scene files")."""
import pytest

from dbench import cli

pytestmark = pytest.mark.mitsuba

PLUGIN = '''from dbench.datasets.scenes.record import Scene, register_scene


def _build(mi, res):
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=res.width, height=res.height)
    {change}
    return d


register_scene(Scene(name="my-room", kind="steady", description="x", build=_build))
'''


def _run(tmp_path, change: str):
    plugin = tmp_path / "my_room_plugin.py"
    plugin.write_text(PLUGIN.format(change=change))
    rc = cli.main(["--plugin", str(plugin), "run", "--method", "noisy", "--scene", "my-room",
                   "--spp", "2", "--res", "8", "--ref-spp", "16", "--repeats", "1", "--quiet",
                   "--cache", str(tmp_path / "cache"), "--out", str(tmp_path / "out")])
    return rc, plugin


@pytest.mark.parametrize("change, said", [
    ('d["sensor"]["film"]["rfilter"] = {"type": "tent"}', "is tent;"),
    ('del d["sensor"]["film"]["rfilter"]',
     "is GaussianFilter (the film names none: hdrfilm's default);"),
    ("pass", "is gaussian;"),  # Mitsuba's Cornell box states a Gaussian
])
def test_a_plugin_scene_without_a_box_filter_exits_2_naming_it(isolated, renderer, tmp_path,
                                                               capsys, change, said):
    rc, plugin = _run(tmp_path, change)
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert err.startswith(f"dbench: scene my-room ({plugin}): the film's reconstruction "
                          f"filter {said}"), err
    assert err.endswith('put "rfilter": {"type": "box"} in the film of the dictionary build '
                        'returns'), err
    assert "Traceback" not in err and not list((tmp_path / "cache").glob("*/*"))


def test_a_plugin_scene_with_a_box_filter_renders(isolated, renderer, tmp_path, capsys):
    rc, _ = _run(tmp_path, 'd["sensor"]["film"]["rfilter"] = {"type": "box"}')
    assert rc == 0, capsys.readouterr().err
    assert (tmp_path / "out" / "report.md").is_file()


@pytest.mark.parametrize("integrator, said", [
    ('{"type": "direct"}', "direct"),
    ('{"type": "path", "max_depth": 3, "hide_emitters": True}', "path with hide_emitters")])
def test_a_plugin_scene_whose_integrator_would_be_replaced_exits_2(isolated, renderer, tmp_path,
                                                                   capsys, integrator, said):
    """A Scene renders with path at its own max_depth: a dictionary naming another integrator
    (or other settings) is refused in one line, never replaced without a word."""
    rc, plugin = _run(tmp_path, 'd["sensor"]["film"]["rfilter"] = {"type": "box"}; '
                                f'd["integrator"] = {integrator}')
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert err.startswith(f"dbench: scene my-room ({plugin}): its dictionary's integrator is "
                          f"{said}, but a Scene renders with path at its max_depth (8)"), err
    assert "Traceback" not in err and not list((tmp_path / "cache").glob("*/*"))


def test_a_plugin_scene_states_the_depth_it_renders_at(isolated, renderer, tmp_path, capsys):
    """The Scene's max_depth sets the depth (README.md); the dictionary's other depth is
    stated in the run's settings."""
    rc, _ = _run(tmp_path, 'd["sensor"]["film"]["rfilter"] = {"type": "box"}; '
                           'd["integrator"] = {"type": "path", "max_depth": 3}')
    assert rc == 0, capsys.readouterr().err
    report = (tmp_path / "out" / "report.md").read_text()
    assert "- max_depth: 8 (file: 3) — the Scene's max_depth renders" in report
