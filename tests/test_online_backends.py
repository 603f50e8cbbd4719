"""The backends a real-time controller keeps from tick to tick: qpoases (hotstart), daqp (daqp.Model), piqp.

What the generated tests of tests/test_backends.py do not cover: a long
sequence of robot ticks solved tick after tick equals the same ticks solved
independently, wrong shapes are refused, and the qpOASES shim's build and
availability. (``--repeat`` against one solve: ``tests/test_contract.py``, for every backend.)
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
import qpsolvers
from known import random_kkt_problem, robot_like_problem

from qpbench.backends import backend_info, backend_names, get_backend
from qpbench.exceptions import ParamError, ProblemFormatError
from qpbench.formats import load_problems

WALL = Path(__file__).resolve().parents[1] / "problems" / "wall"
ONLINE = ("qpoases", "daqp", "piqp")


def _online(names=ONLINE):
    infos = {i.name: i for i in backend_info()}
    return [
        pytest.param(
            n,
            marks=pytest.mark.skipif(
                not infos[n].available, reason=f"{n} unavailable: {infos[n].reason}"
            ),
        )
        for n in names
    ]


@pytest.fixture(scope="module")
def wall_ticks():
    """The 2,000 QPs of problems/wall (every 10th tick of 20 s; the first 13 infeasible)."""
    return [record.problem for record in load_problems(WALL)]


@pytest.mark.parametrize("name", _online())
def test_wall_sequence_equals_independent_solves(name, wall_ticks):
    """2,000 consecutive ticks, updated and warm-started, give the independent solves' statuses and x (1e-8)."""
    carried = get_backend(name)
    fresh = get_backend(name)
    statuses = set()
    iters_carried, iters_fresh = [], []
    for k, problem in enumerate(wall_ticks):
        start = time.perf_counter()
        a = carried.solve(problem)
        wall_time_s = time.perf_counter() - start
        fresh.reset()
        b = fresh.solve(problem)
        assert a.status == b.status, (k, a.status, b.status)
        statuses.add(a.status)
        if a.status == "optimal":
            np.testing.assert_allclose(a.x, b.x, atol=1e-8, rtol=0, err_msg=f"tick {k}")
            assert a.primal_residual() < 1e-6 and a.dual_residual() < 1e-6, k
            assert a.solver_time_s is not None and 0 < a.solver_time_s <= wall_time_s
            iters_carried.append(a.iterations)
            iters_fresh.append(b.iterations)
    assert statuses == {"primal_infeasible", "optimal"}
    if name in ("qpoases", "daqp"):  # active-set methods start from the previous working set
        assert np.mean(iters_carried) < np.mean(iters_fresh), (
            np.mean(iters_carried),
            np.mean(iters_fresh),
        )


@pytest.mark.parametrize("name", _online())
def test_duals_follow_qpsolvers_convention_on_robot_ticks(name, wall_ticks):
    """y, z, z_box of the backend equal those of qpsolvers' DAQP (unique multipliers on these ticks)."""
    backend = get_backend(name, "high_accuracy")
    for problem in wall_ticks[100:400:10]:
        ours = backend.solve(problem)
        ref = qpsolvers.solve_problem(problem, solver="daqp")
        assert ours.status == "optimal" and ref.found
        for field in ("y", "z", "z_box"):
            np.testing.assert_allclose(
                getattr(ours, field), getattr(ref, field), atol=1e-6, err_msg=field
            )
        assert ours.dual_residual() < 1e-8


@pytest.mark.parametrize("name", _online())
def test_wrong_shapes_are_refused(name):
    """An array whose shape does not fit is a ProblemFormatError naming it, never a stale or broadcast solve."""
    backend = get_backend(name, "high_accuracy")
    problem, x, *_ = robot_like_problem(np.random.default_rng(2))
    assert backend.solve(problem).status == "optimal"
    P, q, G, h, A, b, lb, ub = problem.unpack()
    bad = {
        "b": qpsolvers.Problem(P, q, G, h, A, b[:1], lb, ub),  # would broadcast into both rows
        "h": qpsolvers.Problem(P, q, G, h[:-1], A, b, lb, ub),
        "P": qpsolvers.Problem(np.eye(5), q, G, h, A, b, lb, ub),
        "G": qpsolvers.Problem(P, q, G[:, :3], h, A, b, lb, ub),
        "lb": qpsolvers.Problem(P, q, G, h, A, b, lb[:3], ub),
    }
    for key, wrong in bad.items():
        with pytest.raises(ProblemFormatError) as err:
            backend.solve(wrong)
        assert err.value.key == key and name in str(err.value)
    sol = backend.solve(problem)  # the backend still solves the right problem afterwards
    np.testing.assert_allclose(sol.x, x, atol=1e-8)


