"""Tests of tests/known.py: the generated QPs really have the announced solution."""

from __future__ import annotations

import numpy as np
import pytest
import qpsolvers
import scipy.optimize
from known import random_kkt_problem, robot_like_problem

from qpbench.exceptions import ParamError


def _cases():
    rng = np.random.default_rng(12)
    cases = []
    for _ in range(12):
        n = int(rng.integers(4, 21))
        n_eq = int(rng.integers(0, 3))
        n_ineq = int(rng.integers(0, 2 * n))
        n_active = int(rng.integers(0, min(n_ineq, n - n_eq - 2) + 1))
        cases.append((int(rng.integers(1 << 30)), n, n_eq, n_ineq, n_active))
    return cases


@pytest.mark.parametrize("seed,n,n_eq,n_ineq,n_active", _cases())
def test_kkt_point_satisfies_kkt_conditions(seed, n, n_eq, n_ineq, n_active):
    problem, x, y, z, z_box = random_kkt_problem(
        np.random.default_rng(seed), n, n_eq, n_ineq, n_active
    )
    sol = qpsolvers.Solution(problem)
    sol.x, sol.y, sol.z, sol.z_box, sol.found = x, y, z, z_box, True
    assert sol.primal_residual() < 1e-12
    assert sol.dual_residual() < 1e-12
    assert abs(sol.duality_gap()) < 1e-10
    # The announced numbers of active rows, with strictly positive multipliers.
    if n_ineq:
        slack = problem.h - problem.G @ x
        active = np.abs(slack) < 1e-12
        assert active.sum() == n_active
        assert np.all(z[active] >= 0.1) and np.all(z[~active] == 0.0)
        assert np.all(slack[~active] >= 0.1 - 1e-12)
    at_lb, at_ub = x == problem.lb, x == problem.ub
    assert np.all(z_box[at_lb] < 0) and np.all(z_box[at_ub] > 0)
    assert np.all(z_box[~(at_lb | at_ub)] == 0.0)
    assert at_lb.sum() + at_ub.sum() == min(2, n - n_eq - n_active)
    # P is positive definite: x is the unique minimiser.
    assert np.linalg.eigvalsh(problem.P).min() > 0.5


def test_solution_matches_an_independent_solver():
    """SciPy's SLSQP (no qpsolvers, no qpbench) finds the same minimiser."""
    rng = np.random.default_rng(3)
    for _ in range(3):
        problem, x, *_ = random_kkt_problem(rng, 6, 1, 6, 2)
        P, q, G, h, A, b, lb, ub = problem.unpack()
        res = scipy.optimize.minimize(
            lambda v: 0.5 * v @ P @ v + q @ v,
            np.zeros(6),
            jac=lambda v: P @ v + q,
            bounds=list(zip(lb, ub)),
            constraints=[
                {"type": "eq", "fun": lambda v: A @ v - b, "jac": lambda v: A},
                {"type": "ineq", "fun": lambda v: h - G @ v, "jac": lambda v: -G},
            ],
            method="SLSQP",
            options={"ftol": 1e-14, "maxiter": 500},
        )
        assert res.success
        np.testing.assert_allclose(res.x, x, atol=1e-6)


def test_deterministic_for_a_seed():
    a = random_kkt_problem(np.random.default_rng(7), 8, 2, 5, 2)
    b = random_kkt_problem(np.random.default_rng(7), 8, 2, 5, 2)
    for u, v in zip(a[1:], b[1:]):
        np.testing.assert_array_equal(u, v)
    np.testing.assert_array_equal(a[0].P, b[0].P)
    np.testing.assert_array_equal(a[0].q, b[0].q)


def test_without_bounds_and_without_rows():
    problem, x, y, z, z_box = random_kkt_problem(
        np.random.default_rng(1), 5, 0, 0, 0, with_bounds=False
    )
    assert problem.G is None and problem.A is None and problem.lb is None and problem.ub is None
    np.testing.assert_allclose(np.linalg.solve(problem.P, -problem.q), x, atol=1e-12)
    assert y.shape == (0,) and z.shape == (0,) and np.all(z_box == 0)


def test_robot_like_shape():
    rng = np.random.default_rng(0)
    for _ in range(20):
        problem, x, *_ = robot_like_problem(rng)
        assert problem.q.shape == (4,) and problem.A.shape == (2, 4)
        assert 7 <= problem.G.shape[0] <= 14
        assert problem.lb.shape == (4,) and problem.ub.shape == (4,)


@pytest.mark.parametrize(
    "args,key",
    [((4, 2, 3, 3), "n_active"), ((4, 0, 2, 3), "n_active"), ((0, 0, 0, 0), "n")],
)
def test_impossible_counts_raise(args, key):
    with pytest.raises(ParamError) as info:
        random_kkt_problem(np.random.default_rng(0), *args)
    assert info.value.key == key
