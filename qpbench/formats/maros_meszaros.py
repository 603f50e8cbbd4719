"""Maros-Meszaros ``.mat`` files: ``min 1/2 x'Px + q'x + r`` s.t. ``l <= A x <= u``.

``A = [C; I_n]``: rows of ``C`` with ``l == u`` become ``A x = b``, the others one ``G x <=
h`` row per finite side (upper sides first); the last ``n`` rows give ``lb, ub``. A
triangular ``P`` is mirrored; ``r`` is the record's ``offset`` (objectives equal the
published optimal values)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import qpsolvers
import scipy.sparse as spa

from ..exceptions import ProblemFormatError
from .records import ProblemRecord, check_record, reading, sorted_csc

#: Maros-Meszaros convention: a bound with ``|value| >= 1e20`` is infinite.
MM_INFINITY = 1e20


def load_maros_meszaros(path: str | Path) -> ProblemRecord:
    """One Maros-Meszaros problem, named by the file stem."""
    import scipy.io

    path = Path(path)
    name = path.stem
    with reading(path, ".mat"):  # scipy raises ValueError, TypeError, OSError, MatReadError...
        data = scipy.io.loadmat(str(path))

    def fail(key, msg):
        raise ProblemFormatError(f"problem '{name}': {msg}", path=path, key=key)

    for k in ("P", "q", "r", "A", "l", "u", "n", "m"):
        if k not in data:
            fail(k, "missing key")

    try:
        n = int(np.asarray(data["n"]).item())
        m = int(np.asarray(data["m"]).item())
        r = float(np.asarray(data["r"], dtype=np.float64).item())
    except (ValueError, TypeError) as exc:
        fail("n", f"n, m and r must be scalars ({exc})")
    P, A = (_array(data[k], k, fail, matrix=True) for k in ("P", "A"))
    q, lo, up = (_array(data[k], k, fail) for k in ("q", "l", "u"))
    if P.shape != (n, n):
        fail("P", f"shape {P.shape} does not match n = {n}")
    if q.shape != (n,):
        fail("q", f"shape {q.shape} does not match n = {n}")
    if A.shape != (m, n):
        fail("A", f"shape {A.shape} does not match (m, n) = {(m, n)}")
    if lo.shape != (m,) or up.shape != (m,):
        fail("l", f"l, u shapes {lo.shape}, {up.shape} do not match m = {m}")
    if np.any(np.isnan(lo)) or np.any(np.isnan(up)):
        fail("l", "l or u holds NaN")
    P = _symmetric(P)
    lo = np.where(lo <= -MM_INFINITY, -np.inf, lo)
    up = np.where(up >= MM_INFINITY, np.inf, up)
    problem = qpsolvers.Problem(P, q, *_constraints(A, lo, up, m, n))
    record = ProblemRecord(problem=problem, name=name, offset=r)
    check_record(record, path=path)
    return record


def _array(v, key: str, fail, matrix: bool = False):
    """A field of the file as float64: a CSC matrix (indices sorted), else a flat vector."""
    try:
        if matrix:
            M = spa.csc_matrix(v, dtype=np.float64)
            M.sum_duplicates()  # sorts the indices too
            return M
        return np.asarray(v.toarray() if spa.issparse(v) else v, dtype=np.float64).ravel()
    except (TypeError, ValueError) as exc:
        fail(key, f"not a numeric matrix ({exc})" if matrix else f"not numeric ({exc})")


def _symmetric(P: spa.csc_matrix) -> spa.csc_matrix:
    """``P`` mirrored when the file holds one triangle (a non-symmetric full ``P`` is left
    to :func:`~qpbench.formats.records.check_record`, which reports it)."""
    if (P != P.T).nnz == 0:
        return P
    upper, lower = spa.triu(P, format="csc"), spa.tril(P, format="csc")
    if (P != upper).nnz == 0 or (P != lower).nnz == 0:
        P = sorted_csc(P + P.T - spa.diags(P.diagonal()))
    return P


def _constraints(A: spa.csc_matrix, lo: np.ndarray, up: np.ndarray, m: int, n: int) -> tuple:
    """``(G, h, A_eq, b, lb, ub)`` of ``lo <= A x <= up``."""
    rows = A.tocsr()
    identity = m >= n and (rows[m - n :] != spa.identity(n, format="csr")).nnz == 0
    if identity:
        C, lc, uc = rows[: m - n], lo[: m - n], up[: m - n]
        # a bound vector without any finite entry: none
        lb, ub = (None if np.all(np.isinf(v)) else v.copy() for v in (lo[m - n :], up[m - n :]))
    else:  # no identity block: every row is a general constraint
        C, lc, uc = rows, lo, up
        lb = ub = None
    eq = (lc == uc) & np.isfinite(lc)
    upper = ~eq & np.isfinite(uc)
    lower = ~eq & np.isfinite(lc)
    Aeq, beq = (sorted_csc(C[np.flatnonzero(eq)]), uc[eq]) if np.any(eq) else (None, None)
    if np.any(upper) or np.any(lower):
        G = sorted_csc(spa.vstack([C[np.flatnonzero(upper)], -C[np.flatnonzero(lower)]]))
        h = np.concatenate([uc[upper], -lc[lower]])
    else:
        G = h = None
    return G, h, Aeq, beq, lb, ub
