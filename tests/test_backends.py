"""Tests of every registered backend (except the RNN ones, tested in tests/test_rnn*.py).

One test per backend and property, generated from :func:`qpbench.backends.backend_info`
and skipped with the reason when the backend is unavailable here.
"""

from __future__ import annotations

import builtins
from pathlib import Path

import numpy as np
import pytest
import qpsolvers
from conftest import sparse_copy
from known import random_kkt_problem, robot_like_problem

from qpbench.backends import (
    BackendSolution,
    backend_class,
    backend_info,
    backend_names,
    get_backend,
)
from qpbench.backends.base import objective
from qpbench.exceptions import BackendNotFound

#: Tested elsewhere: the networks in test_rnn.py, the noise floor (x = 0) in test_closed_loop.py.
EXCLUDED = {"rnn", "rnn-tuned", "rnn-converged", "noop"}
#: The package's backends (not those other tests register to inject faults).
INFOS = [
    info
    for info in backend_info()
    if info.name not in EXCLUDED
    and backend_class(info.name).__module__.startswith("qpbench.backends.")
]
QP_INFOS = [info for info in INFOS if info.name != "pinv"]
MM_FOLDER = Path(__file__).resolve().parents[1] / "problems" / "maros_meszaros"

#: QP backends that cannot reach the high_accuracy profile, and why (the high-accuracy tests skip them).
LOW_ACCURACY = {
    "qpsolvers:ecos": "qpsolvers hands the QP to ECOS as an SOCP (epigraph of the cost): the dual residual "
    "stalls near 1e-5 whatever its tolerances, and infinite entries of h or the bounds are refused",
    "qpsolvers:gurobi": "Gurobi refuses FeasibilityTol/OptimalityTol below 1e-9 (qpbenchmark's high_accuracy "
    "asks 1e-10): status error",
}

#: (backend, Maros-Meszaros problem) pairs that cannot match the reference, and why.
MM_SKIP = {
    ("qpsolvers:quadprog", "LOTSCHD"): "quadprog needs a positive definite P (LOTSCHD is an LP)",
    (
        "qpsolvers:quadprog",
        "QAFIRO",
    ): "quadprog needs a positive definite P (QAFIRO's P is singular)",
    (
        "qpsolvers:quadprog",
        "ZECEVIC2",
    ): "quadprog needs a positive definite P (ZECEVIC2's P is singular)",
    (
        "qpsolvers:quadprog",
        "HS52",
    ): "quadprog factorises a singular P (eigenvalue 2e-16): objective off by 2e-8 rel.",
    (
        "qpsolvers:quadprog",
        "HS53",
    ): "quadprog factorises a singular P (eigenvalue 8e-17): objective off by 2e-8 rel.",
    (
        "proxqp",
        "HS118",
    ): "ProxQP 0.8 reports PRIMAL_INFEASIBLE after 14 iterations with its default "
    "eps_primal_inf=1e-4 (optimal with eps_primal_inf=1e-12)",
    (
        "qpsolvers:proxqp",
        "HS118",
    ): "ProxQP 0.8 reports PRIMAL_INFEASIBLE after 14 iterations with its default "
    "eps_primal_inf=1e-4 (optimal with eps_primal_inf=1e-12)",
    (
        "cvxpy",
        "HS52",
    ): "OSQP under cvxpy (singular P written as ||L'x||^2) reaches max_iter=1e6 at eps 1e-9",
    (
        "qpsolvers:cvxopt",
        "GENHS28",
    ): "qpsolvers 4.13's cvxopt route drops A x = b when there is no inequality "
    "and no bound: 'optimal' with a primal residual of 2.7",
    (
        "qpsolvers:cvxopt",
        "HS52",
    ): "qpsolvers 4.13's cvxopt route drops A x = b when there is no inequality "
    "and no bound: 'optimal' with a primal residual of 0.71",
    ("qpsolvers:cvxopt", "QAFIRO"): "cvxopt's qp() stops with status 'unknown' on this LP at 1e-10",
}


