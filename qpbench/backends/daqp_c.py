"""The backends ``daqp`` and ``daqp-stateless`` as compiled code calling DAQP's C API (exported
by the ``daqp`` extension): the solves a compiled closed loop makes each tick (:func:`kernels`).

They mirror :mod:`qpbench.backends.daqp_` call for call (stacking, settings, exit flags, duals).
The C structs live in numpy memory of a :class:`State`, their field offsets data of the state
(:data:`LAYOUTS`, per daqp version). The kernels detach their settings before
``free_daqp_workspace`` frees them, point ``sense`` back at their own array after
``free_daqp_ldp``, and drop the workspace a failed ``daqp_update_ldp`` resets.
"""

from __future__ import annotations

import ctypes
import importlib.metadata
import importlib.util
import math
from functools import cache
from typing import NamedTuple

import numpy as np

from ..exceptions import ParamError
from ..packed import ME, MI, OFF_A, OFF_B, OFF_G, OFF_H, OFF_LB, OFF_P, OFF_Q, OFF_UB
from ..statuses import TICK_STATUSES
from .daqp_ import EXITFLAGS, UNKNOWN_EXITFLAG

_int, _dbl, _ptr = ctypes.c_int, ctypes.c_double, ctypes.c_void_p


class _Problem011(ctypes.Structure):
    """``DAQPProblem`` of daqp 0.11.0 (``include/types.h``)."""

    _fields_ = [
        *[(k, _int) for k in ("n", "m", "ms")],
        *[(k, _ptr) for k in ("H", "f", "A", "bupper", "blower", "sense", "break_points")],
        ("nh", _int),
        ("problem_type", _int),
    ]


class _Settings011(ctypes.Structure):
    """``DAQPSettings`` of daqp 0.11.0 (``include/types.h``; 136 bytes)."""

    _fields_ = [
        *[(k, _dbl) for k in ("primal_tol", "dual_tol", "zero_tol", "pivot_tol", "progress_tol")],
        ("cycle_tol", _int),
        ("iter_limit", _int),
        *[(k, _dbl) for k in ("fval_bound", "eps_prox", "eta_prox", "rho_soft", "rel_subopt")],
        *[(k, _dbl) for k in ("abs_subopt", "sing_tol", "refactor_tol", "time_limit", "w_soft")],
        ("eq_reduction", _int),
        ("presolve", _int),
    ]


class _Result011(ctypes.Structure):
    """``DAQPResult`` of daqp 0.11.0 (``include/api.h``)."""

    _fields_ = [
        *[(k, _ptr) for k in ("x", "lam")],
        *[(k, _dbl) for k in ("fval", "soft_slack")],
        *[(k, _int) for k in ("exitflag", "iter", "nodes")],
        *[(k, _dbl) for k in ("solve_time", "setup_time")],
    ]


class _Workspace011(ctypes.Structure):
    """``DAQPWorkspace`` of daqp 0.11.0 (``include/types.h``; 328 bytes), field by field: only
    its size and the offsets of ``qp``, ``n``, ``m``, ``ms``, ``sense``, ``settings`` are used."""

    _fields_ = [
        ("qp", _ptr),
        *[(k, _int) for k in ("n", "m", "ms")],
        *[(k, _ptr) for k in ("M", "dupper", "dlower", "Rinv", "v", "sense", "scaling", "RinvD")],
        *[(k, _ptr) for k in ("x", "xold", "lam", "lam_star", "u")],
        ("fval", _dbl),
        *[(k, _ptr) for k in ("L", "D", "xldl", "zldl")],
        ("reuse_ind", _int),
        ("WS", _ptr),
        *[(k, _int) for k in ("n_active", "iterations", "sing_ind")],
        ("prox_mask", _ptr),
        ("n_prox", _int),
        ("soft_slack", _dbl),
        ("settings", _ptr),
        ("bnb", _ptr),
        ("outer_iter", _int),
        *[(k, _ptr) for k in ("hierarchy", "avi", "eq", "timer", "Mu")],
        *[(k, _ptr) for k in ("rho_ls", "rho_us", "w_ls", "w_us")],
        ("state", _int),
    ]


