"""Property-based tests (hypothesis): backends vs. references, metric invariances, Jacobians, rows.

Random feasible QPs come from :func:`known.random_kkt_problem` (a chosen
KKT point, so the optimum is known independently of any solver), sizes 1 to
50, with and without each constraint kind.

Metric invariances (qpsolvers' residuals, inf-norms):

=====================  ==================  ===========================================
metric                 row permutation     positive row scaling ``G_i, h_i -> s_i G_i, s_i h_i``
=====================  ==================  ===========================================
x*, objective          invariant           invariant (same feasible set)
primal residual        invariant           NOT invariant: row i's violation is scaled by s_i
dual residual          invariant           invariant (with ``z_i -> z_i / s_i``: ``G' z`` unchanged)
duality gap            invariant           invariant (``h_i z_i`` unchanged)
optimality gap         invariant           invariant
=====================  ==================  ===========================================
"""

from __future__ import annotations

import math
import warnings

import faulty_backends as fb
import numpy as np
import pytest
import qpsolvers
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from known import random_kkt_problem

from qpbench.backends import backend_names
from qpbench.formats import ProblemRecord, ProblemSet
from qpbench.harness.bench import BenchConfig, run_bench
from qpbench.harness.results import read_results
from qpbench.metrics import evaluate
from qpbench.profiles import PROFILES
from qpbench.reference import reference_solution

TOL = PROFILES["default"].tolerance
FAST = settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)

#: Backends that must solve every strongly convex, well-conditioned random QP
#: to the default profile's tolerances (exact methods, tight settings).
MUST_SUCCEED = {
    "clarabel",
    "osqp",
    "proxqp",
    "qpsolvers:clarabel",
    "qpsolvers:daqp",
    "qpsolvers:piqp",
    "qpsolvers:proxqp",
    "qpsolvers:quadprog",
    "cvxpy",
}
#: Approximate by design: ``pinv`` ignores inequalities and bounds; ``rnn`` takes
#: one integration step per call (online). Their success is not expected but,
#: when claimed, must be right.
APPROXIMATE = {"pinv", "rnn", "rnn-tuned", "rnn-converged", "qpsolvers:highs", "qpsolvers:scs"}


