"""How ``dbench sweep`` runs its groups: in its own process, on a local process pool
(``--workers N``) or as Ray tasks (:func:`execute`), and how a pool stops.

Ctrl-C (SIGINT to the terminal's process group) reaches the sweep and its workers alike. The
workers ignore it, so that none of them reports the interrupt as its group's result and goes on
to the next group; the sweep process cancels the groups not started, terminates the workers (a
cell being written by one is left as a temporary file, removed by the next run, and is computed
again then) and exits with code 130, keeping every finished cell (README.md, the ``dbench sweep``
paragraph). A worker also dies with the sweep process (Linux ``PR_SET_PDEATHSIG``), so
``kill -9`` of a sweep never leaves workers behind.

:func:`check_executor` refuses, before the sweep writes anything, an executor it cannot use.
"""
from __future__ import annotations

import signal
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Callable, Sequence

from . import identity

#: seconds a terminated worker is given to exit before it is killed
STOP_GRACE_S = 3.0


def check_executor(executor: str) -> None:
    """Refuse an executor :func:`dbench.run.sweep.run_sweep` does not have, and ``ray`` where
    Ray is not installed (an optional dependency, pyproject.toml's ``ray`` extra): found only
    when the groups were dispatched, it ended the run as an internal error after sweep.json
    was written and the references rendered."""
    import importlib.util

    from ..errors import DbenchInputError

    if executor not in ("local", "ray"):
        raise DbenchInputError(f"--executor: {executor!r}; valid: local, ray")
    if executor == "ray" and importlib.util.find_spec("ray") is None:
        raise DbenchInputError("--executor ray: Ray is not installed here (pip install "
                               "'dbench[ray]'); install it, or use --executor local")


def _die_with_parent() -> None:
    """The worker is killed when the sweep process dies (Linux PR_SET_PDEATHSIG)."""
    try:
        import ctypes
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # pragma: no cover - not Linux
        pass


def worker_start(plugin_specs: Sequence[str] = (), load_lines: Sequence[str] = ()) -> None:
    """Process-pool initializer: ignore Ctrl-C (the sweep process stops the pool), end at once
    on the SIGTERM with which :func:`stop` ends it, die with the parent, then load the parent's
    plugins (entry points, $DBENCH_PLUGINS and every --plugin), so the worker can build plugin
    methods, and hash every method's code afresh. ``load_lines``: the Mitsuba warnings the
    sweep process's loads of its scenes gave, kept in sweep.log once, which the worker's loads
    of the same scenes do not repeat (:func:`dbench.datasets.mitsuba_log.inherit`)."""
    from .. import plugins, registry  # noqa: F401 - the built-in methods before the plugins
    from ..datasets import mitsuba_log

    mitsuba_log.inherit(load_lines)

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # the sweep process's SIGTERM handler, forked into the worker, raised its interrupt there:
    # an idle worker (waiting for a group) printed "Process ForkProcess-2: Traceback ..." on
    # every Ctrl-C or SIGTERM of the sweep
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _die_with_parent()
    plugins.worker_init(plugin_specs)
    # the worker hashes the code as it finds it, for run_group to compare with the sweep's
    # hash: a fork inherits the sweep's hashes, which would hide a file edited since
    identity.method_version.cache_clear()


