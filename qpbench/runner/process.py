"""Worker processes, the one place that starts, feeds, times out and reaps them: a worker answers
``fn(arg)`` requests one at a time (:class:`Worker`; :func:`run_tasks` is the pool); a request
ends ``ok``, ``error`` (it raised), ``time_limit`` (SIGKILL at its deadline) or ``crashed``."""

from __future__ import annotations

import importlib
import logging
import math
import multiprocessing
import os
import signal
import socket
import sys
import time
import weakref
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from multiprocessing.connection import wait
from typing import TYPE_CHECKING

from ..statuses import describe_exception

if TYPE_CHECKING:
    from multiprocessing.connection import Connection
    from multiprocessing.context import BaseContext

log = logging.getLogger("qpbench.runner")

#: Time allowed for the forkserver's preload and for a worker to start [s].
START_TIMEOUT_S = 120.0
#: Least slack added to a solve's time limit before its worker is killed [s] (:func:`deadline`).
DEADLINE_MARGIN_S = 1.0
#: Runs of a task before it is reported lost (the first and one retry), in a pool that retries.
MAX_ATTEMPTS = 2

#: Modules the forkserver imports once, for every worker forked from it.
PRELOAD = (
    "qpbench.runner.process",
    "qpbench.harness.guard",
    "qpbench.backends",
    "numpy",
    "scipy.sparse",
    "qpbench.harness.preload",
    "qpbench.harness.closed_loop",  # every closed-loop run's worker (pandas, the loop)
)

#: Environment variable naming the kernels the forkserver's preload loads (comma-separated).
PRELOAD_KERNELS_ENV = "QPBENCH_PRELOAD_KERNELS"

_CTX = None
_KERNELS: tuple[str, ...] = ()
#: The kernels the running forkserver loaded, and the workers forked from it (alive or not).
_PRELOADED: tuple[str, ...] = ()
_FORKED: weakref.WeakSet = weakref.WeakSet()


def preload_kernels(names) -> None:
    """Name the compiled kernels the forkserver loads for every worker (:func:`qpbench.jit.prepare`)."""
    global _KERNELS
    _KERNELS = tuple(names)


def context(fresh: bool = False) -> BaseContext:
    """The start method's context, its forkserver started and preloaded now; ``fresh``: ``spawn``,
    never a fork of a process that may hold threads and locks. A forkserver that loaded fewer
    kernels than are named now is replaced once no worker forked from it lives (each worker
    would load the others itself; a live worker would seem dead when its server ends)."""
    global _CTX, _PRELOADED
    if fresh:
        return multiprocessing.get_context("spawn")
    stale = _CTX is not None and _CTX.get_start_method() == "forkserver"
    stale = stale and not set(_KERNELS) <= set(_PRELOADED)
    if stale and not any(w.proc.is_alive() for w in _FORKED):
        from multiprocessing import forkserver

        stop = getattr(forkserver._forkserver, "_stop", None)  # CPython's, since 3.8
        if stop is not None:
            stop()  # the next worker starts a new server
            _CTX = None
    if _CTX is None:
        forkserver = "forkserver" in multiprocessing.get_all_start_methods()
        ctx = multiprocessing.get_context("forkserver" if forkserver else "spawn")
        if forkserver:
            _PRELOADED = _KERNELS
            os.environ[PRELOAD_KERNELS_ENV] = ",".join(_KERNELS)
            ctx.set_forkserver_preload(list(PRELOAD))
            # wait for the preload now (a child doing nothing): no deadline covers it
            proc = ctx.Process(target=_noop, name="qpbench-forkserver-ready")
            with _safe_path():
                proc.start()
            proc.join(START_TIMEOUT_S)
        _CTX = ctx
    return _CTX


def _noop() -> None:
    pass


@contextmanager
def _safe_path():
    """The forkserver started with ``PYTHONSAFEPATH`` set: CPython 3.11's server imports its
    preload with the current folder first on its path (it runs ``python -c``), so in a clone
    with qpbench installed beside it the workers ran the clone's ``qpbench/`` while this process
    ran the installed one, and every compiled kernel was compiled and cached twice."""
    before = os.environ.get("PYTHONSAFEPATH")
    os.environ["PYTHONSAFEPATH"] = "1"
    try:
        yield
    finally:
        if before is None:
            del os.environ["PYTHONSAFEPATH"]
        else:
            os.environ["PYTHONSAFEPATH"] = before


