"""Wall time of 20 s of the ``wall`` scenario at 1 kHz in closed loop, with the fastest backend.

Target: at most 0.6 s wall time (real-time factor >= 33). Ranks the available
QP backends on a 2 s run, then runs the full duration with the fastest; also
runs a *null* backend (returns zero velocity without solving) so the loop's
own overhead per tick (build + sense + log + plant) is printed separately
from the solver's time.

    python bench/closed_loop_speed.py [--scenario wall] [--duration 20] [--backends a,b,c]
"""

from __future__ import annotations

import argparse

import numpy as np

from qpbench.backends import backend_names
from qpbench.backends.base import Backend, BackendSolution
from qpbench.sim.loop import simulate

#: Backends tried by default: those that answer the robot's ticks in tens of
#: microseconds and report the infeasible start quickly (an ADMM or a
#: proximal solver may iterate to its limit on each infeasible tick; pass
#: them with --backends to include them).
CANDIDATES = (
    "qpsolvers:daqp",
    "qpsolvers:quadprog",
    "qpsolvers:piqp",
)


class DirectDaqp(Backend):
    """DAQP called through its own ``daqp.solve`` (no qpsolvers layer); for this benchmark only.

    Shows what the loop does with a solver that costs a few microseconds per
    tick; primal answer only (no duals).
    """

    name = "daqp-direct (bench only)"
    family = "active set"

    def _solve(self, problem, warm_start):
        import daqp

        n = problem.q.size
        rows_A = [] if problem.A is None else [problem.A]
        rows_G = [] if problem.G is None else [problem.G]
        A = np.vstack(rows_A + rows_G) if rows_A or rows_G else np.zeros((0, n))
        m_eq = 0 if problem.A is None else problem.b.size
        m_in = 0 if problem.G is None else problem.h.size
        bu = np.concatenate([problem.ub] + ([problem.b] if m_eq else []) + ([problem.h] if m_in else []))
        bl = np.concatenate([problem.lb] + ([problem.b] if m_eq else []) + ([np.full(m_in, -1e30)] if m_in else []))
        sense = np.zeros(n + m_eq + m_in, dtype=np.int32)
        sense[n:n + m_eq] = 5  # equality
        x, _, flag, _ = daqp.solve(problem.P, problem.q, A, bu, bl, sense)
        sol = BackendSolution(problem, status="optimal" if flag in (1, 2) else "primal_infeasible" if flag == -1 else "error")
        sol.x = np.asarray(x) if flag in (1, 2) else None
        return sol


class NullBackend(Backend):
    """Commands zero velocity without solving: measures the loop around the solver."""

    name = "null"
    family = "none"

    def _solve(self, problem, warm_start):
        sol = BackendSolution(problem, status="optimal")
        sol.x = np.zeros(problem.q.size)
        sol.obj = 0.0
        return sol


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="wall")
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--rank-duration", type=float, default=2.0, help="simulated seconds per backend when ranking")
    parser.add_argument("--backends", default=None, help="comma-separated candidates (default: a built-in list)")
    args = parser.parse_args()
    available = set(backend_names())
    cands = [b for b in (args.backends.split(",") if args.backends else CANDIDATES) if b in available]

    null = simulate(args.scenario, NullBackend(), duration=args.duration)
    s = null.summary
    per_tick = s["wall_time_s"] / s["ticks"] * 1e6
    solve = null.log["solve_time_s"].median() * 1e6
    print(f"loop overhead (null backend): {s['wall_time_s']:.3f} s for {args.duration:g} s, {per_tick:.1f} us/tick "
          f"(of which the Backend.solve wrapper {solve:.1f} us)")

    print(f"\nranking on {args.rank_duration:g} s of {args.scenario}:")
    print(f"{'backend':<22} {'wall [s]':>9} {'us/tick':>8} {'median solve [us]':>18} {'infeasible':>10}")
    ranked = []
    for b in cands:
        r = simulate(args.scenario, b, duration=args.rank_duration)
        s = r.summary
        ranked.append((s["wall_time_s"], b))
        print(f"{b:<22} {s['wall_time_s']:>9.3f} {s['wall_time_s'] / s['ticks'] * 1e6:>8.1f} "
              f"{s['solve_time_median_s'] * 1e6:>18.1f} {s['infeasible_ticks']:>10}")
    if not ranked:
        print("no QP backend available")
        return
    try:
        import daqp  # noqa: F401

        r = simulate(args.scenario, DirectDaqp(), duration=args.rank_duration)
        s = r.summary
        print(f"{'daqp-direct (bench)':<22} {s['wall_time_s']:>9.3f} {s['wall_time_s'] / s['ticks'] * 1e6:>8.1f} "
              f"{s['solve_time_median_s'] * 1e6:>18.1f} {s['infeasible_ticks']:>10}")
        r = simulate(args.scenario, DirectDaqp(), duration=args.duration)
        s = r.summary
        print(f"  (not a registered backend) {args.duration:g} s: wall {s['wall_time_s']:.3f} s, "
              f"real-time factor {s['real_time_factor']:.1f}, min distance {s['min_obstacle_distance']:.6f} m")
    except ImportError:
        pass
    best = min(ranked)[1]
    r = simulate(args.scenario, best, duration=args.duration)
    s = r.summary
    print(f"\n{args.scenario}, {args.duration:g} s at {1 / s['dt']:.0f} Hz with {best}: wall {s['wall_time_s']:.3f} s, "
          f"real-time factor {s['real_time_factor']:.1f} (target: <= 0.6 s, factor >= 33)")
    print(f"  median solve {s['solve_time_median_s'] * 1e6:.1f} us, loop overhead {per_tick:.1f} us/tick")


if __name__ == "__main__":
    main()
