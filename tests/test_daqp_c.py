"""DAQP's C API called from compiled code (qpbench/backends/daqp_c.py): the same answers as the
Python backends ``daqp`` and ``daqp-stateless``, call for call, and the API's traps."""

from __future__ import annotations

import ctypes
import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import qpsolvers

from qpbench.backends import backend_names, daqp_c, get_backend
from qpbench.backends.daqp_ import EXITFLAGS, UNKNOWN_EXITFLAG
from qpbench.exceptions import ParamError
from qpbench.packed import pack
from qpbench.statuses import TICK_STATUSES

pytestmark = pytest.mark.skipif(
    "daqp" not in backend_names() or daqp_c.unavailable_reason() is not None,
    reason="no compiled DAQP route here",
)

SOLVE, RESET = 0, 1
BACKENDS = ("daqp", "daqp-stateless")


def _driver(solve, reset):
    """A compiled loop over ``ops`` (``SOLVE`` row ``i`` of ``bufs``, or ``RESET``), as the
    compiled engine calls a backend."""
    import numba

    @numba.njit
    def run(st, bufs, ops, warm, sols, infos, statuses):
        for i in range(ops.shape[0]):
            if ops[i] == RESET:
                reset(st)
                statuses[i] = -1
            else:
                statuses[i] = solve(st, bufs[i], warm, sols[i], infos[i])

    return run


def _run_compiled(backend, problems, ops, state=None):
    """``(statuses, sols, infos)`` of the compiled route on ``problems`` (``None`` rows: resets),
    through the solve the engine calls (``either``, by the state's backend)."""
    n = max(p.shape[0] for p in problems if p is not None)
    me = max(p.shape[1] for p in problems if p is not None)
    mi = max(p.shape[2] for p in problems if p is not None)
    width = max(p.buffer.size for p in problems if p is not None)
    bufs = np.zeros((len(problems), width))
    for i, p in enumerate(problems):
        if p is not None:
            bufs[i, : p.buffer.size] = p.buffer
    options = get_backend(backend).options()
    stateless = backend == "daqp-stateless"
    st = daqp_c.make_state(n, me, mi, options, stateless) if state is None else state
    sols = np.zeros((len(problems), n + me + mi))
    infos = np.zeros((len(problems), 4))
    statuses = np.zeros(len(problems), dtype=np.int64)
    try:
        _driver(daqp_c.kernels().either, daqp_c.kernels().reset)(
            st, bufs, np.asarray(ops, dtype=np.int64), np.zeros(n), sols, infos, statuses
        )
    finally:
        daqp_c.close_state(st)
    return statuses, sols, infos


def _assert_same_as_python(backend, problems, ops):
    """Each call of the compiled route gives the Python backend's status, x, y, z (bit for bit),
    iterations and exit flag; returns the statuses seen."""
    statuses, sols, infos = _run_compiled(backend, problems, ops)
    be = get_backend(backend)
    seen = []
    for i, (op, problem) in enumerate(zip(ops, problems)):
        if op == RESET:
            be.reset()
            continue
        ref = be.solve(problem)
        n, me, mi = problem.shape
        assert TICK_STATUSES[statuses[i]] == ref.status, i
        assert EXITFLAGS.get(int(infos[i, 2]), UNKNOWN_EXITFLAG)[1] == ref.extras["raw_status"]
        assert np.isnan(infos[i, 1]) == (ref.iterations is None)
        assert np.isnan(infos[i, 0]) == (ref.solver_time_s is None)
        if ref.iterations is not None:
            assert infos[i, 1] == ref.iterations
        if ref.status == "optimal":
            np.testing.assert_array_equal(sols[i, :n], ref.x)
            np.testing.assert_array_equal(sols[i, n : n + me], ref.y if me else [])
            np.testing.assert_array_equal(sols[i, n + me : n + me + mi], ref.z if mi else [])
        else:
            assert ref.x is None and np.isnan(sols[i, : n + me + mi]).all()
        seen.append(ref.status)
    return seen


