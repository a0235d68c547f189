"""Shared argument handling of the commands: ``--param`` values, comma lists, the checks every
rendering command makes, the cache, the scene and its default spp."""
from __future__ import annotations

import argparse
import ast
from collections.abc import Sequence as _Sequence
from typing import Any, Callable, Sequence

from ..errors import DbenchInputError


def rankable() -> tuple[str, ...]:
    """Columns ``--rank-by`` accepts: the metric records marked rankable
    (dbench/metrics/records.py)."""
    from ..metrics import records  # on use: the command line starts without NumPy

    return records.rankable()


class _Rankable(_Sequence):
    """:func:`rankable` as a sequence, read from the records each time it is used."""

    def __getitem__(self, i):
        return rankable()[i]

    def __len__(self) -> int:
        return len(rankable())

    def __repr__(self) -> str:
        return repr(rankable())


#: Columns ``--rank-by`` accepts (the metric records marked rankable, read on use).
RANKABLE = _Rankable()


def check_rank_by(name: str) -> None:
    """Refuse a ``--rank-by`` that no rankable metric record names (one line, the choices)."""
    choices = rankable()
    if name not in choices:
        raise DbenchInputError(f"--rank-by: {name!r}; valid: {', '.join(choices)}")


def _parse_value(text: str) -> Any:
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def parse_params(items: Sequence[str], method_names: Sequence[str]) -> dict[str, dict[str, Any]]:
    """``key=value`` (every method that has ``key``) or ``method.key=value`` (one method, over a
    ``key=value`` in either order). One key given two different values at the same level is
    refused: settling it by the order of the options would be a silent choice."""
    from .. import registry

    out: dict[str, dict[str, Any]] = {m: {} for m in method_names}
    seen: dict[str, tuple[Any, str]] = {}  # key as given -> (value, item)
    parsed = []
    for item in items:
        if "=" not in item:
            raise DbenchInputError(f"--param: expected key=value or method.key=value, got {item!r}")
        key, value = item.split("=", 1)
        key = key.strip()
        value = _parse_value(value)
        if key in seen and seen[key][0] != value:
            raise DbenchInputError(f"--param {item}: {key} is also given as {seen[key][1]}; "
                                   f"give one value")
        seen[key] = (value, item)
        parsed.append((item, key, value))
    # general keys first, so that method.key=value wins whatever the order
    for item, key, value in sorted(parsed, key=lambda p: "." in p[1]):
        target, _, name = key.rpartition(".")
        if target:
            if target not in out:
                raise DbenchInputError(f"--param {item}: method {target!r} is not in this run "
                                       f"({', '.join(method_names)})")
            if name not in registry.method_class(target).defaults:
                raise DbenchInputError(f"--param {item}: {target} has no parameter {name!r}; "
                                       f"valid: {sorted(registry.method_class(target).defaults)}")
            out[target][name] = value
        else:
            takers = [m for m in method_names if name in registry.method_class(m).defaults]
            if not takers:
                raise DbenchInputError(f"--param {item}: no method of this run has a parameter "
                                       f"{name!r}")
            for m in takers:
                out[m][name] = value
    return out


def seed_arg(text: str):
    """argparse ``type`` of ``--seed``: an integer in [0, MAX_SEED]
    (:func:`dbench.datasets.references.seed_problem`); anything else comes back as a
    :class:`dbench.cli.bounds.BadCount`, refused in one line before the command does anything
    (argparse's own refusal would print its usage too)."""
    from ..datasets.references import seed_problem
    from .bounds import BadCount

    try:
        value = int(str(text).strip())
    except ValueError:
        value = text
    problem = seed_problem(value)
    if problem:
        bad = BadCount(text)
        bad.why = problem
        return bad
    return value


def normal_encoding_arg(text: str):
    """argparse ``type`` of ``--normal-encoding``: ``signed`` or ``unsigned``
    (dbench.datasets.folders.normals); anything else comes back as a
    :class:`dbench.cli.bounds.BadCount`, refused in one line naming the option and the valid
    choices before the command does anything (argparse's ``choices`` would print its usage)."""
    from .bounds import BadCount

    choices = ("signed", "unsigned")  # dbench.datasets.folders.normals.ENCODINGS, without NumPy
    value = str(text).strip().lower()
    if value in choices:
        return value
    bad = BadCount(text)
    bad.why = f"{text!r}; valid: {', '.join(choices)}"
    return bad


def _split(text: str, option: str, distinct: bool = True) -> list[str]:
    """``"a, b"`` → ["a", "b"]; an empty item (``"4,,8"``, ``"jbf,"``) is refused naming
    ``option``: a typo there would otherwise run a shorter list than the one meant. With
    ``distinct`` an item given twice is refused too (:func:`check_distinct`)."""
    items = [t.strip() for t in text.split(",")]
    if not all(items):
        raise DbenchInputError(f"{option}: an empty item in {text!r}; give a comma list "
                               f"without empty items")
    return check_distinct(items, option, text) if distinct else items


