"""Backend ``qpoases``: qpOASES (online active set) with hotstart, through a compiled shim.

``min 1/2 x'Hx + g'x  s.t.  lb <= x <= ub,  lbA <= A x <= ubA`` with ``A = [A_eq; G]``,
``lbA = [b; -inf]``, ``ubA = [b; h]``, written into the shim's buffer (:mod:`._qpoases_shim`).
``init()`` on the first tick of a shape and after a status other than optimal, else
``hotstart()``; ``warm_start`` is ignored. Settings: ``max_iter`` -> ``nWSR``, ``time_limit``
[s], ``preset`` (:data:`PRESETS`), :data:`OPTION_NAMES`. ``solver_time_s``: the shim's
``CLOCK_MONOTONIC`` time (qpOASES' own in ``extras["qpoases_cputime_s"]``). The same solver
for compiled closed loops: :func:`make_state`, :func:`compiled`, :func:`close_state`.
"""

from __future__ import annotations

import ctypes
import weakref
from functools import cache
from typing import NamedTuple

import numpy as np

from ..exceptions import ParamError
from ..statuses import TICK_STATUSES
from . import _qpoases_shim as shim
from . import register
from ._common import (
    GENERIC_KEYS,
    check_shapes,
    dense_parts,
    generic_settings,
    refuse_unknown,
)
from ._qpoases_shim import OPTION_NAMES, PRESETS, Workspace
from .base import Backend, ViewSolution, new_solution

#: Shim status -> our status.
_STATUSES = {
    0: "optimal",
    1: "max_iter",
    2: "time_limit",
    -2: "primal_infeasible",
    -3: "dual_infeasible",
    -1: "error",
}


@register
class QpoasesBackend(Backend):
    """qpOASES ``SQProblem``: ``init()`` on the first tick of a shape, ``hotstart()`` on the next ones."""

    name = "qpoases"
    certifies_infeasibility = True
    family = "active set (online, parametric)"
    package = "cmeel-qpoases"
    module = None

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """The generic settings, ``preset`` and :data:`OPTION_NAMES`."""
        return frozenset(OPTION_NAMES) | {"preset"} | frozenset(GENERIC_KEYS)

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self._ws: Workspace | None = None
        generic, native = generic_settings(self)
        preset = native.pop("preset", "default")
        if preset not in PRESETS:
            raise ParamError(
                f"unknown preset '{preset}' for backend 'qpoases' (one of: {', '.join(PRESETS)})",
                key="preset",
            )
        self._preset = PRESETS[preset]
        refuse_unknown("qpoases", native, OPTION_NAMES, "preset, or qpOASES options")
        self._native = native
        self._nwsr = int(min(generic["max_iter"], 2**31 - 1))
        limit = generic["time_limit"]
        self._time_limit = float(limit) if limit is not None and np.isfinite(limit) else 0.0
        self._lib = self.prepare()

    @classmethod
    def prepare(cls) -> ctypes.CDLL:
        """Compile the shim if needed and load it (idempotent; call it before timing anything)."""
        return shim.load()

    @classmethod
    def needs_compile(cls) -> bool:
        """Whether :meth:`prepare` would compile the shim (neither loaded nor built yet)."""
        prefix = shim.qpoases_prefix()
        return not shim.LOADED and not (prefix and shim.shim_path(prefix).is_file())

    @classmethod
    def unavailable_reason(cls) -> str | None:
        if shim.qpoases_prefix() is None:
            return "cmeel-qpoases is not installed (pip install cmeel-qpoases)"
        if cls.needs_compile() and shim.compiler() is None:
            return "no C++ compiler ($CXX, g++ or c++) to build the qpOASES shim"
        return None

    def reset(self) -> None:
        self._ws = None

    def workspace(self, key: tuple[int, int, int, bool], **buffers) -> Workspace:
        """A :class:`Workspace` of shape ``key`` with this backend's options (``buffers``: its
        ``d`` and ``iv``)."""
        return Workspace(
            key, self._lib, self._preset, self._native, self._nwsr, self._time_limit, **buffers
        )

    def _solve(self, problem, warm_start):
        P, q, A, b = problem.P, problem.q, problem.A, problem.b
        G, h, lb, ub = problem.G, problem.h, problem.lb, problem.ub
        # Types only (each copy below converts to float64), written out: a tick pays no call.
        if not (
            type(P) is _ndarray
            and type(q) is _ndarray
            and q.ndim == 1
            and (A is None or (type(A) is _ndarray and type(b) is _ndarray))
            and (G is None or (type(G) is _ndarray and type(h) is _ndarray))
            and (lb is None or type(lb) is _ndarray)
            and (ub is None or type(ub) is _ndarray)
        ):
            P, q, A, b, G, h, lb, ub = dense_parts(problem)
        # The sizes decide: a copy into a buffer of another size raises, one of the same size
        # cannot broadcast; check_shapes names the array when the sizes changed or a copy raised.
        # Written out like _common.shapes, not a call to it: a call per tick shows in
        # bench/backend_overhead.py (alternating runs, bench/README).
        sizes = (
            P.size,
            q.size,
            None if A is None else A.size,
            None if b is None else b.size,
            None if G is None else G.size,
            None if h is None else h.size,
            None if lb is None else lb.size,
            None if ub is None else ub.size,
        )
        ws = self._ws
        if ws is None or sizes != ws.sizes:  # the workspace of this shape (checked here)
            me, mi = check_shapes(self.name, q.shape[0], P, A, b, G, h, lb, ub)
            key = (q.shape[0], me, mi, lb is not None or ub is not None)
            if ws is None or ws.key != key:
                self._ws = None
                ws = self._ws = self.workspace(key)
            ws.sizes = sizes
        n, me, mi, box = ws.key
        try:
            ws.H[:] = P
            ws.g[:] = q
            if me:
                ws.A_eq[:] = A
                ws.lbA_eq[:] = b
                ws.ubA_eq[:] = b
            if mi:
                ws.A_in[:] = G
                ws.ubA_in[:] = h
            if box:
                ws.lb[:] = -_INF if lb is None else lb
                ws.ub[:] = _INF if ub is None else ub
        except ValueError:
            ws.sizes = None
            check_shapes(self.name, q.shape[0], P, A, b, G, h, lb, ub)
            raise
        st = self._lib.qpb_solve(ws.handle)
        obj, _, solve_time, cputime = ws.s.tolist()
        _, _, iterations, raw, _ = ws.iv.tolist()
        extras = {"raw_status": raw, "qpoases_cputime_s": cputime}
        sol = new_solution(problem, _STATUSES[st], extras, ViewSolution)
        sol.iterations = iterations
        sol.solver_time_s = solve_time
        if st == 0:  # x and the multipliers: one copy, x a view of it (the duals on first read)
            out = sol._out = ws.xy.copy()
            parts = sol._slices = ws.parts
            sol.x = out[parts[0]]
            sol._obj = obj
        elif st == -1:
            sol.error = raw_message(raw)
        return sol