@pytest.fixture(scope="module")
def controller_qps():
    """The QPs of short closed loops, both formulations: ``{(scenario, formulation): [problem]}``
    (free: no obstacle rows, infeasible in its first 115 ticks; wall: 7 obstacle rows,
    infeasible in its first 123)."""
    from qpbench.sim.loop import simulate

    out = {}
    for scenario in ("free", "wall"):
        for formulation in ("paper", "soft"):
            result = simulate(scenario, "daqp-stateless", formulation, duration=0.14, every=1)
            out[scenario, formulation] = [r.problem for r in result.records]
    return out


def _loop_sequence(qps, scenario):
    """The calls a closed loop makes, and more: each tick's paper QP, then its soft QP (the
    fallback of the first 130 ticks', most of them infeasible) but on every third tick, and on
    every 5th; two soft QPs in a row every 7th tick, a reset every 40 calls."""
    paper, soft = qps[scenario, "paper"], qps[scenario, "soft"]
    problems, ops = [], []
    for k in range(len(paper)):
        problems.append(paper[k])
        if (k < 130 and k % 3) or k % 5 == 0:
            problems.append(soft[k])
        if k % 7 == 0 and k + 1 < len(soft):
            problems += [soft[k], soft[k + 1]]
        if k % 40 == 39:
            problems.append(None)
    ops = [RESET if p is None else SOLVE for p in problems]
    return problems, ops


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("scenario", ["free", "wall"])
def test_same_answers_as_the_python_backend_on_the_controllers_qps(
    controller_qps, backend, scenario
):
    problems, ops = _loop_sequence(controller_qps, scenario)
    seen = _assert_same_as_python(backend, problems, ops)
    assert {"optimal", "primal_infeasible"} <= set(seen)


def _box_qp(q, lb=-1.0, ub=1.0, P=None):
    """``min x'x + q'x`` (or ``1/2 x'Px + q'x``) on a box, one equality and two inequalities."""
    q = np.asarray(q, dtype=float)
    n = q.size
    P = 2.0 * np.eye(n) if P is None else P
    A, b = np.ones((1, n)), np.array([0.5])
    G, h = np.vstack([np.eye(n)[0], -np.eye(n)[1]]), np.array([0.8, 0.9])
    lb, ub = np.full(n, lb), np.full(n, ub)
    return pack(qpsolvers.Problem(P, q, G, h, A, b, lb, ub))


def test_the_engines_solve_is_the_backend_its_state_was_made_for():
    """``either`` keeps a workspace for ``daqp``'s state and none for ``daqp-stateless``'s,
    with the same answer."""
    problem = _box_qp([1.0, -2.0, 0.5])
    sols = []
    for stateless in (False, True):
        st = daqp_c.make_state(3, 1, 2, get_backend("daqp").options(), stateless)
        sol = np.zeros(6)
        status = daqp_c.kernels().either(st, problem.buffer, np.zeros(3), sol, np.zeros(4))
        assert TICK_STATUSES[status] == "optimal"
        assert st.meta[daqp_c.HAS_MODEL] == (0 if stateless else 1)
        daqp_c.close_state(st)
        sols.append(sol)
    np.testing.assert_allclose(sols[0], sols[1], atol=1e-12)


