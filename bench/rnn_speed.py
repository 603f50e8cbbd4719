"""Speed of the projection network (backends ``rnn`` and ``rnn-converged``) on the robot's QPs.

    python bench/rnn_speed.py [--scenario wall] [--duration 4] [--passes 3]

Ticks: the consecutive per-tick QPs of a closed-loop run (every tick kept).

1. ``rnn`` online (the working setting: eps = 1e-3, 5 Euler sub-steps, l1 clip 10),
   replaying the run of the network itself: median time per tick of
   ``Backend.solve`` (its short per-tick path), of the general path, of the
   compiled kernel call alone, and of the sub-steps alone (the kernel's cost
   per Euler step measured on a long integration); then the pieces of Python
   work the generic interface needs around the kernel, each timed alone,
   and their sum with the kernel: the floor of a ``Backend.solve`` call.
2. ``rnn-converged`` to 1e-6 from the previous tick's state, on the ticks of a
   DAQP run (the QP's trajectory) that DAQP finds feasible: median and p90
   steps and microseconds, overall and on ticks with an active obstacle row;
   the ratio of its median to the fastest qpsolvers backend's median on the
   same ticks, and to the ``daqp`` backend's (DAQP's own API), all through
   ``Backend.solve``.

Times are per-tick minima over ``--passes`` replays (the machine is shared);
figures are printed, nothing is written.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from dataclasses import replace

import numpy as np


def ticks(scenario: str, duration: float, backend: str, rnn: dict | None = None):
    from qpbench.sim.loop import simulate
    from qpbench.sim.scenario import load_scenario

    sc = load_scenario(scenario)
    if rnn is not None:
        sc = replace(sc, rnn=dict(rnn))
    return sc, simulate(sc, backend, duration=duration, every=1).records


def replay(make, problems, passes: int) -> tuple[np.ndarray, list]:
    """Per-tick minimum of ``solve`` wall time [s] over ``passes`` fresh replays."""
    best = np.full(len(problems), np.inf)
    sols = []
    perf = time.perf_counter_ns
    for _ in range(passes):
        be = make()
        sols = []
        for k, p in enumerate(problems):
            t0 = perf()
            s = be.solve(p)
            dt = perf() - t0
            best[k] = min(best[k], dt * 1e-9)
            sols.append(s)
    return best, sols


class _General:
    """Calls the base class's ``Backend.solve`` on an rnn backend: its general (converting) path."""

    def __init__(self, backend):
        self.backend = backend

    def solve(self, problem):
        from qpbench.backends.base import Backend

        return Backend.solve(self.backend, problem)


def _load() -> str:
    try:
        return "load average %.2f %.2f %.2f on %d cores" % (*os.getloadavg(), os.cpu_count() or 0)
    except OSError:  # pragma: no cover
        return "load average unknown"


