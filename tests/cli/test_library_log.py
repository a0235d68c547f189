"""The other libraries' warnings (dbench/run/capture.py): kept in ``run.log`` / ``sweep.log``
and counted in ``report.md`` (README.md, "Usage")."""
from __future__ import annotations

import logging

from dbench.run.capture import count_text, library_warnings, log_text


def test_one_warning_is_one_warning_in_the_log_and_the_count():
    assert log_text(["x"]).splitlines()[0] == "1 library warning"
    assert log_text(["x", "y"]).splitlines()[0] == "2 library warnings"
    assert count_text(["x"]) == "1 library warning, see run.log"
    assert log_text([]) == "no library warnings\n"


def test_nested_blocks_keep_a_logging_record_once():
    """A serial sweep runs each group inside its own block, inside the sweep's: the innermost
    keeps the record (the sweep then gets it from the group's lines), so sweep.log holds a
    library's logging warning once, not twice."""
    with library_warnings() as outer:
        with library_warnings() as inner:
            logging.getLogger("some.library").warning("once")
        logging.getLogger("some.library").warning("after")
    assert inner == ["WARNING some.library: once"]
    assert outer == ["WARNING some.library: after"]
