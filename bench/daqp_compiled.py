"""Per-call time of DAQP's C API called from compiled code (qpbench/backends/daqp_c.py) against
the Python backends it mirrors, ``daqp`` (a persistent ``daqp.Model``) and ``daqp-stateless``
(``daqp.solve``), on the calls a closed loop makes.

The calls: those a ``--scenario`` closed loop of ``daqp`` (``--duration`` s at 1 kHz) makes, as
it made them (each tick's paper QP, the soft fallback after a paper QP not solved, the resets),
recorded by a ``daqp`` backend that copies every problem it is given. Per route:

- ``python``: ``Backend.solve`` timed with ``time.perf_counter`` around it (as the Python loop
  times a tick's solve);
- ``compiled, from Python``: the compiled solve called from Python on the packed buffer;
- ``compiled, in a compiled loop``: a compiled loop over the same calls timing each with
  ``CLOCK_MONOTONIC`` (``native.clock``), as the compiled engine calls it.

Each runs over the whole sequence ``--repeat`` times, fresh state each pass; per call the
fastest pass is kept; the table gives the median and p99 over calls [us]. Every pass must give
the Python backend's statuses and x bit for bit (else the script stops with exit 1).

Usage::

    python bench/daqp_compiled.py [--scenario wall] [--duration 2] [--repeat 5]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from qpbench.backends import daqp_c, get_backend
from qpbench.backends.daqp_ import DaqpModelBackend
from qpbench.native import clock
from qpbench.packed import PackedProblem, pack
from qpbench.sim.loop import simulate
from qpbench.statuses import TICK_STATUSES

#: An entry of the recorded sequence that is a reset, not a solve.
RESET = None


class _Recorder(DaqpModelBackend):
    """Backend ``daqp`` keeping a copy of each problem it solves and a :data:`RESET` per reset."""

    calls: list | None = None

    def solve(self, problem, warm_start=None):
        if type(problem) is not PackedProblem:
            problem = pack(problem)
        self.calls.append(PackedProblem(problem.buffer.copy()))
        return super().solve(problem, warm_start)

    def reset(self) -> None:
        super().reset()
        if self.calls:  # not the resets before the first call
            self.calls.append(RESET)


def loop_calls(scenario: str, duration: float) -> list:
    """The calls (packed problems, or :data:`RESET`) of a closed loop of ``daqp``."""
    recorder = _Recorder()
    recorder.calls = []
    simulate(scenario, recorder, "paper", duration=duration)
    return recorder.calls


def _compiled_loop(solve, reset):
    import numba

    monotonic = clock()

    @numba.njit
    def run(st, bufs, is_reset, warm, sols, infos, statuses, times):
        ts = np.zeros(2, dtype=np.int64)
        for i in range(bufs.shape[0]):
            if is_reset[i]:
                reset(st)
                continue
            t0 = monotonic(ts)
            statuses[i] = solve(st, bufs[i], warm, sols[i], infos[i])
            times[i] = monotonic(ts) - t0

    return run


def _python_pass(backend: str, calls: list):
    be = get_backend(backend)
    times, statuses, xs = np.full(len(calls), np.nan), [], []
    perf = time.perf_counter
    for i, p in enumerate(calls):
        if p is RESET:
            be.reset()
            statuses.append(None)
            xs.append(None)
            continue
        t0 = perf()
        sol = be.solve(p)
        times[i] = perf() - t0
        statuses.append(sol.status)
        xs.append(sol.x)
    return times, statuses, xs


def _compiled_pass(backend: str, calls: list, in_loop: bool):
    solve, reset = daqp_c.compiled(backend)
    shapes = np.array([p.shape for p in calls if p is not RESET])
    n, me, mi = shapes.max(axis=0)
    st = daqp_c.make_state(n, me, mi, get_backend(backend).options())
    width = max(p.buffer.size for p in calls if p is not RESET)
    bufs = np.zeros((len(calls), width))
    for i, p in enumerate(calls):
        if p is not RESET:
            bufs[i, : p.buffer.size] = p.buffer
    is_reset = np.array([p is RESET for p in calls])
    sols, infos = np.zeros((len(calls), n + me + mi)), np.zeros((len(calls), 4))
    statuses, times = np.full(len(calls), -1, dtype=np.int64), np.full(len(calls), np.nan)
    warm = np.zeros(n)
    try:
        if in_loop:
            _compiled_loop(solve, reset)(st, bufs, is_reset, warm, sols, infos, statuses, times)
        else:
            perf = time.perf_counter
            for i in range(len(calls)):
                if is_reset[i]:
                    reset(st)
                    continue
                row, s, info = bufs[i], sols[i], infos[i]
                t0 = perf()
                statuses[i] = solve(st, row, warm, s, info)
                times[i] = perf() - t0
    finally:
        daqp_c.close_state(st)
    names = [None if r else TICK_STATUSES[s] for r, s in zip(is_reset, statuses)]
    return (
        times,
        names,
        [sols[i, : p.shape[0]] if p is not RESET else None for i, p in enumerate(calls)],
    )


def _same(ref, got) -> bool:
    _, s_ref, x_ref = ref
    _, s_got, x_got = got
    if s_ref != s_got:
        return False
    return all(
        a is None or s != "optimal" or np.array_equal(a, b) for a, b, s in zip(x_ref, x_got, s_ref)
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="wall")
    parser.add_argument("--duration", type=float, default=2.0)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    daqp_c.kernels()
    calls = loop_calls(args.scenario, args.duration)
    n_solves = sum(p is not RESET for p in calls)
    print(
        f"{args.scenario}, {args.duration:g} s: {n_solves} solves, "
        f"{sum(p is RESET for p in calls)} resets; fastest of {args.repeat} passes per call"
    )
    routes = {
        "python": lambda b: _python_pass(b, calls),
        "compiled, from Python": lambda b: _compiled_pass(b, calls, False),
        "compiled, in a compiled loop": lambda b: _compiled_pass(b, calls, True),
    }
    print(f"{'backend':16} {'route':30} {'median [us]':>12} {'p99 [us]':>10} {'mean [us]':>10}")
    ok = True
    for backend in ("daqp", "daqp-stateless"):
        ref = _python_pass(backend, calls)
        for route, run in routes.items():
            run(backend)  # warm (compiles or loads the driver)
            passes = [run(backend) for _ in range(args.repeat)]
            ok &= all(_same(ref, p) for p in passes)
            best = np.nanmin(np.array([p[0] for p in passes]), axis=0)
            best = best[~np.isnan(best)] * 1e6
            print(
                f"{backend:16} {route:30} {np.median(best):12.2f} "
                f"{np.percentile(best, 99):10.2f} {best.mean():10.2f}"
            )
    print("same statuses and x bit for bit on every pass:", ok)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
