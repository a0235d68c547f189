"""``dbench bench plugins``: the entry-point scan timed in a fresh interpreter after the
built-in methods load (dbench/speed/files.py)."""
import math

from dbench.speed.files import bench_plugin_discovery, format_result


def test_plugin_discovery_is_timed_in_a_fresh_interpreter():
    r = bench_plugin_discovery(repeats=1)
    assert r["benchmark"] == "plugins" and r["repeats"] == 1
    assert math.isfinite(r["builtins_s"]) and r["builtins_s"] > 0
    assert math.isfinite(r["discovery_s"]) and r["discovery_s"] >= 0
    assert format_result(r).startswith("plugin discovery (entry points")
