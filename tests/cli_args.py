"""argv for the tests that call :func:`dbench.cli.main` with a base argv and a change to it
(importable from every test folder: pytest puts ``tests/`` on ``sys.path`` for
``tests/conftest.py``). A single-valued option given twice is refused (README.md, "Usage"),
so a change replaces the option's value where it stands instead of giving the option again."""
from __future__ import annotations

from typing import Sequence


def with_options(argv: Sequence[str], *change: str) -> list[str]:
    """``argv`` with ``change`` (OPTION VALUE pairs of single-valued options): an option already
    in ``argv`` gets the new value in its place, any other is added at the end."""
    assert len(change) % 2 == 0, change
    argv = list(argv)
    for option, value in zip(change[::2], change[1::2]):
        if option in argv:
            argv[argv.index(option) + 1] = value
        else:
            argv += [option, value]
    return argv
