"""``dbench train``: every argument checked before the training set renders or anything is
written (README.md, "Usage"), then :func:`dbench.learn.train.run_training`.

Checked up front, each refusal one line and exit 2: the counts and sizes the training can
finish with (:func:`dbench.learn.train.check_training`: ``--steps``, ``--minutes``,
``--scenes``, ``--res``, ``--sequences``, ``--width-scale``), the options that apply to one
model only, ``--from-weights`` (read before the training set line: a file that is not an
autoencoder's weights with its record is refused), ``--cache`` and the output folder, which
must be a folder this user can write (``--out`` or, by default, the method's package folder);
a folder the check created goes again when the command ends without writing the model.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import DbenchInputError
from .args import _writable_cache


def cmd_train(args: argparse.Namespace) -> int:
    """Render (or read cached) procedural training scenes, train, write the ONNX + JSON."""
    from ..io import remove_empty
    from ..learn.train import check_training, run_training

    overrides = {"seed": args.seed}
    if args.steps is not None:
        overrides["steps"] = args.steps
    if args.minutes is not None:
        overrides["max_minutes"] = args.minutes
    if args.width_scale is not None:
        if args.method != "autoencoder":
            raise DbenchInputError("--width-scale: only the autoencoder has widths")
        overrides["width_scale"] = args.width_scale
    if args.sequences is not None and args.method != "autoencoder":
        raise DbenchInputError("--sequences: only the autoencoder is recurrent")
    if args.sequences is None:
        args.sequences = 16 if args.method == "autoencoder" else 0
    check_training(args.method, n_scenes=args.scenes, res=args.res, sequences=args.sequences,
                   **overrides)
    if args.from_weights is not None:
        _check_from_weights(args, overrides)
    cache = _writable_cache(args)
    created = _writable_out(args)
    try:
        run_training(args.method, n_scenes=args.scenes, res=args.res,
                     ref_spp=args.ref_spp or 2048, out_dir=args.out, sequences=args.sequences,
                     cache=cache, from_weights=args.from_weights, **overrides)
    except BaseException:
        remove_empty(created)  # the folders the check made, while they hold nothing
        raise
    return 0


def _check_from_weights(args: argparse.Namespace, overrides: dict) -> None:
    """``--from-weights`` applies: the autoencoder, a file, no stage-1 setting, sequences (the
    weights themselves are read by run_training before anything renders)."""
    if args.method != "autoencoder":
        raise DbenchInputError("--from-weights: only the autoencoder has later stages")
    if not Path(args.from_weights).is_file():
        raise DbenchInputError(f"--from-weights: no such file {args.from_weights}")
    overrides.pop("seed")  # stage 1's; stage 3 has its own
    if overrides:
        raise DbenchInputError("--from-weights: --steps, --minutes and --width-scale are "
                               "stage-1 settings")
    if not args.sequences:
        raise DbenchInputError("--from-weights: stage 3 trains on sequences; leave out "
                               "--sequences 0")


def _writable_out(args: argparse.Namespace) -> list[Path]:
    """Check the folder the model is written into (``--out``, else the method's package
    folder) before anything renders: a folder this user can write, where the model's files
    are not folders. Returns the folders the check created (deepest first)."""
    from ..io import ensure_writable_dir, missing_folders
    from ..learn.ship import PACKAGE_METHODS

    given = args.out is not None
    out = Path(args.out) if given else PACKAGE_METHODS / args.method
    what = "--out" if given else "--out (not given: the package folder)"
    created = missing_folders(out)
    ensure_writable_dir(out, what)  # (refused, it leaves none of the folders it made)
    for name in (f"{args.method}.onnx", f"{args.method}.json"):
        if (out / name).is_dir():  # (then out was there before: the check created nothing)
            raise DbenchInputError(f"{what} {out}: {name} there is a folder; the model is "
                                   f"written as that file")
    return created


__all__ = ["cmd_train"]
