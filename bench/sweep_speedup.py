"""Speed-up of a sweep on 2 local worker processes over a serial one, and what a Dask task costs.

1. **Speed-up**: the same sweep (``--sweep``, ``--samples`` instances of
   ``--duration`` s with ``--backends``) run in this process, on 1 local
   worker process (``--jobs 1``), on 2 (``--jobs 2``) and on an in-process
   Dask ``LocalCluster`` of 2 workers; wall time of each and the ratio to
   ``--jobs 1`` (close to 2 on 2 idle cores; worker start-up included). The rows of the three runs are compared
   outside the timing columns (they must be identical).
2. **Dask's cost per task**: on a 1-worker ``LocalCluster``, the round trip
   of ``--tasks`` tasks that do nothing (submit, schedule, run, send back,
   collect with ``as_completed``), per task; and, end to end, ``--repeat``
   closed-loop instances of 20 s of ``wall`` with DAQP (the sweep's task),
   one at a time, in a process of its own (spawned, the run in its main
   thread with nothing beside it: the in-process reference) and on three
   1-worker clusters, open together and used in turn run by run: Dask's
   defaults, qpbench's own (:data:`qpbench.runner.dask_.WORKER_CONFIG`),
   and Dask's defaults reached as an existing cluster, where the executor
   registers its worker plugin; medians. The overhead (total through Dask
   minus the total in a process of its own) is split into the time before
   the task starts, its run on the worker, the time after it ends, and on
   the worker the CPU time of the other threads (the event loop) and the
   task thread's waits. Target: under 5 % of a 20 s instance.

The machine's load average is printed with the figures (it may be shared).

    python bench/sweep_speedup.py [--sweep problems/sweeps/wall.toml] [--samples 24] [--duration 6]
        [--backends daqp,osqp,qpoases] [--tasks 200] [--repeat 15]
        [--skip-speedup]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from contextlib import ExitStack, contextmanager
from pathlib import Path

from qpbench.jit import warmup
from qpbench.runner import DaskExecutor, ProcessExecutor, SerialExecutor
from qpbench.sweep.runner import COLUMNS, TIMING_COLUMNS, read_sweep_rows, run_sweep
from qpbench.sweep.spec import load_sweep

ROOT = Path(__file__).resolve().parents[1]


def _nothing(x):
    return x


def timed_sweep(spec, backends, executor, folder: Path) -> tuple[float, list[dict]]:
    start = time.perf_counter()
    try:
        run_sweep(spec, backends, folder, executor, force=True)
    finally:
        executor.close()
    return time.perf_counter() - start, read_sweep_rows(folder / "sweep.csv")


def speedup(args) -> None:
    spec = load_sweep(args.sweep, samples=args.samples, duration=args.duration)
    backends = args.backends.split(",")
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, make in (
            ("in this process", SerialExecutor),
            ("1 worker (--jobs 1)", lambda: ProcessExecutor(1)),
            ("2 workers (--jobs 2)", lambda: ProcessExecutor(2)),
            ("Dask LocalCluster, 2 workers", lambda: DaskExecutor(jobs=2)),
        ):
            runs[label] = timed_sweep(spec, backends, make(), Path(tmp) / str(len(runs)))
    serial_s, serial_rows = runs["1 worker (--jobs 1)"]
    print(
        f"sweep {spec.name}: {spec.samples} instances x {len(backends)} backends ({args.backends}), "
        f"{spec.duration} s each"
    )
    for label, (wall, rows) in runs.items():
        compared = [c for c in COLUMNS if c not in TIMING_COLUMNS]
        differ = sum(any(a[c] != b[c] for c in compared) for a, b in zip(serial_rows, rows))
        print(
            f"  {label:30s} {wall:8.2f} s   speed-up over --jobs 1 {serial_s / wall:5.2f}   rows differing "
            f"outside timing: {differ} of {len(rows)}"
        )


def _wall_task(duration: float):
    """The sweep's task of scenario wall (``duration`` s) with DAQP."""
    from qpbench.harness.closed_loop import LoopTask
    from qpbench.sim.scenario import scenario_path

    text = scenario_path("wall").read_text().replace("duration = 20.0", f"duration = {duration!r}")
    return LoopTask("wall.toml", "daqp", scenario_text=text, bands=(0.2, 1e-4))


