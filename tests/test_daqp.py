"""Backend ``daqp`` (DAQP through its own API): what the generated tests of tests/test_backends.py do not cover."""

from __future__ import annotations

import numpy as np
import pytest
import qpsolvers
from known import random_kkt_problem, robot_like_problem

from qpbench.backends import backend_names, get_backend
from qpbench.exceptions import ParamError

pytestmark = pytest.mark.skipif("daqp" not in backend_names(), reason="daqp unavailable")


def test_settings_come_from_the_profile_and_unknown_ones_are_refused():
    assert get_backend("daqp-stateless", "high_accuracy").options() == {
        "primal_tol": 1e-9,
        "dual_tol": 1e-9,
        "iter_limit": 1_000_000,
        "time_limit": 10.0,
    }
    options = get_backend("daqp-stateless", "low_accuracy", max_iter=7, eps_prox=0.0).options()
    assert (
        options["iter_limit"] == 7 and options["primal_tol"] == 1e-4 and options["eps_prox"] == 0.0
    )
    with pytest.raises(ParamError) as err:
        get_backend("daqp-stateless", primal_tolerance=1e-3)
    assert err.value.key == "primal_tolerance" and "primal_tol" in str(err.value)


def test_singular_p_needs_daqps_proximal_iterations():
    """P = diag(1, 0): solved with DAQP's default automatic regularisation; eps_prox = 0 refuses it."""
    problem = qpsolvers.Problem(
        np.diag([1.0, 0.0]), np.array([1.0, 1.0]), None, None, None, None, -np.ones(2), np.ones(2)
    )
    sol = get_backend("daqp-stateless", "high_accuracy").solve(problem)
    assert sol.status == "optimal"
    np.testing.assert_allclose(sol.x, [-1.0, -1.0], atol=1e-9)
    np.testing.assert_allclose(
        sol.z_box, [0.0, -1.0], atol=1e-9
    )  # only the lower bound of x2 is active
    refused = get_backend("daqp-stateless", eps_prox=0.0).solve(problem)
    assert (
        refused.status == "error"
        and "NONCONVEX" in refused.error
        and refused.x is None
        and not refused.found
    )


@pytest.mark.parametrize(
    "flag, status",
    [
        (1, "optimal"),
        (2, "optimal"),
        (-1, "primal_infeasible"),
        (-2, "max_iter"),
        (-3, "dual_infeasible"),
        (-4, "max_iter"),
        (-5, "error"),
        (-6, "error"),
        (-7, "time_limit"),
        (-99, "error"),
    ],
)
def test_exit_flags_become_statuses(monkeypatch, flag, status):
    """Each DAQP exit flag maps to one status; only an optimal one carries x, duals and objective."""
    from qpbench.backends import daqp_

    problem, x, y, z, z_box = robot_like_problem(np.random.default_rng(3))
    real = daqp_._daqp()
    calls = []

    class Fake:
        Model = real.Model

        @staticmethod
        def solve(*args, **kwargs):
            calls.append(kwargs)
            xx, fval, _, info = real.solve(*args, **kwargs)
            return xx, fval, flag, info

    monkeypatch.setattr(daqp_, "_daqp", lambda: Fake)
    sol = get_backend("daqp-stateless", "high_accuracy").solve(problem)
    assert sol.status == status and sol.found == (status == "optimal")
    assert calls[0]["iter_limit"] == 1_000_000
    if status == "optimal":
        np.testing.assert_allclose(sol.x, x, atol=1e-8)
        np.testing.assert_allclose(sol.y, y, atol=1e-6)
        assert sol.obj == pytest.approx(0.5 * x @ problem.P @ x + problem.q @ x, abs=1e-8)
    else:
        assert sol.x is None and sol.y is None and sol.z is None
    assert (sol.error is not None) == (status == "error")
    assert sol.extras["raw_status"] == daqp_.EXITFLAGS.get(flag, daqp_.UNKNOWN_EXITFLAG)[1]


def test_same_answer_as_qpsolvers_route_on_robot_ticks():
    """On consecutive ticks of the wall scenario (across its infeasible start): DAQP's own route gives
    qpsolvers' route's answers, and names the infeasible ticks that qpsolvers' route cannot."""
    from qpbench.sim.loop import simulate

    records = simulate("wall", "daqp-stateless", duration=0.2, every=1).records[100:200]
    ours, theirs = get_backend("daqp-stateless"), get_backend("qpsolvers:daqp")
    statuses = set()
    for rec in records:
        a, b = ours.solve(rec.problem), theirs.solve(rec.problem)
        statuses.add(a.status)
        assert a.found == b.found
        if a.found:
            np.testing.assert_allclose(a.x, b.x, atol=1e-12)
            for f in ("y", "z", "z_box"):
                np.testing.assert_allclose(getattr(a, f), getattr(b, f), atol=1e-12)
            assert a.primal_residual() < 1e-9 and a.dual_residual() < 1e-9
        else:
            assert a.status == "primal_infeasible" and b.status == "not_solved"
    assert statuses == {"optimal", "primal_infeasible"}


def test_buffers_are_per_shape_and_do_not_leak_between_calls():
    """Alternating shapes (two problems share one) and one without box: each answer is the known one."""
    rng = np.random.default_rng(11)
    cases = [
        random_kkt_problem(rng, 6, 2, 5, 2),
        random_kkt_problem(rng, 5, 0, 4, 1),
        random_kkt_problem(rng, 6, 2, 5, 3),
    ]
    p, x, y, z, z_box = random_kkt_problem(rng, 4, 1, 3, 1, False)  # no box
    cases.append((p, x, y, z, z_box))
    backend = get_backend("daqp-stateless", "high_accuracy")
    for _ in range(2):
        for problem, x, y, z, z_box in cases:
            sol = backend.solve(problem)
            assert sol.status == "optimal"
            np.testing.assert_allclose(sol.x, x, atol=1e-8)
            np.testing.assert_allclose(sol.z, z, atol=1e-6)
            if problem.lb is None and problem.ub is None:
                assert sol.z_box.size == 0
    assert len(backend._buffers) == 3  # the first and third problems share a shape, hence a buffer
    backend.reset()
    assert backend._buffers == {}


def test_persistent_model_updates_a_problem_with_bounds_only():
    """Box-only QPs of one shape (the soft formulation without obstacles): the model is updated
    without constraint rows, and each answer is the clipped unconstrained minimum."""
    backend = get_backend("daqp", "high_accuracy")
    lb, ub = -np.ones(4), np.ones(4)
    for q in ([3.0, -1.0, 0.5, -4.0], [1.0, 2.0, -3.0, 0.0], [0.2, -0.2, 5.0, -5.0]):
        q = np.array(q)
        problem = qpsolvers.Problem(2.0 * np.eye(4), q, None, None, None, None, lb, ub)
        sol = backend.solve(problem)
        assert sol.status == "optimal"
        np.testing.assert_allclose(sol.x, np.clip(-q / 2.0, lb, ub), atol=1e-12)
    assert backend._model is not None  # set up once, then updated
