"""What the backend modules share: settings, and a problem's arrays in the forms solvers take."""

from __future__ import annotations

import importlib
import math
from functools import cache
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as spa

from ..exceptions import ParamError, ProblemFormatError
from ..memory import DENSE_MAX_ENTRIES, dense_entries

if TYPE_CHECKING:
    import qpsolvers

    from .base import Backend

#: An empty, read-only vector: the multipliers of an absent block.
EMPTY = np.zeros(0)
EMPTY.flags.writeable = False

#: A solver's module by name, imported on first use.
solver_module = cache(importlib.import_module)

#: Setting names every backend understands; the profile provides their values.
GENERIC_KEYS = ("eps_abs", "eps_rel", "max_iter", "time_limit")


def generic_settings(backend: Backend) -> tuple[dict, dict]:
    """``(generic, native)``: :data:`GENERIC_KEYS` (the profile's, overridden by the user's),
    and the user's other settings."""
    generic = {key: getattr(backend.profile, key) for key in GENERIC_KEYS}
    native = {}
    for key, value in backend.settings.items():
        (generic if key in generic else native)[key] = value
    return generic, native


#: Each solver's names for the generic settings, as qpbenchmark's ``SolverSettings`` plus
#: iteration limits: native name -> generic key, or a function of ``(eps_abs, eps_rel,
#: max_iter, time_limit)``.
_NATIVE: dict[str, dict[str, object]] = {
    "clarabel": {
        "tol_feas": "eps_abs",
        "tol_gap_abs": "eps_abs",
        "tol_gap_rel": "eps_rel",
        "max_iter": lambda e, r, k, t: min(k, 2**32 - 1),  # Clarabel's u32
        "time_limit": "time_limit",
    },
    "daqp": {"primal_tol": "eps_abs", "dual_tol": "eps_abs", "iter_limit": "max_iter"},
    "highs": {
        "primal_feasibility_tolerance": "eps_abs",
        "dual_feasibility_tolerance": "eps_abs",
        "time_limit": "time_limit",
    },
    "osqp": {key: key for key in ("eps_abs", "eps_rel", "max_iter", "time_limit")},
    "piqp": {
        "eps_abs": "eps_abs",
        "eps_rel": "eps_rel",
        "eps_duality_gap_abs": "eps_abs",
        "eps_duality_gap_rel": "eps_rel",
        "max_iter": "max_iter",
    },
    "scs": {
        "eps_abs": "eps_abs",
        "eps_rel": "eps_rel",
        "max_iters": "max_iter",
        "time_limit_secs": "time_limit",
    },
    # qpbenchmark sets feastol only; the gap tolerances (defaults 1e-7 absolute, 1e-6 relative)
    # would stop cvxopt far from a 1e-9 answer.
    "cvxopt": {
        "feastol": "eps_abs",
        "abstol": "eps_abs",
        "reltol": lambda e, r, k, t: max(r, e),
        "maxiters": "max_iter",
    },
    # qpbenchmark's (feastol only): tighter gap tolerances make ECOS's dual residual worse, not better.
    "ecos": {"feastol": "eps_abs"},
    # qpbenchmark's; Gurobi refuses tolerances below 1e-9 (a GurobiError: status error; high_accuracy asks 1e-9).
    "gurobi": {"FeasibilityTol": "eps_abs", "OptimalityTol": "eps_abs", "TimeLimit": "time_limit"},
    "hpipm": {
        "tol_dual_gap": "eps_abs",
        "tol_eq": "eps_abs",
        "tol_ineq": "eps_abs",
        "tol_stat": "eps_abs",
    },
    "qpswift": {"RELTOL": lambda e, r, k, t: e * np.sqrt(3.0)},
    "qpoases": {"time_limit": "time_limit"},
    "sip": {"eps_abs": "eps_abs", "eps_rel": "eps_rel", "time_limit": "time_limit"},
}
_NATIVE["proxqp"] = _NATIVE["piqp"]
_NATIVE["kvxopt"] = _NATIVE["cvxopt"]
_NATIVE["qpalm"] = _NATIVE["osqp"]