def _param(infos, high_accuracy=False):
    params = []
    for info in infos:
        marks = [
            pytest.mark.skipif(not info.available, reason=f"{info.name} unavailable: {info.reason}")
        ]
        if high_accuracy and info.name in LOW_ACCURACY:
            marks.append(pytest.mark.skip(reason=f"{info.name}: {LOW_ACCURACY[info.name]}"))
        params.append(pytest.param(info.name, id=info.name, marks=marks))
    return params


def _random_cases(seed: int, count: int):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        n = int(rng.integers(4, 21))
        n_eq = int(rng.integers(0, 3))
        n_ineq = int(rng.integers(1, 2 * n))
        n_active = int(rng.integers(0, min(n_ineq, n - n_eq - 2) + 1))
        cond = float(10 ** rng.uniform(0, 3))
        yield random_kkt_problem(rng, n, n_eq, n_ineq, n_active, True, cond=cond)


def _check_solution(sol: BackendSolution, x, y, z, z_box, xtol=1e-6, gap=True):
    assert sol.status == "optimal", (sol.status, sol.error, sol.extras.get("raw_status"))
    assert sol.found
    np.testing.assert_allclose(sol.x, x, atol=xtol, rtol=0)
    # Duals: KKT residuals through qpsolvers' own Solution methods, and the unique multipliers.
    assert sol.primal_residual() < 1e-6
    assert sol.dual_residual() < 1e-6
    if gap:  # qpsolvers' duality_gap is NaN when h holds inf (inf * 0)
        assert abs(sol.duality_gap()) < 1e-5
    np.testing.assert_allclose(sol.y, y, atol=1e-5)
    np.testing.assert_allclose(sol.z, z, atol=1e-5)
    np.testing.assert_allclose(sol.z_box, z_box, atol=1e-5)


# ----------------------------------------------------------------- known solutions


@pytest.mark.parametrize("name", _param(QP_INFOS, high_accuracy=True))
def test_known_solutions_high_accuracy(name):
    backend = get_backend(name, "high_accuracy")
    for problem, x, y, z, z_box in _random_cases(seed=101, count=10):
        backend.reset()
        sol = backend.solve(problem)
        _check_solution(sol, x, y, z, z_box)
        assert sol.backend == name
        assert sol.obj == pytest.approx(objective(problem, x), abs=1e-6)


@pytest.mark.parametrize("name", _param(QP_INFOS, high_accuracy=True))
def test_warm_start_argument(name):
    """A primal warm start (exact or not) changes nothing in the answer."""
    backend = get_backend(name, "high_accuracy")
    problem, x, y, z, z_box = robot_like_problem(np.random.default_rng(5))
    _check_solution(backend.solve(problem, warm_start=x), x, y, z, z_box)
    _check_solution(backend.solve(problem, warm_start=np.zeros_like(x)), x, y, z, z_box)


@pytest.mark.parametrize("name", _param(QP_INFOS, high_accuracy=True))
def test_sequence_then_new_shape_then_reset(name):
    """Same pattern tick after tick (with entries that become zero), then a new shape, then back."""
    backend = get_backend(name, "high_accuracy")
    rng = np.random.default_rng(17)
    sequence = []
    for k in range(4):
        problem, x, y, z, z_box = robot_like_problem(rng, n_ineq=9)
        if k == 2:
            # A structurally-zero Jacobian entry in this tick only: rebuild the problem
            # around the same KKT point with A[0, 1] = 0 (b and q follow).
            A = problem.A.copy()
            A[0, 1] = 0.0
            q = -(problem.P @ x + A.T @ y + problem.G.T @ z + z_box)
            problem = qpsolvers.Problem(
                problem.P, q, problem.G, problem.h, A, A @ x, problem.lb, problem.ub
            )
        sequence.append((problem, x, y, z, z_box))
    other = random_kkt_problem(rng, 7, 1, 5, 2)
    persistent = None
    for i, (problem, *known) in enumerate(sequence):
        sol = backend.solve(problem)
        _check_solution(sol, *known)
        state = _persistent_object(backend)
        if i == 0 or sol.extras.get(
            "cold_retry"
        ):  # proxqp re-solves a warm "infeasible" on a new object
            persistent = state
        elif persistent is not None:
            assert state is persistent, (
                "the solver object was rebuilt for a problem of the same pattern"
            )
    _check_solution(backend.solve(other[0]), *other[1:])
    if persistent is not None:
        assert _persistent_object(backend) is not persistent
    _check_solution(backend.solve(sequence[0][0]), *sequence[0][1:])
    backend.reset()
    if persistent is not None:
        assert _persistent_object(backend) is None
    _check_solution(backend.solve(sequence[1][0]), *sequence[1][1:])