def test_a_failed_update_drops_the_workspace_and_the_next_call_sets_up_afresh():
    """Bounds lb > ub in a QP of the same shape: ``daqp_update_ldp`` refuses them (exit flag -1,
    the workspace reset); both routes say primal_infeasible and set up afresh after."""
    ok = _box_qp([1.0, -2.0, 0.5])
    bad = _box_qp([1.0, -2.0, 0.5], lb=1.0, ub=-1.0)
    problems = [ok, bad, ok, _box_qp([0.3, 0.2, -0.1])]
    seen = _assert_same_as_python("daqp", problems, [SOLVE] * 4)
    assert seen == ["optimal", "primal_infeasible", "optimal", "optimal"]
    st = daqp_c.make_state(3, 1, 2, get_backend("daqp").options())
    solve, _ = daqp_c.compiled("daqp")
    sol, info = np.zeros(6), np.zeros(4)
    models = []
    for p in problems:
        solve(st, p.buffer, np.zeros(3), sol, info)
        models.append(int(st.meta[daqp_c.HAS_MODEL]))
    daqp_c.close_state(st)
    assert models == [1, 0, 1, 1]


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_refused_set_up_is_an_error_and_the_next_call_sets_up(backend):
    """A singular P with DAQP's proximal iterations off: set-up refused (NONCONVEX), status
    error on both routes, then a regular QP is solved."""
    singular = _box_qp([1.0, 1.0, 1.0], P=np.diag([1.0, 0.0, 1.0]))
    problems = [_box_qp([1.0, -2.0, 0.5]), singular, _box_qp([1.0, -2.0, 0.5])]
    options = dict(eps_prox=0.0)
    statuses, sols, infos = _run_compiled_with(backend, problems, options)
    be = get_backend(backend, **options)
    refs = [be.solve(p) for p in problems]
    assert [r.status for r in refs] == ["optimal", "error", "optimal"]
    assert [TICK_STATUSES[s] for s in statuses] == ["optimal", "error", "optimal"]
    assert infos[1, 2] == -5 and "NONCONVEX" in refs[1].error
    np.testing.assert_array_equal(sols[2, :3], refs[2].x)


def _run_compiled_with(backend, problems, options):
    st = daqp_c.make_state(3, 1, 2, get_backend(backend, **options).options())
    solve, _ = daqp_c.compiled(backend)
    sols, infos = np.zeros((len(problems), 6)), np.zeros((len(problems), 4))
    statuses = [solve(st, p.buffer, np.zeros(3), sols[i], infos[i]) for i, p in enumerate(problems)]
    assert st.meta[daqp_c.HAS_MODEL] == (backend == "daqp")  # stateless keeps nothing
    daqp_c.close_state(st)
    return statuses, sols, infos


def _work_field(st, structs, name):
    """A field of the state's ``DAQPWorkspace`` read through ctypes' own struct."""
    return getattr(structs.workspace.from_buffer(st.work), name)


def test_the_layout_is_the_librarys():
    """After a set-up, DAQP's workspace holds what the state wrote at the layout's offsets:
    the problem's address and sizes, the settings' address; the settings read back through the
    layout are daqp.Model's with the backend's options; the equality rows' sense is 5."""
    import daqp

    structs = daqp_c.LAYOUTS[daqp_c.installed_version()]
    assert [ctypes.sizeof(t) for t in structs] == [80, 136, 64, 328]
    options = get_backend("daqp").options()
    st = daqp_c.make_state(3, 1, 2, options)
    for memory, struct in zip((st.qp, st.settings, st.result, st.work), structs):
        assert memory.nbytes == ctypes.sizeof(struct)  # all four are whole words
    model = daqp.Model()
    model.settings = options
    assert {k: getattr(structs.settings.from_buffer(st.settings), k) for k in model.settings} == (
        model.settings
    )
    solve, _ = daqp_c.compiled("daqp")
    solve(st, _box_qp([1.0, -2.0, 0.5]).buffer, np.zeros(3), np.zeros(6), np.zeros(4))
    try:
        assert _work_field(st, structs, "qp") == st.qp.ctypes.data
        assert _work_field(st, structs, "settings") == st.settings.ctypes.data
        assert [_work_field(st, structs, k) for k in ("n", "m", "ms")] == [3, 6, 3]
        sense = (ctypes.c_int * 6).from_address(_work_field(st, structs, "sense"))
        assert sense[3] & 5 == 5 and all(sense[k] & 4 == 0 for k in (0, 1, 2, 4, 5))
    finally:
        daqp_c.close_state(st)


