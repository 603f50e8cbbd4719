"""Tasks on a Dask ``distributed`` cluster: an existing one, or a local one on 127.0.0.1. A task
runs in a thread beside the worker's event loop, sharing its GIL, so the workers are quieted
(:data:`WORKER_CONFIG`, or :mod:`.dask_worker` on an existing cluster)."""

from __future__ import annotations

import logging
import tomllib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from ..exceptions import InputError, ParamError
from ..statuses import describe_exception
from .process import Done, retry_note, run_located

if TYPE_CHECKING:
    from distributed.security import Security

log = logging.getLogger("qpbench.runner")

#: Dask settings of a sweep's workers: no statistical profiler, a slower event-loop health check.
WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
}
#: The plugin's equivalent of :data:`WORKER_CONFIG` on a running worker.
QUIET_STOP = ("profile", "profile-cycle")
QUIET_SLOW = {"tick": 1.0}


def load_security(path: str | Path) -> Security:
    """A ``distributed.security.Security`` (encryption required) from a TOML or YAML file
    naming PEM files relative to its folder: ``ca_file`` (the certificate authority),
    ``cert_file`` (this machine's certificate), ``key_file``."""
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
    files = []
    for key in ("ca_file", "cert_file", "key_file"):
        if not isinstance(raw.get(key), str):
            raise InputError("missing key (the path of a PEM file)", path=path, key=key)
        file = (path.parent / raw[key]).resolve()
        if not file.is_file():
            raise InputError(f"no such file: {file}", path=path, key=key)
        files.append(str(file))
    from distributed.security import Security

    ca, cert, key = files  # this machine's certificate for every role
    pems = {f"tls_{role}_cert": cert for role in ("client", "scheduler", "worker")}
    pems |= {f"tls_{role}_key": key for role in ("client", "scheduler", "worker")}
    return Security(tls_ca_file=ca, require_encryption=True, **pems)


class DaskExecutor:
    """Tasks on the cluster at ``scheduler``, or (``None``) on a ``LocalCluster`` of ``jobs``
    single-threaded worker processes; ``security``: :func:`load_security`'s, for TLS. A task
    whose worker was lost is submitted once more, then reported lost."""

    name = "dask"

    def __init__(self, scheduler: str | None = None, security=None, jobs: int = 1):
        try:
            import dask
            from distributed import Client, LocalCluster
        except ImportError:
            why = "--executor dask needs dask and distributed: pip install 'qpbench[dask]'"
            raise ParamError(why, key="--executor") from None
        self.cluster = None
        self._plugin = False
        if scheduler is None:
            # one task on a worker at a time (saturation 1.0): a worker that dies takes only the
            # task it was running with it, never one merely queued there
            local = {
                "distributed.scheduler.allowed-failures": 0,
                "distributed.scheduler.worker-saturation": 1.0,
            }
            with dask.config.set({**WORKER_CONFIG, **local}):
                self.cluster = LocalCluster(
                    n_workers=jobs,
                    threads_per_worker=1,
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
                why = f"cannot reach the Dask scheduler: {describe_exception(exc)}"
                raise InputError(why, key="--scheduler") from None
            from .dask_worker import PLUGIN_NAME, QuietWorker

            try:
                self.client.register_plugin(QuietWorker(QUIET_STOP, QUIET_SLOW), name=PLUGIN_NAME)
                self._plugin = True
            except Exception as exc:  # noqa: BLE001 - a cluster refusing plugins still runs tasks
                msg = "could not quiet the Dask workers' profiler (%s): tasks run slower"
                log.warning(msg, describe_exception(exc))
        self.address = self.client.scheduler.address

    @property
    def concurrency(self) -> int:
        return sum(self._per_host()[1].values()) or 1

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

        def submit(i: int, key, arg, attempt: int):
            name = f"qpbench-task-{i}-{attempt}"
            fut = self.client.submit(run_located, fn, arg, pure=False, key=name)
            pending[fut] = (i, key, arg, attempt)
            return fut

        queue = as_completed([submit(i, key, arg, 1) for i, (key, arg) in enumerate(items)])
        for fut in queue:
            i, key, arg, attempts = pending.pop(fut)
            if fut.status == "finished":
                value, host, worker = fut.result()
                if worker not in hosts:
                    hosts, threads = self._per_host()
                concurrent = threads.get(hosts.get(worker), 1)
                yield Done(key, value, None, attempts, host, worker, concurrent)
            elif lost := retry_note(key, describe_exception(fut.exception()), attempts):
                yield Done(key, None, lost, attempts, "", "", 0)
            else:
                queue.add(submit(i, key, arg, attempts + 1))

    def close(self) -> None:
        if self._plugin:
            from .dask_worker import PLUGIN_NAME

            try:
                self.client.unregister_worker_plugin(PLUGIN_NAME)
            except Exception as exc:  # noqa: BLE001 - closing goes on: the plugin stays registered
                log.warning("could not remove the Dask worker plugin: %s", describe_exception(exc))
            self._plugin = False
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()
