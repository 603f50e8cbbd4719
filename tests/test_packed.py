"""PackedProblem: one buffer, ordinary qpsolvers fields; the online network's per-tick path on it."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest
import qpsolvers
from known import robot_like_problem

from qpbench.backends import get_backend
from qpbench.backends.base import Backend
from qpbench.backends.rnn import WORKING_SETTINGS, TickSolution
from qpbench.exceptions import ProblemFormatError
from qpbench.packed import HEADER, PackedProblem, pack
from qpbench.rnn import kernels

FIELDS = ("P", "q", "G", "h", "A", "b", "lb", "ub")


def variants(problem):
    """The problem and versions with parts absent (as qpsolvers allows)."""
    p = problem
    yield "full", p
    yield "no equality", qpsolvers.Problem(p.P, p.q, p.G, p.h, None, None, p.lb, p.ub)
    yield "no inequality", qpsolvers.Problem(p.P, p.q, None, None, p.A, p.b, p.lb, p.ub)
    yield "no box", qpsolvers.Problem(p.P, p.q, p.G, p.h, p.A, p.b)
    yield "lower bound only", qpsolvers.Problem(p.P, p.q, p.G, p.h, p.A, p.b, p.lb, None)
    yield "one equality as 1-D", qpsolvers.Problem(p.P, p.q, p.G, p.h, p.A[0], p.b[:1], p.lb, p.ub)


@pytest.fixture
def robot_qp(rng):
    return robot_like_problem(rng, n_ineq=7)[0]


def test_pack_round_trip_and_same_solution(robot_qp):
    for label, p in variants(robot_qp):
        packed = pack(p)
        assert isinstance(packed, qpsolvers.Problem), label
        for f in FIELDS:
            mine, ref = getattr(packed, f), getattr(p, f)
            assert (mine is None) == (ref is None), (label, f)
            if ref is not None:
                np.testing.assert_array_equal(
                    mine, np.atleast_2d(ref) if f == "A" else ref, err_msg=f"{label} {f}"
                )
                assert mine.dtype == np.float64 and np.shares_memory(mine, packed.buffer), (
                    label,
                    f,
                )
        packed.check_constraints()
        a = qpsolvers.solve_problem(p, solver="daqp")
        b = qpsolvers.solve_problem(packed, solver="daqp")
        np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-12, err_msg=label)


def test_fields_cannot_be_reassigned_but_writes_reach_the_buffer(robot_qp):
    packed = pack(robot_qp)
    with pytest.raises(AttributeError, match="PackedProblem.q cannot be set"):
        packed.q = np.zeros(4)
    packed.q[0] = 12.5  # one storage: the buffer says the same
    assert PackedProblem(packed.buffer).q[0] == 12.5


def test_pickle_keeps_the_views(robot_qp):
    packed = pack(robot_qp)
    back = pickle.loads(pickle.dumps(packed))
    assert type(back) is PackedProblem and back.shape == packed.shape == (4, 2, 7)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(back, f), getattr(packed, f))
        assert np.shares_memory(getattr(back, f), back.buffer)


def test_bad_buffers_are_refused(robot_qp):
    good = pack(robot_qp).buffer
    cases = {
        "short": (good[:5], "buffer"),
        "not whole": (np.concatenate([[4.5], good[1:]]), "buffer"),
        "P outside": (np.concatenate([good[:3], [len(good) - 3], good[4:]]), "P"),
        "q before the header": (np.concatenate([good[:4], [2.0], good[5:]]), "q"),
        "P absent": (np.concatenate([good[:3], [-1.0], good[4:]]), "P"),
        "G absent with mi > 0": (np.concatenate([good[:7], [-1.0], good[8:]]), "G"),
        "2-D": (good.reshape(1, -1), "buffer"),
        "nan header": (np.concatenate([[np.nan], good[1:]]), "buffer"),
    }
    for label, (buf, key) in cases.items():
        with pytest.raises(ProblemFormatError) as err:
            PackedProblem(buf)
        assert err.value.key == key, label


def test_kernel_header_length_is_the_format_s():
    assert kernels.HEADER is HEADER


# ---------------------------------------------------------------------------
# the online network on packed problems
# ---------------------------------------------------------------------------
def sequence(rng, count=40, n_ineq=7):
    problems = []
    for _ in range(count):
        problems.append(robot_like_problem(rng, n_ineq=n_ineq)[0])
    return problems


@pytest.mark.parametrize(
    "settings", [WORKING_SETTINGS, {"eps": 0.02}], ids=["fixed-substeps", "auto-substeps"]
)
def test_packed_path_equals_plain_and_general_paths(rng, settings):
    """The same ticks as PackedProblem, as plain Problem and through the general path: same numbers, bit for bit."""
    problems = sequence(rng)
    # odd ticks mid-sequence: another equality/inequality split of the same total, absent parts
    p = problems[20]
    problems[20] = qpsolvers.Problem(
        p.P,
        p.q,
        np.vstack([p.G[:6]]),
        p.h[:6],
        np.vstack([p.A, p.G[6]]),
        np.append(p.b, p.h[6]),
        p.lb,
        p.ub,
    )
    problems[30] = qpsolvers.Problem(p.P, p.q, p.G, p.h, None, None, p.lb, p.ub)
    problems[31] = qpsolvers.Problem(p.P, p.q, p.G, p.h, p.A, p.b, None, None)
    runs = {}
    for label in ("packed", "plain", "general"):
        be = get_backend("rnn", dt=1e-3, **settings)
        sols = []
        for q in problems:
            q = pack(q) if label == "packed" else q
            sols.append(Backend.solve(be, q) if label == "general" else be.solve(q))
        runs[label] = (sols, be.state.xi.copy())
    ref, ref_xi = runs["general"]
    for label in ("packed", "plain"):
        sols, xi = runs[label]
        np.testing.assert_array_equal(xi, ref_xi, err_msg=label)
        for k, (a, b) in enumerate(zip(sols, ref)):
            for f in ("x", "y", "z", "z_box"):
                va, vb = getattr(a, f), getattr(b, f)
                assert (va is None) == (vb is None), (label, k, f)
                if va is not None:
                    np.testing.assert_array_equal(va, vb, err_msg=f"{label} tick {k} {f}")
            assert (a.status, a.iterations, a.found, a.backend) == (
                b.status,
                b.iterations,
                b.found,
                b.backend,
            ), (label, k)
            assert a.obj == pytest.approx(b.obj, rel=1e-12, abs=1e-15)


def test_a_header_that_lies_goes_to_the_general_path(rng):
    """A buffer whose header disagrees with the state is refused by the kernel, not read out of bounds."""
    problems = sequence(rng, count=5)
    be, ref = get_backend("rnn", **WORKING_SETTINGS), get_backend("rnn", **WORKING_SETTINGS)
    for p in problems[:4]:
        be.solve(pack(p))
        ref.solve(p)
    good = pack(problems[4])
    bad = good.buffer.copy()
    bad[2] = 70.0  # mi far beyond the buffer
    liar = PackedProblem.from_views(bad, *(getattr(good, f) for f in FIELDS))
    a, b = be.solve(liar), ref.solve(problems[4])
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(be.state.xi, ref.state.xi)


def test_tick_solution_duals_are_fixed_views_and_survive_copies(rng):
    problems = sequence(rng, count=3)
    be = get_backend("rnn", **WORKING_SETTINGS)
    be.solve(pack(problems[0]))
    sol = be.solve(pack(problems[1]))
    assert type(sol) is TickSolution and sol.found == (sol.status == "optimal")
    y = sol.y.copy()
    be.solve(pack(problems[2]))  # a later tick does not touch an earlier answer
    np.testing.assert_array_equal(sol.y, y)
    assert sol.y is sol.y and sol.x.base is sol.z_box.base is sol.y.base  # one output array
    back = pickle.loads(pickle.dumps(sol))
    for f in ("x", "y", "z", "z_box"):
        np.testing.assert_array_equal(getattr(back, f), getattr(sol, f))
    other = dataclasses.replace(sol, status="max_iter")
    np.testing.assert_array_equal(other.z, sol.z)
    assert sol.extras == {} and sol.obj == pytest.approx(
        0.5 * sol.x @ problems[1].P @ sol.x + problems[1].q @ sol.x
    )
    # residuals through qpsolvers agree with the network's own verdict
    assert sol.primal_residual() >= 0.0 and sol.dual_residual() >= 0.0
