"""The ``qpoases`` backend's compiled route (``make_state``, ``compiled()``'s solve and reset,
``close_state``) against the backend class, call by call, on the controller's QPs."""

from __future__ import annotations

import gc
import subprocess
import sys
import textwrap

import numba
import numpy as np
import pytest
import qpsolvers

from qpbench.backends import get_backend
from qpbench.backends.qpoases_ import close_state, compiled, make_state
from qpbench.packed import pack
from qpbench.sim import log as tick_log
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario
from qpbench.statuses import TICK_STATUSES

pytestmark = pytest.mark.skipif(
    get_backend("qpoases").unavailable_reason() is not None, reason="qpoases unavailable"
)

RESET = "reset"


def _driver():
    """A compiled caller of the protocol (as an engine calls it): reset first when asked."""
    solve, reset = compiled()

    @numba.njit
    def step(st, buf, warm, sol, info, do_reset):
        if do_reset:
            reset(st)
        return solve(st, buf, warm, sol, info)

    return step


@pytest.fixture(scope="module")
def loop_qps():
    """A closed loop's ``paper`` QPs on ``wall`` (obstacle rows; the infeasible start, then
    optimal ticks) and on ``free`` (no row), and the ``soft`` QP of each tick (its fallback's:
    same joint angles, from the tick log)."""
    out = {}
    for name in ("wall", "free"):
        sc = load_scenario(name)
        assert sc.make_adaptive() is None  # the gains are the controller's
        ctrl = sc.make_controller()
        result = simulate(sc, "qpoases", duration=0.25, every=1)
        thetas = result.log[tick_log.theta_columns(ctrl.n)].to_numpy()
        paper = [r.problem for r in result.records]
        soft = [
            ctrl.build(np.ascontiguousarray(theta), r.t, formulation="soft").problem
            for theta, r in zip(thetas, result.records)
        ]
        assert np.array_equal(
            ctrl.build(thetas[9], result.records[9].t).problem.buffer, paper[9].buffer
        )
        out[name] = paper, soft
    return out


def _sequence(paper, soft):
    """The loop's order: the soft QP after each failed paper one and every 7th tick; the first
    (infeasible) QP again in the optimal part (a failed hotstart); a reset after it, and one
    between two paper QPs."""
    seq = []
    for k, problem in enumerate(paper):
        seq.append(problem)
        if k < 140 or k % 7 == 3:
            seq.append(soft[k])
        if k == 200:
            seq += [paper[0], RESET, soft[k], paper[0]]
        if k == 230:  # between two optimal paper QPs
            seq.append(RESET)
    return seq


@pytest.mark.parametrize("settings", [{}, {"max_iter": 4}, {"preset": "mpc"}])
@pytest.mark.parametrize("scenario", ["wall", "free"])
def test_compiled_solve_is_the_backend(loop_qps, scenario, settings):
    """Same x (to 1e-12), duals, status, nWSR and return value as the backend, call by call."""
    paper, soft = loop_qps[scenario]
    n, me, mi = paper[0].shape
    backend = get_backend("qpoases", **settings)
    step = _driver()
    st = make_state(n, me, mi, **settings)
    sol, info, warm = np.full(n + me + mi, -7.0), np.zeros(4), np.zeros(n)
    seen = set()
    do_reset = False
    try:
        for k, problem in enumerate(_sequence(paper, soft)):
            if problem is RESET:
                backend.reset()
                do_reset = True
                continue
            ref = backend.solve(problem)
            status = TICK_STATUSES[step(st, problem.buffer, warm, sol, info, do_reset)]
            do_reset = False
            seen.add((problem.shape[1], status))
            assert status == ref.status, k
            assert (info[1], info[2]) == (ref.iterations, ref.extras["raw_status"]), k
            assert info[0] > 0 and info[3] >= 0
            m = problem.shape[1] + problem.shape[2]
            if ref.status == "optimal":
                np.testing.assert_allclose(sol[:n], ref.x, rtol=0, atol=1e-12, err_msg=str(k))
                duals = np.concatenate([ref.y, ref.z])
                np.testing.assert_allclose(sol[n : n + m], duals, rtol=0, atol=1e-12)
            else:
                assert ref.x is None and np.isnan(sol[: n + m]).all(), k
    finally:
        close_state(st)
    # both formulations met, the paper one infeasible, solved or stopped (nWSR of 4)
    stopped = "max_iter" if settings.get("max_iter") == 4 else "optimal"
    assert {(me, "primal_infeasible"), (0, "optimal"), (me, stopped), (0, stopped)} <= seen