_INF = np.inf
_ndarray = np.ndarray


# -- the compiled route: QpoasesBackend on a packed problem, one workspace per shape, made
# afresh (qpb_renew) on a change of shape and after reset(), as the backend would.


class State(NamedTuple):
    """What the compiled ``solve`` keeps between calls: ``table`` (a row per shape: ``n, me,
    mi, box``, the ``SQProblem``'s address (0: freed), the offsets in ``data`` of the shim's
    buffers), ``data`` (the shapes' ``d`` end to end), ``iv`` (the shim's, a row per shape),
    ``current`` (the row last solved; -1: make the solver afresh)."""

    table: np.ndarray
    data: np.ndarray
    iv: np.ndarray
    current: np.ndarray


#: Columns of :attr:`State.table`.
_N, _ME, _MI, _BOX, _HANDLE, _H, _G, _A, _LB, _UB, _LBA, _UBA, _XY, _S = range(14)
#: Shim status + 3 -> index in :data:`~qpbench.statuses.TICK_STATUSES`.
_STATUS_INDEX = tuple(TICK_STATUSES.index(_STATUSES[code]) for code in range(-3, 3))


def make_state(n: int, me_max: int, mi_max: int, profile="default", **settings) -> State:
    """The compiled solve's state for QPs of ``n`` variables, ``mi_max`` inequality rows and
    ``me_max`` or no equality rows, with bounds; ``profile``, ``settings`` as the backend's."""
    backend = QpoasesBackend(profile, **settings)
    shapes = sorted({(n, me_max, mi_max, True), (n, 0, mi_max, True)}, reverse=True)
    ends = [shim.layout(k[0], k[1] + k[2]) for k in shapes]
    starts = np.cumsum([0] + [e[-1] for e in ends])
    table = np.zeros((len(shapes), _S + 1), dtype=np.int64)
    st = State(
        table,
        np.zeros(starts[-1]),
        np.zeros((len(shapes), 5), dtype=np.intc),
        -np.ones(1, dtype=np.int64),
    )
    free = backend._lib.qpb_free
    weakref.finalize(st.data, _free_handles, free, table)  # handles freed with the buffers
    for k, (key, e, start) in enumerate(zip(shapes, ends, starts)):
        ws = backend.workspace(key, d=st.data[start : start + e[-1]], iv=st.iv[k])
        table[k, :_HANDLE] = key
        table[k, _HANDLE] = ws.detach()
        table[k, _H:] = start + e[:-1]
    return st


