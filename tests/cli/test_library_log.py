"""The other libraries' warnings (dbench/run/capture.py): kept in ``run.log`` / ``sweep.log``
and counted in ``report.md`` (README.md, "Usage")."""
from __future__ import annotations

from dbench.run.capture import count_text, log_text


def test_one_warning_is_one_warning_in_the_log_and_the_count():
    assert log_text(["x"]).splitlines()[0] == "1 library warning"
    assert log_text(["x", "y"]).splitlines()[0] == "2 library warnings"
    assert count_text(["x"]) == "1 library warning, see run.log"
    assert log_text([]) == "no library warnings\n"