def _interface_pieces(problem, passes: int, count: int = 100_000) -> list[tuple[str, float]]:
    """Seconds per call of the unavoidable Python work around the kernel."""
    from qpbench.backends.base import BackendSolution

    perf = time.perf_counter_ns
    out = np.empty(30)
    x = out[:4]

    def make_solution():
        sol = BackendSolution(problem)
        sol.status, sol.x, sol.y, sol.z, sol.z_box, sol.obj, sol.iterations = "max_iter", x, x, x, x, 0.0, 5

    s1, s2, s3, s4 = slice(0, 4), slice(4, 6), slice(6, 13), slice(13, 17)

    def views():
        return out[s1], out[s2], out[s3], out[s4]

    def timing():
        start = perf()
        return (perf() - start) * 1e-9

    def read_problem():
        P, q, A, G, lb, ub = problem.P, problem.q, problem.A, problem.G, problem.lb, problem.ub
        return (type(P) is np.ndarray and type(q) is np.ndarray and type(A) is np.ndarray and type(G) is np.ndarray
                and type(lb) is np.ndarray and type(ub) is np.ndarray, problem.b.shape[0], problem.h.shape[0])

    def output_array():
        return np.empty(30)

    pieces = [
        ("BackendSolution(problem) + its 7 fields", make_solution),
        ("4 output views x, y, z, z_box", views),
        ("timing (2 perf_counter_ns)", timing),
        ("read the problem's fields, check types, shape key", read_problem),
        ("the output array", output_array),
    ]
    result = []
    for name, fn in pieces:
        best = np.inf
        for _ in range(passes):
            t0 = perf()
            for _ in range(count):
                fn()
            best = min(best, (perf() - t0) * 1e-9 / count)
        result.append((name, best))
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="wall")
    parser.add_argument("--duration", type=float, default=4.0, help="simulated seconds of ticks")
    parser.add_argument("--passes", type=int, default=3)
    args = parser.parse_args()

    from qpbench.backends import backend_names, get_backend
    from qpbench.backends.rnn import WORKING_SETTINGS
    from qpbench.rnn import network as nw

    warnings.simplefilter("ignore")
    us = 1e6

    # -- 1. online ---------------------------------------------------------
    sc, recs = ticks(args.scenario, args.duration, "rnn", WORKING_SETTINGS)
    problems = [r.problem for r in recs]
    settings = dict(WORKING_SETTINGS, dt=sc.dt)
    t_solve, _ = replay(lambda: get_backend("rnn", **settings), problems, args.passes)
    # the general path (Backend.solve of the base class: convert, check, then the same kernel)
    t_general, _ = replay(lambda: _General(get_backend("rnn", **settings)), problems, args.passes)
    # kernel call alone, same sequence
    be = get_backend("rnn", **settings)
    be.solve(problems[0])
    kern = be._kernel
    t_kernel = np.full(len(problems), np.inf)
    perf = time.perf_counter_ns
    for _ in range(args.passes):
        be.reset()
        be.solve(problems[0])
        prm = be._prm
        for k, p in enumerate(problems[1:], 1):
            st = be.state
            n, me, mi = st.shape
            sol = np.empty(3 * n + 2 * (me + mi))
            t0 = perf()
            kern(p.P, p.q, p.A, p.b, p.G, p.h, p.lb, p.ub, st.xi, prm, sol)
            t_kernel[k] = min(t_kernel[k], (perf() - t0) * 1e-9)
    t_kernel = t_kernel[1:]
    # what the generic interface costs around the kernel, piece by piece
    pieces = _interface_pieces(problems[len(problems) // 2], args.passes)
    # cost of one Euler step: a long fixed integration of one tick's QP
    p = problems[len(problems) // 2]
    qp = nw.dense_qp(p)
    steps = 200_000
    per_step = np.inf
    for _ in range(args.passes):
        st = nw.NetworkState.cold(*qp.shape)
        t0 = perf()
        nw.integrate(qp, st, r_total=0.2 * steps, substeps=steps, p_range=(1.0, 1.0))
        per_step = min(per_step, (perf() - t0) * 1e-9 / steps)
    n, me, mi = qp.shape
    print(f"# rnn online, {args.scenario}, {len(problems)} consecutive ticks, settings {settings}; {_load()}")
    print(f"  QP size n={n}, equalities {me}, inequalities {mi}")
    print(f"  Backend.solve per tick: median {np.median(t_solve) * us:.2f} us, p90 {np.percentile(t_solve, 90) * us:.2f} us"
          f" (target <= 2 us)")
    print(f"  general path (convert + check + kernel) per tick: median {np.median(t_general) * us:.2f} us")
    print(f"  kernel call per tick (numba dispatch + {WORKING_SETTINGS['substeps']} steps + duals): "
          f"median {np.median(t_kernel) * us:.2f} us")
    print(f"  one Euler step (numba): {per_step * 1e9:.0f} ns; {WORKING_SETTINGS['substeps']} steps = "
          f"{WORKING_SETTINGS['substeps'] * per_step * us:.2f} us")
    print(f"  overhead outside the kernel (Backend.solve - kernel): {(np.median(t_solve) - np.median(t_kernel)) * us:.2f} us")
    print("  pieces of that overhead (each timed alone in a tight loop, best of passes):")
    for name, t in pieces:
        print(f"    {name:<58} {t * 1e9:6.0f} ns")
    floor = np.median(t_kernel) + sum(t for _, t in pieces)
    print(f"  floor through the generic interface (kernel + the pieces above): about {floor * us:.2f} us")

    # -- 2. converged ------------------------------------------------------
    sc, recs = ticks(args.scenario, args.duration, "qpsolvers:daqp")
    problems, active = [], []
    ref = get_backend("qpsolvers:daqp")
    for r in recs:
        s = ref.solve(r.problem)
        if s.found:
            problems.append(r.problem)
            active.append(s.z is not None and s.z.max() > 1e-9)
    active = np.array(active)
    conv = lambda: get_backend("rnn-converged", tol=1e-6, max_iter=1_000_000, method="euler")  # noqa: E731
    t_conv, sols = replay(conv, problems, args.passes)
    steps = np.array([s.iterations for s in sols])
    found = np.array([s.found for s in sols])
    conv_semi = lambda: get_backend("rnn-converged", tol=1e-6, max_iter=1_000_000, method="semi-implicit")  # noqa: E731
    t_semi, sols_semi = replay(conv_semi, problems, args.passes)
    steps_semi = np.array([s.iterations for s in sols_semi])
    print(f"\n# rnn-converged to 1e-6 from the previous tick's state, {args.scenario}, "
          f"{len(problems)} feasible consecutive ticks ({active.sum()} with an active obstacle row)")
    print(f"  converged on {found.sum()} of {len(found)}")
    for label, st_, tt in (("euler", steps, t_conv), ("semi-implicit", steps_semi, t_semi)):
        for name, mask in (("all", np.ones_like(active)), ("obstacle active", active), ("no active row", ~active)):
            if mask.any():
                print(f"  {label:13s} {name:16s} steps median {np.median(st_[mask]):.0f}, p90 {np.percentile(st_[mask], 90):.0f}; "
                      f"time median {np.median(tt[mask]) * us:.2f} us, p90 {np.percentile(tt[mask], 90) * us:.2f} us")

    results = {}
    for name in backend_names():
        if not (name.startswith("qpsolvers:") or name == "daqp") or name in ("qpsolvers:scs", "qpsolvers:highs"):
            continue
        t_ref, s_ref = replay(lambda: get_backend(name), problems, args.passes)
        if all(s.found for s in s_ref):
            results[name] = t_ref
    print("\n# QP backends on the same ticks: qpsolvers:* and daqp (Backend.solve, per-tick min over passes)")
    for name, tt in sorted(results.items(), key=lambda kv: np.median(kv[1])):
        print(f"  {name:20s} median {np.median(tt) * us:8.2f} us, p90 {np.percentile(tt, 90) * us:8.2f} us")
    via_qpsolvers = {k: v for k, v in results.items() if k.startswith("qpsolvers:")}
    fastest = min(via_qpsolvers, key=lambda k: np.median(via_qpsolvers[k]))
    for label, tt in (("euler", t_conv), ("semi-implicit", t_semi)):
        print(f"  rnn-converged ({label}) / {fastest}: median ratio {np.median(tt) / np.median(results[fastest]):.2f}"
              f" (goal <= 2)")
        if "daqp" in results:
            print(f"  rnn-converged ({label}) / daqp (own API): median ratio "
                  f"{np.median(tt) / np.median(results['daqp']):.2f}")


if __name__ == "__main__":
    main()
