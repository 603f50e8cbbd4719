"""A Dask worker plugin that keeps a worker's event loop out of the way of the task's thread.

A Dask worker runs each task in a thread beside its event loop, and both
need the GIL. The event loop wakes on its own timers: the statistical
profiler (``profile``, every 10 ms: it walks the task's stack while holding
the GIL) and the event loop's health check (``tick``, every 20 ms). Each
wake takes the GIL from the task's thread, so a closed-loop run that is
pure computation runs slower on a worker than in a process of its own.

:class:`QuietWorker` stops those timers while it is registered (the client
registers it on every worker of the cluster, present and future, and
removes it when done, which restores them). A worker started with the same
settings needs no plugin (:data:`qpbench.runner.dask_.WORKER_CONFIG`).

This module imports ``distributed``: import it only where Dask is installed.
"""

from __future__ import annotations

from distributed.diagnostics.plugin import WorkerPlugin

__all__ = ["PLUGIN_NAME", "QuietWorker"]

#: Name of the plugin on the cluster (one registration per cluster: the last client to leave restores).
PLUGIN_NAME = "qpbench-quiet-worker"


class QuietWorker(WorkerPlugin):
    """Take the worker's periodic callbacks ``stop`` away, run ``slow`` less often, while registered.

    Args:
        stop: Names of the worker's periodic callbacks to stop (``Worker.periodic_callbacks``).
        slow: ``{name: period in [s]}`` of callbacks to run less often.

    A stopped callback leaves ``Worker.periodic_callbacks`` (so that a
    worker that joins the cluster later, which sets its plugins up before it
    starts its callbacks, does not start it) and comes back, running, at
    teardown. Callbacks the worker does not have (a worker started with the
    profiler off has no ``profile``) are left alone.
    """

    name = PLUGIN_NAME

    def __init__(self, stop: tuple[str, ...] = (), slow: dict[str, float] | None = None):
        self.stop = tuple(stop)
        self.slow = dict(slow or {})
        self._removed: dict = {}
        self._periods: dict[str, float] = {}

    def setup(self, worker) -> None:
        """Runs on the worker's event loop (the callbacks' own thread)."""
        callbacks = worker.periodic_callbacks
        for name in self.stop:
            if name in callbacks:
                self._removed[name] = pc = callbacks.pop(name)
                pc.stop()
        for name, period in self.slow.items():
            pc = callbacks.get(name)
            if pc is not None and pc.callback_time < period * 1e3:
                self._periods[name] = pc.callback_time
                _retime(pc, period * 1e3)

    def teardown(self, worker) -> None:
        """Runs on the worker's event loop, also when the worker closes (which then stops every callback)."""
        callbacks = worker.periodic_callbacks
        for name, ms in self._periods.items():
            if name in callbacks:
                _retime(callbacks[name], ms)
        for name, pc in self._removed.items():
            callbacks.setdefault(name, pc).start()
        self._removed, self._periods = {}, {}


def _retime(pc, ms: float) -> None:
    """Give tornado periodic callback ``pc`` a period of ``ms`` [ms] (restarting it if it ran)."""
    running = pc.is_running()
    if running:
        pc.stop()
    pc.callback_time = ms
    if running:
        pc.start()