def deadline(time_limit: float, solves: int = 1) -> float:
    """Deadline [s] of a request of ``solves`` solves of at most ``time_limit`` [s] each:
    ``time_limit * solves + max(DEADLINE_MARGIN_S, time_limit / 2)``."""
    return time_limit * solves + max(DEADLINE_MARGIN_S, time_limit / 2)


def death_message(exitcode: int | None) -> str:
    """How a worker ended without an answer (``worker process killed by SIGSEGV``)."""
    if exitcode is not None and exitcode < 0:
        try:
            return f"worker process killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"worker process killed by signal {-exitcode}"
    return f"worker process exited with code {exitcode}"


def requests(conn: Connection) -> Iterator:
    """Each request received on ``conn``, until ``None`` or the other end closes."""
    with suppress(EOFError):
        yield from iter(conn.recv, None)


def _serve(conn, environ: dict, imports: tuple[str, ...]) -> None:
    """A worker: import ``imports``, say ready, answer ``(fn, arg)`` requests until ``None``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ.clear()
    os.environ.update(environ)
    for module in imports:
        importlib.import_module(module)
    conn.send(("ready", None))
    for fn, arg in requests(conn):
        try:
            answer = ("ok", fn(arg))
        except BaseException as exc:  # noqa: BLE001 - reported, the worker lives on
            answer = ("exc", describe_exception(exc))
        try:
            conn.send(answer)
        except Exception as exc:  # noqa: BLE001 - an unpicklable answer
            conn.send(("exc", describe_exception(exc)))


class WorkerDied(Exception):
    """A request gave no answer; ``status`` is ``error``, ``crashed`` or ``time_limit``."""

    def __init__(self, status: str, message: str):
        super().__init__(message)
        self.status = status
        self.message = message


class Worker:
    """One worker process (a daemon) and its pipe; ``imports``: modules it imports before it says
    ready."""

    def __init__(
        self, ctx: BaseContext | None = None, name: str = "qpbench-worker", imports: tuple = ()
    ):
        ctx = ctx if ctx is not None else context()
        self.conn, child = ctx.Pipe()
        args = (child, dict(os.environ), tuple(imports))
        self.proc = ctx.Process(target=_serve, args=args, daemon=True, name=name)
        self.proc.start()
        child.close()
        if ctx.get_start_method() == "forkserver":
            _FORKED.add(self)
        self.ready = False
        self.alive = True
        self.task = None  # the pool's (key, arg, timeout, attempts)
        self.timeout: float | None = None
        self.deadline = math.inf

    def send(self, fn: Callable, arg, timeout: float | None) -> None:
        """Start request ``fn(arg)``, answered within ``timeout`` [s] (``None``: no limit);
        :class:`WorkerDied` (the worker killed) if the worker did not start or died before the
        request reached it."""
        if not self.ready:
            self.deadline, self.timeout = time.monotonic() + START_TIMEOUT_S, START_TIMEOUT_S
            status, payload = self._wait()
            if status != "ready":
                self.kill()
                raise WorkerDied(status, f"{payload} during start")
            self.ready = True
        self.timeout = timeout
        self.deadline = math.inf if timeout is None else time.monotonic() + timeout
        try:
            self.conn.send((fn, arg))
        except OSError:  # the pipe is closed: the worker is gone
            self.proc.join(2)
            message = death_message(self.proc.exitcode)
            self.kill()
            raise WorkerDied("crashed", f"{message} before its request") from None

    def poll(self) -> tuple[str, object] | None:
        """``(status, payload)`` once the request is over, else ``None``."""
        with suppress(EOFError, OSError):
            if self.conn.poll():
                kind, payload = self.conn.recv()
                return {"exc": "error"}.get(kind, kind), payload
        if not self.proc.is_alive():
            self.proc.join(2)
            message = death_message(self.proc.exitcode)
            self.kill()
            return "crashed", message
        if time.monotonic() >= self.deadline:
            self.kill()
            return "time_limit", f"no answer after {self.timeout:.3g} s"
        return None

    def _wait(self) -> tuple[str, object]:
        while (answer := self.poll()) is None:
            left = self.deadline - time.monotonic()
            wait([self.conn, self.proc.sentinel], None if math.isinf(left) else max(left, 0.0))
        return answer

    def call(self, fn: Callable, arg, timeout: float | None, what: str):
        """``fn(arg)`` in the worker within ``timeout`` [s], else :class:`WorkerDied` naming ``what``."""
        self.send(fn, arg, timeout)
        status, payload = self._wait()
        if status == "ok":
            return payload
        if status == "time_limit":
            payload = f"{payload} during {what}; worker killed"
        elif status == "crashed":
            payload = f"{payload} during {what}"
        raise WorkerDied(status, payload)

    def kill(self) -> None:
        """Kill the worker if it is alive (SIGKILL), reap it and close the pipe."""
        self.alive = False
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join(5)
        self.conn.close()

    def stop(self) -> None:
        """Ask the worker to end (it finishes nothing more), then :meth:`kill` what is left."""
        if self.alive and self.proc.is_alive():
            with suppress(OSError, ValueError):
                self.conn.send(None)
                self.proc.join(2)
        self.kill()


def run_located(fn: Callable, arg) -> tuple:
    """``fn(arg)`` with the host and worker that ran it (on a Dask worker: its address)."""
    worker = f"pid{os.getpid()}"
    if "distributed" in sys.modules:
        with suppress(ValueError):  # not in a Dask worker
            worker = sys.modules["distributed"].get_worker().address
    return fn(arg), socket.gethostname(), worker


@dataclass
class Done:
    """A finished task: ``value`` (``fn(arg)``) or ``lost`` (why not, ``status`` saying which);
    where its last attempt ran; ``concurrent``: the tasks that could run at once on that host."""

    key: object
    value: object
    lost: str | None
    attempts: int
    host: str
    worker: str
    concurrent: int
    status: str | None = None


def retry_note(key, why: str, attempt: int, attempts: int = MAX_ATTEMPTS) -> str | None:
    """After attempt ``attempt`` of a task lost ``why``: ``None`` (it runs again) while attempts
    are left, else why it is lost."""
    if attempt < attempts:
        log.warning("%s: %s; running it again", key, why)
        return None
    return f"{why} (attempt {attempt} of {attempts})"


def run_tasks(
    fn: Callable,
    tasks: list[tuple],
    jobs: int,
    *,
    ctx: BaseContext | None = None,
    attempts: int = 1,
    fresh: bool = False,
    name: str = "qpbench-worker",
) -> Iterator[Done]:
    """A :class:`Done` per task ``(key, arg, timeout [s] or None)``, as they end, on up to ``jobs``
    workers; ``attempts``: runs of a task whose worker died; ``fresh``: a new worker per task."""
    if not tasks:
        return
    ctx = ctx if ctx is not None else context()
    host = socket.gethostname()
    queue = deque((key, arg, timeout, 0) for key, arg, timeout in tasks)
    slots = max(1, min(int(jobs), len(tasks)))
    imports = (fn.__module__,)  # the task's module is loaded before any deadline runs
    workers = [Worker(ctx, f"{name}-{i}", imports) for i in range(slots)]
    try:
        while queue or any(w.task for w in workers):
            ended = []  # (worker, (status, payload)) of the tasks over
            for i, w in enumerate(workers):
                if w.task is None and queue:
                    if not w.alive:
                        workers[i] = w = Worker(ctx, f"{name}-{i}", imports)
                    key, arg, timeout, tried = queue.popleft()
                    w.task = (key, arg, timeout, tried + 1)
                    try:
                        w.send(fn, arg, timeout)
                    except WorkerDied as died:  # while starting or being sent it: as mid-task
                        ended.append((w, (died.status, died.message)))
            busy = [w for w in workers if w.task and w.alive]
            if busy and not ended:
                left = min(w.deadline for w in busy) - time.monotonic()
                wait(
                    [w.conn for w in busy] + [w.proc.sentinel for w in busy],
                    None if math.isinf(left) else max(left, 0.0),
                )
            ended += [(w, answer) for w in busy if (answer := w.poll()) is not None]
            for w, answer in ended:
                (key, arg, timeout, tried), w.task = w.task, None
                status, payload = answer
                if fresh:
                    w.stop()  # a new worker for the next task; this one's memory is freed now
                if status == "crashed" and attempts > 1:
                    payload = retry_note(key, payload, tried, attempts)
                    if payload is None:
                        queue.appendleft((key, arg, timeout, tried))
                        continue
                value, lost = (payload, None) if status == "ok" else (None, payload)
                worker = f"pid{w.proc.pid}"
                yield Done(key, value, lost, tried, host, worker, slots, status if lost else None)
    finally:
        for w in workers:
            if w.task is not None:
                w.kill()
            else:
                w.stop()
