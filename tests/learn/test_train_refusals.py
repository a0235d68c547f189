"""``dbench train`` checks every argument before the training set line and before anything
renders or is written: one line on stderr, exit 2 (README.md, "Usage"; dbench/cli/train.py).

Rendering is replaced by a stand-in that fails the test, so a check that lets an argument
through can never start a training run here."""
from __future__ import annotations

import pytest

from dbench import cli


@pytest.fixture
def no_training(monkeypatch, tmp_path):
    """Anything past the checks fails loudly: the training set, the sequences, the training."""
    from dbench.learn import dataset, train

    def rendered(*a, **k):
        raise AssertionError("the training set was rendered")

    monkeypatch.setattr(dataset, "build_training_set", rendered)
    monkeypatch.setattr(dataset, "build_sequence_set", rendered)
    monkeypatch.setattr(train, "train_nca", rendered)
    monkeypatch.setattr(train, "train_autoencoder", rendered)
    return tmp_path


def _refused(capsys, argv, *words):
    try:
        rc = cli.main(["train", *argv])
    except SystemExit as exc:  # argparse's refusals (dbench.cli.parser.Parser)
        rc = exc.code
    out, err = capsys.readouterr()
    assert rc == 2 and err.startswith("dbench: ") and err.count("\n") == 1, (rc, err)
    assert "training set" not in out and "Traceback" not in err, out
    for w in words:
        assert w in err, err
    return err


@pytest.mark.parametrize("argv, words", [
    (["nca", "--steps", "-1"], ["--steps", ">= 1", "-1"]),
    (["nca", "--steps", "0"], ["--steps"]),
    (["autoencoder", "--steps", "0"], ["--steps"]),
    (["nca", "--minutes", "-1"], ["--minutes", "> 0"]),
    (["nca", "--minutes", "0"], ["--minutes"]),
    (["autoencoder", "--sequences", "-1"], ["--sequences", "-1"]),
    (["autoencoder", "--sequences", "2"], ["--sequences", "held out", ">= 3"]),
    (["nca", "--sequences", "0"], ["--sequences", "only the autoencoder"]),
    (["autoencoder", "--width-scale", "0"], ["--width-scale", "> 0"]),
    (["autoencoder", "--width-scale", "-0.5"], ["--width-scale"]),
    (["nca", "--res", "0"], ["--res", "[64, 4096]", "got 0"]),
    (["nca", "--res", "63"], ["--res", "64 px crops"]),
    (["autoencoder", "--res", "64"], ["--res", "96 px crops"]),
    (["nca", "--res", "5000"], ["--res", "4096"]),
    (["nca", "--scenes", "4"], ["--scenes", "holds 4 out", ">= 5"]),
    (["autoencoder", "--scenes", "0"], ["--scenes", ">= 3"]),
    (["nca", "--steps", "many"], ["--steps", "expected an integer"]),
])
def test_bad_counts_and_sizes_are_refused_before_the_training_set(no_training, capsys, argv,
                                                                  words):
    _refused(capsys, [*argv, "--out", str(no_training / "out")], *words)
    assert not (no_training / "out").exists()


def test_scene_param_is_not_an_option_of_train(no_training, capsys):
    """The training scenes are procedural and take no scene parameters: train's parser has no
    --scene-param, so argparse refuses it, in one line."""
    _refused(capsys, ["nca", "--scene-param", "g=1"], "unrecognized arguments", "--scene-param")
    assert "--scene-param" not in cli.build_parser().parse_args(["train", "nca"]).__dict__


def test_an_out_that_cannot_hold_the_model_is_refused_up_front(no_training, capsys,
                                                               monkeypatch):
    afile = no_training / "a-file"
    afile.write_text("x")
    _refused(capsys, ["nca", "--out", str(afile)], "--out", "exists and is not a folder")
    _refused(capsys, ["nca", "--out", str(afile / "below")], "--out", "cannot write there")
    (no_training / "m" / "nca.onnx").mkdir(parents=True)
    _refused(capsys, ["nca", "--out", str(no_training / "m")], "nca.onnx there is a folder")
    # a read-only folder (root writes into a chmod 555 one: the probe file's failure stands in)
    from dbench import io

    def read_only(*a, **k):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(io.tempfile, "mkstemp", read_only)
    _refused(capsys, ["nca", "--out", str(no_training / "ro" / "new"), "--no-cache"], "--out",
             "Permission denied")
    assert not (no_training / "ro").exists()  # the folders the check made go again


def test_from_weights_that_are_not_a_model_are_refused_before_the_training_set(
        no_training, capsys):
    garbage = no_training / "garbage.xml"
    garbage.write_text("<scene/>")
    _refused(capsys, ["autoencoder", "--from-weights", str(garbage), "--out",
                      str(no_training / "out")], "--from-weights", "garbage")
    garbage.with_suffix(".json").write_text("not json")
    _refused(capsys, ["autoencoder", "--from-weights", str(garbage)], "--from-weights",
             "training record")
    import json

    from dbench.learn.ship import PACKAGE_METHODS

    record = json.loads((PACKAGE_METHODS / "autoencoder" / "autoencoder.json").read_text())
    garbage.with_suffix(".json").write_text(json.dumps(record))
    _refused(capsys, ["autoencoder", "--from-weights", str(garbage)], "--from-weights",
             "does not hold the weights")
    nca = json.loads((PACKAGE_METHODS / "nca" / "nca.json").read_text())
    garbage.with_suffix(".json").write_text(json.dumps(nca))
    _refused(capsys, ["autoencoder", "--from-weights", str(garbage)], "--from-weights",
             "nca model")
    _refused(capsys, ["autoencoder", "--from-weights", str(garbage), "--sequences", "0"],
             "--from-weights", "sequences")
    assert not (no_training / "out").exists()


def test_cache_with_no_cache_is_refused(no_training, capsys):
    _refused(capsys, ["nca", "--cache", str(no_training / "c"), "--no-cache"], "--cache",
             "--no-cache")


@pytest.mark.parametrize("argv", [
    ["nca", "--steps", "3", "--minutes", "0.5", "--scenes", "5", "--res", "64"],
    ["autoencoder", "--width-scale", "0.25", "--sequences", "3", "--res", "96"],
    ["autoencoder", "--sequences", "0", "--scenes", "3"],
    ["autoencoder", "--from-weights", "SHIPPED"],  # the shipped model and its record
])
def test_valid_arguments_reach_the_training_set(no_training, capsys, argv):
    """The checks let every valid setting through (the stand-in stops it there), and the
    output folder the check created goes again when the run ends without a model."""
    from dbench.learn.ship import PACKAGE_METHODS

    argv = [str(PACKAGE_METHODS / "autoencoder" / "autoencoder.onnx") if a == "SHIPPED" else a
            for a in argv]
    out = no_training / "new" / "out"
    assert cli.main(["train", *argv, "--out", str(out), "--no-cache"]) == 1
    printed, err = capsys.readouterr()
    assert "training set: " in printed and "rendered" in err, (printed, err)
    assert not (no_training / "new").exists()