def _blocked() -> int:
    """Times this thread has waited so far (voluntary context switches: for the GIL, on a busy
    computation); 0 where Linux's ``/proc/thread-self`` is missing."""
    try:
        with open("/proc/thread-self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("voluntary_ctxt"))
    except OSError:
        return 0


def _on_worker(task) -> dict:
    """``run_row(task)`` where it runs: wall-clock start and end [s since the epoch], CPU time of
    this thread and of the whole process [s], the thread's waits, and the closed loop's own time."""
    from qpbench.harness.closed_loop import run_row

    waits, cpu, process = _blocked(), time.thread_time(), time.process_time()
    start = time.time()
    row = run_row(task)
    end = time.time()
    return {
        "start": start,
        "end": end,
        "cpu": time.thread_time() - cpu,
        "others": time.process_time() - process - (time.thread_time() - cpu),
        "waits": _blocked() - waits,
        "loop": row["wall_time_s"],
    }


@contextmanager
def _plain_cluster():
    """A 1-worker ``LocalCluster`` with Dask's default settings, and a client of it."""
    from distributed import Client, LocalCluster

    with (
        LocalCluster(
            n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client


@contextmanager
def _executor(scheduler=None):
    ex = DaskExecutor(scheduler, jobs=1)
    try:
        yield ex.client
    finally:
        ex.close()


@contextmanager
def _plugged_cluster():
    """Dask's defaults, reached as an existing cluster: the executor registers its worker plugin."""
    with _plain_cluster() as plain, _executor(plain.scheduler.address) as client:
        yield client


#: The Dask set-ups compared: (label, context manager giving a client of a 1-worker cluster).
SETUPS = (
    ("Dask's defaults", _plain_cluster),
    ("qpbench's LocalCluster", _executor),
    ("defaults + QuietWorker plugin", _plugged_cluster),
)


#: What :func:`_timed` gives per run: total [s], submit to start [s], run_row on the worker [s],
#: end to result [s], closed loop [s], CPU of the task's thread and of the others [s], waits.
FIELDS = ("total", "before", "run", "after", "loop", "cpu", "others", "waits")


def _timed(client, task) -> tuple:
    """:data:`FIELDS` of one task: on the cluster of ``client``, or on an :class:`_Alone` process."""
    t0 = time.time()
    if isinstance(client, _Alone):
        r = client.run(task)
        t0, t1 = r["start"], r["end"]
    else:
        r = client.submit(_on_worker, task, pure=False).result()
        t1 = time.time()
    return (
        t1 - t0,
        r["start"] - t0,
        r["end"] - r["start"],
        t1 - r["end"],
        r["loop"],
        r["cpu"],
        r["others"],
        r["waits"],
    )


class _Alone:
    """A spawned process that runs each task in its main thread, with nothing else running in it
    (the reference: a closed loop in a process of its own, as in this process without Dask)."""

    def __init__(self):
        from qpbench.runner.process import Worker, context

        self.worker = Worker(context(fresh=True), "sweep-speedup-alone")

    def run(self, task) -> dict:
        return self.worker.call(_on_worker, task, None, "task")

    def submit(self, fn, task, pure=False):  # the warm-up's call, as on a Dask client
        self.run(task)
        return self

    def result(self):
        return None

    def close(self) -> None:
        self.worker.stop()


@contextmanager
def _alone():
    alone = _Alone()
    try:
        yield alone
    finally:
        alone.close()


def _empty_tasks(client, n: int) -> float:
    from distributed import as_completed

    t0 = time.perf_counter()
    for _ in as_completed([client.submit(_nothing, i, pure=False) for i in range(n)]):
        pass
    return (time.perf_counter() - t0) / n


def dask_overhead(args) -> None:
    import logging

    logging.getLogger("qpbench.runner").setLevel(logging.ERROR)  # the plain tcp:// warning
    task, short = _wall_task(20.0), _wall_task(0.01)
    _on_worker(short)
    setups = (("a process of its own", _alone),) + SETUPS
    runs = {label: [] for label, _ in setups}
    first = {}
    with ExitStack() as stack:
        clients = {label: stack.enter_context(setup()) for label, setup in setups}
        for label, client in clients.items():  # warm: kernels loaded, first full run apart
            client.submit(_on_worker, short, pure=False).result()
            first[label] = _timed(client, task)[0]
        per_task = _empty_tasks(clients["qpbench's LocalCluster"], args.tasks)
        for _ in range(args.repeat):  # one run of each in turn: a change of load hits them all
            for label, client in clients.items():
                runs[label].append(_timed(client, task))
    _print_overhead(args, runs, first, per_task)


def _print_overhead(args, runs: dict, first: dict, per_task: float) -> None:
    med = {k: dict(zip(FIELDS, map(statistics.median, zip(*v)))) for k, v in runs.items()}
    here = med["a process of its own"]["total"]
    print(
        f"Dask's cost per task on a 1-worker LocalCluster: {per_task * 1e3:.2f} ms for an empty task "
        f"({args.tasks} through as_completed, qpbench's cluster)"
    )
    print(
        f"one 20 s wall instance with daqp (the sweep's task), median of {args.repeat}, "
        "one run of each set-up in turn:"
    )
    print(
        f"  {'':30s} {'total':>7s} {'overhead':>18s} {'run_row':>8s} {'loop':>7s} {'before':>7s} "
        f"{'after':>7s} {'cpu':>7s} {'others':>7s} {'waits':>5s} {'1st run':>7s}"
    )
    for label, m in med.items():
        remote = label != "a process of its own"
        over = f"{1e3 * (m['total'] - here):+7.1f} ms {100 * (m['total'] - here) / here:+6.1f} %"
        print(
            f"  {label:30s} {m['total']:5.3f} s {over if remote else '':>18s} {m['run']:6.3f} s "
            f"{m['loop']:5.3f} s {1e3 * m['before']:4.1f} ms {1e3 * m['after']:4.1f} ms {m['cpu']:5.3f} s "
            f"{1e3 * m['others']:4.0f} ms {m['waits']:5.0f} {first[label]:5.3f} s"
        )
    print(
        "  overhead: total minus the total in a process of its own (target < 5 %); run_row: its time where it ran; "
        "loop: the closed loop's wall_time_s;\n  before/after: submit to start, end to result; cpu: the task "
        "thread's CPU time; others: CPU time of the process's other threads meanwhile (the worker's "
        "event loop);\n  waits: the task thread's voluntary context switches (waits for the GIL); 1st run: the "
        "first 20 s instance on a fresh worker (not counted)"
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sweep", default=str(ROOT / "problems" / "sweeps" / "wall.toml"))
    p.add_argument("--samples", type=int, default=24)
    p.add_argument("--duration", type=float, default=6.0)
    p.add_argument("--backends", default="daqp,osqp,qpoases")
    p.add_argument("--tasks", type=int, default=200)
    p.add_argument("--repeat", type=int, default=15, help="20 s instances per set-up")
    p.add_argument("--skip-speedup", action="store_true", help="only the cost of a Dask task")
    args = p.parse_args()
    warmup()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    if not args.skip_speedup:
        speedup(args)
    dask_overhead(args)
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
