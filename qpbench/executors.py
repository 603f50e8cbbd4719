"""Where independent tasks run: this process, local worker processes, or a Dask cluster.

A task is ``fn(arg)`` with ``fn`` a module-level function (so that a worker
can import it by name) and ``arg`` plain picklable data; its value comes back
as a :class:`Done`, in the order the tasks finish. Every executor gives the
same values for the same tasks: only where and when they ran differs.

- :class:`SerialExecutor`: in this process, one task after the other (for
  the Python API; a crash in a solver ends the process).
- :class:`ProcessExecutor`: ``jobs`` long-lived worker processes, forked from
  the forkserver that holds qpbench and its compiled kernels
  (:func:`qpbench.harness.workers.context`). A worker that dies (a
  segfault in a solver, SIGKILL from the out-of-memory killer) loses only its
  task: it is retried once on a fresh worker, then reported lost. With one
  job the tasks run one after the other, the only setting in which solve
  times are not disturbed by other runs.
- :class:`DaskExecutor`: an existing ``distributed`` cluster (``scheduler``
  address, ``tls://`` with a :func:`load_security` file) or an in-process
  ``LocalCluster`` bound to 127.0.0.1. Tasks are submitted at once and
  collected with ``distributed.as_completed``; a task whose worker was lost
  (``KilledWorker``) is submitted once more, then reported lost. The local
  cluster's scheduler gives up on a task at its first lost worker
  (``allowed-failures = 0``) so that the retry is this module's; an external
  scheduler first applies its own ``distributed.scheduler.allowed-failures``.

Dask's workers run whatever pickled code their scheduler sends them: a
scheduler reachable by others lets them run code on every worker. Hence the
local cluster listens on 127.0.0.1 only, and a remote cluster should be
reached over ``tls://`` with certificates (:func:`load_security`).
"""

from __future__ import annotations

import logging
import os
import socket
import sys
import tomllib
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from .exceptions import InputError, ParamError
from .harness.workers import death_message, ignore_interrupts

if TYPE_CHECKING:
    from distributed.security import Security

log = logging.getLogger("qpbench.executors")

__all__ = [
    "EXECUTORS",
    "DaskExecutor",
    "Done",
    "ProcessExecutor",
    "SerialExecutor",
    "default_jobs",
    "load_security",
    "make_executor",
]

#: Names of ``--executor``.
EXECUTORS = ("local", "dask")
#: Runs of a task before it is reported lost (the first and one retry).
MAX_ATTEMPTS = 2


def default_jobs() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


@dataclass
class Done:
    """A finished task.

    Attributes:
        key: The task's key, as given.
        value: ``fn(arg)``, or ``None`` when the task was lost.
        lost: Why it gave nothing (its worker was lost :data:`MAX_ATTEMPTS` times), else ``None``.
        attempts: Times it was started.
        host, worker: Where its last attempt ran.
        concurrent: Tasks that could run at once on that host.
    """

    key: object
    value: object
    lost: str | None
    attempts: int
    host: str
    worker: str
    concurrent: int


def _call(fn: Callable, arg) -> tuple:
    """``fn(arg)`` with the host and worker that ran it."""
    worker = f"pid{os.getpid()}"
    if "distributed" in sys.modules:  # on a Dask worker: its address
        try:
            worker = sys.modules["distributed"].get_worker().address
        except ValueError:
            pass
    return fn(arg), socket.gethostname(), worker


class SerialExecutor:
    """Every task in this process, in order."""

    name = "serial"
    concurrency = 1

    def run(self, fn: Callable, items: list[tuple]) -> Iterator[Done]:
        for key, arg in items:
            value, host, _ = _call(fn, arg)
            yield Done(key, value, None, 1, host, "main", 1)

    def close(self) -> None:
        pass


def _worker_loop(conn, environ: dict) -> None:
    """Body of a worker process: run ``(id, fn, arg)`` requests until ``None``.

    The worker takes the environment of the process that started it
    (``environ``), not the one the forkserver was started with.
    """
    ignore_interrupts()
    os.environ.clear()
    os.environ.update(environ)
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        if msg is None:
            return
        tid, fn, arg = msg
        conn.send((tid, _call(fn, arg)))


class _Worker:
    def __init__(self, ctx, index: int):
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(
            target=_worker_loop,
            args=(child, dict(os.environ)),
            daemon=True,
            name=f"qpbench-worker-{index}",
        )
        self.proc.start()
        child.close()
        self.task = None  # (tid, key, arg, attempts)

    def stop(self, kill: bool = False) -> None:
        try:
            if kill:
                self.proc.kill()
            else:
                self.conn.send(None)
        except (OSError, ValueError):
            pass
        self.proc.join(5)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join(5)
        self.conn.close()


