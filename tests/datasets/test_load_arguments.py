"""datasets.load's seed and ref_spp are checked before anything renders, for every kind of
scene (dbench/datasets/references.py check_render_args): a negative ref_spp rendered an
all-zero reference and cached it, 0 became the default, 1 gave a reference of one chunk whose
variance read as zero (a noise-free reference), and a float seed keyed the cache as its
integer part while the render hashed the float."""
import numpy as np
import pytest

from dbench import datasets
from dbench.errors import DbenchInputError

KINDS = [("cornell", {}), ("orbit", {"frames": 2}), ("cornell-transient", {"bins": 4})]


@pytest.mark.parametrize("scene, extra", KINDS, ids=[k[0] for k in KINDS])
@pytest.mark.parametrize("ref_spp", [-4, 0, 1, 2.5, "16", True])
def test_a_bad_ref_spp_is_refused_before_rendering(tmp_path, scene, extra, ref_spp):
    cache = datasets.Cache(tmp_path / "c")
    with pytest.raises(DbenchInputError, match=r"^ref_spp: expected an integer in \[2, "):
        datasets.load(scene, spp=2, res=8, needs={"reference"}, ref_spp=ref_spp, cache=cache,
                      progress=False, **extra)
    assert not (tmp_path / "c").exists() or not any((tmp_path / "c").rglob("meta.json"))


@pytest.mark.parametrize("scene, extra", KINDS, ids=[k[0] for k in KINDS])
@pytest.mark.parametrize("seed", [1.5, np.float64(1.0), True, -1, 2**40])
def test_a_bad_seed_is_refused_before_rendering(tmp_path, scene, extra, seed):
    with pytest.raises(DbenchInputError, match=r"^seed: expected an integer in \[0, "):
        datasets.load(scene, spp=2, res=8, needs={"color"}, seed=seed, progress=False,
                      cache=datasets.Cache(tmp_path / "c"), **extra)


def test_a_numpy_integer_seed_and_ref_spp_are_integers(renderer, tmp_path):
    f = datasets.load("cornell", spp=2, res=8, needs={"reference"}, seed=np.int64(1),
                      ref_spp=np.int64(16), cache=datasets.Cache(enabled=False),
                      progress=False)
    assert f.meta["seed"] == 1 and f.meta["ref_spp"] == 16 and f.meta["ref_rmse"] > 0


@pytest.mark.parametrize("kw, said", [
    ({"needs": "color"}, "needs: expected a collection of buffer names"),  # read as letters
    ({"needs": 5}, "needs: expected a collection of buffer names"),
    ({"cache": "x"}, "cache: expected a dbench.datasets.Cache"),
    ({"frames": 2}, "frames: cornell is a steady scene; only sequence scenes take frames"),
    ({"bins": 4}, "bins: cornell is a steady scene; only transient scenes take bins"),
    ({"collector": "z"}, "collector: cornell is a steady scene"),
    ({"transform": "bogus"}, "transform: unknown 'bogus'"),  # checked without stats too
])
def test_arguments_a_steady_load_would_not_read_are_refused(kw, said):
    with pytest.raises(DbenchInputError, match=said):
        datasets.load("cornell", spp=2, res=8, **{"needs": {"color"}, **kw})


@pytest.mark.parametrize("scene", [None, 5])
def test_a_scene_that_is_no_name_is_refused(scene):
    with pytest.raises(DbenchInputError, match="scene: expected a catalogue name"):
        datasets.load(scene, spp=2, res=8)
