"""Sparse routes of backends that have both a dense and a sparse API (ProxQP, PIQP).

A problem goes to the sparse API when one of its matrices is ``scipy.sparse``
or when made dense it would hold more than
:data:`qpbench.memory.DENSE_MAX_ENTRIES` entries (``n (n + m)``); the small
dense problems of the robot's ticks keep the dense API.

Persistence on the sparse route follows the dense one: a solver object is kept
per *structure* (:func:`structure_key`: the shapes and the sparsity patterns
of ``P``, ``A``, ``G``), and a problem of the same structure is an ``update``
of the kept object. The sparse solvers' ``update`` keeps the pattern of the
set-up; comparing patterns costs ``O(nnz)``, small against a sparse solve.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as spa

from ..memory import DENSE_MAX_ENTRIES

if TYPE_CHECKING:
    import qpsolvers


def wants_sparse(problem: qpsolvers.Problem) -> bool:
    """True when the problem goes to a sparse API: a scipy.sparse matrix, or too large made dense."""
    P, A, G = problem.P, problem.A, problem.G
    if spa.issparse(P) or spa.issparse(A) or spa.issparse(G):
        return True
    n = np.shape(problem.q)[0]
    m = (0 if A is None else np.atleast_2d(A).shape[0]) + (
        0 if G is None else np.atleast_2d(G).shape[0]
    )
    return n * (n + m) > DENSE_MAX_ENTRIES


def _csc(M, n: int) -> spa.csc_matrix | None:
    """``M`` as a CSC float64 matrix of ``n`` columns (explicit zeros dropped, indices sorted)."""
    if M is None:
        return None
    if spa.issparse(M):
        M = spa.csc_matrix(M, dtype=np.float64)
    else:
        M = spa.csc_matrix(np.asarray(M, dtype=np.float64).reshape(-1, n))
    M.eliminate_zeros()
    M.sort_indices()
    return M


def _vector(v) -> np.ndarray | None:
    return None if v is None else np.asarray(v, dtype=np.float64).reshape(-1)


def sparse_parts(problem: qpsolvers.Problem, upper: bool = False) -> tuple:
    """``P, q, A, b, G, h, lb, ub`` with the matrices as CSC float64 (``None`` kept).

    Args:
        upper: Keep only the upper triangle of ``P`` (what PIQP's sparse API reads).
    """
    q = np.asarray(problem.q, dtype=np.float64).reshape(-1)
    n = q.shape[0]
    P = _csc(problem.P, n)
    if upper:
        P = spa.triu(P, format="csc")
        P.sort_indices()
    A, G = _csc(problem.A, n), _csc(problem.G, n)
    return (
        P,
        q,
        A,
        _vector(problem.b),
        G,
        _vector(problem.h),
        _vector(problem.lb),
        _vector(problem.ub),
    )


def structure_key(*matrices) -> tuple:
    """Shapes and sparsity patterns of CSC matrices (``None`` kept): equal keys, same structure."""
    return tuple(
        None if M is None else (M.shape, M.indptr.tobytes(), M.indices.tobytes()) for M in matrices
    )
