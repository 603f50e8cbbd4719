"""Overhead of qpbench's backends against the solvers' own APIs and qpsolvers.solve_problem.

For each backend, the median wall time of one solve over a few hundred small
dense QPs shaped like the robot's control ticks (n = 4, 2 equalities, 7-14
inequalities, bounds), measured three ways in this process:

- ``ours``: ``Backend.solve`` of qpbench;
- ``direct``: the solver's own Python API called directly with the same
  settings, doing the same work as the backend with nothing around it: set
  the data, solve, and read what the backend must return, i.e. the status,
  the solver's own time, ``x`` and one multiplier per constraint in the
  solver's layout (copied where the API hands back views of buffers the next
  solve overwrites, as the backend must; views and result handles kept across
  calls where the API allows, the thinnest route): a persistent, updated
  object for ``osqp``, ``proxqp``, ``clarabel``, ``piqp`` (as ours);
  ``daqp.Model.update`` + ``solve`` with arrays stacked per call for
  ``daqp``; ``daqp.solve`` with the stacked arrays of the backend for
  ``daqp-stateless``; for ``qpoases``, the compiled shim called through
  ctypes on buffers filled per call (qpOASES has no Python API of its own
  here: this is the thinnest Python route to its ``hotstart``); a fresh call
  of the solver's own function for ``qpsolvers:<name>`` where that is simple
  (daqp, quadprog, piqp, osqp, clarabel, proxqp), else
  ``qpsolvers.solve_problem`` (highs, scs); the same parametrised cvxpy model
  for ``cvxpy``; ``numpy.linalg.lstsq`` for ``pinv``;
- ``qpsolvers``: ``qpsolvers.solve_problem`` with the backend's solver and settings.

What ``ours`` does beyond ``direct`` is qpbench's own bookkeeping: the input
checks, the split of the multipliers into ``y``, ``z``, ``z_box`` (views of
one copy where the solver writes them in one vector), the status mapped to
qpbench's vocabulary, iterations and the objective, the wall time, and the
``BackendSolution`` that holds them. The targets: ``ours/direct`` within 1.1
for every own-API backend, ``ours/qpsolvers`` within 1.05 for the
``qpsolvers:<name>`` routes (whose reference is ``qpsolvers.solve_problem``:
the route is meant to cost what qpsolvers costs).

Problems: consecutive ticks of the ``wall`` scenario (an obstacle row active)
when :mod:`qpbench.sim` can produce them, else ``robot_like_problem`` of ``tests/known.py``.
Each method runs over the whole sequence ``--repeat`` times (fresh state each
pass, passes interleaved between methods); the median is over all calls, or
with ``--stat min`` the median over problems of each problem's fastest pass
(robust when other processes share the cores: a call slowed by them is
dropped unless every pass of it was).

Usage::

    python bench/backend_overhead.py [--count 400] [--repeat 3] [--source sim|known]
        [--profile default] [--backends osqp,proxqp,...] [--stat median|min]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import qpsolvers
import scipy.sparse as spa

from qpbench.backends import backend_names, get_backend
from qpbench.backends.qpsolvers_ import native_settings

# The known-solution problems are a test oracle: they live with the tests.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from known import robot_like_problem  # noqa: E402

# ----------------------------------------------------------------- problems


def sim_problems(count: int, start_tick: int = 1500) -> list[qpsolvers.Problem]:
    """``count`` consecutive QPs of the wall scenario from ``start_tick`` (1 ms ticks)."""
    from qpbench.sim.loop import simulate

    duration = (start_tick + count + 1) * 1e-3
    result = simulate("wall", "qpsolvers:daqp", formulation="paper", duration=duration, every=1)
    records = result.records[start_tick : start_tick + count]
    return [r.problem for r in records]


def known_problems(count: int) -> list[qpsolvers.Problem]:
    rng = np.random.default_rng(0)
    return [robot_like_problem(rng)[0] for _ in range(count)]


# ----------------------------------------------------------------- direct APIs


def _parts(p):
    """Dense ``P, q, G, h, A, b, lb, ub`` with empty arrays for absent blocks."""
    n = p.q.shape[0]
    G = np.zeros((0, n)) if p.G is None else np.asarray(p.G, float)
    h = np.zeros(0) if p.h is None else np.asarray(p.h, float)
    A = np.zeros((0, n)) if p.A is None else np.asarray(p.A, float)
    b = np.zeros(0) if p.b is None else np.asarray(p.b, float)
    lb = np.full(n, -np.inf) if p.lb is None else np.asarray(p.lb, float)
    ub = np.full(n, np.inf) if p.ub is None else np.asarray(p.ub, float)
    return np.asarray(p.P, float), np.asarray(p.q, float), G, h, A, b, lb, ub


def _triu_index(n):
    rows = np.concatenate([np.arange(j + 1) for j in range(n)])
    cols = np.concatenate([np.full(j + 1, j) for j in range(n)])
    indptr = np.concatenate([[0], np.cumsum(np.arange(1, n + 1))])
    return rows, cols, indptr


class DirectOsqp:
    """osqp.OSQP set up once, then update(q, l, u, Px, Ax); C = [G; A; I] with a full dense pattern."""

    def __init__(self, settings, persistent=True):
        self.settings, self.persistent = {**settings, "verbose": False}, persistent
        self.solver = None

    def __call__(self, p):
        import osqp

        P, q, G, h, A, b, lb, ub = _parts(p)
        n = q.shape[0]
        C = np.vstack([G, A, np.eye(n)])
        l = np.concatenate([np.full(G.shape[0], -np.inf), b, lb])
        u = np.concatenate([h, b, ub])
        if self.solver is None or not self.persistent:
            rows, cols, indptr = _triu_index(n)
            self.idx = (rows, cols)
            Pc = spa.csc_matrix((P[rows, cols], rows, indptr), shape=(n, n))
            k = C.shape[0]
            Cc = spa.csc_matrix(
                (C.T.ravel(), np.tile(np.arange(k), n), np.arange(0, k * n + 1, k)), shape=(k, n)
            )
            self.solver = osqp.OSQP()
            self.solver.setup(Pc, q, Cc, l, u, **self.settings)
        else:
            self.solver.update(q=q, l=l, u=u, Px=P[self.idx], Ax=C.T.ravel())
        res = self.solver.solve(raise_error=False)
        info = res.info
        # OSQP 1.x returns fresh arrays: x and y need no copy.
        return info.status_val, res.x, res.y, info.run_time


class DirectClarabel:
    """clarabel.DefaultSolver built once, then update(P, q, A, b); C = [A; G; I; -I], full dense pattern."""

    def __init__(self, settings_fn, persistent=True):
        self.settings_fn, self.persistent = settings_fn, persistent
        self.solver = None

    def __call__(self, p):
        import clarabel

        P, q, G, h, A, b, lb, ub = _parts(p)
        n = q.shape[0]
        I = np.eye(n)
        C = np.vstack([A, G, I, -I])
        d = np.concatenate([b, h, ub, -lb])
        if self.solver is None or not self.persistent:
            rows, cols, indptr = _triu_index(n)
            self.idx = (rows, cols)
            Pc = spa.csc_matrix((P[rows, cols], rows, indptr), shape=(n, n))
            k = C.shape[0]
            Cc = spa.csc_matrix(
                (C.T.ravel(), np.tile(np.arange(k), n), np.arange(0, k * n + 1, k)), shape=(k, n)
            )
            cones = [clarabel.ZeroConeT(A.shape[0]), clarabel.NonnegativeConeT(k - A.shape[0])]
            self.solver = clarabel.DefaultSolver(Pc, q, Cc, d, cones, self.settings_fn())
        else:
            self.solver.update(P=P[self.idx], q=q, A=C.T.ravel(), b=d)
        res = self.solver.solve()
        # Clarabel hands x and z back as lists: arrays, as the backend returns.
        return res.status, np.array(res.x), np.array(res.z), res.solve_time


class DirectProxqp:
    """proxsuite.proxqp.dense.QP init-ed once, then update + solve (warm start with previous result);
    reads the status, the solve time and copies of x, y, z (views and ``results.info`` kept)."""

    def __init__(self, apply_settings):
        self.apply_settings = apply_settings
        self.qp = None
        self.warm = False

    def __call__(self, p):
        import proxsuite

        P, q, G, h, A, b, lb, ub = _parts(p)
        l = np.full(G.shape[0], -np.inf)
        if self.qp is None:
            self.qp = proxsuite.proxqp.dense.QP(
                q.shape[0], A.shape[0], G.shape[0], box_constraints=True
            )
            self.update_preconditioner = self.apply_settings(self.qp)
            self.qp.init(P, q, A, b, G, l, h, lb, ub)
            res = self.qp.results
            self.info, self.views = res.info, (res.x, res.y, res.z)
        else:
            # The keyword: nanobind dispatches it faster than the same call all positional.
            self.qp.update(
                P, q, A, b, G, l, h, lb, ub, update_preconditioner=self.update_preconditioner
            )
        self.qp.solve()
        if not self.warm:  # as the backend: built cold, warm-started from the next tick on
            self.qp.settings.initial_guess = (
                proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
            )
            self.warm = True
        info = self.info
        x, y, z = self.views
        return info.status, x.copy(), y.copy(), z.copy(), info.solve_time


def direct_daqp(settings):
    import daqp

    def solve(p):
        P, q, G, h, A, b, lb, ub = _parts(p)
        n, m, meq = q.shape[0], G.shape[0], A.shape[0]
        Atot = np.vstack([G, A])
        bupper = np.concatenate([ub, h, b])
        blower = np.concatenate([lb, np.full(m, -1e30), b])
        sense = np.zeros(n + m + meq, dtype=np.intc)
        sense[n + m :] = 5
        x, fval, exitflag, info = daqp.solve(P, q, Atot, bupper, blower, sense, **settings)
        return x

    return solve


def direct_daqp_native(options):
    """``daqp.solve`` with the arrays the ``daqp`` backend builds: simple bounds native,
    ``A = [A_eq; G]``, ``bupper = [ub; b; h]``, ``blower = [lb; b; -inf]``,
    ``sense = [0 (n); 5 (me); 0 (mi)]``, and the backend's keyword settings.
    Stacked here with ``np.vstack``/``np.concatenate`` per call, as a user would."""
    import daqp

    def solve(p):
        P, q, G, h, A, b, lb, ub = _parts(p)
        n, me, mi = q.shape[0], A.shape[0], G.shape[0]
        Atot = np.vstack([A, G])
        bupper = np.concatenate([ub, b, h])
        blower = np.concatenate([lb, b, np.full(mi, -np.inf)])
        sense = np.zeros(n + me + mi, dtype=np.intc)
        sense[n : n + me] = 5
        x, fval, exitflag, info = daqp.solve(P, q, Atot, bupper, blower, sense, **options)
        return x

    return solve


class DirectDaqpModel:
    """``daqp.Model``: setup once, then ``update(None, None, A, bupper, blower)`` + ``solve`` (P, q constant
    on the robot's ticks), arrays stacked per call as a user would."""

    def __init__(self, options):
        self.options, self.model = options, None

    def __call__(self, p):
        import daqp

        P, q, G, h, A, b, lb, ub = _parts(p)
        n, me, mi = q.shape[0], A.shape[0], G.shape[0]
        Atot = np.vstack([A, G])
        bupper = np.concatenate([ub, b, h])
        blower = np.concatenate([lb, b, np.full(mi, -np.inf)])
        if self.model is None:
            sense = np.zeros(n + me + mi, dtype=np.intc)
            sense[n : n + me] = 5
            self.model = daqp.Model()
            self.model.settings = dict(self.model.settings, **self.options)
            self.model.setup(P, q, Atot, bupper, blower, sense)
        else:
            self.model.update(None, None, Atot, bupper, blower)
        return self.model.solve()[0]


class DirectPiqp:
    """``piqp.DenseSolver`` set up once, then ``update`` + ``solve``; the status ``solve`` returns,
    the run time, copies of ``x`` and ``y`` and one multiplier per constraint and bound
    (``z_u - z_l``, ``z_bu - z_bl``), from views of ``result`` kept after set-up."""

    def __init__(self, settings):
        self.settings, self.solver = settings, None

    def __call__(self, p):
        import piqp

        if self.solver is None:
            self.solver = piqp.DenseSolver()
            for key, value in self.settings.items():
                setattr(self.solver.settings, key, value)
            self.solver.setup(p.P, p.q, p.A, p.b, p.G, None, p.h, p.lb, p.ub)
            res = self.solver.result
            self.info, self.views = res.info, (res.x, res.y, res.z_l, res.z_u, res.z_bl, res.z_bu)
        else:
            self.solver.update(p.P, p.q, p.A, p.b, p.G, None, p.h, p.lb, p.ub)
        status = self.solver.solve()
        x, y, z_l, z_u, z_bl, z_bu = self.views
        return status, x.copy(), y.copy(), z_u - z_l, z_bu - z_bl, self.info.run_time


class DirectQpoases:
    """The qpOASES shim through ctypes: ``H, g, A = [A_eq; G], lb, ub, lbA, ubA`` written into its buffer,
    ``init`` on the first call and ``hotstart`` after; the status it returns, the solve time and one
    copy of ``x`` with the multipliers (the shim writes them one after the other)."""

    def __init__(self, backend):
        self.backend, self.lib, self.ws = backend, backend.prepare(), None

    def __call__(self, p):
        from qpbench.backends._qpoases_shim import Workspace

        ws = self.ws
        if ws is None:
            b = self.backend
            key = (p.q.shape[0], p.A.shape[0], p.G.shape[0], True)
            ws = self.ws = Workspace(key, self.lib, b._preset, b._native, b._nwsr, b._time_limit)
        ws.H[:] = p.P
        ws.g[:] = p.q
        ws.A_eq[:] = p.A
        ws.A_in[:] = p.G
        ws.lbA_eq[:] = p.b
        ws.ubA_eq[:] = p.b
        ws.ubA_in[:] = p.h
        ws.lb[:] = p.lb
        ws.ub[:] = p.ub
        status = self.lib.qpb_solve(ws.handle)
        return status, ws.xy.copy(), ws.s.item(2)


def direct_quadprog(settings):
    import quadprog

    def solve(p):
        P, q, G, h, A, b, lb, ub = _parts(p)
        n = q.shape[0]
        I = np.eye(n)
        C = np.vstack([A, -G, I, -I])
        rhs = np.concatenate([b, -h, lb, -ub])
        return quadprog.solve_qp(P, -q, C.T, rhs, A.shape[0])[0]

    return solve


def direct_piqp(settings):
    import piqp

    def solve(p):
        P, q, G, h, A, b, lb, ub = _parts(p)
        solver = piqp.DenseSolver()
        for key, value in settings.items():
            setattr(solver.settings, key, value)
        solver.setup(P, q, A, b, G, None, h, lb, ub)
        solver.solve()
        return solver.result.x

    return solve


def direct_proxqp_function(settings):
    import proxsuite

    def solve(p):
        P, q, G, h, A, b, lb, ub = _parts(p)
        n = q.shape[0]
        C = np.vstack([G, np.eye(n)])
        l = np.concatenate([np.full(G.shape[0], -np.inf), lb])
        u = np.concatenate([h, ub])
        return proxsuite.proxqp.dense.solve(P, q, A, b, C, l, u, verbose=False, **settings).x

    return solve


def via_qpsolvers(solver, settings):
    def solve(p):
        return qpsolvers.solve_problem(p, solver=solver, **settings).x

    return solve


def direct_for(name: str, profile: str):
    """(description, callable factory) of the direct API of backend ``name``."""
    backend = get_backend(name, profile)
    if name == "osqp":
        return "osqp.OSQP update", lambda: DirectOsqp(backend._settings())
    if name == "clarabel":
        import clarabel

        return "clarabel.DefaultSolver update", lambda: DirectClarabel(
            lambda: backend._settings(clarabel)
        )
    if name == "proxqp":
        import proxsuite

        return "proxqp.dense.QP update", lambda: DirectProxqp(
            lambda qp: backend._apply_settings(qp, proxsuite.proxqp)
        )
    if name == "daqp":
        return "daqp.Model update", lambda: DirectDaqpModel(backend.options())
    if name == "daqp-stateless":
        return "daqp.solve", lambda: direct_daqp_native(backend.options())
    if name == "piqp":
        return "piqp.DenseSolver update", lambda: DirectPiqp(backend._settings_dict)
    if name == "qpoases":
        return "qpOASES shim hotstart (ctypes)", lambda: DirectQpoases(backend)
    if name == "pinv":
        return "numpy lstsq", lambda: lambda p: np.linalg.lstsq(p.A, p.b, rcond=None)[0]
    if name == "cvxpy":
        import cvxpy as cp

        from qpbench.backends._common import FiniteRows
        from qpbench.backends.cvxpy_ import _Model

        solver, options = backend._solver_options(cp)

        def factory():
            models = {}

            def solve(p):
                P, q, G, h, A, b, lb, ub = _parts(p)
                rows = FiniteRows(p, q.shape[0])
                key = (q.shape[0], A.shape[0], rows.kept)
                if key not in models:
                    models[key] = _Model(cp, q.shape[0], A.shape[0], rows)
                model = models[key]
                model.set_values(p, rows, lb, ub)
                model.problem.solve(solver=solver, warm_start=True, **options)
                return model.x.value

            return solve

        return f"cvxpy Problem.solve ({solver})", factory
    if name.startswith("qpsolvers:"):
        solver = name.split(":", 1)[1]
        settings = backend.solver_options
        table = {
            "daqp": ("daqp.solve", direct_daqp),
            "quadprog": ("quadprog.solve_qp", direct_quadprog),
            "piqp": ("piqp.DenseSolver (fresh)", direct_piqp),
            "osqp": ("osqp.OSQP (fresh)", lambda s: DirectOsqp(s, persistent=False)),
            "proxqp": ("proxqp.dense.solve", direct_proxqp_function),
        }
        if solver == "clarabel":
            import clarabel

            return "clarabel.DefaultSolver (fresh)", lambda: DirectClarabel(
                lambda: _clarabel_settings(clarabel, settings), persistent=False
            )
        if solver in table:
            desc, make = table[solver]
            return desc, lambda: make(settings)
        return "qpsolvers.solve_problem", lambda: via_qpsolvers(solver, settings)
    return None, None


def _clarabel_settings(clarabel, options):
    s = clarabel.DefaultSettings()
    s.verbose = False
    for key, value in options.items():
        setattr(s, key, value)
    return s


def qpsolvers_for(name: str, profile: str):
    """qpsolvers.solve_problem with the backend's solver and settings, or None."""
    solver = {
        "osqp": "osqp",
        "proxqp": "proxqp",
        "clarabel": "clarabel",
        "piqp": "piqp",
        "daqp": "daqp",
        "daqp-stateless": "daqp",
        "qpoases": "qpoases",
    }.get(name)
    if name.startswith("qpsolvers:"):
        solver = name.split(":", 1)[1]
    if solver is None or solver not in qpsolvers.available_solvers:
        return None
    generic = get_backend(name, profile).profile
    settings = native_settings(
        solver, generic.eps_abs, generic.eps_rel, generic.max_iter, generic.time_limit
    )
    return lambda: via_qpsolvers(solver, settings)


# ----------------------------------------------------------------- timing


def time_pass(solve, problems) -> list[float]:
    times = []
    for p in problems:
        start = time.perf_counter_ns()
        solve(p)
        times.append((time.perf_counter_ns() - start) * 1e-3)
    return times


def parse_args(argv=None) -> argparse.Namespace:
    # Options declared one by one as in the other bench scripts (bench/accuracy_margin.py has
    # the same shape): each script's own options, no shared parser to factor out.
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--count", type=int, default=400, help="number of QPs (default 400)")
    parser.add_argument("--repeat", type=int, default=3, help="passes per method (default 3)")
    parser.add_argument("--source", choices=("sim", "known"), default="sim")
    parser.add_argument("--profile", default="default")
    parser.add_argument(
        "--backends", default=None, help="comma-separated backend names (default: all but rnn*)"
    )
    parser.add_argument(
        "--stat",
        choices=("median", "min"),
        default="median",
        help="median of all calls, or median over problems of each one's fastest pass",
    )
    return parser.parse_args(argv)


def load_problems(source: str, count: int) -> tuple[str, list[qpsolvers.Problem]]:
    """``(source used, problems)``: the wall scenario's ticks, or robot-like QPs."""
    if source == "sim":
        try:
            return source, sim_problems(count)
        except Exception as exc:  # the simulator is optional here
            print(
                f"# qpbench.sim unavailable ({type(exc).__name__}: {exc}); using known.robot_like_problem"
            )
    return "known", known_problems(count)


def measure(name: str, problems, profile: str, repeat: int, stat: str) -> tuple[dict, str | None]:
    """Median time per call of ``ours``, ``direct`` and ``qpsolvers`` (those that exist) for
    backend ``name``, passes interleaved between methods; and the direct API's description."""
    desc, direct_factory = direct_for(name, profile)
    methods = {
        "ours": lambda: get_backend(name, profile).solve,
        "direct": direct_factory,
        "qpsolvers": qpsolvers_for(name, profile),
    }
    times: dict[str, list[list[float]]] = {k: [] for k, f in methods.items() if f is not None}
    for _ in range(repeat):
        for key in times:
            solve = methods[key]()
            solve(problems[0])  # first call: imports, compilation, set-up of the first shape
            times[key].append(time_pass(solve, problems))
    if stat == "min":
        return {k: statistics.median(map(min, zip(*v))) for k, v in times.items()}, desc
    return {k: statistics.median([t for p in v for t in p]) for k, v in times.items()}, desc


def main(argv=None) -> int:
    args = parse_args(argv)
    warnings.simplefilter("ignore")
    source, problems = load_problems(args.source, args.count)
    sizes = sorted(
        {
            (p.q.shape[0], 0 if p.A is None else p.A.shape[0], 0 if p.G is None else p.G.shape[0])
            for p in problems
        }
    )
    stat = (
        "median wall time per solve"
        if args.stat == "median"
        else "median over QPs of the fastest pass"
    )
    print(
        f"# {len(problems)} QPs from {source}; (n, meq, m) in {sizes}; profile {args.profile}; "
        f"{args.repeat} passes; {stat} in microseconds"
    )
    names = (
        args.backends.split(",")
        if args.backends
        else [n for n in backend_names() if not n.startswith("rnn")]
    )
    header = (
        f"| {'backend':<20} | {'ours':>9} | {'direct':>9} | {'ours/direct':>11} | {'qpsolvers':>9} "
        f"| {'ours/qpsolvers':>14} | direct API"
    )
    print(header)
    print("|" + "|".join("-" * (len(c) + 0) for c in header.split("|")[1:]))

    def fmt(v):
        return f"{v:9.1f}" if v is not None else f"{'-':>9}"

    for name in names:
        med, desc = measure(name, problems, args.profile, args.repeat, args.stat)
        ours, direct, qps = med["ours"], med.get("direct"), med.get("qpsolvers")
        r1 = f"{ours / direct:11.2f}" if direct else f"{'-':>11}"
        r2 = f"{ours / qps:14.2f}" if qps else f"{'-':>14}"
        print(
            f"| {name:<20} | {fmt(ours)} | {fmt(direct)} | {r1} | {fmt(qps)} | {r2} | {desc or '-'}"
        )
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
