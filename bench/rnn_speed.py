"""Speed of the projection network (backends ``rnn`` and ``rnn-converged``) on the robot's QPs.

    python bench/rnn_speed.py [--scenario wall] [--duration 4] [--passes 5] [--online-only]

Ticks: the consecutive per-tick QPs of a closed-loop run (every tick kept).

1. ``rnn`` online (the working setting, ``WORKING_SETTINGS``: the defaults of ``rnn-tuned``),
   replaying the run of the network itself, median and p90 time per tick of
   ``Backend.solve``: on the controller's problems (``PackedProblem``: the
   per-tick path hands the kernel one buffer), the same plus reading the
   duals ``y, z, z_box`` (views made on first read), on the same QPs as plain
   ``qpsolvers.Problem`` objects (eight arrays), and through the general
   (converting) path; then the compiled kernel call alone, one Euler step,
   the closed loop's own per-tick solve time (``simulate``'s log), and the
   pieces of Python work around the kernel, each timed alone.
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


def replay(make, problems, passes: int, read_duals: bool = False) -> tuple[np.ndarray, list]:
    """Per-tick minimum of ``solve`` wall time [s] over ``passes`` fresh replays.

    With ``read_duals`` the time includes reading ``y``, ``z`` and ``z_box``.
    """
    best = np.full(len(problems), np.inf)
    sols = []
    perf = time.perf_counter_ns
    for _ in range(passes):
        be = make()
        sols = []
        for k, p in enumerate(problems):
            if read_duals:
                t0 = perf()
                s = be.solve(p)
                s.y, s.z, s.z_box  # noqa: B018 - the read is what is timed
                dt = perf() - t0
            else:
                t0 = perf()
                s = be.solve(p)
                dt = perf() - t0
            best[k] = min(best[k], dt * 1e-9)
            sols.append(s)
    return best, sols


def in_loop(scenario: str, duration: float, passes: int) -> np.ndarray:
    """Per-tick minimum over ``passes`` closed-loop runs of ``rnn-tuned`` of the loop's own solve time [s]."""
    from qpbench.sim.loop import simulate

    best = None
    for _ in range(passes):
        t = simulate(scenario, "rnn-tuned", duration=duration).log["solve_time_s"].to_numpy()
        best = t if best is None else np.minimum(best, t)
    return best


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
    """Seconds per call of the Python work of the per-tick path around the kernel, each piece alone."""
    from qpbench.backends.rnn import TickSolution

    perf = time.perf_counter_ns
    new = object.__new__
    out = np.empty(30)
    sx, slices = slice(0, 4), (slice(0, 4), slice(4, 6), slice(6, 13), slice(13, 17))

    def make_solution():
        sol = new(TickSolution)
        sol.problem = problem
        sol.x, sol.y, sol.z, sol.z_box = out, out, out, out
        sol.iterations = 5
        sol.status = "max_iter"
        sol.found = False
        sol.backend = "rnn"
        sol.wall_time_s = 1e-6

    def x_view():
        return out[sx]

    def dual_views():
        return out[slices[1]], out[slices[2]], out[slices[3]]

    clock = time.perf_counter

    def timing():
        start = clock()
        return clock() - start

    def output_array():
        return np.empty(30)

    pieces = [
        ("TickSolution + its 10 fields", make_solution),
        ("the view x", x_view),
        ("the output array", output_array),
        ("timing (2 perf_counter)", timing),
        ("3 views y, z, z_box", dual_views),
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
    parser.add_argument("--passes", type=int, default=5)
    parser.add_argument("--online-only", action="store_true", help="part 1 only (rnn online)")
    args = parser.parse_args()

    from qpbench.backends import backend_names, get_backend
    from qpbench.backends.rnn import WORKING_SETTINGS
    from qpbench.rnn import kernels as nk
    from qpbench.rnn import network as nw

    warnings.simplefilter("ignore")
    us = 1e6

    # -- 1. online ---------------------------------------------------------
    import qpsolvers

    sc, recs = ticks(args.scenario, args.duration, "rnn", WORKING_SETTINGS)
    problems = [r.problem for r in recs]  # the controller's PackedProblem objects
    plain = [
        qpsolvers.Problem(
            p.P.copy(),
            p.q.copy(),
            p.G.copy(),
            p.h.copy(),
            p.A.copy(),
            p.b.copy(),
            p.lb.copy(),
            p.ub.copy(),
        )
        for p in problems
    ]
    settings = dict(WORKING_SETTINGS, dt=sc.dt)
    make = lambda: get_backend("rnn", **settings)  # noqa: E731
    t_solve, sols = replay(make, problems, args.passes)
    t_duals, _ = replay(make, problems, args.passes, read_duals=True)
    t_plain, sols_plain = replay(make, plain, args.passes)
    # the general path (Backend.solve of the base class: convert, check, then the same kernel)
    t_general, _ = replay(lambda: _General(make()), problems, args.passes)
    for a, b in zip(sols, sols_plain):  # one network, whichever path: same numbers
        assert np.array_equal(a.x, b.x) and np.array_equal(a.z, b.z)
    # the packed kernel's call alone, same sequence
    kern = nk.packed_kernel()
    t_kernel = np.full(len(problems), np.inf)
    perf = time.perf_counter_ns
    for _ in range(args.passes):
        be = make()
        be.solve(problems[0])
        xi, prm = be.state.xi, be._prm
        n, me, mi = be.state.shape
        size = 3 * n + 2 * (me + mi)
        for k, p in enumerate(problems[1:], 1):
            out = np.empty(size)
            buf = p.buffer
            t0 = perf()
            kern(buf, xi, prm, out)
            t_kernel[k] = min(t_kernel[k], (perf() - t0) * 1e-9)
    t_kernel = t_kernel[1:]
    t_loop = in_loop(args.scenario, args.duration, args.passes)
    pieces = _interface_pieces(problems[len(problems) // 2], args.passes)
    # cost of one Euler step: a long fixed integration of one tick's QP
    p = problems[len(problems) // 2]
    qp = nw.dense_qp(p)
    steps = 200_000
    per_step = np.inf
    for _ in range(args.passes):
        st = nw.NetworkState.cold(*qp.shape)
        t0 = perf()
        nw.integrate(qp, st, r_total=0.2 * steps, substeps=steps, p_range=(1.0, 1.0), clamp=False)
        per_step = min(per_step, (perf() - t0) * 1e-9 / steps)
    n, me, mi = qp.shape

    def fig(t):
        return f"median {np.median(t) * us:.2f} us, p90 {np.percentile(t, 90) * us:.2f} us"

    print(
        f"# rnn online, {args.scenario}, {len(problems)} consecutive ticks, settings {settings}; {_load()}"
    )
    print(f"  QP size n={n}, equalities {me}, inequalities {mi}")
    print(f"  Backend.solve per tick, the controller's problems: {fig(t_solve)} (target <= 2 us)")
    print(f"  ... and reading y, z, z_box too:                   {fig(t_duals)}")
    print(f"  Backend.solve, same QPs as plain qpsolvers.Problem: {fig(t_plain)}")
    print(f"  general path (convert + check + kernel):           {fig(t_general)}")
    print(f"  closed loop's own solve time per tick (rnn-tuned): {fig(t_loop)}")
    print(
        f"  kernel call (dispatch + {WORKING_SETTINGS['substeps']} steps + residuals + duals): {fig(t_kernel)}"
    )
    print(
        f"  one Euler step (numba): {per_step * 1e9:.0f} ns; {WORKING_SETTINGS['substeps']} steps = "
        f"{WORKING_SETTINGS['substeps'] * per_step * us:.2f} us"
    )
    print(
        f"  outside the kernel (Backend.solve - kernel): {(np.median(t_solve) - np.median(t_kernel)) * us:.2f} us"
    )
    print("  pieces of the Python work (each timed alone in a tight loop, best of passes):")
    for name, t in pieces:
        print(f"    {name:<58} {t * 1e9:6.0f} ns")

    if args.online_only:
        return
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
    conv_semi = lambda: get_backend(
        "rnn-converged", tol=1e-6, max_iter=1_000_000, method="semi-implicit"
    )  # noqa: E731
    t_semi, sols_semi = replay(conv_semi, problems, args.passes)
    steps_semi = np.array([s.iterations for s in sols_semi])
    print(
        f"\n# rnn-converged to 1e-6 from the previous tick's state, {args.scenario}, "
        f"{len(problems)} feasible consecutive ticks ({active.sum()} with an active obstacle row)"
    )
    print(f"  converged on {found.sum()} of {len(found)}")
    for label, st_, tt in (("euler", steps, t_conv), ("semi-implicit", steps_semi, t_semi)):
        for name, mask in (
            ("all", np.ones_like(active)),
            ("obstacle active", active),
            ("no active row", ~active),
        ):
            if mask.any():
                print(
                    f"  {label:13s} {name:16s} steps median {np.median(st_[mask]):.0f}, "
                    f"p90 {np.percentile(st_[mask], 90):.0f}; "
                    f"time median {np.median(tt[mask]) * us:.2f} us, p90 {np.percentile(tt[mask], 90) * us:.2f} us"
                )

    results = {}
    for name in backend_names():
        if not (name.startswith("qpsolvers:") or name == "daqp") or name in (
            "qpsolvers:scs",
            "qpsolvers:highs",
        ):
            continue
        t_ref, s_ref = replay(lambda: get_backend(name), problems, args.passes)
        if all(s.found for s in s_ref):
            results[name] = t_ref
    print(
        "\n# QP backends on the same ticks: qpsolvers:* and daqp (Backend.solve, per-tick min over passes)"
    )
    for name, tt in sorted(results.items(), key=lambda kv: np.median(kv[1])):
        print(
            f"  {name:20s} median {np.median(tt) * us:8.2f} us, p90 {np.percentile(tt, 90) * us:8.2f} us"
        )
    via_qpsolvers = {k: v for k, v in results.items() if k.startswith("qpsolvers:")}
    fastest = min(via_qpsolvers, key=lambda k: np.median(via_qpsolvers[k]))
    for label, tt in (("euler", t_conv), ("semi-implicit", t_semi)):
        print(
            f"  rnn-converged ({label}) / {fastest}: median ratio {np.median(tt) / np.median(results[fastest]):.2f}"
            f" (goal <= 2)"
        )
        if "daqp" in results:
            print(
                f"  rnn-converged ({label}) / daqp (own API): median ratio "
                f"{np.median(tt) / np.median(results['daqp']):.2f}"
            )


if __name__ == "__main__":
    main()