class Structs(NamedTuple):
    """The C structs of one daqp version, as ctypes structures."""

    problem: type[ctypes.Structure]
    settings: type[ctypes.Structure]
    result: type[ctypes.Structure]
    workspace: type[ctypes.Structure]


#: daqp version -> its structs, transcribed from that version's headers.
LAYOUTS = {"0.11.0": Structs(_Problem011, _Settings011, _Result011, _Workspace011)}

#: The C functions the kernels call (names as exported by the ``daqp`` extension).
C_FUNCTIONS = (
    "setup_daqp",
    "daqp_update_ldp",
    "daqp_solve",
    "daqp_quadprog",
    "free_daqp_workspace",
    "free_daqp_ldp",
    "daqp_default_settings",
)

# Entries of State.layout: byte offsets of the struct fields the kernels touch, the structs'
# sizes [bytes], DAQP's update masks and the sense of an equality row.
(P_N, P_M, P_MS, P_H, P_F, P_A, P_BU, P_BL, P_SENSE, P_BP, P_NH, P_TYPE) = range(12)
(R_X, R_LAM, R_EXIT, R_ITER, R_SOLVE, R_SETUP) = range(12, 18)
(W_QP, W_N, W_M, W_MS, W_SENSE, W_SETTINGS) = range(18, 24)
(SIZE_P, SIZE_S, SIZE_R, SIZE_W) = range(24, 28)
(U_RINV, U_M, U_V, U_D, U_SENSE, SENSE_EQ) = range(28, 34)
LAYOUT_SIZE = 34

#: ``DAQP_UPDATE_Rinv``, ``_M``, ``_v``, ``_d``, ``_sense`` and ``DAQP_ACTIVE |
#: DAQP_IMMUTABLE`` (an equality row) of ``include/constants.h`` (the same in every version).
_MASKS = (1, 2, 4, 8, 16, 5)

# Entries of State.meta: whether a workspace is set up, its shape key (n, me, mi, box), the
# capacity the state was made for, whether it is ``daqp-stateless``'s.
HAS_MODEL, KEY_N, KEY_ME, KEY_MI, KEY_BOX, N_MAX, ME_MAX, MI_MAX, STATELESS = range(9)

#: The status index of ``optimal``.
OPTIMAL = TICK_STATUSES.index("optimal")

#: Exit flags -FLAG_SPAN..FLAG_SPAN have an entry in State.statuses; the last entry is the
#: status of any other flag.
FLAG_SPAN = 16


#: What the kernels keep between calls, numpy memory only: the C structs (``*32``, ``resultf``:
#: int32 and float64 views), ``settings0`` (each set-up's start), the problem arrays, DAQP's
#: ``x`` and ``lam``, ``clock`` (set-up time [s]).
State = NamedTuple(
    "State",
    [
        (name, np.ndarray)
        for name in """layout statuses meta qp qp32 settings settings0 result result32 resultf work
        work32 H f A bu bl sense x lam clock""".split()
    ],
)


class Kernels(NamedTuple):
    """The compiled solves ``solve(st, buf, warm, sol, info) -> status`` of ``daqp``,
    ``daqp-stateless`` and ``either`` (as the state was made), and ``reset(st)``."""

    model: object
    stateless: object
    either: object
    reset: object


@cache
def installed_version() -> str | None:
    """The installed daqp distribution's version, or ``None``."""
    try:
        return importlib.metadata.version("daqp")
    except importlib.metadata.PackageNotFoundError:
        return None


def library_path() -> str | None:
    """The file of the ``daqp`` extension module (the library exporting DAQP's C API)."""
    spec = importlib.util.find_spec("daqp")
    return None if spec is None else spec.origin


def unavailable_reason(version: str | None = None) -> str | None:
    """``None`` when the compiled route can run ``version`` (default: installed), else why not."""
    version = installed_version() if version is None else version
    if version is None or library_path() is None:
        return "daqp is not installed: no compiled DAQP route"
    if version not in LAYOUTS:
        known = ", ".join(LAYOUTS)
        return (
            f"daqp {version}: the compiled DAQP route knows the C structs of daqp {known} only "
            "(the backend runs on the Python engine)"
        )
    lib = _library()
    missing = [name for name in C_FUNCTIONS if not hasattr(lib, name)]
    if missing:
        return f"daqp {version} at {library_path()} does not export {', '.join(missing)}"
    return None