def check_distinct(items: Sequence, option: str, text: str, shown: Sequence | None = None
                   ) -> list:
    """``items`` when no two are equal; a DbenchInputError naming ``option`` and the repeated
    item otherwise: a repeated item would be run once (or twice) without a word, and the
    printed settings would not say which (``shown``: the items as the user wrote them)."""
    seen: dict = {}
    for i, item in enumerate(items):
        if item in seen:
            first, again = (shown[seen[item]], shown[i]) if shown is not None else (item, item)
            same = f"{again!r} is given twice" if first == again else \
                f"{first!r} and {again!r} name the same item"
            raise DbenchInputError(f"{option}: {same} in {text!r}; give each once")
        seen[item] = i
    return list(items)


def list_items(texts: str | Sequence[str], option: str,
               items_of: Callable[[str], list[str]]) -> list[str] | None:
    """The items of a list option (``--method``, ``--methods``, ``--scenes``) given as
    ``texts``, one text per time it is given (argparse's ``append``): ``all`` alone → None
    (every name); else every text's items (``items_of(text)``) in order, each list adding its
    items, never the last list alone (README.md, "Usage"). An item given twice, in one list or
    two, is refused (:func:`check_distinct`), and so is ``all`` beside anything: it stands
    alone."""
    texts = [texts] if isinstance(texts, str) else list(texts)
    if len(texts) == 1 and texts[0].strip() == "all":
        return None
    items = [item for text in texts for item in items_of(text)]
    if "all" in items:
        raise DbenchInputError(f"{option}: {' '.join(texts)!r}; 'all' stands alone (give all, "
                               f"or NAME[,NAME...] without it)")
    return check_distinct(items, option, " ".join(texts))


def names_arg(texts: str | Sequence[str], option: str) -> list[str] | None:
    """``all`` → None (every name); ``"a,b"`` → ["a", "b"] (:func:`_split`); given more than
    once, every list's names (:func:`list_items`)."""
    return list_items(texts, option, lambda text: _split(text, option, distinct=False))


def method_names(texts: str | Sequence[str], option: str) -> list[str] | None:
    """:func:`names_arg` of a method list, as the names the methods are published under; two
    names of one method (an alias and its name) are refused as a repeated item."""
    from .. import registry

    given = names_arg(texts, option)
    if given is None:
        return None
    shown = " ".join([texts] if isinstance(texts, str) else texts)
    return check_distinct([registry.canonical(n) for n in given], option, shown, given)


def warn_left_out(option: str, scenes: bool = False) -> str:
    """Where ``option`` is ``all``: one warning line on stderr naming the plugins that failed
    to load and why (:func:`dbench.plugins.left_out`; with ``scenes``, the scene plugins), so
    that "all" never means "all that loaded" without a word; the line (``''`` when every
    plugin loaded), for a report's notes."""
    import sys

    from .. import plugins

    line = plugins.left_out(option, plugins.SCENE_GROUP if scenes else plugins.METHOD_GROUP)
    if line:
        print(f"dbench: warning: {line}", file=sys.stderr)
    return line


MAX_PARAM_CHARS = 1000


def _ints(text: str, name: str) -> list[int]:
    """``"4,16"`` → [4, 16]; a DbenchInputError naming ``name`` and the valid range
    (dbench.cli.bounds) for anything else."""
    from .bounds import MAX_COUNT, parse_count

    out, given = [], _split(text, name)
    for t in given:
        try:
            out.append(parse_count(t))
        except ValueError:
            raise DbenchInputError(f"{name}: expected a comma list of integers in "
                                   f"[1, {MAX_COUNT}], got {t!r} in {text!r}") from None
    return check_distinct(out, name, text, given)  # "4,4e0" is 4 twice


def _check_common(args: argparse.Namespace) -> None:
    """Checks shared by ``run`` and ``sweep``, done before anything renders."""
    from ..data import check_count
    from ..resolution import parse_res

    for item in args.param or []:
        if len(item) > MAX_PARAM_CHARS:
            raise DbenchInputError(f"--param: {len(item)} characters; at most {MAX_PARAM_CHARS}")
    args.res = parse_res(args.res, "--res")
    for name in ("repeats", "seeds"):
        check_count(f"--{name}", getattr(args, name))
    from ..datasets.references import check_seed

    check_seed(args.seed, args.seeds)  # the last noisy seed is --seed + --seeds − 1
    from ..datasets.references import check_ref_spp, reference_spp

    if args.ref_spp is not None:
        check_ref_spp(args.ref_spp)
    else:

        reference_spp()  # a bad DBENCH_REF_SPP is refused here, before anything renders
    if getattr(args, "bins", None) is not None:  # the transient film's memory at this size
        from ..datasets.transient.scene import check_bins

        check_bins(args.bins, args.res, "--bins")
    check_rank_by(args.rank_by)
    from ..data import check_transform

    try:
        check_transform(args.transform or "box-cox", DEFAULT_LAM if args.lam is None else args.lam)
    except DbenchInputError as exc:
        raise DbenchInputError(f"--transform/--lam: {exc}") from None