def _persistent_object(backend):
    """The persistent solver object of the backends that keep one (else None)."""
    for attr in ("_solver", "_qp", "_model", "_ws"):
        if hasattr(backend, attr):
            return getattr(backend, attr)
    return None


def test_persistent_backends_keep_their_object():
    """The persistent backends do keep a solver object (so the identity checks above bite)."""
    problem = robot_like_problem(np.random.default_rng(0))[0]
    for name in ("osqp", "proxqp", "clarabel", "daqp", "qpoases", "piqp"):
        if name not in backend_names():
            continue
        backend = get_backend(name)
        backend.solve(problem)
        assert _persistent_object(backend) is not None, name


def test_proxqp_cached_result_views_follow_warm_starts():
    """proxqp reads x, y, z through cached views of ``qp.results``: they must stay
    those of the live object across updates, explicit warm starts (which make
    ProxQP reallocate ``results.x``) and rebuilds, and the returned arrays are copies."""
    if "proxqp" not in backend_names():
        pytest.skip("proxsuite unavailable")
    backend = get_backend("proxqp", "high_accuracy")
    rng = np.random.default_rng(11)
    kept = []
    previous = None
    for i in range(12):
        problem, x, y, z, z_box = robot_like_problem(rng)
        warm = previous if i % 3 == 1 else None
        sol = backend.solve(problem, warm)
        _check_solution(sol, x, y, z, z_box)
        res = backend._qp.results
        n_in = problem.G.shape[0]
        assert np.array_equal(sol.x, res.x) and np.array_equal(sol.y, res.y)
        assert np.array_equal(
            np.concatenate([sol.z, sol.z_box]), res.z[: n_in + problem.q.shape[0]]
        )
        assert not np.shares_memory(sol.x, res.x) and not np.shares_memory(sol.z, res.z)
        kept.append((sol, sol.x.copy(), sol.z_box.copy()))
        previous = sol.x
        if i == 7:
            backend.reset()
    for sol, x, z_box in kept:  # later solves did not write into earlier solutions
        assert np.array_equal(sol.x, x) and np.array_equal(sol.z_box, z_box)


def test_cvxpy_model_cached_per_shape():
    if "cvxpy" not in backend_names():
        pytest.skip("cvxpy unavailable")
    backend = get_backend("cvxpy", "high_accuracy")
    rng = np.random.default_rng(4)
    a = robot_like_problem(rng, n_ineq=8)
    b = robot_like_problem(rng, n_ineq=8)
    _check_solution(backend.solve(a[0]), *a[1:])
    model = next(iter(backend._models.values()))
    _check_solution(backend.solve(b[0]), *b[1:])
    assert len(backend._models) == 1 and next(iter(backend._models.values())) is model
    backend.reset()
    assert backend._models == {}


def test_infinite_bounds_and_rows():
    """+-inf in lb, ub and h are handled (clarabel and cvxpy leave those rows out)."""
    problem, x, y, z, z_box = random_kkt_problem(np.random.default_rng(8), 6, 1, 4, 1)
    inactive_b = np.flatnonzero(z_box == 0)[:2]
    inactive_g = np.flatnonzero(z == 0)[:1]
    lb, ub, h = problem.lb.copy(), problem.ub.copy(), problem.h.copy()
    lb[inactive_b[0]] = -np.inf
    ub[inactive_b[1]] = np.inf
    h[inactive_g] = np.inf
    problem = qpsolvers.Problem(problem.P, problem.q, problem.G, h, problem.A, problem.b, lb, ub)
    for name in (
        "osqp",
        "proxqp",
        "clarabel",
        "cvxpy",
        "daqp",
        "daqp-stateless",
        "qpoases",
        "piqp",
        "qpsolvers:daqp",
    ):
        if name in backend_names():
            _check_solution(
                get_backend(name, "high_accuracy").solve(problem), x, y, z, z_box, gap=False
            )