@cache
def _library() -> ctypes.CDLL:
    return ctypes.CDLL(library_path())


def layout_of(structs: Structs) -> np.ndarray:
    """The State.layout entries (``P_*``, ``R_*``, ``W_*``, ``SIZE_*``, ``U_*``) of ``structs``."""
    p, s, r, w = structs
    out = np.zeros(LAYOUT_SIZE, dtype=np.int64)
    names = ("n", "m", "ms", "H", "f", "A", "bupper", "blower", "sense", "break_points", "nh")
    out[P_N : P_TYPE + 1] = [getattr(p, k).offset for k in (*names, "problem_type")]
    out[R_X : R_SETUP + 1] = [
        getattr(r, k).offset for k in ("x", "lam", "exitflag", "iter", "solve_time", "setup_time")
    ]
    out[W_QP : W_SETTINGS + 1] = [
        getattr(w, k).offset for k in ("qp", "n", "m", "ms", "sense", "settings")
    ]
    out[SIZE_P : SIZE_W + 1] = [ctypes.sizeof(t) for t in structs]
    out[U_RINV : SENSE_EQ + 1] = _MASKS
    return out


def settings_struct(structs: Structs, options: dict) -> np.ndarray:
    """``DAQPSettings`` as int64 words: DAQP's defaults with ``options`` (DAQP's names) over them.

    Raises:
        ParamError: an unknown option, or an integer one outside C's ``int``.
    """
    settings = structs.settings()
    _library().daqp_default_settings(ctypes.byref(settings))
    fields = dict(structs.settings._fields_)
    for key, value in options.items():
        kind = fields.get(key)
        if kind is None:
            raise ParamError(f"unknown DAQP setting '{key}' ({', '.join(fields)})", key=key)
        if kind is _int and (
            isinstance(value, bool) or value != int(value) or not -(2**31) <= value < 2**31
        ):
            raise ParamError(f"DAQP setting '{key}' must be a C int, got {value!r}", key=key)
        setattr(settings, key, int(value) if kind is _int else float(value))
    return _words(bytes(settings))