def test_free_daqp_workspace_frees_the_settings_so_the_state_detaches_its_own():
    """DAQP frees (and clears) the settings a workspace points to; the kernels clear the pointer
    to the state's settings first, which stay intact through set-ups and drops."""
    structs = daqp_c.LAYOUTS[daqp_c.installed_version()]
    lib = ctypes.CDLL(daqp_c.library_path())
    work = structs.workspace()
    lib.allocate_daqp_settings(ctypes.byref(work))
    assert work.settings is not None
    lib.free_daqp_workspace(ctypes.byref(work))
    assert work.settings is None  # freed by DAQP: numpy memory there would be free()d

    st = daqp_c.make_state(3, 1, 2, get_backend("daqp").options())
    solve, reset = daqp_c.compiled("daqp")
    for q in ([1.0, -2.0, 0.5], [0.1, 0.2, 0.3]):
        solve(st, _box_qp(q).buffer, np.zeros(3), np.zeros(6), np.zeros(4))
        reset(st)
        np.testing.assert_array_equal(st.settings, st.settings0)
        assert not st.work.any() and st.meta[daqp_c.HAS_MODEL] == 0


def test_the_problems_sense_never_points_at_freed_constraint_states():
    """An update points the problem's ``sense`` at the workspace's constraint states (as
    daqp.Model does), which ``free_daqp_ldp`` frees: after a drop it is the state's array again."""
    structs = daqp_c.LAYOUTS[daqp_c.installed_version()]
    st = daqp_c.make_state(3, 1, 2, get_backend("daqp").options())
    solve, reset = daqp_c.compiled("daqp")
    qp = structs.problem.from_buffer(st.qp)
    args = (np.zeros(3), np.zeros(6), np.zeros(4))
    solve(st, _box_qp([1.0, -2.0, 0.5]).buffer, *args)
    assert qp.sense == st.sense.ctypes.data  # set up from the state's array
    solve(st, _box_qp([0.5, -2.0, 0.5]).buffer, *args)
    assert qp.sense == _work_field(st, structs, "sense")  # updated from DAQP's own
    reset(st)
    assert qp.sense == st.sense.ctypes.data
    solve(st, _box_qp([0.5, -2.0, 0.5]).buffer, *args)
    solve(st, _box_qp([0.5, -2.0, 0.5], lb=1.0, ub=-1.0).buffer, *args)  # failed update: dropped
    assert qp.sense == st.sense.ctypes.data and st.meta[daqp_c.HAS_MODEL] == 0
    daqp_c.close_state(st)


def _heap_in_use() -> int:
    """Bytes the C heap has handed out (glibc's ``mallinfo2().uordblks``)."""

    class MallInfo2(ctypes.Structure):
        _fields_ = [(k, ctypes.c_size_t) for k in ("a", "b", "c", "d", "e", "f", "g", "used")]
        _fields_ += [(k, ctypes.c_size_t) for k in ("free", "keep")]

    libc = ctypes.CDLL(None)
    libc.mallinfo2.restype = MallInfo2
    return libc.mallinfo2().used


@pytest.mark.skipif(not hasattr(ctypes.CDLL(None), "mallinfo2"), reason="needs glibc's mallinfo2")
def test_set_ups_updates_failures_and_drops_leak_nothing():
    """600 calls (set-ups, updates, a failed update, a refused set-up, resets) in one compiled
    loop: the C heap in use is the same after as before (DAQP's arrays all freed)."""
    good = [_box_qp([1.0, -2.0, 0.5]), _box_qp([0.2, 0.1, -0.3])]
    bad = _box_qp([1.0, -2.0, 0.5], lb=1.0, ub=-1.0)
    # update, failed update, set-up, reset, refused set-up, set-up, update
    cycle = [good[0], good[1], bad, good[0], None, bad, good[1], good[0]] * 75
    ops = np.array([RESET if p is None else SOLVE for p in cycle], dtype=np.int64)
    bufs = np.array([np.zeros(good[0].buffer.size) if p is None else p.buffer for p in cycle])
    st = daqp_c.make_state(3, 1, 2, get_backend("daqp").options())
    run = _driver(*daqp_c.compiled("daqp"))
    out = np.zeros((len(cycle), 6)), np.zeros((len(cycle), 4)), np.zeros(len(cycle), np.int64)
    run(st, bufs, ops, np.zeros(3), *out)  # compiles; ends with a workspace set up
    daqp_c.close_state(st)
    before = _heap_in_use()
    run(st, bufs, ops, np.zeros(3), *out)
    daqp_c.close_state(st)
    assert _heap_in_use() - before < 256  # a leak is 100s of bytes a set-up: 100 kB here
    assert set(out[2]) == {-1, 0, 1}