# ----------------------------------------------------------------- pinv


def test_pinv_is_jmpi():
    """x = A^+ b whatever G, h, lb, ub; without equalities the unconstrained minimiser."""
    rng = np.random.default_rng(2)
    problem, *_ = random_kkt_problem(rng, 6, 2, 5, 2)
    sol = get_backend("pinv").solve(problem)
    assert sol.status == "optimal"
    np.testing.assert_allclose(sol.x, np.linalg.pinv(problem.A) @ problem.b, atol=1e-12)
    assert np.all(sol.z == 0) and np.all(sol.z_box == 0)
    # The paper's QP (P = I, q = 0) with no active inequality: pinv is its exact solution.
    A = rng.standard_normal((2, 4))
    b = rng.standard_normal(2)
    paper = qpsolvers.Problem(
        np.eye(4),
        np.zeros(4),
        np.ones((1, 4)),
        np.array([100.0]),
        A,
        b,
        -100 * np.ones(4),
        100 * np.ones(4),
    )
    sol = get_backend("pinv").solve(paper)
    assert sol.primal_residual() < 1e-12 and sol.dual_residual() < 1e-12
    # Without equalities: -P^-1 q, bounds ignored (the metrics show the violation).
    problem, *_ = random_kkt_problem(rng, 5, 0, 3, 1)
    sol = get_backend("pinv").solve(problem)
    np.testing.assert_allclose(sol.x, np.linalg.solve(problem.P, -problem.q), atol=1e-10)
    assert sol.dual_residual() < 1e-10


# ----------------------------------------------------------------- infeasible / unbounded


def _infeasible_problem():
    """x0 + x1 = 3 with 0 <= x <= 1: primal infeasible."""
    return qpsolvers.Problem(
        np.eye(3),
        np.array([1.0, -1.0, 0.5]),
        np.array([[1.0, 0.0, 1.0]]),
        np.array([1.0]),
        np.array([[1.0, 1.0, 0.0]]),
        np.array([3.0]),
        np.zeros(3),
        np.ones(3),
    )


def _unbounded_problem():
    """P = diag(1, 1, 0), q = -e2, and no row limits x2: dual infeasible (unbounded below)."""
    return qpsolvers.Problem(
        np.diag([1.0, 1.0, 0.0]),
        np.array([0.3, -0.2, -1.0]),
        np.array([[1.0, 1.0, 0.0]]),
        np.array([1.0]),
        np.array([[1.0, -1.0, 0.0]]),
        np.array([0.1]),
    )


@pytest.mark.parametrize("name", _param(QP_INFOS))
def test_infeasible_and_unbounded(name):
    backend = get_backend(name, "default")
    infeasible = backend.solve(_infeasible_problem())
    backend.reset()
    unbounded = backend.solve(_unbounded_problem())
    cls = type(backend)
    assert cls.certifies_infeasibility is not None, (
        f"{name}: say whether it can classify infeasibility"
    )
    if cls.certifies_infeasibility:
        assert infeasible.status == "primal_infeasible", (infeasible.status, infeasible.error)
        assert unbounded.status == "dual_infeasible", (unbounded.status, unbounded.error)
    else:
        assert cls.infeasibility_note, f"{name}: say why it cannot classify infeasibility"
        # It cannot tell both; it never says the wrong one, and what it returns must not pass as a solution.
        assert infeasible.status != "dual_infeasible" and unbounded.status != "primal_infeasible"
        assert not (
            infeasible.status == "primal_infeasible" and unbounded.status == "dual_infeasible"
        ), name
        for sol in (infeasible, unbounded):
            if (
                sol.status == "optimal"
            ):  # HiGHS on the unbounded problem, see its infeasibility_note
                assert max(sol.primal_residual(), sol.dual_residual()) > 0.5
    for sol in (infeasible, unbounded):
        if sol.status == "error":
            assert sol.error


