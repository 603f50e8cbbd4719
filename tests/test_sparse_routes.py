"""Sparse routes of ProxQP and PIQP: scipy.sparse input goes to their sparse APIs, the robot's
small dense problems keep the dense ones (issue: sparse from file to solver)."""

from __future__ import annotations

import numpy as np
import pytest
import qpsolvers
import scipy.sparse as spa
from conftest import LIMITED_CLI, MAROS_MESZAROS_DIR, random_problem, write_band_set

from qpbench.backends import backend_class, get_backend
from qpbench.backends._common import wants_sparse
from qpbench.formats import load_problems

ROUTES = ("proxqp", "piqp")
MM_FILES = sorted(MAROS_MESZAROS_DIR.glob("*.mat"))


def _skip_unavailable(name):
    why = backend_class(name).unavailable_reason()
    if why:
        pytest.skip(why)


def _sparse_copy(problem: qpsolvers.Problem) -> qpsolvers.Problem:
    def csc(M):
        return None if M is None else spa.csc_matrix(M)

    return qpsolvers.Problem(
        csc(problem.P),
        problem.q,
        csc(problem.G),
        problem.h,
        csc(problem.A),
        problem.b,
        problem.lb,
        problem.ub,
    )


def _sparse_solver_kind(backend) -> str:
    """``dense`` or ``sparse``: the API of the solver object the backend keeps."""
    kept = backend._qp if backend.name == "proxqp" else backend._solver
    return "sparse" if "sparse" in type(kept).__module__ + type(kept).__name__.lower() else "dense"


@pytest.mark.parametrize("name", ROUTES)
def test_declared_sparse(name):
    assert backend_class(name).sparse is True


@pytest.mark.parametrize("name", ROUTES)
@pytest.mark.parametrize("path", MM_FILES, ids=lambda p: p.stem)
def test_maros_meszaros_sparse_agrees_with_clarabel(name, path):
    """Each of the 14 shipped Maros-Meszaros problems, read as CSC, through the sparse API:
    same objective as Clarabel, and qpsolvers' residuals of (x, y, z, z_box) small."""
    _skip_unavailable(name)
    problem = load_problems(path)[0].problem
    assert spa.issparse(problem.P)
    ref = get_backend("clarabel", "high_accuracy").solve(problem)
    sol = get_backend(name, "high_accuracy").solve(problem)
    assert ref.status == "optimal"
    assert sol.status == "optimal", sol.extras
    scale = 1.0 + abs(ref.obj)
    assert abs(sol.obj - ref.obj) <= 1e-5 * scale
    # duals in qpsolvers' convention: its KKT residuals judge them
    assert sol.primal_residual() <= 1e-6 * (1 + np.abs(sol.x).max())
    assert sol.dual_residual() <= 1e-5 * scale
    assert abs(sol.duality_gap()) <= 1e-5 * scale


@pytest.mark.parametrize("name", ROUTES)
def test_dense_and_sparse_input_same_solution_and_route(name):
    _skip_unavailable(name)
    rng = np.random.default_rng(3)
    problem = random_problem(rng, n=6, n_ineq=4, n_eq=2)
    backend = get_backend(name, "high_accuracy")
    dense = backend.solve(problem)
    assert _sparse_solver_kind(backend) == "dense" and not wants_sparse(problem)
    sparse = backend.solve(_sparse_copy(problem))
    assert _sparse_solver_kind(backend) == "sparse" and wants_sparse(_sparse_copy(problem))
    assert dense.status == sparse.status == "optimal"
    for key in ("x", "y", "z", "z_box"):
        np.testing.assert_allclose(getattr(sparse, key), getattr(dense, key), atol=1e-6)