class ProcessExecutor:
    """``jobs`` local worker processes; a lost worker's task is retried once, then reported lost."""

    name = "processes"

    def __init__(self, jobs: int):
        if jobs < 1:
            raise ParamError(f"must be >= 1, got {jobs}", key="--jobs")
        self.concurrency = jobs
        self._workers: list[_Worker] = []

    def _start(self, index: int) -> _Worker:
        from .harness.workers import context as _context

        return _Worker(_context(), index)

    def run(self, fn: Callable, items: list[tuple]) -> Iterator[Done]:
        from multiprocessing.connection import wait

        host = socket.gethostname()
        queue = deque((i, key, arg, 0) for i, (key, arg) in enumerate(items))
        self._workers = [self._start(i) for i in range(min(self.concurrency, len(items)))]
        try:
            while queue or any(w.task for w in self._workers):
                for w in self._workers:
                    if w.task is None and queue:
                        tid, key, arg, attempts = queue.popleft()
                        w.task = (tid, key, arg, attempts + 1)
                        w.conn.send((tid, fn, arg))
                busy = [w for w in self._workers if w.task]
                wait([w.conn for w in busy] + [w.proc.sentinel for w in busy])
                for i, w in enumerate(self._workers):
                    if not w.task:
                        continue
                    done = self._collect(w, host)
                    if done is None and w.proc.is_alive():
                        continue
                    if done is None:  # the worker died with the task
                        done = self._lost(w, queue, host)
                        self._workers[i] = self._start(i)
                    if done is not None:
                        yield done
        finally:
            self.close()

    def _collect(self, w: _Worker, host: str) -> Done | None:
        try:
            if not w.conn.poll():
                return None
            _, (value, _, worker) = w.conn.recv()
        except (EOFError, OSError):
            return None
        _, key, _, attempts = w.task
        w.task = None
        return Done(key, value, None, attempts, host, worker, self.concurrency)

    def _lost(self, w: _Worker, queue: deque, host: str) -> Done | None:
        w.proc.join(5)
        why = death_message(w.proc.exitcode)
        tid, key, arg, attempts = w.task
        w.task = None
        w.conn.close()
        if attempts < MAX_ATTEMPTS:
            log.warning("%s: %s; running it again", key, why)
            queue.appendleft((tid, key, arg, attempts))
            return None
        return Done(
            key,
            None,
            f"{why} (attempt {attempts} of {MAX_ATTEMPTS})",
            attempts,
            host,
            f"pid{w.proc.pid}",
            self.concurrency,
        )

    def close(self) -> None:
        for w in self._workers:
            w.stop(kill=w.task is not None)
        self._workers = []