def close_state(st: State) -> None:
    """Free the solvers of ``st`` (safe to call twice; a solve on ``st`` after this raises)."""
    _free_handles(shim.load().qpb_free, st.table)


def _free_handles(free, table: np.ndarray) -> None:
    """``free`` each solver of ``table`` still held, marking it freed (0)."""
    for row in table:
        handle, row[_HANDLE] = int(row[_HANDLE]), 0
        if handle:
            free(handle)


@cache
def compiled():
    """``(solve, reset)`` of the solver protocol of compiled closed loops (compiled on first call)."""
    from numba import types

    from ..native import load_permanently, njit

    shim.load()
    load_permanently(str(shim.shim_path(shim.qpoases_prefix())))
    globals()["_qpb_solve"] = types.ExternalFunction("qpb_solve", types.intc(types.intp))
    globals()["_qpb_renew"] = types.ExternalFunction("qpb_renew", types.void(types.intp))
    jit = njit()
    return jit(_solve_py), jit(_reset_py)


def _solve_py(st, buf, warm, sol, info):  # pragma: no cover - compiled
    """Solve the packed problem ``buf`` as :meth:`QpoasesBackend.solve`: ``[x; y; z]`` (NaN
    unless optimal) into ``sol``, the shim's time [s], ``nWSR`` done, the return value and
    qpOASES' CPU time [s] into ``info``; the status index. An unknown shape raises."""
    n, me, mi = int(buf[0]), int(buf[1]), int(buf[2])
    m = me + mi
    oP, oq, oA, ob = int(buf[3]), int(buf[4]), int(buf[5]), int(buf[6])
    oG, oh, olb, oub = int(buf[7]), int(buf[8]), int(buf[9]), int(buf[10])
    box = 1 if olb >= 0 or oub >= 0 else 0
    table = st.table
    k = -1
    for r in range(table.shape[0]):
        if table[r, _N] == n and table[r, _ME] == me and table[r, _MI] == mi:
            k = r if table[r, _BOX] == box else k
    if k < 0:
        raise ValueError("qpoases: a QP of a shape make_state was not given")
    row = table[k]
    handle = row[_HANDLE]
    if handle == 0:
        raise ValueError("qpoases: solve on a closed state")
    if st.current[0] != k:  # another shape than the last call's, or after reset: a new solver
        _qpb_renew(handle)  # noqa: F821 - bound by compiled()
        st.current[0] = k
    # the backend's fills: H, g; A = [A_eq; G], lbA = [b; -inf] (set once), ubA = [b; h]
    d, H, A, lbA, ubA = st.data, row[_H], row[_A], row[_LBA], row[_UBA]
    d[H : H + n * n] = buf[oP : oP + n * n]
    d[row[_G] : row[_G] + n] = buf[oq : oq + n]
    if me:
        d[A : A + me * n] = buf[oA : oA + me * n]
        d[lbA : lbA + me] = buf[ob : ob + me]
        d[ubA : ubA + me] = buf[ob : ob + me]
    if mi:
        d[A + me * n : A + m * n] = buf[oG : oG + mi * n]
        d[ubA + me : ubA + m] = buf[oh : oh + mi]
    for j in range(n):  # a missing bound: +-inf, as the backend's
        d[row[_LB] + j] = buf[olb + j] if olb >= 0 else -np.inf
        d[row[_UB] + j] = buf[oub + j] if oub >= 0 else np.inf
    code = _qpb_solve(handle)  # noqa: F821 - bound by compiled()
    s, iv = row[_S], st.iv[k]
    info[0], info[1], info[2], info[3] = d[s + 2], iv[2], iv[3], d[s + 3]
    if code == 0:
        xy = row[_XY]
        for j in range(n):
            sol[j] = d[xy + j]
        for j in range(m):  # y, then z: after x and the bounds' multipliers
            sol[n + j] = d[xy + 2 * n + j]
    else:
        for j in range(n + m):
            sol[j] = np.nan
    return _STATUS_INDEX[code + 3]


def _reset_py(st):  # pragma: no cover - compiled
    """:meth:`QpoasesBackend.reset`: the next call makes its solver afresh."""
    st.current[0] = -1


def raw_message(raw: int) -> str:
    """qpOASES' message for return value ``raw``, as the backend's ``error`` says it."""
    message = shim.load().qpb_message(raw)
    text = message.decode(errors="replace") if message else ""
    return f"qpOASES return value {raw}: {text}"