#: Options added at ``eps_abs <= 1e-7`` (the ``high_accuracy`` profile).
_HIGH_ACCURACY = {
    "osqp": {"polishing": True},
    "piqp": {"check_duality_gap": True},
    "proxqp": {"check_duality_gap": True},
}


def native_settings(
    solver: str, eps_abs: float, eps_rel: float, max_iter: int, time_limit: float
) -> dict:
    """qpsolvers keyword arguments for the generic settings (``time_limit`` [s]); ``{}`` for a
    solver without a translation."""
    names = _NATIVE.get(solver)
    if names is None:
        return {}
    generic = dict(eps_abs=eps_abs, eps_rel=eps_rel, max_iter=int(max_iter), time_limit=time_limit)
    args = tuple(generic.values())
    settings = {
        name: generic[key] if type(key) is str else key(*args) for name, key in names.items()
    }
    if eps_abs <= 1e-7:
        settings.update(_HIGH_ACCURACY.get(solver, {}))
    return settings


def solver_options(backend: Backend, solver: str, names: dict | None = None) -> dict:
    """The options an own-API backend gives ``solver``, as the ``qpsolvers:<solver>`` route:
    the generic settings in the solver's names (``names``: native name -> ``(generic key,
    conversion)``, ``None`` setting nothing; default :func:`native_settings`), then the user's
    others. Under a ``qpbenchmark:<settings>`` profile, qpbenchmark's arguments instead of
    the profile's generic settings."""
    generic, native = generic_settings(backend)
    given = backend.profile.solver_options
    if given is None:
        own = _translate(generic, names) if names else native_settings(solver, **generic)
        return {**own, **native}
    user = {k: v for k, v in backend.settings.items() if k in GENERIC_KEYS}
    user = _translate(user, names) if names else {k: user[k] for k in user if k in _NATIVE[solver]}
    return {**given.get(solver, {}), **user, **native}


def _translate(generic: dict, names: dict) -> dict:
    out = {}
    for name, (key, convert) in names.items():
        value = convert(generic[key]) if key in generic else None
        if value is not None:
            out[name] = value
    return out


def refuse_unknown(backend: str, native: dict, allowed, own: str) -> None:
    """Raise :class:`~qpbench.exceptions.ParamError` on the first key of ``native`` not allowed."""
    for key in native:
        if key not in allowed:
            raise ParamError(
                f"unknown setting '{key}' for backend '{backend}' ({own}: "
                f"{', '.join(allowed)}; generic: {', '.join(GENERIC_KEYS)})",
                key=key,
            )


def own_settings(obj: object) -> set[str]:
    """The public data attributes of a solver's settings object (its setting names)."""
    return {a for a in dir(obj) if not a.startswith("_") and not callable(getattr(obj, a))}