def test_a_run_that_fails_half_way_frees_everything_and_runs_again(controller_qps):
    """An exception between calls and one inside the compiled solve (a QP larger than the state):
    close_state (twice) frees the workspace; a new run gives the Python backend's answers."""
    problems, ops = _loop_sequence(controller_qps, "wall")
    problems, ops = problems[:60], ops[:60]
    st = daqp_c.make_state(4, 2, 7, get_backend("daqp").options())
    solve, _ = daqp_c.compiled("daqp")
    with pytest.raises(RuntimeError, match="half way"):
        try:
            for p in problems[:20]:
                if p is not None:
                    solve(st, p.buffer, np.zeros(4), np.zeros(13), np.zeros(4))
            assert st.meta[daqp_c.HAS_MODEL] == 1
            raise RuntimeError("the run failed half way")
        finally:
            daqp_c.close_state(st)
    daqp_c.close_state(st)
    assert st.meta[daqp_c.HAS_MODEL] == 0 and not st.work.any()
    small = daqp_c.make_state(4, 2, 0, get_backend("daqp").options())
    solve(small, controller_qps["free", "soft"][-1].buffer, np.zeros(4), np.zeros(6), np.zeros(4))
    assert small.meta[daqp_c.HAS_MODEL] == 1
    with pytest.raises(ValueError, match="larger than the state"):
        solve(small, problems[0].buffer, np.zeros(4), np.zeros(13), np.zeros(4))
    daqp_c.close_state(small)
    assert small.meta[daqp_c.HAS_MODEL] == 0
    _assert_same_as_python("daqp", problems, ops)


def test_an_unknown_daqp_version_is_refused_in_one_line(monkeypatch):
    reason = daqp_c.unavailable_reason("0.9.1")
    assert "daqp 0.9.1" in reason and "\n" not in reason and "Python engine" in reason
    monkeypatch.setattr(daqp_c, "installed_version", lambda: "0.12.0")
    with pytest.raises(RuntimeError, match="daqp 0.12.0"):
        daqp_c.make_state(4, 2, 0, {})


def test_bad_settings_are_refused_by_name():
    with pytest.raises(ParamError, match="primal_tolerance"):
        daqp_c.make_state(4, 2, 0, {"primal_tolerance": 1e-6})
    with pytest.raises(ParamError, match="iter_limit"):
        daqp_c.make_state(4, 2, 0, {"iter_limit": 1.5})


_CACHE_SCRIPT = textwrap.dedent(
    """
    import json, numpy as np, qpsolvers
    from qpbench.backends import daqp_c, get_backend
    from qpbench.packed import pack
    p = pack(qpsolvers.Problem(np.eye(2), np.ones(2), None, None, None, None, -np.ones(2), np.ones(2)))
    k = daqp_c.kernels()
    st = daqp_c.make_state(2, 0, 0, get_backend("daqp").options())
    for solve in (k.model, k.stateless, k.either):
        solve(st, p.buffer, np.zeros(2), np.zeros(2), np.zeros(4))
    k.reset(st)
    print(json.dumps({name: [sum(d.stats.cache_hits.values()), sum(d.stats.cache_misses.values())]
                      for name, d in k._asdict().items()}))
    """
)


@pytest.mark.slow
def test_the_kernels_load_from_numbas_cache_in_a_second_process():
    """In the session's kernel cache (the first process compiles what is not there yet; a cold
    cache is tests/test_warmup.py's), the second process compiles nothing: a kernel that could
    not be cached would be compiled again."""
    runs = []
    for _ in range(2):
        proc = subprocess.run(
            [sys.executable, "-c", _CACHE_SCRIPT], capture_output=True, text=True, timeout=900
        )
        assert proc.returncode == 0, proc.stderr
        runs.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    assert all(hits >= 1 and misses == 0 for hits, misses in runs[1].values()), runs