def _words(data: bytes) -> np.ndarray:
    """``data`` as zero-padded int64 words (8-byte aligned memory for a C struct)."""
    out = np.zeros(-(-len(data) // 8), dtype=np.int64)
    out.view(np.uint8)[: len(data)] = np.frombuffer(data, dtype=np.uint8)
    return out


def make_state(n: int, me_max: int, mi_max: int, options: dict, stateless: bool = False) -> State:
    """A state for at most ``n`` variables, ``me_max`` equality and ``mi_max`` inequality rows,
    DAQP's settings ``options``; ``stateless``: ``either`` runs ``daqp-stateless``.

    Raises:
        RuntimeError: the installed daqp is not one this route knows.
        ParamError: a bad option or size.
    """
    reason = unavailable_reason()
    if reason is not None:
        raise RuntimeError(reason)
    for key, value in (("n", n), ("me_max", me_max), ("mi_max", mi_max)):
        if int(value) != value or value < (1 if key == "n" else 0):
            raise ParamError(f"make_state: {key} = {value!r} is not a valid size", key=key)
    structs = LAYOUTS[installed_version()]
    layout = layout_of(structs)
    statuses = np.full(2 * FLAG_SPAN + 2, TICK_STATUSES.index(UNKNOWN_EXITFLAG[0]), dtype=np.int64)
    for flag, (status, _) in EXITFLAGS.items():
        statuses[flag + FLAG_SPAN] = TICK_STATUSES.index(status)
    meta = np.zeros(9, dtype=np.int64)
    meta[N_MAX], meta[ME_MAX], meta[MI_MAX], meta[STATELESS] = n, me_max, mi_max, stateless
    settings0 = settings_struct(structs, options)
    qp, result, work = (_words(bytes(int(layout[k]))) for k in (SIZE_P, SIZE_R, SIZE_W))
    rows, m = me_max + mi_max, n + me_max + mi_max
    structs = qp, qp.view(np.int32), settings0.copy(), settings0, result, result.view(np.int32)
    structs += result.view(np.float64), work, work.view(np.int32)
    H, f, A, bu, bl, x, lam, clock = map(np.zeros, (n * n, n, rows * n, m, m, n, m, 1))
    sense = np.zeros(m, dtype=np.int32)
    return State(layout, statuses, meta, *structs, H, f, A, bu, bl, sense, x, lam, clock)


def close_state(st: State) -> None:
    """Free what DAQP allocated for ``st`` (its workspace's arrays); safe to call again."""
    if st.meta[HAS_MODEL]:
        kernels().reset(st)


# C functions, bound by kernels() (ExternalFunctions resolved by name in the loaded library).
_c_setup = _c_update = _c_solve = _c_quadprog = _c_free_workspace = _c_free_ldp = None


@cache
def kernels() -> Kernels:
    """The compiled kernels (compiled, or loaded from numba's cache, on first call)."""
    from numba import types

    from ..native import load_permanently, njit

    reason = unavailable_reason()
    if reason is not None:
        raise RuntimeError(reason)
    load_permanently(library_path())
    p, i = types.intp, types.intc
    names = globals()
    names["_c_setup"] = types.ExternalFunction("setup_daqp", i(p, p, p))
    names["_c_update"] = types.ExternalFunction("daqp_update_ldp", i(i, p, p))
    names["_c_solve"] = types.ExternalFunction("daqp_solve", types.void(p, p))
    names["_c_quadprog"] = types.ExternalFunction("daqp_quadprog", types.void(p, p, p))
    names["_c_free_workspace"] = types.ExternalFunction("free_daqp_workspace", types.void(p))
    names["_c_free_ldp"] = types.ExternalFunction("free_daqp_ldp", types.void(p))
    jit = njit(_nrt=False)
    inline = njit(inline="always")  # no call, no refcounts
    for name in [k for k in names if k.endswith("_jit")]:
        names[name] = inline(names[name])
    return Kernels(jit(_solve_model), jit(_solve_stateless), jit(_solve_either), names["_drop_jit"])


def compiled(backend: str):
    """``(solve, reset)`` of backend ``daqp`` or ``daqp-stateless``."""
    k = kernels()
    if backend not in ("daqp", "daqp-stateless"):
        raise ParamError(f"no compiled DAQP route for backend '{backend}'", key="backend")
    return (k.model if backend == "daqp" else k.stateless), k.reset


# ---------------------------------------------------------------- compiled code (numba)
# Pointers are written as int64 words at offset // 8, ints as int32 at offset // 4.


def _shape(st, buf):
    """``(n, me, mi, nb)`` of the packed problem ``buf`` (``nb``: box rows, n or 0)."""
    n, me, mi = int(buf[0]), int(buf[ME]), int(buf[MI])
    meta = st.meta
    if n > meta[N_MAX] or me > meta[ME_MAX] or mi > meta[MI_MAX]:
        raise ValueError("daqp: the problem is larger than the state was made for")
    nb = n if (buf[OFF_LB] >= 0 or buf[OFF_UB] >= 0) else 0
    return n, me, mi, nb


def _stack(st, buf, n, me, mi, nb):
    """Write ``A = [A_eq; G]``, ``bu = [ub; b; h]``, ``bl = [lb; b; -inf]`` and the sense flags
    (equality rows: ``layout[SENSE_EQ]``) of ``buf`` into the state's arrays."""
    A, bu, bl, sense = st.A, st.bu, st.bl, st.sense
    oA, ob, oG, oh = int(buf[OFF_A]), int(buf[OFF_B]), int(buf[OFF_G]), int(buf[OFF_H])
    for k in range(me * n):
        A[k] = buf[oA + k]
    for k in range(mi * n):
        A[me * n + k] = buf[oG + k]
    olb, oub = int(buf[OFF_LB]), int(buf[OFF_UB])
    for k in range(nb):
        bu[k] = buf[oub + k] if oub >= 0 else math.inf
        bl[k] = buf[olb + k] if olb >= 0 else -math.inf
        sense[k] = 0
    eq = st.layout[SENSE_EQ]
    for k in range(me):
        bu[nb + k] = bl[nb + k] = buf[ob + k]
        sense[nb + k] = eq
    for k in range(mi):
        bu[nb + me + k] = buf[oh + k]
        bl[nb + me + k] = -math.inf
        sense[nb + me + k] = 0


def _copy_changed(buf, off, dst, size):
    """Copy ``buf[off : off + size]`` into ``dst``; whether any differed bitwise (NaNs equal)."""
    changed = False
    for k in range(size):
        a, b = buf[off + k], dst[k]
        if a == b:
            differ = math.copysign(1.0, a) != math.copysign(1.0, b)
        else:
            differ = not (a != a and b != b)
        if differ:
            changed = True
            dst[k] = a
    return changed


def _fresh_settings(st):
    """The profile's settings into the struct DAQP reads (word by word: no numba error path)."""
    for k in range(st.settings0.shape[0]):
        st.settings[k] = st.settings0[k]


def _point_problem(st, n, m, nb, rows):
    """Fill ``DAQPProblem`` with the state's arrays, as ``daqp.Model.setup`` does."""
    lay, qp, qp32 = st.layout, st.qp, st.qp32
    qp32[lay[P_N] >> 2] = n
    qp32[lay[P_M] >> 2] = m
    qp32[lay[P_MS] >> 2] = nb
    qp[lay[P_H] >> 3] = st.H.ctypes.data
    qp[lay[P_F] >> 3] = st.f.ctypes.data
    qp[lay[P_A] >> 3] = st.A.ctypes.data if rows else 0
    qp[lay[P_BU] >> 3] = st.bu.ctypes.data if m else 0
    qp[lay[P_BL] >> 3] = st.bl.ctypes.data if m else 0
    qp[lay[P_SENSE] >> 3] = st.sense.ctypes.data if m else 0
    qp[lay[P_BP] >> 3] = 0
    qp32[lay[P_NH] >> 2] = 0
    qp32[lay[P_TYPE] >> 2] = 0


def _clear_result(st, m):
    """``DAQPResult`` zeroed, pointing at the state's ``x`` and (with constraints) ``lam``."""
    lay, res = st.layout, st.result
    res[:] = 0
    res[lay[R_X] >> 3] = st.x.ctypes.data
    res[lay[R_LAM] >> 3] = st.lam.ctypes.data if m else 0


def _outcome(st, flag, n, me, mi, nb, sol):
    """The status of exit ``flag``; ``[x; y; z]`` into ``sol`` when optimal, else NaN."""
    statuses = st.statuses
    span = (statuses.shape[0] - 2) // 2
    status = statuses[flag + span] if -span <= flag <= span else statuses[-1]
    if status == OPTIMAL:
        x, lam = st.x, st.lam
        for k in range(n):
            sol[k] = x[k]
        for k in range(me + mi):
            sol[n + k] = lam[nb + k]
    else:
        for k in range(n + me + mi):
            sol[k] = math.nan
    return status


def _drop(st):
    """Free DAQP's arrays of a set-up workspace (settings detached first); ``sense`` back home."""
    lay, meta = st.layout, st.meta
    if meta[HAS_MODEL]:
        work = st.work
        work[lay[W_SETTINGS] >> 3] = 0
        _c_free_workspace(work.ctypes.data)
        _c_free_ldp(work.ctypes.data)
        work[:] = 0
        meta[HAS_MODEL] = 0
    st.qp[lay[P_SENSE] >> 3] = st.sense.ctypes.data


def _set_up(st, buf, n, m, nb, rows):
    """``setup_daqp`` on a zeroed workspace with the profile's settings; its exit flag."""
    lay, work = st.layout, st.work
    _fresh_settings_jit(st)
    work[:] = 0
    work[lay[W_SETTINGS] >> 3] = st.settings.ctypes.data
    _copy_changed_jit(buf, int(buf[OFF_P]), st.H, n * n)
    _copy_changed_jit(buf, int(buf[OFF_Q]), st.f, n)
    _point_problem_jit(st, n, m, nb, rows)
    st.x[:] = 0.0
    st.lam[:] = 0.0
    flag = _c_setup(st.qp.ctypes.data, work.ctypes.data, st.clock.ctypes.data)
    if flag < 0:
        work[:] = 0
    else:
        st.meta[HAS_MODEL] = 1
    return flag


def _update(st, buf, n, m, rows):
    """``daqp_update_ldp`` as ``daqp.Model.update``: ``H``, ``f`` only when changed."""
    lay = st.layout
    mask = 0
    if _copy_changed_jit(buf, int(buf[OFF_P]), st.H, n * n):
        mask |= lay[U_RINV]
    if _copy_changed_jit(buf, int(buf[OFF_Q]), st.f, n):
        mask |= lay[U_V]
    if rows:
        mask |= lay[U_M]
    if m:
        mask |= lay[U_D]
    if mask & (lay[U_RINV] | lay[U_M]):  # the workspace's own constraint states
        st.qp[lay[P_SENSE] >> 3] = st.work[lay[W_SENSE] >> 3]
        mask |= lay[U_SENSE]
    return _c_update(np.int32(mask), st.work.ctypes.data, st.qp.ctypes.data)


def _solve_model(st, buf, warm, sol, info):
    """One call of backend ``daqp`` (``warm`` ignored, as there); the status index."""
    n, me, mi, nb = _shape_jit(st, buf)
    rows, m = me + mi, nb + me + mi
    _stack_jit(st, buf, n, me, mi, nb)
    meta = st.meta
    box = 1 if nb else 0
    if meta[HAS_MODEL] and (
        meta[KEY_N] != n or meta[KEY_ME] != me or meta[KEY_MI] != mi or meta[KEY_BOX] != box
    ):
        _drop_jit(st)
    meta[KEY_N], meta[KEY_ME], meta[KEY_MI], meta[KEY_BOX] = n, me, mi, box
    if meta[HAS_MODEL]:
        flag = _update_jit(st, buf, n, m, rows)
        if flag < 0:
            _drop_jit(st)
    else:
        flag = _set_up_jit(st, buf, n, m, nb, rows)
    if flag < 0:  # refused: the status alone, as read_result without a solve's info
        info[0] = info[1] = math.nan
        info[2] = flag
        return _outcome_jit(st, flag, n, me, mi, nb, sol)
    lay, work = st.layout, st.work
    _clear_result_jit(st, st.work32[lay[W_M] >> 2])
    _c_solve(st.result.ctypes.data, work.ctypes.data)
    flag = st.result32[lay[R_EXIT] >> 2]
    info[0] = 0.0 + st.resultf[lay[R_SOLVE] >> 3]
    info[1] = st.result32[lay[R_ITER] >> 2]
    info[2] = flag
    status = _outcome_jit(st, flag, n, me, mi, nb, sol)
    if status != OPTIMAL:
        _drop_jit(st)  # set up afresh on the next call
    return status


def _solve_stateless(st, buf, warm, sol, info):
    """One call of backend ``daqp-stateless`` (``daqp_quadprog``, as ``daqp.solve``)."""
    n, me, mi, nb = _shape_jit(st, buf)
    rows, m = me + mi, nb + me + mi
    _stack_jit(st, buf, n, me, mi, nb)
    _copy_changed_jit(buf, int(buf[OFF_P]), st.H, n * n)
    _copy_changed_jit(buf, int(buf[OFF_Q]), st.f, n)
    _fresh_settings_jit(st)
    _point_problem_jit(st, n, m, nb, rows)
    _clear_result_jit(st, m)
    _c_quadprog(st.result.ctypes.data, st.qp.ctypes.data, st.settings.ctypes.data)
    lay = st.layout
    flag = st.result32[lay[R_EXIT] >> 2]
    info[0] = st.resultf[lay[R_SETUP] >> 3] + st.resultf[lay[R_SOLVE] >> 3]
    info[1] = st.result32[lay[R_ITER] >> 2]
    info[2] = flag
    return _outcome_jit(st, flag, n, me, mi, nb, sol)


def _solve_either(st, buf, warm, sol, info):
    """The solve of ``daqp-stateless`` or ``daqp``, as ``st`` was made."""
    if st.meta[STATELESS]:
        return _solve_stateless_jit(st, buf, warm, sol, info)
    return _solve_model_jit(st, buf, warm, sol, info)


# Rebound to compiled versions by kernels() (numba resolves them from these globals).
_shape_jit = _shape
_stack_jit = _stack
_copy_changed_jit = _copy_changed
_point_problem_jit = _point_problem
_fresh_settings_jit = _fresh_settings
_clear_result_jit = _clear_result
_outcome_jit = _outcome
_drop_jit = _drop
_set_up_jit = _set_up
_update_jit = _update
_solve_model_jit = _solve_model
_solve_stateless_jit = _solve_stateless
