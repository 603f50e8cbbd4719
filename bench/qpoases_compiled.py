"""Per-call time of the ``qpoases`` backend's compiled solve against ``Backend.solve``.

The calls of a ``wall`` closed loop driven by ``qpoases`` (its ``paper`` QP each tick, the
``soft`` fallback QP after each failed one: the infeasible start), solved in the loop's order
by three routes, fresh state each pass, passes interleaved:

- ``backend``: ``QpoasesBackend.solve`` (ctypes), timed around the call in Python;
- ``compiled, from Python``: the compiled ``solve`` called from Python per QP (numba's
  dispatch included), timed the same way;
- ``compiled, in a kernel``: one compiled loop over the QPs, each call timed with the compiled
  monotonic clock (what a compiled closed loop pays).

Per call, the fastest of ``--repeat`` passes; then the median and p90 over the calls, the median
of the shim's own time of the call (``solver_time_s``, ``info[0]``), and the median over the
``paper`` calls the backend solved (hotstart), those it did not (the infeasible start: ``init``
on a solver made afresh after each change of shape) and the ``soft`` calls. The routes' ``x``
are compared bit for bit.

Usage::

    python bench/qpoases_compiled.py [--duration 2.0] [--repeat 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from qpbench.backends.qpoases_ import QpoasesBackend, close_state, compiled, make_state
from qpbench.native import clock
from qpbench.sim import log as tick_log
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario
from qpbench.statuses import TICK_STATUSES


def loop_calls(duration: float) -> tuple[list, np.ndarray]:
    """The loop's QPs in call order (as problems, and their buffers stacked), from a ``wall``
    run: each tick's ``paper`` QP, then its ``soft`` QP where the tick fell back."""
    sc = load_scenario("wall")
    ctrl = sc.make_controller()
    result = simulate(sc, "qpoases", duration=duration, every=1)
    thetas = result.log[tick_log.theta_columns(ctrl.n)].to_numpy()
    fell_back = result.log["fallback"].to_numpy(dtype=bool)
    calls = []
    for theta, fb, rec in zip(thetas, fell_back, result.records):
        calls.append(rec.problem)
        if fb:
            calls.append(ctrl.build(np.ascontiguousarray(theta), rec.t, formulation="soft").problem)
    return calls, np.stack([p.buffer for p in calls])


def _kernel(solve, monotonic):
    import numba

    @numba.njit
    def run(st, bufs, warm, sol, info, times, own, xs, codes):
        ts = np.zeros(2, dtype=np.int64)
        n = warm.shape[0]
        for k in range(bufs.shape[0]):
            t0 = monotonic(ts)
            codes[k] = solve(st, bufs[k], warm, sol, info)
            times[k] = monotonic(ts) - t0
            own[k] = info[0]
            xs[k] = sol[:n]

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--duration", type=float, default=2.0, help="seconds of wall simulated")
    parser.add_argument("--repeat", type=int, default=5, help="passes per route")
    args = parser.parse_args()
    calls, bufs = loop_calls(args.duration)
    n, me, mi = calls[0].shape
    solve, _ = compiled()
    run = _kernel(solve, clock())
    count = len(calls)
    routes = ("backend", "compiled, from Python", "compiled, in a kernel")
    times = {r: np.full((args.repeat, count), np.inf) for r in routes}
    own = {r: np.full((args.repeat, count), np.inf) for r in routes}
    xs = {r: np.full((count, n), np.nan) for r in routes}
    statuses = {r: [None] * count for r in routes}
    sol, info, warm = np.zeros(n + me + mi), np.zeros(4), np.zeros(n)
    perf = time.perf_counter
    for rep in range(args.repeat):
        backend = QpoasesBackend()
        for k, p in enumerate(calls):
            t0 = perf()
            s = backend.solve(p)
            times["backend"][rep, k] = perf() - t0
            own["backend"][rep, k] = s.solver_time_s
            statuses["backend"][k] = s.status
            if s.x is not None:
                xs["backend"][k] = s.x
        st = make_state(n, me, mi)
        try:
            r = "compiled, from Python"
            for k, b in enumerate(bufs):
                t0 = perf()
                code = solve(st, b, warm, sol, info)
                times[r][rep, k] = perf() - t0
                own[r][rep, k] = info[0]
                statuses[r][k] = TICK_STATUSES[code]
                xs[r][k] = sol[:n]
        finally:
            close_state(st)
        st = make_state(n, me, mi)
        r = "compiled, in a kernel"
        codes = np.zeros(count, dtype=np.int64)
        try:
            run(st, bufs, warm, sol, info, times[r][rep], own[r][rep], xs[r], codes)
        finally:
            close_state(st)
        statuses[r] = [TICK_STATUSES[c] for c in codes]
    soft = np.array([p.shape[1] == 0 for p in calls])
    solved = np.array([s == "optimal" for s in statuses["backend"]])
    groups = {
        "paper optimal": ~soft & solved,
        "paper failing": ~soft & ~solved,
        "soft": soft,
    }
    sizes = ", ".join(f"{name} {int(mask.sum())}" for name, mask in groups.items())
    print(f"{count} calls ({sizes}), {args.repeat} passes; per call the fastest pass [us]:")
    head = "".join(f"{name + ' median':>22s}" for name in groups)
    print(f"{'route':22s} {'median':>7s} {'p90':>7s} {'own median':>11s}{head}")
    for r in routes:
        t, o = times[r].min(axis=0) * 1e6, own[r].min(axis=0) * 1e6
        cols = "".join(f"{np.median(t[mask]):22.2f}" for mask in groups.values())
        print(f"{r:22s} {np.median(t):7.2f} {np.percentile(t, 90):7.2f} {np.median(o):11.2f}{cols}")
    ref = xs["backend"]
    for r in routes[1:]:
        same_status = statuses[r] == statuses["backend"]
        both = ~np.isnan(ref[:, 0])
        bitwise = np.array_equal(xs[r][both], ref[both])
        diff = np.nanmax(np.abs(xs[r][both] - ref[both])) if both.any() else 0.0
        print(
            f"{r}: statuses {'same' if same_status else 'DIFFER'}; x on {int(both.sum())} optimal"
            f" calls {'bit for bit' if bitwise else 'not bit for bit'} (max |dx| {diff:.1e})"
        )


if __name__ == "__main__":
    main()