def dense_bounds(problem: qpsolvers.Problem, n: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``(lb, ub)`` as full float vectors, or ``(None, None)`` when the problem has no box."""
    lb, ub = problem.lb, problem.ub
    if lb is None and ub is None:
        return None, None
    lb = np.full(n, -np.inf) if lb is None else np.asarray(lb, dtype=float)
    ub = np.full(n, np.inf) if ub is None else np.asarray(ub, dtype=float)
    return lb, ub


def as_dense(M: np.ndarray | spa.spmatrix | spa.sparray) -> np.ndarray:
    """A dense float array of a dense or scipy.sparse matrix."""
    if type(M) is np.ndarray and M.dtype == np.float64:
        return M
    if spa.issparse(M):
        return M.toarray()
    return np.asarray(M, dtype=float)


def all_dense(*matrices: object) -> bool:
    """True when every given matrix is a numpy array or None."""
    return all(M is None or type(M) is np.ndarray for M in matrices)


class StackedCsc:
    """CSC patterns of ``P``'s upper triangle and of ``C = [D; s_1 I[idx_1]; ...]``: the
    ``blocks`` (``D``) over rows ``idx`` of ``s I`` per ``(s, idx)`` of ``eyes``. Dense
    matrices are stored with every entry (docs/architecture.md, "Backends")."""

    def __init__(self, P, blocks: list, eyes: list[tuple[float, np.ndarray]], n: int):
        self.n, self.eyes = n, eyes
        k = sum(M.shape[0] for M in blocks)
        self.rows = k + sum(idx.size for _, idx in eyes)
        self.dense = all_dense(P, *blocks)
        self.structure = ()
        if self.dense:  # every entry stored: the pattern of all-ones blocks
            P, blocks = np.ones((n, n)), [np.ones((k, n))]
            kept = np.ones((n, k + len(eyes)), bool)  # C's data is D' (C order) where kept
            for i, (_, idx) in enumerate(eyes):
                kept[:, k + i] = np.isin(np.arange(n), idx)
            self._C_mask = None if kept.all() else kept.ravel()
            self._D = np.empty((k + len(eyes), n))  # [D; s_1; s_2 ...]: C' in C order, unmasked
            self._D[k:] = np.array([sign for sign, _ in eyes]).reshape(-1, 1)
        Pc, Cc = self._sparse(P, blocks)
        self.P_indices, self.P_indptr = Pc.indices, Pc.indptr
        self.C_indices, self.C_indptr = Cc.indices, Cc.indptr
        if self.dense:
            #: ``P[P_index]`` is the data vector of ``P``'s upper triangle.
            self.P_index = (Pc.indices.astype(np.intp), np.repeat(np.arange(n), np.diff(Pc.indptr)))
        else:
            self.structure = structure_key(Pc, Cc)

    def _sparse(self, P, blocks) -> tuple[spa.csc_matrix, spa.csc_matrix]:
        P = spa.triu(spa.csc_matrix(P, dtype=float), format="csc")
        C = [spa.csc_matrix(M, dtype=float) for M in blocks]
        eye = spa.identity(self.n, format="csr")
        C += [sign * eye[idx] for sign, idx in self.eyes if idx.size]
        C = spa.vstack(C, format="csc") if C else spa.csc_matrix((0, self.n))
        P.sort_indices()
        C.sort_indices()
        return P, C

    def data(self, P, blocks) -> tuple[np.ndarray, np.ndarray]:
        """``(P_data, C_data)`` of a problem's ``P`` and ``blocks`` in this pattern's order."""
        if not self.dense:
            P, C = self._sparse(P, blocks)
            return P.data, C.data
        D = self._D  # its identity rows already set
        row = 0
        for M in blocks:
            D[row : row + M.shape[0]] = M
            row += M.shape[0]
        C_data = D.T.flatten()
        return P[self.P_index], C_data if self._C_mask is None else C_data[self._C_mask]

    def matrices(self, P, blocks) -> tuple[spa.csc_matrix, spa.csc_matrix]:
        """``(P, C)`` as CSC matrices of this pattern."""
        P_data, C_data = self.data(P, blocks)
        n = self.n
        P = spa.csc_matrix((P_data, self.P_indices, self.P_indptr), shape=(n, n))
        return P, spa.csc_matrix((C_data, self.C_indices, self.C_indptr), shape=(self.rows, n))


def finite_mask(problem: qpsolvers.Problem, n: int) -> tuple[bool, np.ndarray]:
    """``(with_box, kept)``: whether there are bounds, and which rows of ``[G; lb; ub]`` are finite."""
    lb, ub = problem.lb, problem.ub
    with_box = lb is not None or ub is not None
    parts = [np.empty(0) if problem.G is None else problem.h]
    if with_box:
        parts += [
            np.full(n, -np.inf) if lb is None else lb,
            np.full(n, np.inf) if ub is None else ub,
        ]
    else:
        parts.append(np.full(2 * n, np.nan))  # no box: nothing kept
    return with_box, np.isfinite(np.concatenate(parts))


class FiniteRows:
    """The rows of ``G`` and the bounds with a finite right-hand side (as Clarabel's presolve):
    ``g_idx``, ``lb_idx``, ``ub_idx``, and ``kept``, their mask as bytes."""

    def __init__(self, problem: qpsolvers.Problem, n: int):
        self.n = n
        m = self.m_all = 0 if problem.G is None else problem.G.shape[0]
        self.with_box, kept = finite_mask(problem, n)
        masks = kept[:m], kept[m : m + n], kept[m + n :]
        self.all_kept = all(mask.all() for mask in masks)
        self.g_idx, self.lb_idx, self.ub_idx = map(np.flatnonzero, masks)
        self.kept = kept.tobytes()

    def scatter(self, w_g, w_lb, w_ub) -> tuple[np.ndarray, np.ndarray]:
        """``(z, z_box)`` from the multipliers of the kept rows of ``G``, ``lb`` and ``ub``."""
        z = np.zeros(self.m_all)
        z[self.g_idx] = w_g
        z_box = np.zeros(self.n if self.with_box else 0)
        z_box[self.lb_idx] -= w_lb
        z_box[self.ub_idx] += w_ub
        return z, z_box


def dense_parts(problem: qpsolvers.Problem) -> tuple[np.ndarray | None, ...]:
    """``P, q, A, b, G, h, lb, ub`` as dense float64 arrays (``None`` kept; ``A``, ``G`` 2-D)."""
    P = np.ascontiguousarray(as_dense(problem.P), dtype=np.float64)
    q, b, h, lb, ub = _vectors(problem)
    n = q.shape[0]
    A, G = (None if M is None else as_dense(M).reshape(-1, n) for M in (problem.A, problem.G))
    return P, q, A, b, G, h, lb, ub


def _vectors(problem: qpsolvers.Problem) -> tuple[np.ndarray | None, ...]:
    """``q, b, h, lb, ub`` as 1-D float64 arrays (``None`` kept)."""
    return tuple(
        None if v is None else np.asarray(v, dtype=np.float64).reshape(-1)
        for v in (problem.q, problem.b, problem.h, problem.lb, problem.ub)
    )


def dense_f64_parts(problem: qpsolvers.Problem) -> tuple[np.ndarray | None, ...] | None:
    """``P, q, A, b, G, h, lb, ub`` as they are when a controller built them (float64 arrays,
    ``q`` 1-D, ``A``, ``G`` 2-D), else ``None``; shapes unchecked."""
    P, q, A, b = problem.P, problem.q, problem.A, problem.b
    G, h, lb, ub = problem.G, problem.h, problem.lb, problem.ub
    if not (
        _is_f64(P)
        and _is_f64(q)
        and q.ndim == 1
        and (A is None or (_is_f64(A) and A.ndim == 2 and _is_f64(b)))
        and (G is None or (_is_f64(G) and G.ndim == 2 and _is_f64(h)))
        and (lb is None or _is_f64(lb))
        and (ub is None or _is_f64(ub))
    ):
        return None
    return P, q, A, b, G, h, lb, ub


def _is_f64(v) -> bool:
    """Whether ``v`` is a float64 numpy array (dtype by identity first)."""
    return type(v) is _ndarray and (v.dtype is _f64 or v.dtype == _f64)


_ndarray = np.ndarray
_f64 = np.dtype(np.float64)


def shapes(P, q, A, b, G, h, lb, ub) -> tuple:
    """The shape of each array (``None`` kept): equal tuples, arrays of the same shapes.
    Written out: a loop over the arrays shows in a tick (bench/backend_overhead.py)."""
    return (
        P.shape,
        q.shape,
        None if A is None else A.shape,
        None if b is None else b.shape,
        None if G is None else G.shape,
        None if h is None else h.shape,
        None if lb is None else lb.shape,
        None if ub is None else ub.shape,
    )


def all_finite(x: np.ndarray) -> bool:
    """Whether every entry of ``x`` is finite (a short vector by a Python loop: no ufunc call)."""
    return all(map(_isfinite, x.tolist())) if x.size <= 32 else bool(np.isfinite(x).all())


_isfinite = math.isfinite


def check_shapes(backend: str, n: int, P, A, b, G, h, lb, ub) -> tuple[int, int]:
    """``(me, mi)``, the rows of ``A`` and ``G``, after checking every array's shape.

    Raises:
        ProblemFormatError: an array whose shape does not fit (naming it and both shapes).
    """
    if P.shape != (n, n):
        _refuse(backend, "P", P.shape, (n, n))
    me = _rows(backend, A, b, n, ("A", "b", "me"))
    mi = _rows(backend, G, h, n, ("G", "h", "mi"))
    for key, v in (("lb", lb), ("ub", ub)):
        if v is not None and v.shape != (n,):
            _refuse(backend, key, v.shape, (n,))
    return me, mi


def _refuse(backend: str, key: str, shape, expected) -> None:
    raise ProblemFormatError(
        f"backend '{backend}': {key} has shape {tuple(shape)}, expected {tuple(expected)} "
        "(from q and the rows of A and G)",
        key=key,
    )


def _rows(backend: str, M, v, n: int, names: tuple[str, str, str]) -> int:
    if M is None:
        return 0
    matrix, vector, count = names
    if M.ndim != 2 or M.shape[1] != n:
        _refuse(backend, matrix, M.shape, (count, n))
    m = M.shape[0]
    if v is None or v.shape != (m,):
        _refuse(backend, vector, () if v is None else v.shape, (m,))
    return m


def wants_sparse(problem: qpsolvers.Problem) -> bool:
    """True when the problem goes to a sparse API: a scipy.sparse matrix, or too large made dense."""
    if spa.issparse(problem.P) or spa.issparse(problem.A) or spa.issparse(problem.G):
        return True
    return dense_entries(problem) > DENSE_MAX_ENTRIES


def dense_route(problem: qpsolvers.Problem) -> tuple[np.ndarray | None, ...] | None:
    """The dense parts of a problem, or ``None`` when it goes to a sparse API."""
    parts = dense_f64_parts(problem)
    if parts is not None and parts[1].shape[0] <= _SMALL_N:
        return parts
    return None if wants_sparse(problem) else dense_parts(problem)


#: Above this many variables :func:`dense_route` asks :func:`wants_sparse` (``n (n + m)`` entries).
_SMALL_N = 2_000


def _csc(M, n: int) -> spa.csc_matrix | None:
    """``M`` as CSC float64 of ``n`` columns (explicit zeros dropped, indices sorted)."""
    if M is None:
        return None
    if spa.issparse(M):
        M = spa.csc_matrix(M, dtype=np.float64)
    else:
        M = spa.csc_matrix(np.asarray(M, dtype=np.float64).reshape(-1, n))
    M.eliminate_zeros()
    M.sort_indices()
    return M


def sparse_parts(problem: qpsolvers.Problem, upper: bool = False) -> tuple:
    """``P, q, A, b, G, h, lb, ub`` with CSC float64 matrices; ``upper``: ``P``'s upper triangle."""
    q, b, h, lb, ub = _vectors(problem)
    n = q.shape[0]
    P = _csc(problem.P, n)
    if upper:
        P = spa.triu(P, format="csc")
        P.sort_indices()
    return P, q, _csc(problem.A, n), b, _csc(problem.G, n), h, lb, ub


def structure_key(*matrices) -> tuple:
    """Shapes and sparsity patterns of CSC matrices (``None`` kept): equal keys, same structure."""
    return tuple(
        None if M is None else (M.shape, M.indptr.tobytes(), M.indices.tobytes()) for M in matrices
    )