@st.composite
def kkt_problems(draw):
    n = draw(st.integers(1, 50))
    n_eq = draw(st.sampled_from([0, draw(st.integers(0, max(0, n // 3)))]))
    n_ineq = draw(st.sampled_from([0, draw(st.integers(0, 2 * n))]))
    with_bounds = draw(st.booleans())
    room = n - n_eq
    n_active = draw(st.integers(0, min(n_ineq, room)))
    n_active_bounds = min(2, room - n_active) if with_bounds else 0
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    return random_kkt_problem(rng, n, n_eq, n_ineq, n_active, with_bounds, n_active_bounds)


#: qpsolvers routes whose unconstrained QPs go to SciPy's LSQR instead of the solver.
QPSOLVERS_LSQR_ROUTE = ("qpsolvers:clarabel", "qpsolvers:scs")

#: An unconstrained QP (no G, A or bounds): every backend must handle it.
UNCONSTRAINED = random_kkt_problem(np.random.default_rng(0), 4, 0, 0, 0, False, 0)


@FAST
@given(case=kkt_problems())
@example(case=UNCONSTRAINED)
def test_every_backend_success_agrees_with_the_reference(case, tmp_path_factory):
    problem, x_star, *_ = case
    record = ProblemRecord(problem, "kkt")
    ref = reference_solution(record)
    assert ref.status == "optimal"
    np.testing.assert_allclose(ref.x, x_star, atol=1e-6)  # the reference is right
    names = [
        n for n in backend_names() if not n.startswith(("faulty:", "stateful:"))
    ]  # built-ins only
    out = tmp_path_factory.mktemp("prop") / "r.csv"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        summary = run_bench(
            ProblemSet("kkt", None, [record]),
            BenchConfig(backends=names, warmup=False, isolate="never"),
            out,
            references=[ref],
        )
    rows = {r["backend"]: r for r in read_results(out).rows}
    assert set(rows) == set(names) and summary.rows == len(names)
    for name, row in rows.items():
        if name in QPSOLVERS_LSQR_ROUTE and problem.is_unconstrained and row["status"] == "error":
            # qpsolvers hands an unconstrained QP of these solvers to SciPy's LSQR
            # at its default tolerance and then rejects the answer when
            # |P x + q| > 1e-8: a qpsolvers finding, pinned here by its message.
            assert "unbounded below" in row["error"], (name, row["error"])
            continue
        assert row["status"] not in ("error", "crashed", "invalid"), (name, row["error"])
        assert row["reference_status"] == "optimal"
        if row["success"] == "True":
            assert row["status"] == "optimal" and row["found"] == "True"
            assert float(row["optimality_gap"]) <= TOL.gap
            assert float(row["primal_residual"]) <= TOL.primal
        if name in MUST_SUCCEED:
            assert row["success"] == "True", (name, row)


def _perturbed_solution(problem, ref, rng, scale=1e-3):
    sol = qpsolvers.Solution(problem)
    sol.found = True
    sol.x = ref.x + scale * rng.standard_normal(ref.x.size)
    sol.y = None if ref.y is None else ref.y.copy()
    sol.z = None if ref.z is None else ref.z.copy()
    sol.z_box = None if ref.z_box is None else ref.z_box.copy()
    return sol


def _metrics(problem, sol, ref):
    return evaluate(ProblemRecord(problem, "p"), sol, ref, TOL)


INVARIANT = ("objective", "dual_residual", "duality_gap", "optimality_gap")


@FAST
@given(case=kkt_problems(), seed=st.integers(0, 2**32 - 1))
def test_metrics_under_row_permutation_and_positive_row_scaling(case, seed):
    problem, *_ = case
    if problem.G is None:
        return
    rng = np.random.default_rng(seed)
    ref = reference_solution(ProblemRecord(problem, "p"))
    sol = _perturbed_solution(problem, ref, rng)  # slightly off: nonzero residuals
    base = _metrics(problem, sol, ref)
    m = problem.G.shape[0]

    # Row permutation of (G, h), duals permuted alike: every metric is invariant.
    perm = rng.permutation(m)
    pp = qpsolvers.Problem(
        problem.P,
        problem.q,
        problem.G[perm],
        problem.h[perm],
        problem.A,
        problem.b,
        problem.lb,
        problem.ub,
    )
    ps = _perturbed_solution(pp, ref, np.random.default_rng(0), scale=0.0)
    ps.x, ps.z = sol.x, sol.z[perm]
    permuted = _metrics(pp, ps, ref)
    for key in INVARIANT + ("primal_residual",):
        assert permuted[key] == pytest.approx(base[key], rel=1e-9, abs=1e-12), key

    # Positive row scaling: z_i -> z_i / s_i keeps G'z, h_i z_i, the feasible set and x*.
    s = np.exp(rng.uniform(-3.0, 3.0, m))
    sp = qpsolvers.Problem(
        problem.P,
        problem.q,
        s[:, None] * problem.G,
        s * problem.h,
        problem.A,
        problem.b,
        problem.lb,
        problem.ub,
    )
    ss = _perturbed_solution(sp, ref, np.random.default_rng(0), scale=0.0)
    ss.x, ss.z = sol.x, sol.z / s
    scaled = _metrics(sp, ss, ref)
    for key in INVARIANT:
        assert scaled[key] == pytest.approx(base[key], rel=1e-7, abs=1e-10), key
    # The primal residual is the inf-norm of the violations, row i's scaled by s_i:
    viol = [np.max(np.maximum(s * (problem.G @ sol.x - problem.h), 0.0))]
    if problem.A is not None:
        viol.append(np.max(np.abs(problem.A @ sol.x - problem.b)))
    if problem.lb is not None:
        viol.append(np.max(np.maximum(problem.lb - sol.x, 0.0)))
        viol.append(np.max(np.maximum(sol.x - problem.ub, 0.0)))
    assert scaled["primal_residual"] == pytest.approx(max(viol), rel=1e-9, abs=1e-15)

    # The optimum itself (x, objective) is invariant: solve the scaled and permuted problems.
    for q2 in (pp, sp):
        ref2 = reference_solution(ProblemRecord(q2, "p2"))
        np.testing.assert_allclose(ref2.x, ref.x, atol=1e-6)
        assert ref2.objective == pytest.approx(ref.objective, rel=1e-7, abs=1e-8)


@settings(max_examples=40, deadline=None)
@given(
    lengths=st.lists(st.floats(0.05, 2.0), min_size=2, max_size=8),
    seed=st.integers(0, 2**32 - 1),
)
def test_planar_arm_jacobians_equal_finite_differences(lengths, seed):
    kin = pytest.importorskip("qpbench.robot.kinematics")
    arm = kin.PlanarArm(lengths)
    rng = np.random.default_rng(seed)
    theta = rng.uniform(-np.pi, np.pi, arm.n)
    h = 1e-6
    J = arm.points_jacobians(theta, [arm.n - 1], [1.0])[1][0]  # the end effector's
    fd = np.empty_like(J)
    for k in range(arm.n):
        e = np.zeros(arm.n)
        e[k] = h
        fd[:, k] = (arm.end_effector(theta + e) - arm.end_effector(theta - e)) / (2 * h)
    np.testing.assert_allclose(J, fd, atol=1e-7 * max(1.0, sum(lengths)))
    links = rng.integers(0, arm.n, size=5)
    fracs = rng.uniform(0.0, 1.0, size=5)
    _, Jp = arm.points_jacobians(theta, links, fracs)
    for k in range(arm.n):
        e = np.zeros(arm.n)
        e[k] = h
        col = (arm.points(theta + e, links, fracs) - arm.points(theta - e, links, fracs)) / (2 * h)
        np.testing.assert_allclose(Jp[:, :, k], col, atol=1e-7 * max(1.0, sum(lengths)))


cells = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**40), 2**40),
    st.floats(allow_nan=False),
    st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=30),
)


@settings(max_examples=60, deadline=None)
@given(values=st.lists(cells, min_size=1, max_size=4))
def test_any_row_round_trips_through_the_csv(values, tmp_path_factory):
    from qpbench.harness.results import ResultsWriter
    from qpbench.harness.results import bench_columns as columns

    row = {c: None for c in columns()}
    row.update(problem="p", backend="b", profile="default")
    targets = ("objective", "error", "tick", "scenario")
    for key, value in zip(targets, values):
        row[key] = value
    path = tmp_path_factory.mktemp("csv") / "r.csv"
    with ResultsWriter(path, new=True) as writer:
        writer.write_rows([row])
    back = read_results(path).rows
    assert len(back) == 1 and path.read_text().count("\n") == 2
    for key, value in zip(targets, values):
        text = back[0][key]
        if value is None:
            assert text == ""
        elif isinstance(value, bool):
            assert text == str(value)
        elif isinstance(value, float):
            assert float(text) == value or (math.isinf(value) and text in ("inf", "-inf"))
        elif isinstance(value, int):
            assert int(text) == value
        else:
            assert (
                text == " ".join(value.split())
                if ("\n" in value or "\r" in value)
                else text == value
            )


@settings(
    max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_resume_from_any_cut_point_matches_a_full_run(data, tmp_path_factory):
    from qpbench.harness.results import TIMING_COLUMNS

    folder = tmp_path_factory.mktemp("resume")
    records = fb.tick_records(4, scenario="wall") + fb.tick_records(3, scenario="free", seed=3)
    pset = ProblemSet("s", None, records)
    refs = [reference_solution(r) for r in records]
    config = BenchConfig(
        backends=["stateful:count-copy", "stateful:last-native", "stateful:count-fail2"],
        isolate="never",
    )
    full = folder / "full.csv"
    run_bench(pset, config, full, references=refs)
    data_bytes = full.read_bytes()
    cut = folder / "cut.csv"
    fraction = data.draw(st.floats(0.0, 1.0))  # the file's length varies with the timings
    cut.write_bytes(data_bytes[: int(fraction * len(data_bytes))])
    run_bench(pset, config, cut, resume=True, references=refs)

    def key(rows):
        return sorted(tuple((k, v) for k, v in r.items() if k not in TIMING_COLUMNS) for r in rows)

    assert key(read_results(cut).rows) == key(read_results(full).rows)
