"""A Dask worker plugin that keeps a worker's event loop timers from taking the GIL from the
task's thread (imports ``distributed``)."""

from __future__ import annotations

from distributed.diagnostics.plugin import WorkerPlugin

#: Name of the plugin on the cluster (one registration per cluster).
PLUGIN_NAME = "qpbench-quiet-worker"


class QuietWorker(WorkerPlugin):
    """Stop the worker's periodic callbacks ``stop`` and run ``slow`` (``{name: period [s]}``)
    less often, while registered (a stopped one leaves ``Worker.periodic_callbacks``)."""

    name = PLUGIN_NAME

    def __init__(self, stop: tuple[str, ...] = (), slow: dict[str, float] | None = None):
        self.stop = tuple(stop)
        self.slow = dict(slow or {})
        self._removed: dict = {}
        self._periods: dict[str, float] = {}

    def setup(self, worker) -> None:
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
        callbacks = worker.periodic_callbacks
        for name, ms in self._periods.items():
            if name in callbacks:
                _retime(callbacks[name], ms)
        for name, pc in self._removed.items():
            callbacks.setdefault(name, pc).start()
        self._removed, self._periods = {}, {}


def _retime(pc, ms: float) -> None:
    running = pc.is_running()
    if running:
        pc.stop()
    pc.callback_time = ms
    if running:
        pc.start()