def stop(pool: ProcessPoolExecutor) -> None:
    """Cancel the groups not started and end the workers now (SIGTERM, then SIGKILL)."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        if p.is_alive():
            p.terminate()
    for p in processes:
        p.join(STOP_GRACE_S)
        if p.is_alive():
            p.kill()
            p.join(1.0)


def _start_method():
    """The workers' start method: started afresh, never forked from the sweep process. A fork
    copies a process whose thread pools (PyTorch's OpenMP, after any tensor operation) cannot
    run in the copy: its first such operation waited forever, so a sweep started where PyTorch
    had already run (a notebook, a script, the test suite) hung. ``forkserver`` (Python 3.14's
    default on Linux) forks from a clean server; ``spawn`` elsewhere."""
    import multiprocessing

    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")


def run_groups(fn: Callable, args: Sequence, groups: Sequence[tuple], workers: int,
               plugin_specs: Sequence[str], done: Callable[[list], None]) -> None:
    """Run ``fn(*args, *group)`` for every group on ``workers`` processes, calling ``done``
    with each group's result as it finishes; any exception or interrupt stops the pool
    before it propagates."""
    from ..datasets.mitsuba_log import load_lines

    pool = ProcessPoolExecutor(max_workers=workers, initializer=worker_start,
                               initargs=(tuple(plugin_specs), load_lines()),
                               mp_context=_start_method())
    try:
        futures = [pool.submit(fn, *args, *g) for g in groups]
        for f in as_completed(futures):
            done(f.result())
    except BaseException:
        stop(pool)
        raise
    pool.shutdown(wait=True)


def execute(groups: Sequence[tuple], args: tuple, executor: str, workers: int, progress: bool,
            warned: list[str], local: Callable, remote_fn: Callable) -> None:
    """Run the groups of :func:`dbench.run.sweep.plan` (their references rendered already):
    ``local(*args, *group, beside=...)`` here or on the pool, ``remote_fn(plugin specs, *args,
    *group, most_beside=...)`` as Ray tasks; each returns ``{"written": [...], "warnings":
    [...]}``, and ``warned`` gathers the groups' library warnings, from every worker.

    Groups run side by side render, judge and time at once on the same cores, so a cell's
    time then includes that contention: each cell records how many other groups could run
    beside it (``timed_beside``: the pool's other workers, or the other Ray tasks its node
    runs at once; 0 in one process), and the reports say so (README.md, the ``dbench sweep``
    paragraph)."""
    from functools import partial

    from tqdm.auto import tqdm

    from .. import plugins

    if not groups:
        return
    bar = tqdm(total=sum(len(g[2]) for g in groups), desc="sweep", unit="cell",
               disable=not progress)

    def done(result: dict[str, list[str]]) -> None:
        warned.extend(result["warnings"])
        bar.update(len(result["written"]))

    plugin_specs = plugins.requested()  # workers load the same plugins as this process
    said = side_by_side_line(executor, workers, len(groups))
    if said:  # once nothing refused the sweep: a refusal stays one line
        print(f"dbench: warning: {said}", file=sys.stderr)
    if executor == "ray":
        import ray

        if not ray.is_initialized():
            ray.init(ignore_reinit_error=True, include_dashboard=False, log_to_driver=False)
        remote = ray.remote(remote_fn)
        from ..datasets.mitsuba_log import load_lines

        lines = load_lines()  # as the pool's workers get them (worker_start)
        pending = [remote.remote(plugin_specs, *args, *g, most_beside=len(groups) - 1,
                                 load_lines=lines) for g in groups]
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            done(ray.get(ready[0]))
    elif workers > 1:  # a group alone on the pool is timed alone
        run_groups(partial(local, beside=min(workers, len(groups)) - 1), args, groups,
                   workers, plugin_specs, done)
    else:
        for g in groups:
            done(local(*args, *g))
    bar.close()


def ray_beside(most: int) -> int:
    """In a Ray task: how many other tasks its node may run at once, at most ``most`` (the
    sweep's other groups). Ray gives a task one CPU and a node as many task slots as it has
    CPUs (its ``CPU`` resource), so a node of 4 CPUs times a cell beside up to 3 others."""
    import ray

    try:
        node = ray.get_runtime_context().get_node_id()
        cpus = next(n.get("Resources", {}).get("CPU", 1) for n in ray.nodes()
                    if n.get("NodeID") == node)
    except Exception:  # noqa: BLE001 - no node table: Ray's default, one slot per core
        from .machine import usable_cores
        cpus = usable_cores()
    return max(0, min(int(cpus) - 1, int(most)))


def side_by_side_line(executor: str, workers: int, groups: int) -> str:
    """What ``dbench sweep`` says before its ``groups`` run where it times cells side by side
    (``--workers`` above 1 and several groups, or Ray), '' where it times them alone."""
    from .machine import cores_text

    if groups <= 1 or (executor != "ray" and workers <= 1):
        return ""
    if executor == "ray":
        return ("--executor ray: a node runs as many cells at once as it has CPUs, so the "
                "cells are timed side by side; their time_s includes that contention and does "
                "not compare with a sweep's with --workers 1")
    return (f"--workers {workers}: up to {min(workers, groups)} cells are timed side by side "
            f"on {cores_text()}; their time_s includes that contention and does not "
            "compare with a sweep's with --workers 1")


__all__ = ["STOP_GRACE_S", "check_executor", "execute", "ray_beside", "run_groups",
           "side_by_side_line", "stop", "worker_start"]