def _writable_cache(args: argparse.Namespace):
    """The run's cache, checked for writing before anything renders. ``--cache DIR`` that
    cannot be written is refused (exit 2): the user named it. The cache only saves time, so
    when the folder comes from the environment (``$DBENCH_CACHE`` naming a file, a read-only
    home's ``~/.cache/dbench``) the command carries on without it, after one warning line, and
    renders everything (a sweep, whose workers share renders through the cache, refuses:
    :func:`dbench.run.sweep.run_sweep`)."""
    import sys

    from .. import datasets
    from ..datasets.cache import origin
    from ..io import ensure_writable_dir

    cache = datasets.Cache(args.cache, enabled=not args.no_cache)
    if not cache.enabled:
        return cache
    if args.cache is not None:
        ensure_writable_dir(cache.root, "--cache")
        return cache
    try:
        ensure_writable_dir(cache.root, origin(args.cache))
    except DbenchInputError as exc:
        print(f"dbench: warning: {exc}; carrying on without the cache (nothing is read from "
              f"it or saved; --cache DIR names another)", file=sys.stderr)
        args.no_cache = True
        return datasets.Cache(cache.root, enabled=False)
    return cache


def _scene_of(args: argparse.Namespace):
    """The Scene of ``--scene`` (catalogue name, scene file or folder) with ``--scene-param``
    (NAME=VALUE, or SCENE:NAME=VALUE naming this one scene as written in ``--scene``:
    dbench.datasets.scenes.scoped) and, for a folder of renders, ``--normal-encoding`` (refused
    for a scene dbench renders, whose normals are its own, signed)."""
    from ..datasets.scenes import catalogue as scenes, scoped

    every, own = scoped.split(args.scene_param, [args.scene], "--scene")
    scene = scoped.scene_of(args.scene, every, own)
    return scenes.with_normal_encoding(scene, getattr(args, "normal_encoding", None), args.scene)


def check_kind_options(args: argparse.Namespace, scenes: Sequence, names: Sequence[str]) -> None:
    """Refuse ``--frames`` where none of ``scenes`` (named ``names``) is a sequence and
    ``--bins`` where none is transient: read by nothing, they would leave the user believing
    the run used them (and a sweep would store them in its identity)."""
    kinds = {sc.kind for sc in scenes}
    for option, kind in (("frames", "sequence"), ("bins", "transient")):
        if getattr(args, option, None) is not None and kind not in kinds:
            held = (f"{names[0]} is a {scenes[0].kind} scene" if len(scenes) == 1 else
                    f"this sweep's scenes ({', '.join(names)}) have none")
            raise DbenchInputError(f"--{option}: only {kind} scenes take it; {held}")


#: λ of the Box-Cox and Yeo-Johnson transforms where ``--lam`` is not given
DEFAULT_LAM = 0.5


def check_lam(args: argparse.Namespace, scenes: Sequence, names: Sequence[str],
              spps: Sequence[int]) -> None:
    """Refuse a ``--lam`` that none of ``scenes`` (named ``names``, at ``spps``) reads, or that
    differs from the λ a folder's statistics were gathered with; then set ``args.lam`` (not
    given: :data:`DEFAULT_LAM`). λ is read only by the Box-Cox and Yeo-Johnson transforms: with
    ``--transform identity``, or without ``--transform`` where every scene's statistics use the
    identity (transient scenes, folders of variance images), it would change nothing while the
    run records it (docs/methods/statistical.md §3). A folder's statistics are compared, at
    each of ``spps``, under their own transform with this λ by
    :func:`dbench.datasets.check_folder_transform` (which also compares a ``--transform``
    given with it)."""
    from ..datasets import check_folder_transform, default_transform

    lam, args.lam = args.lam, DEFAULT_LAM if args.lam is None else args.lam
    if lam is None or args.transform not in (None, "identity"):
        return
    if args.transform == "identity":
        raise DbenchInputError("--lam: the identity transform takes no λ; leave --lam out or "
                               "give --transform box-cox or yeo-johnson")
    unread = []
    for sc, name in zip(scenes, names):
        if sc.renders:
            held = {default_transform(sc.kind)}
        else:
            kept = [s for s in spps if s in sc.info.stats_settings]
            held = {sc.info.stats_settings[s][0] for s in kept}
            for s in kept:  # each spp: their λ may differ from one to the next
                check_folder_transform(sc, s, sc.info.stats_settings[s][0], lam, "--lam")
        if held <= {"identity"}:
            unread.append(f"{name} ({'identity' if held else 'no statistics'})")
    if len(unread) == len(names):
        raise DbenchInputError(f"--lam: only the box-cox and yeo-johnson transforms take λ, and "
                               f"no scene here uses one: {', '.join(unread)}; give --transform "
                               f"with it")


def _default_spp(scene, fallback: int = 16) -> int:
    """``--spp`` when not given: ``fallback`` for rendered scenes; a folder's only spp (a
    folder with several makes the user choose)."""
    if scene.renders:
        return fallback
    spps = list(scene.info.spps)
    if len(spps) == 1:
        return spps[0]
    raise DbenchInputError(f"--spp: {scene.info.path} holds spp {', '.join(map(str, spps))}; "
                           f"choose one")
