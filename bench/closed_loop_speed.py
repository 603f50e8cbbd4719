"""Wall time of 20 s of the ``wall`` scenario at 1 kHz in closed loop, with the fastest backends.

Target: at most 0.6 s wall time (real-time factor >= 33) with the fastest
available backend. Only registered backends are timed (what ``qpbench
simulate --backend NAME`` runs). The script

1. ranks the candidate QP backends on a short run (``--rank-duration``);
2. runs the full duration ``--repeat`` times with each of the ``--top``
   fastest and prints the median wall time and real-time factor (min and
   max in brackets), the median per-tick solve time and the infeasible /
   fallback counts;
3. prints, as a reference line, the loop's own cost per tick (build + sense +
   log + plant) with a *null* backend that commands zero velocity without
   solving (not a registered backend; labelled as such);
4. optionally (``--rnn``) the online ``rnn`` backend with its working
   setting, which is a different controller (the network's state), not a
   QP solver: printed apart, not ranked.

The load average is printed with the figures: the machine may be shared.

    python bench/closed_loop_speed.py [--scenario wall] [--duration 20] [--repeat 3] [--top 3]
        [--backends a,b,c] [--rnn]
"""

from __future__ import annotations

import argparse
import os
import warnings

import numpy as np

from qpbench.backends import backend_names
from qpbench.backends.base import Backend, BackendSolution
from qpbench.sim.loop import simulate

#: Candidates tried by default: backends that answer the robot's ticks in
#: microseconds to tens of microseconds and classify the infeasible start
#: quickly (an ADMM or interior-point backend may be added with --backends).
CANDIDATES = (
    "daqp",
    "qpsolvers:daqp",
    "qpsolvers:quadprog",
    "proxqp",
    "qpsolvers:piqp",
)

#: 20 s of simulated time in at most 0.6 s of wall time.
TARGET_RTF = 20.0 / 0.6


class NullBackend(Backend):
    """Reference only (not registered): commands zero velocity without solving."""

    name = "null (reference, not a solver)"
    family = "none"

    def _solve(self, problem, warm_start):
        sol = BackendSolution(problem, status="optimal")
        sol.x = np.zeros(problem.q.size)
        sol.obj = 0.0
        return sol


def _load() -> str:
    try:
        return "load average %.2f %.2f %.2f (1/5/15 min) on %d cores" % (
            *os.getloadavg(),
            os.cpu_count() or 0,
        )
    except OSError:  # pragma: no cover - not on every platform
        return "load average unknown"


def _runs(scenario, backend, duration, repeat):
    """``repeat`` runs; returns (summaries, median wall [s])."""
    out = [simulate(scenario, backend, duration=duration).summary for _ in range(repeat)]
    return out, float(np.median([s["wall_time_s"] for s in out]))


def _line(label, summaries, duration):
    walls = np.array([s["wall_time_s"] for s in summaries])
    s = summaries[0]
    med = float(np.median(walls))
    solve = float(np.median([x["solve_time_median_s"] for x in summaries])) * 1e6
    return (
        f"{label:<26} {med:>7.3f} [{walls.min():.3f}, {walls.max():.3f}] {duration / med:>7.1f} "
        f"{med / s['ticks'] * 1e6:>8.2f} {solve:>11.2f} {s['infeasible_ticks']:>10} {s['fallback_ticks']:>8}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="wall")
    parser.add_argument(
        "--duration", type=float, default=20.0, help="simulated seconds of the timed runs"
    )
    parser.add_argument(
        "--rank-duration",
        type=float,
        default=2.0,
        help="simulated seconds per backend when ranking",
    )
    parser.add_argument(
        "--repeat", type=int, default=3, help="timed runs per backend (median reported)"
    )
    parser.add_argument(
        "--top", type=int, default=3, help="how many of the fastest backends get the timed runs"
    )
    parser.add_argument(
        "--backends", default=None, help="comma-separated candidates (default: a built-in list)"
    )
    parser.add_argument(
        "--rnn", action="store_true", help="also time the online rnn backend (working setting)"
    )
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    available = set(backend_names())
    cands = [
        b for b in (args.backends.split(",") if args.backends else CANDIDATES) if b in available
    ]
    print(f"# {args.scenario}, dt from the scenario; {_load()}")

    print(f"\nranking on {args.rank_duration:g} s of {args.scenario} (one run each):")
    print(
        f"{'backend':<22} {'wall [s]':>9} {'us/tick':>8} {'median solve [us]':>18} {'infeasible':>10}"
    )
    ranked = []
    for b in cands:
        s = simulate(args.scenario, b, duration=args.rank_duration).summary
        ranked.append((s["wall_time_s"], b))
        print(
            f"{b:<22} {s['wall_time_s']:>9.3f} {s['wall_time_s'] / s['ticks'] * 1e6:>8.1f} "
            f"{s['solve_time_median_s'] * 1e6:>18.1f} {s['infeasible_ticks']:>10}"
        )
    if not ranked:
        print("no QP backend available")
        return
    best = [b for _, b in sorted(ranked)[: args.top]]

    print(
        f"\n{args.scenario}, {args.duration:g} s, {args.repeat} runs each; wall time median [min, max]:"
    )
    header = (
        f"{'backend':<26} {'wall [s]':>7} {'[min, max]':<14} {'RTF':>7} {'us/tick':>8} {'solve [us]':>11} "
        f"{'infeasible':>10} {'fallback':>8}"
    )
    print(header)
    results = {}
    for b in best:
        summaries, med = _runs(args.scenario, b, args.duration, args.repeat)
        results[b] = med
        print(_line(b, summaries, args.duration))
    null, _ = _runs(args.scenario, NullBackend(), args.duration, args.repeat)
    print(_line("null (loop only; ref.)", null, args.duration))
    if args.rnn and "rnn" in available:
        from dataclasses import replace

        from qpbench.backends.rnn import WORKING_SETTINGS
        from qpbench.sim.scenario import load_scenario

        sc = replace(load_scenario(args.scenario), rnn=dict(WORKING_SETTINGS))
        rnn, _ = _runs(sc, "rnn", args.duration, args.repeat)
        print(_line("rnn online (not a QP)", rnn, args.duration))

    fastest = min(results, key=results.get)
    med = results[fastest]
    verdict = "met" if args.duration / med >= TARGET_RTF else "NOT met"
    print(
        f"\nfastest: {fastest}, {med:.3f} s for {args.duration:g} s, real-time factor {args.duration / med:.1f} "
        f"(target: 20 s in <= 0.6 s, factor >= {TARGET_RTF:.1f}: {verdict}); {_load()}"
    )


if __name__ == "__main__":
    main()