@pytest.mark.parametrize("name", ROUTES)
def test_sparse_update_keeps_solver_per_structure(name):
    """Same structure: the kept sparse solver is updated (as the dense path); another pattern: a new one."""
    _skip_unavailable(name)
    rng = np.random.default_rng(5)
    backend = get_backend(name, "high_accuracy")
    base = _sparse_copy(random_problem(rng, n=8, n_ineq=5, n_eq=2))
    first = backend.solve(base)
    kept = backend._qp if name == "proxqp" else backend._solver
    moved = qpsolvers.Problem(
        base.P, base.q + 0.5, base.G, base.h, base.A, base.b, base.lb, base.ub
    )
    second = backend.solve(moved)
    assert (backend._qp if name == "proxqp" else backend._solver) is kept
    fresh = get_backend(name, "high_accuracy").solve(moved)
    assert first.status == second.status == fresh.status == "optimal"
    np.testing.assert_allclose(second.x, fresh.x, atol=1e-6)
    other = spa.csc_matrix(np.diag(np.linspace(1, 2, 8)))  # another sparsity pattern of P
    backend.solve(
        qpsolvers.Problem(other, base.q, base.G, base.h, base.A, base.b, base.lb, base.ub)
    )
    assert (backend._qp if name == "proxqp" else backend._solver) is not kept


@pytest.mark.parametrize("name", ROUTES)
def test_large_dense_input_goes_sparse(name, monkeypatch):
    """A dense problem above the dense-only limit is handed to the sparse API (limit lowered here)."""
    _skip_unavailable(name)
    import qpbench.backends._common as routes

    problem = random_problem(np.random.default_rng(7), n=6, n_ineq=4, n_eq=2)
    monkeypatch.setattr(routes, "DENSE_MAX_ENTRIES", 10)
    monkeypatch.setattr(routes, "_SMALL_N", 2)
    backend = get_backend(name)
    sol = backend.solve(problem)
    assert sol.status == "optimal" and _sparse_solver_kind(backend) == "sparse"


@pytest.mark.parametrize("name", ROUTES)
def test_sparse_infeasible_stays_infeasible(name):
    _skip_unavailable(name)
    n = 4
    # x_0 >= 1 and x_0 <= -1 (rows of G), bounds on every variable
    G = spa.csc_matrix(np.vstack([-np.eye(n)[0], np.eye(n)[0]]))
    problem = qpsolvers.Problem(
        spa.identity(n, format="csc"),
        np.ones(n),
        G,
        np.array([-1.0, -1.0]),
        lb=-5 * np.ones(n),
        ub=5 * np.ones(n),
    )
    assert get_backend(name).solve(problem).status == "primal_infeasible"


@pytest.mark.slow
def test_100k_banded_through_sparse_routes_under_2gb(tmp_path):
    """A 100,000-variable banded QP (a dense P alone would be 80 GB) through ``bench`` with
    ``ulimit -v 2GB``: PIQP solves it with its sparse API, as Clarabel does; ProxQP's sparse
    API is given it too (no dense copy, no out-of-memory) but 0.8 needs minutes on it, so
    its row may end at the profile's time limit while the run goes on."""
    import csv
    import subprocess
    import sys

    write_band_set(tmp_path / "set")
    out = tmp_path / "rows.csv"
    backends = ",".join(
        b for b in ("clarabel",) + ROUTES if not backend_class(b).unavailable_reason()
    )
    bench = subprocess.run(
        [
            sys.executable,
            "-c",
            LIMITED_CLI.format(limit=2 * 1024**3),
            "bench",
            str(tmp_path / "set"),
            "--backends",
            backends,
            "--out",
            str(out),
            "--memory-budget",
            "1GB",
            # no discarded warm-up solve: the same solve again (ProxQP's runs to its 10 s limit)
            "--no-warmup",
        ],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert bench.returncode in (0, 1), (
        bench.stderr
    )  # 1: a row did not succeed (ProxQP's time limit)
    with open(out, newline="") as fh:
        rows = {r["backend"]: r for r in csv.DictReader(fh)}
    assert set(rows) == set(backends.split(","))
    if rows.get("proxqp", {}).get("status") == "time_limit":
        del rows["proxqp"]
    for name, row in rows.items():
        assert row["status"] == "optimal" and row["success"] == "True", (
            name,
            row["status"],
            row["error"],
        )
        assert abs(float(row["objective"]) - float(rows["clarabel"]["objective"])) <= 1e-5 * (
            1 + abs(float(rows["clarabel"]["objective"]))
        )
