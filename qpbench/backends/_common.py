"""Small helpers shared by the backend modules (no solver imports here).

- :func:`generic_settings` merges a profile with the user's settings;
- :func:`qpbenchmark_options` gives an own-API backend qpbenchmark's arguments
  for its solver under a ``qpbenchmark:<settings>`` profile;
- :func:`dense_bounds` turns optional ``lb``/``ub`` into full vectors;
- :func:`as_dense`, :func:`all_dense` handle dense/sparse input cheaply;
- :func:`dense_f64_parts` is the dense backends' per-tick fast path, :func:`dense_parts`
  the conversion of anything else;
- :func:`dense_upper_layout` gives the CSC structure of a dense cost matrix's
  upper triangle with *every* entry stored.

Dense blocks are stored with their full (dense) pattern by the sparse solvers'
backends: the robot's QPs are tiny and some Jacobian entries are
structurally zero in some ticks only, so a pattern taken from the non-zeros
would change from tick to tick and force a rebuild of the solver.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as spa

if TYPE_CHECKING:
    from collections.abc import Callable

    import qpsolvers

    from .base import Backend

#: Setting names every backend understands; the profile provides their values.
GENERIC_KEYS = ("eps_abs", "eps_rel", "max_iter", "time_limit")


def generic_settings(backend: Backend) -> tuple[dict, dict]:
    """Split a backend's settings into generic values and native solver options.

    Returns:
        ``(generic, native)``: ``generic`` holds :data:`GENERIC_KEYS` from the
        profile overridden by the user's settings of the same name; ``native``
        holds the other user settings, passed to the solver verbatim (they
        override what the backend derives from ``generic``).
    """
    profile = backend.profile
    generic = {
        "eps_abs": profile.eps_abs,
        "eps_rel": profile.eps_rel,
        "max_iter": profile.max_iter,
        "time_limit": profile.time_limit,
    }
    native = {}
    for key, value in backend.settings.items():
        if key in generic:
            generic[key] = value
        else:
            native[key] = value
    return generic, native


def qpbenchmark_options(
    backend: Backend, solver: str, translate: Callable[[dict], dict]
) -> dict | None:
    """The options an own-API backend gives ``solver`` under a qpbenchmark profile.

    Under ``qpbenchmark:<settings>`` the ``qpsolvers:<solver>`` route passes
    qpbenchmark's keyword arguments for the solver verbatim and nothing else
    (:mod:`qpbench.backends.qpsolvers_`); the solver's own-API backend does the
    same work from the same options: qpbenchmark's arguments (native names, as
    qpsolvers hands them on), then the generic settings the user gave
    (``--set osqp.eps_abs=...``, through ``translate``), then the user's native
    ones. Nothing of qpbench's own profiles is added (no tighter tolerance,
    iteration limit or polishing): under ``qpbenchmark:default`` the solver runs
    with its own defaults and qpbenchmark's time limit where it sets one.

    Args:
        backend: The backend (its profile and settings).
        solver: qpsolvers' name of the solver (the key of qpbenchmark's arguments).
        translate: Maps a dict of some of :data:`GENERIC_KEYS` to the solver's option names.

    Returns:
        The options, or ``None`` under qpbench's own profiles.
    """
    given = backend.profile.solver_options
    if given is None:
        return None
    options = dict(given.get(solver, {}))
    options.update(translate({k: v for k, v in backend.settings.items() if k in GENERIC_KEYS}))
    options.update({k: v for k, v in backend.settings.items() if k not in GENERIC_KEYS})
    return options


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
    """True when every given matrix is a numpy array or None (fast path of the backends)."""
    return all(M is None or type(M) is np.ndarray for M in matrices)


def dense_upper_layout(n: int) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray, np.ndarray]:
    """Index arrays of the CSC upper triangle of a dense ``n x n`` matrix, every entry stored.

    Returns:
        ``((rows, cols), indices, indptr)``: ``P[rows, cols]`` is the CSC data
        vector (column-major order), ``indices``/``indptr`` its structure.
    """
    rows = (
        np.concatenate([np.arange(j + 1) for j in range(n)]).astype(np.int64)
        if n
        else np.zeros(0, np.int64)
    )
    cols = (
        np.concatenate([np.full(j + 1, j) for j in range(n)]).astype(np.int64)
        if n
        else np.zeros(0, np.int64)
    )
    indptr = np.concatenate([[0], np.cumsum(np.arange(1, n + 1))]).astype(np.int64)
    return (rows, cols), rows, indptr


def dense_parts(problem: qpsolvers.Problem) -> tuple[np.ndarray | None, ...]:
    """The problem's ``P, q, A, b, G, h, lb, ub`` as dense float64 arrays (``None`` kept).

    ``A`` and ``G`` are 2-D (a single row given as a vector becomes one row); the vectors
    are 1-D. The dense-API backends (daqp, qpoases, piqp) read a problem through this.
    """
    P = np.ascontiguousarray(as_dense(problem.P), dtype=np.float64)
    q = np.asarray(problem.q, dtype=np.float64).reshape(-1)
    n = q.shape[0]

    def rows(M, v):
        if M is None:
            return None, None
        return as_dense(M).reshape(-1, n), np.asarray(v, dtype=np.float64).reshape(-1)

    A, b = rows(problem.A, problem.b)
    G, h = rows(problem.G, problem.h)
    lb = None if problem.lb is None else np.asarray(problem.lb, dtype=np.float64).reshape(-1)
    ub = None if problem.ub is None else np.asarray(problem.ub, dtype=np.float64).reshape(-1)
    return P, q, A, b, G, h, lb, ub


def dense_f64_parts(problem: qpsolvers.Problem) -> tuple[np.ndarray | None, ...] | None:
    """The problem's ``P, q, A, b, G, h, lb, ub`` as they are, or ``None`` when one needs converting.

    The per-tick fast path of the dense backends: the arrays a controller builds (numpy
    arrays of float64, ``q`` 1-D, ``A`` and ``G`` 2-D, absent parts ``None``) are passed on
    untouched; for anything else (sparse, lists, a single row as a vector, other dtypes)
    this returns ``None`` and the backend converts, with :func:`dense_parts` or its own
    route. Shapes are not compared here (see :mod:`._shapes`).

    Each dtype is tested by identity first (the float64 descriptor is a singleton except
    in unpickled arrays, which fall back to ``==``): this keeps the call as cheap as the
    inline tests it replaces. The tests of ``A, b`` and ``G, h`` are written out twice on
    purpose: a helper for one block would cost a call per block and tick.
    """
    P = problem.P
    q = problem.q
    A = problem.A
    b = problem.b
    G = problem.G
    h = problem.h
    lb = problem.lb
    ub = problem.ub
    if (
        type(P) is _ndarray
        and (P.dtype is _f64 or P.dtype == _f64)
        and type(q) is _ndarray
        and (q.dtype is _f64 or q.dtype == _f64)
        and q.ndim == 1
        # The tests of (A, b) and (G, h) are the same, written out twice: a helper per block
        # would cost a Python call per block and tick (see the docstring).
        and (
            A is None
            or (
                type(A) is _ndarray
                and (A.dtype is _f64 or A.dtype == _f64)
                and A.ndim == 2
                and type(b) is _ndarray
                and (b.dtype is _f64 or b.dtype == _f64)
            )
        )
        and (
            G is None
            or (
                type(G) is _ndarray
                and (G.dtype is _f64 or G.dtype == _f64)
                and G.ndim == 2
                and type(h) is _ndarray
                and (h.dtype is _f64 or h.dtype == _f64)
            )
        )
        and (lb is None or (type(lb) is _ndarray and (lb.dtype is _f64 or lb.dtype == _f64)))
        and (ub is None or (type(ub) is _ndarray and (ub.dtype is _f64 or ub.dtype == _f64)))
    ):
        return P, q, A, b, G, h, lb, ub
    return None


_ndarray = np.ndarray
_f64 = np.dtype(np.float64)