# ----------------------------------------------------------------- daqp.Model


def test_daqp_model_updates_only_what_changed(monkeypatch, wall_ticks):
    """H and f go to Model.update only when they changed; A and the bounds every tick; one Model per shape."""
    if "daqp" not in backend_names():
        pytest.skip("daqp unavailable")
    from qpbench.backends import daqp_ as daqp_model

    real = daqp_model._daqp()
    calls = []

    class Recording:
        def __init__(self):
            self.inner = real.Model()
            calls.append(("new",))

        settings = property(
            lambda s: s.inner.settings, lambda s, v: setattr(s.inner, "settings", v)
        )

        def setup(self, *args):
            return self.inner.setup(*args)

        def update(self, H, f, A, bu, bl):
            calls.append(("update", H is not None, f is not None))
            return self.inner.update(H, f, A, bu, bl)

        def solve(self):
            return self.inner.solve()

    class Module:
        Model = Recording

    backend = get_backend("daqp", "high_accuracy")  # reads DAQP's setting names: no model kept
    monkeypatch.setattr(daqp_model, "_daqp", lambda: Module)

    def check(problem):
        ref = qpsolvers.solve_problem(problem, solver="daqp")
        np.testing.assert_allclose(backend.solve(problem).x, ref.x, atol=1e-9)

    ticks = wall_ticks[100:104]  # the paper's QP: P = I and q = 0 at every tick
    for problem in ticks:
        check(problem)
    assert calls == [("new",)] + [("update", False, False)] * 3
    P, q, G, h, A, b, lb, ub = ticks[0].unpack()
    check(qpsolvers.Problem(2 * P, q, G, h, A, b, lb, ub))
    assert calls[-1] == ("update", True, False)
    check(qpsolvers.Problem(2 * P, q + 0.1, G, h, A, b, lb, ub))
    assert calls[-1] == ("update", False, True)
    other = random_kkt_problem(np.random.default_rng(4), 5, 1, 3, 1)
    np.testing.assert_allclose(backend.solve(other[0]).x, other[1], atol=1e-8)
    assert calls[-1] == ("new",)


# ----------------------------------------------------------------- qpoases


pytest_qpoases = pytest.mark.skipif("qpoases" not in backend_names(), reason="qpoases unavailable")


@pytest_qpoases
def test_qpoases_settings():
    with pytest.raises(ParamError) as err:
        get_backend("qpoases", terminationTol=1e-9)
    assert err.value.key == "terminationTol" and "terminationTolerance" in str(err.value)
    with pytest.raises(ParamError):
        get_backend("qpoases", preset="turbo")
    problem, x, *_ = random_kkt_problem(np.random.default_rng(6), 8, 2, 6, 3)
    for settings in (
        {"preset": "mpc"},
        {"preset": "reliable"},
        {"terminationTolerance": 1e-12, "enableEqualities": 1},
    ):
        sol = get_backend("qpoases", **settings).solve(problem)
        np.testing.assert_allclose(sol.x, x, atol=1e-7)


@pytest_qpoases
def test_qpoases_time_limit():
    """qpOASES' CPU-time limit stops the homotopy: status time_limit, no x."""
    problem = random_kkt_problem(np.random.default_rng(9), 40, 2, 60, 20)[0]
    sol = get_backend("qpoases", time_limit=1e-9).solve(problem)
    assert sol.status == "time_limit" and sol.x is None and not sol.found
    assert get_backend("qpoases").solve(problem).status == "optimal"