# ----------------------------------------------------------------- settings and errors


@pytest.mark.parametrize(
    "name",
    [
        "osqp",
        "proxqp",
        "clarabel",
        "daqp",
        "daqp-stateless",
        "qpoases",
        "piqp",
        "qpsolvers:osqp",
        "qpsolvers:piqp",
        "cvxpy",
    ],
)
def test_max_iter_setting_overrides_profile(name):
    if name not in backend_names():
        pytest.skip(f"{name} unavailable")
    problem = random_kkt_problem(np.random.default_rng(9), 15, 2, 20, 6)[0]
    sol = get_backend(name, "high_accuracy", max_iter=1).solve(problem)
    assert sol.status == "max_iter", (sol.status, sol.extras.get("raw_status"))
    assert not sol.found


def test_solver_error_becomes_status():
    """quadprog refuses a singular P: status error with the message, no exception."""
    if "qpsolvers:quadprog" not in backend_names():
        pytest.skip("quadprog unavailable")
    problem = qpsolvers.Problem(
        np.diag([1.0, 0.0]), np.array([1.0, 1.0]), None, None, None, None, -np.ones(2), np.ones(2)
    )
    sol = get_backend("qpsolvers:quadprog").solve(problem)
    assert sol.status == "error" and "positive definite" in sol.error
    assert not sol.found


def test_unknown_backend_lists_available_names():
    with pytest.raises(BackendNotFound) as info:
        get_backend("no-such-solver")
    message = str(info.value)
    assert "no-such-solver" in message
    for name in ("pinv", "osqp", "qpsolvers:daqp"):
        if name in backend_names():
            assert name in message


