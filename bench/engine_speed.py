"""The compiled engine against the Python engine, in one run: per-tick times, the solver's share
of the tick, the real-time factor, and a sweep of perturbed instances.

For every scenario and backend with a compiled solve, ``--repeat`` runs of ``--duration`` s on
each engine, the engines alternating (python, compiled, python, ...) so that neither always runs
first or on a warmer machine; the kernels are loaded before anything is timed. Per engine it
prints the median over the runs of:

- ``tick us``: the median whole tick (build, solve, fallback, step, log row) [us];
- ``solve us``: the median solve [us] (the call with the tick's QP until its answer is in the
  caller's memory);
- ``solver share``: the summed solve and fallback-solve times over the summed tick times;
- ``RTF``: simulated time over the run's wall time.

and the ratio python / compiled of the tick and the run's wall time. Then (``--sweep N``) the
same sweep of N perturbed instances of ``wall`` (``problems/sweeps/wall.toml``) with each
backend of ``--sweep-backends`` on each engine, one worker, timed as a whole (instances made
and judged, as ``qpbench sweep`` runs them), alternating engines.

The load average is printed with the figures: the machine may be shared.

``--compile`` measures instead what a fresh clone pays to compile the engines (numba's cache
empty): a few ticks of ``wall`` on the Python engine with every backend (their own kernels, the
build and the step), then, per backend in turn, its first run on the compiled engine [s]; a
backend whose engine another one already compiled pays only its own state.

    python bench/engine_speed.py [--scenarios wall,narrow] [--backends daqp,qpoases,...]
        [--duration 20] [--repeat 5] [--sweep 200] [--sweep-backends daqp]
    NUMBA_CACHE_DIR=$(mktemp -d) python bench/engine_speed.py --compile [--backends ...]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from qpbench.engine.compiled import SOLVERS
from qpbench.jit import warmup
from qpbench.sim.loop import simulate

ENGINES = ("python", "compiled")


def one_run(scenario: str, backend: str, duration: float, engine: str) -> dict:
    """The figures of one run on ``engine``."""
    start = time.perf_counter()
    result = simulate(scenario, backend, duration=duration, engine=engine)
    wall = time.perf_counter() - start
    s, log = result.summary, result.log
    if s["engine"] != engine:
        raise SystemExit(f"{backend} ran on the {s['engine']} engine: {s['engine_note']}")
    solver = log["solve_time_s"].sum() + log["fallback_solve_time_s"].fillna(0.0).sum()
    return {
        "tick": float(log["tick_time_s"].median()),
        "solve": float(log["solve_time_s"].median()),
        "share": float(solver / log["tick_time_s"].sum()),
        "rtf": float(s["real_time_factor"]),
        "run": float(s["wall_time_s"]),
        "wall": wall,
        "verdict": s["verdict"],
    }


def sweep_time(backend: str, samples: int, engine: str) -> float:
    """Wall time [s] of ``qpbench sweep problems/sweeps/wall.toml`` with one worker."""
    from qpbench.runner import SerialExecutor
    from qpbench.sweep.runner import run_sweep
    from qpbench.sweep.spec import load_sweep

    spec = load_sweep(Path("problems/sweeps/wall.toml"), samples=samples)
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        run_sweep(spec, [backend], out, SerialExecutor(), engine=engine)
        return time.perf_counter() - start


def compile_times(backends: list[str]) -> None:
    """Print each backend's first compiled run [s of CPU, and wall], after the Python engine's
    kernels (CPU time: the machine may be shared)."""
    cache = os.environ.get("NUMBA_CACHE_DIR")
    if not cache or any(Path(cache).iterdir()):
        raise SystemExit("--compile: set NUMBA_CACHE_DIR to an empty folder (mktemp -d)")
    print(f"load average before: {os.getloadavg()}")
    cpu, wall = time.process_time(), time.perf_counter()
    for backend in backends:
        simulate("wall", backend, duration=0.003, engine="python", warmup_ticks=0)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    print(f"{'python engine':15} {cpu:6.1f} s CPU {wall:6.1f} s wall (every backend)")
    total = 0.0
    for backend in backends:
        cpu, wall = time.process_time(), time.perf_counter()
        result = simulate("wall", backend, duration=0.003, engine="compiled", warmup_ticks=0)
        if result.summary["engine"] != "compiled":
            raise SystemExit(f"{backend} ran on the python engine: {result.summary['engine_note']}")
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        total += cpu
        print(f"{backend:15} {cpu:6.1f} s CPU {wall:6.1f} s wall (compiled engine)")
    print(f"{'compiled, all':15} {total:6.1f} s CPU")
    print(f"load average after: {os.getloadavg()}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default="wall,narrow")
    parser.add_argument("--backends", default=",".join(b for b in SOLVERS if b != "noop"))
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--sweep", type=int, default=200, metavar="N")
    parser.add_argument("--sweep-backends", default="daqp")
    parser.add_argument("--compile", action="store_true", help="cold compile times instead")
    args = parser.parse_args()
    backends = args.backends.split(",")
    if args.compile:
        return compile_times(["noop", *backends])
    warmup([*backends, "noop"])
    print(f"load average before: {os.getloadavg()}")
    header = (
        f"{'scenario':9} {'backend':10} {'engine':8} {'tick us':>8} {'solve us':>9} "
        f"{'share':>6} {'RTF':>8}  verdict"
    )
    for scenario in args.scenarios.split(","):
        print(f"\n{header}")
        for backend in [*backends, "noop"]:
            runs = {e: [] for e in ENGINES}
            for _ in range(args.repeat):
                for engine in ENGINES:
                    runs[engine].append(one_run(scenario, backend, args.duration, engine))
            med = {
                e: {
                    k: statistics.median(r[k] for r in runs[e])
                    for k in runs[e][0]
                    if k != "verdict"
                }
                for e in ENGINES
            }  # noqa: E501
            for engine in ENGINES:
                m = med[engine]
                print(
                    f"{scenario:9} {backend:10} {engine:8} {m['tick'] * 1e6:8.2f} "
                    f"{m['solve'] * 1e6:9.2f} {m['share'] * 100:5.0f}% {m['rtf']:8.0f}  "
                    f"{runs[engine][0]['verdict']}"
                )
            ratio_tick = med["python"]["tick"] / med["compiled"]["tick"]
            ratio_run = med["python"]["run"] / med["compiled"]["run"]
            print(
                f"{'':9} {backend:10} python/compiled: tick {ratio_tick:.1f}x, run {ratio_run:.1f}x"
            )
    for backend in args.sweep_backends.split(",") if args.sweep else ():
        times = {e: [] for e in ENGINES}
        for _ in range(max(1, args.repeat // 2)):
            for engine in ENGINES:
                times[engine].append(sweep_time(backend, args.sweep, engine))
        p, c = (statistics.median(times[e]) for e in ENGINES)
        print(
            f"\nsweep of {args.sweep} wall instances with {backend}: python {p:.1f} s, "
            f"compiled {c:.1f} s, python/compiled {p / c:.1f}x (median of {len(times['python'])})"
        )
    print(f"\nload average after: {os.getloadavg()}")
    np.set_printoptions()


if __name__ == "__main__":
    main()