@pytest_qpoases
def test_qpoases_solution_fields_behave_like_plain_fields():
    """The multipliers QpoasesSolution makes on first read: equal to qpsolvers' (a second
    solver), read twice the same object, replaced by an assignment, kept by pickling and
    dataclasses.replace; an empty z_box without bounds; None with no solution."""
    import dataclasses
    import pickle

    problem, x, y, z, z_box = random_kkt_problem(np.random.default_rng(4), 6, 2, 5, 2)
    sol = get_backend("qpoases").solve(problem)
    ref = qpsolvers.solve_problem(problem, "daqp")
    for field in ("x", "y", "z", "z_box"):
        np.testing.assert_allclose(getattr(sol, field), getattr(ref, field), atol=1e-8)
    assert sol.y is sol.y
    assert qpsolvers.Solution.dual_residual(sol) < 1e-9
    for copy in (pickle.loads(pickle.dumps(sol)), dataclasses.replace(sol)):
        for field in ("x", "y", "z", "z_box"):
            np.testing.assert_array_equal(getattr(copy, field), getattr(sol, field))
    sol.z = np.zeros(5)
    assert not sol.z.any()
    P, q, G, h, A, b, _, _ = problem.unpack()
    no_bounds = get_backend("qpoases").solve(qpsolvers.Problem(P, q, G, h, A, b))
    assert no_bounds.z_box.shape == (0,) and no_bounds.z.shape == (5,)
    failed = get_backend("qpoases", time_limit=1e-9).solve(
        random_kkt_problem(np.random.default_rng(9), 40, 2, 60, 20)[0]
    )
    assert failed.status == "time_limit"
    assert failed.x is None and failed.y is None and failed.z is None and failed.z_box is None


@pytest_qpoases
def test_qpoases_hotstart_state_is_the_ticks_solved(wall_ticks):
    """The hotstart state is what the ticks solved made it: a fresh instance that replays them
    (after another shape, or while the first one solves on) gives the same x and iterations."""
    backend = get_backend("qpoases")
    for problem in wall_ticks[200:210]:
        backend.solve(problem)
    first = backend.solve(wall_ticks[210])
    other = backend.fresh()
    other.solve(random_kkt_problem(np.random.default_rng(1), 5, 1, 2, 1)[0])
    for problem in wall_ticks[200:210]:
        other.solve(problem)
        backend.solve(wall_ticks[260])
    again = other.solve(wall_ticks[210])
    np.testing.assert_array_equal(first.x, again.x)
    assert first.iterations == again.iterations


@pytest_qpoases
def test_qpoases_unavailable_reasons(monkeypatch, tmp_path):
    from qpbench.backends import _qpoases_shim as shim

    cls = type(get_backend("qpoases"))
    monkeypatch.setattr(shim, "qpoases_prefix", lambda: None)
    assert "cmeel-qpoases" in cls.unavailable_reason()
    monkeypatch.undo()
    monkeypatch.setattr(shim, "LOADED", [])
    monkeypatch.setattr(shim, "compiler", lambda: None)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))  # no shim compiled there
    assert "compiler" in cls.unavailable_reason()
    names = {i.name: i for i in backend_info()}
    assert not names["qpoases"].available and "compiler" in names["qpoases"].reason


@pytest_qpoases
def test_qpoases_shim_compiles_atomically(monkeypatch, tmp_path):
    """Two builds of the shim at once: both succeed, the library loads, no temporary file is left."""
    import ctypes

    from qpbench.backends import _qpoases_shim as shim

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    prefix = shim.qpoases_prefix()
    target = shim.shim_path(prefix)
    assert str(target).startswith(str(tmp_path)) and not target.exists()
    errors = []

    def build():
        try:
            shim.compile_shim(prefix, target)
        except Exception as exc:  # noqa: BLE001
            errors.append(exc)

    threads = [threading.Thread(target=build) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    lib = ctypes.CDLL(str(target))
    assert lib.qpb_known_option(b"terminationTolerance") == 1 and lib.qpb_known_option(b"nope") == 0
    assert sorted(p.name for p in target.parent.iterdir()) == [target.name]
