"""``--seed`` takes what a render seed can be, [0, 2**32 − 1] (Mitsuba's seeds are unsigned
32-bit), and ``--seed`` + ``--seeds`` − 1 must fit too; anything else is one line naming
--seed and the range, exit 2, before anything renders. The reported reference seed is the
one used."""
import pytest

from dbench import datasets
from dbench.cli import main
from dbench.datasets.references import MAX_SEED, check_ref_seed, check_seed
from dbench.errors import DbenchInputError


def _run(tmp_path, *extra):
    return ["run", "--method", "noisy", "--scene", "cornell", "--spp", "2", "--res", "8",
            "--ref-spp", "16", "--repeats", "1", "--quiet", "--cache", str(tmp_path / "cache"),
            "--out", str(tmp_path / "out"), *extra]


@pytest.mark.parametrize("extra, top", [(["--seed", "-5"], MAX_SEED),
                                        (["--seed=-1"], MAX_SEED),
                                        (["--seed", str(2**32)], MAX_SEED),
                                        (["--seed", "abc"], MAX_SEED),
                                        (["--seed", str(MAX_SEED), "--seeds", "3"], MAX_SEED - 2)])
def test_bad_seeds_are_one_line_before_anything_renders(tmp_path, capsys, extra, top):
    assert main(_run(tmp_path, *extra)) == 2
    captured = capsys.readouterr()
    err = captured.err
    assert err.count("\n") == 1 and err.startswith("dbench: --seed: ")
    assert f"[0, {top}]" in err and "ref_seed" not in err and "Traceback" not in err
    assert not (tmp_path / "cache").exists() and not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", [["render", "--scene", "cornell", "--spp", "2", "--res",
                                      "8"],
                                     ["sweep", "--scenes", "cornell", "--methods", "noisy",
                                      "--spp", "2", "--res", "8"]])
def test_every_command_with_seed_refuses_a_negative_one(tmp_path, capsys, command):
    out = ["--out", str(tmp_path / "out")] if command[0] == "sweep" else []
    assert main([*command, *out, "--seed", "-5", "--cache", str(tmp_path / "cache")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--seed" in err and f"[0, {MAX_SEED}]" in err
    assert not (tmp_path / "cache").exists() and not (tmp_path / "out").exists()


def test_library_checks():
    assert check_seed(0) == 0 and check_seed(MAX_SEED) == MAX_SEED
    assert check_seed(MAX_SEED - 1, n_seeds=2) == MAX_SEED - 1
    for bad in (-1, MAX_SEED + 1, 1.0, True, "3", None):
        with pytest.raises(DbenchInputError, match="--seed"):
            check_seed(bad)
    with pytest.raises(DbenchInputError, match="--seeds 2"):
        check_seed(MAX_SEED, n_seeds=2)
    assert check_ref_seed(None) == 0
    with pytest.raises(DbenchInputError, match="ref_seed"):
        check_ref_seed(MAX_SEED + 1)


@pytest.mark.mitsuba
def test_the_reported_reference_seed_is_the_one_used(renderer, tmp_path):
    import pandas as pd

    assert main(_run(tmp_path, "--seed", "7")) == 0
    table = pd.read_csv(tmp_path / "out" / "metrics.csv")
    assert (table["ref_seed"] == 7).all()
    frame = datasets.load("cornell", spp=2, res=8, ref_spp=16, seed=7, ref_seed=7,
                          needs={"reference"}, cache=datasets.Cache(tmp_path / "cache"),
                          progress=False)
    assert frame.meta["ref_seed"] == 7 and "reference" in frame.meta["cache_hits"]