def test_missing_package_is_unavailable(monkeypatch):
    real_import = builtins.__import__

    def fake_import(name, *args, **kwargs):
        if name.split(".")[0] in ("osqp", "cvxpy"):
            raise ImportError(f"No module named '{name}'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    infos = {info.name: info for info in backend_info()}
    for name in ("osqp", "cvxpy"):
        assert not infos[name].available
        assert name in infos[name].reason
        assert name not in backend_names()
        with pytest.raises(BackendNotFound) as info:
            get_backend(name)
        assert "unavailable" in str(info.value) and "pinv" in str(info.value)
    assert infos["pinv"].available


def test_qpsolvers_availability_follows_qpsolvers(monkeypatch):
    monkeypatch.setattr(
        qpsolvers, "available_solvers", [s for s in qpsolvers.available_solvers if s != "daqp"]
    )
    info = {i.name: i for i in backend_info()}["qpsolvers:daqp"]
    assert not info.available and "daqp" in info.reason
    with pytest.raises(BackendNotFound):
        get_backend("qpsolvers:daqp")


def test_one_qpsolvers_backend_per_available_solver():
    names = {i.name for i in backend_info()}  # every registered backend
    for solver in qpsolvers.available_solvers:
        assert f"qpsolvers:{solver}" in names
    for name in ("osqp", "proxqp", "clarabel", "pinv", "cvxpy"):
        assert name in names


# ----------------------------------------------------------------- Maros-Meszaros subset


@pytest.fixture(scope="module")
def maros_meszaros():
    formats = pytest.importorskip("qpbench.formats")
    reference = pytest.importorskip("qpbench.reference")
    if not MM_FOLDER.is_dir():
        pytest.skip(f"{MM_FOLDER} not present")
    records = list(formats.load_problems(MM_FOLDER))
    return [(record, reference.reference_solution(record)) for record in records]


@pytest.mark.parametrize("name", _param(QP_INFOS, high_accuracy=True))
def test_maros_meszaros_objective(name, maros_meszaros):
    backend = get_backend(name, "high_accuracy")
    checked = 0
    for record, ref in maros_meszaros:
        if (name, record.name) in MM_SKIP or ref.status != "optimal":
            continue
        backend.reset()
        sol = backend.solve(record.problem)
        assert sol.status == "optimal", (
            record.name,
            sol.status,
            sol.error,
            sol.extras.get("raw_status"),
        )
        f = objective(record.problem, sol.x) + record.offset
        assert abs(f - ref.objective) <= 1e-8 * max(1.0, abs(ref.objective)), (
            record.name,
            f,
            ref.objective,
        )
        checked += 1
    assert checked >= len(maros_meszaros) - 5


@pytest.mark.parametrize("name", _param(QP_INFOS, high_accuracy=True))
def test_sparse_input(name):
    """CSC matrices give the same answer, and a sequence of them reuses the solver object."""
    backend = get_backend(name, "high_accuracy")
    rng = np.random.default_rng(23)
    for _ in range(2):
        problem, x, y, z, z_box = random_kkt_problem(rng, 8, 2, 6, 2)
        sparse = sparse_copy(problem)
        _check_solution(backend.solve(sparse), x, y, z, z_box)


@pytest.fixture(scope="module")
def robot_ticks():
    """Consecutive QPs of the wall scenario across its infeasible start (ticks 100-259)."""
    loop = pytest.importorskip("qpbench.sim.loop")
    result = loop.simulate("wall", "qpsolvers:daqp", formulation="paper", duration=0.26, every=1)
    problems = [r.problem for r in result.records[100:260]]
    reference = get_backend("qpsolvers:clarabel", "high_accuracy")
    return problems, [reference.solve(p) for p in problems]


#: Backends that keep a solver object or working set from tick to tick.
PERSISTENT = ("osqp", "proxqp", "clarabel", "cvxpy", "daqp", "qpoases", "piqp")


@pytest.mark.parametrize("name", _param([i for i in QP_INFOS if i.name in PERSISTENT]))
def test_persistent_on_robot_ticks(name, robot_ticks):
    """Tick after tick, updated and warm-started: same statuses and solutions as a cold reference."""
    problems, refs = robot_ticks
    statuses = {r.status for r in refs}
    assert statuses == {"optimal", "primal_infeasible"}  # the sequence crosses the infeasible start
    backend = get_backend(name, "default")
    for k, (problem, ref) in enumerate(zip(problems, refs)):
        sol = backend.solve(problem)
        assert sol.status == ref.status, (k, sol.status, ref.status)
        if ref.status == "optimal":
            np.testing.assert_allclose(sol.x, ref.x, atol=1e-5)


def test_clarabel_reports_no_solver_time_after_an_update():
    """Clarabel's solve_time after update() exceeds the call's wall time; it is left out."""
    from known import robot_like_problem

    backend = get_backend("clarabel")
    rng = np.random.default_rng(3)
    problems = [robot_like_problem(rng, n_ineq=7)[0] for _ in range(30)]
    first = backend.solve(problems[0])
    assert first.solver_time_s is not None and first.solver_time_s > 0
    later = [backend.solve(p) for p in problems[1:]]
    assert backend._layout is not None  # the persistent solver was updated, not rebuilt
    assert all(s.status == "optimal" and s.solver_time_s is None for s in later)


@pytest.mark.parametrize("name", ["qpsolvers:daqp", "qpsolvers:quadprog", "qpsolvers:osqp"])
def test_qpsolvers_routes_do_not_warn(name):
    """An ignored warm start and a failed solve are statuses, not warnings (without a catch_warnings per call)."""
    import warnings

    if name not in backend_names():
        pytest.skip(f"{name} unavailable")
    problem, x, *_ = robot_like_problem(np.random.default_rng(12))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        backend = get_backend(name, "high_accuracy")
        sol = backend.solve(problem, warm_start=x)
        failed = backend.solve(_infeasible_problem())
    assert sol.status == "optimal" and failed.status != "optimal"
    assert [str(w.message) for w in caught] == []


def test_qpsolvers_status_readers_of_the_added_solvers():
    """The status tables of ecos, cvxopt, qpalm and gurobi (read only when qpsolvers says found=False)."""
    from types import SimpleNamespace

    from qpbench.backends import qpsolvers_ as qs

    assert qs.STATUS_READERS["ecos"]({"exitFlag": 1})[0] == "primal_infeasible"
    assert qs.STATUS_READERS["ecos"]({"exitFlag": 2})[0] == "dual_infeasible"
    assert qs.STATUS_READERS["ecos"]({"exitFlag": -1})[0] == "max_iter"
    assert qs.STATUS_READERS["ecos"]({"exitFlag": 10})[0] == "not_solved"
    assert qs.STATUS_READERS["cvxopt"]({"status": "unknown"}) == ("not_solved", "unknown")
    assert (
        qs.STATUS_READERS["qpalm"]({"info": SimpleNamespace(status="primal infeasible")})[0]
        == "primal_infeasible"
    )
    assert (
        qs.STATUS_READERS["qpalm"]({"info": SimpleNamespace(status="maximum iterations reached")})[
            0
        ]
        == "max_iter"
    )
    assert qs.STATUS_READERS["gurobi"]({"status": 3})[0] == "primal_infeasible"
    assert qs.STATUS_READERS["gurobi"]({"status": 4}) == ("not_solved", "4")
    assert qs.STATUS_READERS["gurobi"]({"status": 9})[0] == "time_limit"
    if "qpsolvers:gurobi" in backend_names():  # Gurobi refuses 1e-10: a status, not an exception
        sol = get_backend("qpsolvers:gurobi", "high_accuracy", eps_abs=1e-10).solve(
            robot_like_problem(np.random.default_rng(1))[0]
        )
        assert sol.status == "error" and "FeasibilityTol" in sol.error


def test_all_solvers_extra_is_listed_when_missing(monkeypatch):
    """qpalm, ecos, cvxopt and gurobi are listed by `qpbench backends` even when not installed, saying how."""
    monkeypatch.setattr(
        qpsolvers,
        "available_solvers",
        [s for s in qpsolvers.available_solvers if s not in ("qpalm", "ecos", "cvxopt", "gurobi")],
    )
    infos = {i.name: i for i in backend_info()}
    for solver in ("qpalm", "ecos", "cvxopt", "gurobi"):
        info = infos[f"qpsolvers:{solver}"]
        assert not info.available and "qpbench[all-solvers]" in info.reason


@pytest.mark.parametrize("solver", ["daqp", "ecos", "quadprog"])
def test_dense_only_qpsolvers_routes_take_sparse_problems(solver):
    """The dense-only routes take a sparse problem (densified for quadprog, whose qpsolvers
    wrapper raises "problem has sparse matrices"): the same x as the dense problem."""
    name = f"qpsolvers:{solver}"
    if backend_class(name).unavailable_reason():
        pytest.skip(backend_class(name).unavailable_reason())
    problem, x, *_ = random_kkt_problem(np.random.default_rng(8), 6, 2, 5, 2)
    backend = get_backend(name)
    dense, sparse = backend.solve(problem), backend.solve(sparse_copy(problem))
    assert dense.status == sparse.status == "optimal", (dense.error, sparse.error)
    np.testing.assert_allclose(sparse.x, dense.x, atol=1e-12)
    np.testing.assert_allclose(dense.x, x, atol=1e-6)


def test_qpsolvers_routes_call_what_solve_problem_calls(monkeypatch):
    """The routes call qpsolvers' function for the solver as solve_problem does: the same x and
    duals as solve_problem with the same options, its constraint check (an incomplete
    inequality is an error naming it), and solve_problem itself when no table is found."""
    import qpbench.backends.qpsolvers_ as route

    problem = robot_like_problem(np.random.default_rng(11))[0]
    for solver in ("daqp", "quadprog", "osqp"):
        backend = get_backend(f"qpsolvers:{solver}")
        ours = backend.solve(problem)
        ref = qpsolvers.solve_problem(problem, solver, **backend.solver_options)
        for field in ("x", "y", "z", "z_box"):
            np.testing.assert_array_equal(getattr(ours, field), getattr(ref, field))
    P, q, G, h, A, b, lb, ub = problem.unpack()
    broken = qpsolvers.Problem(P, q, G, None, A, b, lb, ub)
    sol = get_backend("qpsolvers:daqp").solve(broken)
    assert sol.status == "error" and "incomplete inequality" in sol.error
    assert (
        route.solver_function("daqp")
        is qpsolvers.solve_problem.__globals__["solve_function"]["daqp"]
    )

    def solve_problem(*args, **kwargs):  # a function whose module has no dispatch table
        return qpsolvers.solve_problem(*args, **kwargs)

    monkeypatch.setattr(route, "_solve_problem", solve_problem)
    fallback = route.solver_function("daqp")
    assert fallback.__name__ == "through_solve_problem"
    np.testing.assert_array_equal(fallback(problem).x, qpsolvers.solve_problem(problem, "daqp").x)


def test_float64_wrappers_hand_back_float64_arrays():
    """The qpsolvers routes take the results of FLOAT64_WRAPPERS' solvers as given: each of them
    that is installed returns float64 arrays (or None) through qpsolvers.solve_problem itself,
    with and without inequality rows and bounds, and on an infeasible problem; a solver
    outside the set (clarabel's duals are lists) is why the set exists."""
    import warnings

    from qpbench.backends.qpsolvers_ import FLOAT64_WRAPPERS

    full = robot_like_problem(np.random.default_rng(5))[0]
    P, q, G, h, A, b, lb, ub = full.unpack()
    problems = {
        "robot tick": full,
        "no inequalities": qpsolvers.Problem(P, q, None, None, A, b, lb, ub),
        "no bounds": qpsolvers.Problem(P, q, G, h, A, b),
        "infeasible": _infeasible_problem(),
        "unbounded": _unbounded_problem(),
    }
    installed = sorted(FLOAT64_WRAPPERS & set(qpsolvers.available_solvers))
    assert {"daqp", "quadprog", "osqp", "proxqp", "piqp"} <= set(installed)
    for solver in installed:
        for label, problem in problems.items():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    result = qpsolvers.solve_problem(problem, solver)
                except (qpsolvers.QPError, ValueError):
                    continue  # an error, not a result (quadprog on the infeasible problem)
            for field in ("x", "y", "z", "z_box"):
                value = getattr(result, field)
                assert value is None or (type(value) is np.ndarray and value.dtype == np.float64), (
                    solver,
                    label,
                    field,
                    type(value),
                )
    assert "clarabel" not in FLOAT64_WRAPPERS


def test_qpsolvers_routes_report_the_iterations_qpsolvers_keeps():
    """Each qpsolvers route with an iteration reader reports the count from its solver's extras
    (a positive int), the others None; a missing or malformed entry is None, never an error."""
    from types import SimpleNamespace

    from qpbench.backends import qpsolvers_ as qs

    assert qs.iterations("quadprog", {"iterations": np.array([5, 1])}) == 5
    assert qs.iterations("quadprog", {"iterations": np.array([[7, 0]])}) == 7
    assert qs.iterations("osqp", {"info": SimpleNamespace(iter=12)}) == 12
    assert qs.iterations("scs", {"iter": 40}) == 40
    assert qs.iterations("cvxopt", {"iterations": 9}) == 9
    assert qs.iterations("quadprog", {}) is None
    assert qs.iterations("osqp", {"info": None}) is None
    assert qs.iterations("daqp", {"iterations": 3}) is None  # qpsolvers keeps none for DAQP
    problem = robot_like_problem(np.random.default_rng(3))[0]
    for solver in ("quadprog", "osqp", "proxqp", "piqp", "daqp", "clarabel"):
        name = f"qpsolvers:{solver}"
        if name not in backend_names() or backend_class(name).unavailable_reason():
            continue
        sol = get_backend(name).solve(problem)
        assert sol.status == "optimal", (name, sol.status)
        if solver in qs.ITERATION_READERS:
            assert type(sol.iterations) is int and sol.iterations > 0, (name, sol.iterations)
        else:
            assert sol.iterations is None, name
        for field in ("x", "y", "z", "z_box"):  # float64 arrays, also from wrappers giving lists
            value = getattr(sol, field)
            assert type(value) is np.ndarray and value.dtype == np.float64, (name, field)
