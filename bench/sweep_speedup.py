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
   closed-loop instances of 20 s of ``wall`` with DAQP run in this process
   and then one by one on that worker: (Dask - in process) / instances,
   against the instance's own time. Target: under 5 % of a 20 s instance.

The machine's load average is printed with the figures (it may be shared).

    python bench/sweep_speedup.py [--sweep problems/sweeps/wall.toml] [--samples 24] [--duration 6]
        [--backends daqp,osqp,qpoases] [--tasks 200] [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

from qpbench.executors import DaskExecutor, ProcessExecutor, SerialExecutor
from qpbench.jit import warmup
from qpbench.sweep.rows import same_outside_timing
from qpbench.sweep.runner import read_sweep_rows, run_sweep
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
        differ = sum(bool(same_outside_timing(a, b)) for a, b in zip(serial_rows, rows))
        print(
            f"  {label:30s} {wall:8.2f} s   speed-up over --jobs 1 {serial_s / wall:5.2f}   rows differing "
            f"outside timing: {differ} of {len(rows)}"
        )


def _wall_task(duration: float):
    """The sweep's task of scenario wall (``duration`` s) with DAQP."""
    from qpbench.sim.scenario import scenario_path
    from qpbench.sweep.task import SweepTask

    text = scenario_path("wall").read_text().replace("duration = 20.0", f"duration = {duration!r}")
    meta = {
        "instance": "wall",
        "backend": "daqp",
        "instance_file": "wall.toml",
        "sample": 0,
        "sweep": "bench",
        "base_scenario": "wall",
        "parameters": {},
        "duration": duration,
        "force_band": 0.2,
        "tracking_band": 1e-4,
    }
    return SweepTask(meta, text)


def dask_overhead(args) -> None:
    from distributed import as_completed

    from qpbench.sweep.task import run_task

    task, short = _wall_task(20.0), _wall_task(0.01)
    run_task(short)
    local, loop_local, loop_remote = [], [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        loop_local.append(run_task(task)["wall_time_s"])
        local.append(time.perf_counter() - t0)
    ex = DaskExecutor(jobs=1)
    try:
        client = ex.client
        client.submit(run_task, short, pure=False).result()
        t0 = time.perf_counter()
        for _ in as_completed([client.submit(_nothing, i, pure=False) for i in range(args.tasks)]):
            pass
        per_task = (time.perf_counter() - t0) / args.tasks
        remote = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            loop_remote.append(client.submit(run_task, task, pure=False).result()["wall_time_s"])
            remote.append(time.perf_counter() - t0)
    finally:
        ex.close()
    inst, dask_inst = statistics.median(local), statistics.median(remote)
    print(
        f"Dask LocalCluster (1 worker), {args.tasks} empty tasks: {per_task * 1e3:.2f} ms per task "
        f"({100 * per_task / inst:.2f} % of a 20 s wall instance with daqp, {inst:.3f} s in this process)"
    )
    print(
        f"one 20 s wall instance with daqp (the sweep's task), median of {args.repeat}: {inst:.3f} s in this "
        f"process, {dask_inst:.3f} s through Dask: overhead {1e3 * (dask_inst - inst):.1f} ms "
        f"({100 * (dask_inst - inst) / inst:.1f} %; target < 5 %)"
    )
    lo, lr = statistics.median(loop_local), statistics.median(loop_remote)
    print(
        f"  of which the closed loop itself (its wall_time_s): {lo:.3f} s here, {lr:.3f} s on the worker "
        f"({1e3 * (lr - lo):+.1f} ms: the worker runs tasks in a thread beside its own event loop)"
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sweep", default=str(ROOT / "problems" / "sweeps" / "wall.toml"))
    p.add_argument("--samples", type=int, default=24)
    p.add_argument("--duration", type=float, default=6.0)
    p.add_argument("--backends", default="daqp,osqp,qpoases")
    p.add_argument("--tasks", type=int, default=200)
    p.add_argument("--repeat", type=int, default=5)
    args = p.parse_args()
    warmup()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    speedup(args)
    dask_overhead(args)
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
