"""argv for the tests that call :func:`dbench.cli.main` with a base argv and a change to it
(importable from every test folder: pytest puts ``tests/`` on ``sys.path`` for
``tests/conftest.py``). A single-valued option given twice is refused (README.md, "Usage"),
so a change replaces the option's value where it stands instead of giving the option again.
Also the check of a refusal (one line, exit 2) and a small scene file with a ``$light``."""
from __future__ import annotations

from typing import Sequence

from dbench import cli


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


def refused(capsys, argv: Sequence[str], *words: str) -> str:
    """Runs ``dbench argv`` and checks it was refused as README.md ("Usage") says: exit 2, one
    line on standard error starting ``dbench: `` and holding each of ``words``, no traceback.
    Returns that line."""
    rc = cli.main(list(argv))
    out, err = capsys.readouterr()
    assert rc == 2 and err.startswith("dbench: ") and err.count("\n") == 1, (rc, out, err)
    assert "Traceback" not in err
    for w in words:
        assert w in err, err
    return err


def lamp_scene(light: str | None = None) -> str:
    """A 16² scene file (a sphere under an area light) whose light's radiance is ``$light``:
    with ``light``, its ``<default>``; without, a value the command line must give."""
    default = f'\n  <default name="light" value="{light}"/>' if light is not None else ""
    return f"""<scene version="3.0.0">{default}
  <sensor type="perspective"><float name="fov" value="50"/>
    <transform name="to_world"><lookat origin="0,1,4" target="0,0.3,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
    </film></sensor>
  <shape type="sphere"><float name="radius" value="0.5"/></shape>
  <shape type="rectangle"><transform name="to_world"><translate y="2"/></transform>
    <emitter type="area"><rgb name="radiance" value="$light"/></emitter></shape>
</scene>
"""