def load_security(path: str | Path) -> Security:
    """A ``distributed.security.Security`` from a small TOML or YAML file.

    The file names PEM files (relative paths are read from the file's folder)::

        ca_file = "ca.pem"       # the certificate authority that signed every certificate
        cert_file = "node.pem"   # this machine's certificate
        key_file = "node-key.pem"

    The same certificate serves the client and, for the in-process local
    cluster, its scheduler and workers. Encryption is required.

    Raises:
        InputError: unreadable file, unknown or missing key, missing PEM file.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
        if path.suffix.lower() in (".yaml", ".yml"):
            import yaml

            raw = yaml.safe_load(text)
        else:
            raw = tomllib.loads(text)
    except Exception as exc:  # noqa: BLE001 - unreadable, bad TOML or YAML: one line
        raise InputError(
            f"cannot read the security file: {type(exc).__name__}: {exc}", path=path
        ) from None
    if not isinstance(raw, dict):
        raise InputError("expected keys ca_file, cert_file, key_file", path=path)
    for key in raw:
        if key not in ("ca_file", "cert_file", "key_file"):
            raise InputError(
                "unknown key (expected ca_file, cert_file, key_file)", path=path, key=key
            )
    files = {}
    for key in ("ca_file", "cert_file", "key_file"):
        if not isinstance(raw.get(key), str):
            raise InputError("missing key (the path of a PEM file)", path=path, key=key)
        file = (path.parent / raw[key]).resolve()
        if not file.is_file():
            raise InputError(f"no such file: {file}", path=path, key=key)
        files[key] = str(file)
    from distributed.security import Security

    ca, cert, key = files["ca_file"], files["cert_file"], files["key_file"]
    return Security(
        tls_ca_file=ca,
        tls_client_cert=cert,
        tls_client_key=key,
        tls_scheduler_cert=cert,
        tls_scheduler_key=key,
        tls_worker_cert=cert,
        tls_worker_key=key,
        require_encryption=True,
    )


class DaskExecutor:
    """Tasks on a Dask ``distributed`` cluster: the one at ``scheduler``, or a local one on 127.0.0.1."""

    name = "dask"

    def __init__(self, scheduler: str | None = None, security=None, jobs: int = 1):
        try:
            import dask
            from distributed import Client, LocalCluster
        except ImportError:
            raise ParamError(
                "--executor dask needs dask and distributed: pip install 'qpbench[dask]'",
                key="--executor",
            ) from None
        self.cluster = None
        if scheduler is None:
            with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
                self.cluster = LocalCluster(
                    n_workers=jobs,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    dashboard_address=None,
                    security=security,
                    protocol="tls://" if security is not None else None,
                )
            self.client = Client(self.cluster, security=security)
        else:
            try:
                self.client = Client(scheduler, security=security, timeout="30s")
            except (OSError, TimeoutError, ValueError, TypeError) as exc:
                raise InputError(
                    f"cannot reach the Dask scheduler: {type(exc).__name__}: {exc}",
                    key="--scheduler",
                ) from None
        self.address = self.client.scheduler.address

    @property
    def concurrency(self) -> int:
        return (
            sum(w.get("nthreads", 1) for w in self.client.scheduler_info()["workers"].values()) or 1
        )

    def _per_host(self) -> tuple[dict, dict]:
        workers = self.client.scheduler_info()["workers"]
        threads: dict[str, int] = {}
        for w in workers.values():
            threads[w["host"]] = threads.get(w["host"], 0) + w.get("nthreads", 1)
        return {a: w["host"] for a, w in workers.items()}, threads

    def run(self, fn: Callable, items: list[tuple]) -> Iterator[Done]:
        from distributed import as_completed

        hosts, threads = self._per_host()
        pending = {}
        for i, (key, arg) in enumerate(items):
            pending[self.client.submit(_call, fn, arg, pure=False, key=f"qpbench-task-{i}-1")] = (
                i,
                key,
                arg,
                1,
            )
        queue = as_completed(list(pending))
        for fut in queue:
            i, key, arg, attempts = pending.pop(fut)
            if fut.status == "finished":
                value, host, worker = fut.result()
                if worker not in hosts:
                    hosts, threads = self._per_host()
                yield Done(
                    key, value, None, attempts, host, worker, threads.get(hosts.get(worker), 1)
                )
                continue
            why = f"{type(fut.exception()).__name__}: {fut.exception()}"
            if attempts < MAX_ATTEMPTS:
                log.warning("%s: %s; running it again", key, why)
                new = self.client.submit(
                    _call, fn, arg, pure=False, key=f"qpbench-task-{i}-{attempts + 1}"
                )
                pending[new] = (i, key, arg, attempts + 1)
                queue.add(new)
                continue
            yield Done(
                key, None, f"{why} (attempt {attempts} of {MAX_ATTEMPTS})", attempts, "", "", 0
            )

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def make_executor(
    name: str, jobs: int, scheduler: str | None = None, security_file: str | None = None
) -> SerialExecutor | ProcessExecutor | DaskExecutor:
    """The executor of ``--executor NAME --jobs N [--scheduler ADDRESS --security FILE]``.

    ``local`` is :class:`ProcessExecutor`: with one job the runs are made
    one after the other, as serially as in this process (the worker times
    them itself) but a crash in a solver loses only the run it hit;
    ``dask`` is :class:`DaskExecutor`.

    Raises:
        ParamError: an unknown executor, a scheduler or security file without
            ``dask``, a ``tls://`` address without a security file.
    """
    if name not in EXECUTORS:
        raise ParamError(
            f"unknown executor '{name}' (choose from {', '.join(EXECUTORS)})", key="--executor"
        )
    if jobs < 1:
        raise ParamError(f"must be >= 1, got {jobs}", key="--jobs")
    if name == "local":
        if scheduler is not None or security_file is not None:
            raise ParamError("--scheduler and --security need --executor dask", key="--scheduler")
        return ProcessExecutor(jobs)
    if scheduler is not None and scheduler.startswith("tls://") and security_file is None:
        raise ParamError(
            "a tls:// scheduler needs --security FILE (CA, certificate, key)", key="--security"
        )
    if security_file is not None and scheduler is not None and not scheduler.startswith("tls://"):
        raise ParamError("--security needs a tls:// scheduler address", key="--scheduler")
    if scheduler is not None and not scheduler.startswith("tls://"):
        log.warning(
            "Dask scheduler %s without TLS: whoever can reach it can run code on every worker "
            "(use tls:// and --security)",
            scheduler,
        )
    security = load_security(security_file) if security_file is not None else None
    return DaskExecutor(scheduler, security, jobs)