def test_close_when_a_run_raises_half_way(loop_qps):
    """An exception in the compiled solve (a shape the state was not made for) and one between
    calls: the state is closed by the caller's ``finally``, twice without harm; a solve on a
    closed state raises instead of touching a freed solver."""
    paper, soft = loop_qps["wall"]
    n, me, mi = paper[0].shape
    step = _driver()
    st = make_state(n, me, mi)
    sol, info, warm = np.zeros(n + me + mi), np.zeros(4), np.zeros(n)
    p = paper[160]
    other = pack(qpsolvers.Problem(p.P, p.q, None, None, p.A, p.b, p.lb, p.ub))  # no rows
    with pytest.raises(ValueError, match="shape make_state was not given"):
        step(st, other.buffer, warm, sol, info, False)
    try:
        with pytest.raises(RuntimeError, match="half way"):
            for k in range(150, 200):
                assert TICK_STATUSES[step(st, paper[k].buffer, warm, sol, info, False)] == "optimal"
                if k == 170:
                    raise RuntimeError("half way")
    finally:
        close_state(st)
    assert (st.table[:, 4] == 0).all()  # the handles, freed
    close_state(st)
    with pytest.raises(ValueError, match="closed state"):
        step(st, paper[171].buffer, warm, sol, info, False)


def test_a_state_dropped_unclosed_frees_its_solvers():
    """The solvers go with the state's buffers (a caller that forgot close_state leaks none),
    marked freed in its table."""
    st = make_state(4, 2, 7)
    table = st.table
    assert (table[:, 4] != 0).all()
    del st
    gc.collect()
    assert (table[:, 4] == 0).all()


_CACHE_SCRIPT = textwrap.dedent(
    """
    import numpy as np, qpsolvers
    from qpbench.backends.qpoases_ import close_state, compiled, make_state
    from qpbench.packed import pack

    solve, reset = compiled()
    P = np.array([[2.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 1.0]])
    problem = pack(qpsolvers.Problem(P, np.array([1.0, -1.0, 0.5]), np.ones((1, 3)),
        np.array([0.5]), np.array([[1.0, -1.0, 0.0]]), np.array([0.2]), -np.ones(3), np.ones(3)))
    st = make_state(3, 1, 1)
    sol, info = np.zeros(5), np.zeros(4)
    status = solve(st, problem.buffer, np.zeros(3), sol, info)
    reset(st)
    close_state(st)
    print(status, sum(solve.stats.cache_hits.values()), sum(solve.stats.cache_misses.values()),
          sum(reset.stats.cache_hits.values()), sum(reset.stats.cache_misses.values()))
    """
)


def test_second_process_loads_the_compiled_solve_from_the_cache():
    """The solve calls the shim by symbol name, so numba caches it: in the session's kernel
    cache (the first process compiles what is not there yet; a cold cache is
    tests/test_warmup.py's), the second process compiles nothing."""
    runs = []
    for _ in range(2):
        done = subprocess.run([sys.executable, "-c", _CACHE_SCRIPT], capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        runs.append(done.stdout.split())
    assert runs[0][0] == "0"  # optimal
    assert runs[1] == ["0", "1", "0", "1", "0"]  # optimal; loaded


def test_backend_prints_nothing_after_a_change_of_shape():
    """qpOASES' destructor makes its messages visible again; the shim hides them: the ``paper``
    QP failing after a ``soft`` one (a new solver, the old one freed) prints nothing."""
    script = textwrap.dedent(
        """
        from qpbench.backends import get_backend
        from qpbench.sim.scenario import load_scenario

        sc = load_scenario("wall")
        ctrl = sc.make_controller()
        theta = sc.theta0.astype(float)
        paper, soft = (ctrl.build(theta, 0.0, formulation=f).problem for f in ("paper", "soft"))
        backend = get_backend("qpoases")
        print([backend.solve(p).status for p in (paper, soft, paper, paper)])
        """
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    expected = ["primal_infeasible", "optimal", "primal_infeasible", "primal_infeasible"]
    assert done.stdout == f"{expected}\n"
    assert "ERROR" not in done.stderr
