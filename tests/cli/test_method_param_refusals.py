"""A parameter a method's own constructor refuses is refused naming the method
(dbench.registry.get; README.md, "Usage"): ``dbench sweep --methods jbf,oidn --param
jbf.sigma=1`` said ``dbench: sigma: expected 8 numbers ...`` and left the user to guess which
method refused. One line, exit 2, before anything renders, for run, sweep and bench, built-in
methods and plugins alike; a message that already starts with the method's name keeps it once."""
from __future__ import annotations

import pytest

from dbench import cli, plugins, registry
from dbench.errors import DbenchInputError

SIGMA = "sigma: expected 8 numbers (x, y, albedo r, g, b, normal x, y, z), got 1"


@pytest.mark.parametrize("name, params, said", [
    ("jbf", {"sigma": 1}, f"jbf: {SIGMA}"),
    ("jbf", {"radius": 2.5}, "jbf: radius: expected an integer"),
    ("oidn", {"quality": "best"}, "oidn: quality: expected one of"),
    ("jbf+gate", {"sigma": 1}, f"jbf+gate: {SIGMA}"),
    # already named: not twice
    ("noisy", {"radius": 3}, "noisy: unknown parameter(s) ['radius']"),
    ("nca", {"weights": "/nonexistent/nca.onnx"}, "nca.weights: /nonexistent/nca.onnx")])
def test_a_refused_parameter_names_the_method(name, params, said):
    with pytest.raises(DbenchInputError) as caught:
        registry.get(name, **params)
    assert str(caught.value).startswith(said), str(caught.value)


def _refused(capsys, tmp_path, argv: list[str], said: str) -> None:
    assert cli.main(argv) == 2
    out, err = capsys.readouterr()
    assert err == f"dbench: {said}\n", err
    assert not (tmp_path / "out").exists()
    cache = tmp_path / "cache"  # nothing rendered: no cache entry
    assert not cache.exists() or not [p for p in cache.rglob("*") if p.is_file()]


@pytest.mark.parametrize("argv", [
    ["run", "--scene", "cornell", "--method", "jbf", "--param", "jbf.sigma=1"],
    ["run", "--scene", "cornell", "--method", "oidn,jbf", "--param", "sigma=1"],
    ["sweep", "--scenes", "cornell", "--methods", "jbf,oidn", "--param", "jbf.sigma=1",
     "--spp", "4"]])
def test_run_and_sweep_name_the_method_before_rendering(tmp_path, capsys, argv):
    _refused(capsys, tmp_path, [*argv, "--res", "16", "--cache", str(tmp_path / "cache"),
                                "--out", str(tmp_path / "out")], f"jbf: {SIGMA}")


def test_bench_names_the_method(tmp_path, capsys):
    _refused(capsys, tmp_path, ["bench", "jbf", "--param", "sigma=1", "--res", "16",
                                "--device", "cpu", "--out", str(tmp_path / "out")],
             f"jbf: {SIGMA}")


PLUGIN = '''
from dbench.errors import DbenchInputError
from dbench.registry import Denoiser, register


@register("picky-{name}")
class Picky(Denoiser):
    defaults = {{"level": 1}}

    def __init__(self, **params):
        super().__init__(**params)
        raise DbenchInputError({message!r})

    def denoise(self, data):
        return data.color
'''


@pytest.mark.parametrize("name, message, said", [
    ("plain", "level: expected 1, 2 or 3, got 7", "picky-plain: level: expected 1, 2 or 3"),
    ("named", "picky-named: level 7 is too high", "picky-named: level 7 is too high")])
def test_a_plugin_constructor_refusal_names_the_method(isolated, tmp_path, capsys, name,
                                                       message, said):
    path = tmp_path / f"picky_{name}.py"
    path.write_text(PLUGIN.format(name=name, message=message))
    for argv in (["run", "--scene", "cornell", "--method", f"picky-{name}"],
                 ["sweep", "--scenes", "cornell", "--methods", f"picky-{name}", "--spp", "4"]):
        assert cli.main([*argv, "--param", "level=7", "--res", "16", "--plugin", str(path),
                         "--cache", str(tmp_path / "cache"),
                         "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(f"dbench: {said}"), err
        assert not (tmp_path / "out").exists()
    plugins.load(str(path))
    with pytest.raises(DbenchInputError, match=f"^{said}"):
        registry.get(f"picky-{name}")
