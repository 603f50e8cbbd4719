"""Maros-Meszaros ``.mat`` files (keys ``P q r A l u n m``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import qpsolvers

from ..exceptions import ProblemFormatError
from .records import MM_INFINITY, ProblemRecord, _dense, check_record


def load_maros_meszaros(path: str | Path) -> ProblemRecord:
    """Read one Maros-Meszaros problem (``.mat`` with keys ``P q r A l u n m``).

    See the module docstring for the conversion. The record's ``offset`` is ``r``
    and its name is the file stem.

    Raises:
        ProblemFormatError: unreadable file, missing key, inconsistent sizes.
    """
    import scipy.io

    path = Path(path)
    name = path.stem
    try:
        data = scipy.io.loadmat(str(path))
    except FileNotFoundError:
        raise ProblemFormatError("no such file", path=path) from None
    except Exception as exc:  # scipy raises ValueError, TypeError, OSError, MatReadError...
        raise ProblemFormatError(f"unreadable .mat ({type(exc).__name__}: {exc})", path=path) from None
    for k in ("P", "q", "r", "A", "l", "u", "n", "m"):
        if k not in data:
            raise ProblemFormatError(f"problem '{name}': missing key", path=path, key=k)

    def fail(key, msg):
        raise ProblemFormatError(f"problem '{name}': {msg}", path=path, key=key)

    try:
        n = int(np.asarray(data["n"]).item())
        m = int(np.asarray(data["m"]).item())
        r = float(np.asarray(data["r"], dtype=np.float64).item())
    except (ValueError, TypeError) as exc:
        fail("n", f"n, m and r must be scalars ({exc})")
    P = _dense(data["P"], "P", path, name)
    A = _dense(data["A"], "A", path, name)
    q = _dense(data["q"], "q", path, name).ravel()
    lo = _dense(data["l"], "l", path, name).ravel()
    up = _dense(data["u"], "u", path, name).ravel()
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
    if not np.array_equal(P, P.T):
        if np.array_equal(P, np.triu(P)) or np.array_equal(P, np.tril(P)):
            P = P + P.T - np.diag(np.diag(P))
        # else: left to check_problem, which reports a non-symmetric P
    lo = np.where(lo <= -MM_INFINITY, -np.inf, lo)
    up = np.where(up >= MM_INFINITY, np.inf, up)
    if m >= n and np.array_equal(A[m - n :], np.eye(n)):
        C, lc, uc = A[: m - n], lo[: m - n], up[: m - n]
        lb, ub = lo[m - n :].copy(), up[m - n :].copy()
    else:  # no identity block: every row is a general constraint
        C, lc, uc = A, lo, up
        lb = ub = None
    eq = (lc == uc) & np.isfinite(lc)
    upper = ~eq & np.isfinite(uc)
    lower = ~eq & np.isfinite(lc)
    Aeq, beq = (C[eq], uc[eq]) if np.any(eq) else (None, None)
    G_rows = [C[upper], -C[lower]]
    h_rows = [uc[upper], -lc[lower]]
    if np.any(upper) or np.any(lower):
        G, h = np.vstack(G_rows), np.concatenate(h_rows)
    else:
        G = h = None
    if lb is not None and np.all(lb == -np.inf):
        lb = None
    if ub is not None and np.all(ub == np.inf):
        ub = None
    problem = qpsolvers.Problem(
        P,
        q,
        None if G is None else np.ascontiguousarray(G),
        h,
        None if Aeq is None else np.ascontiguousarray(Aeq),
        beq,
        lb,
        ub,
    )
    record = ProblemRecord(problem=problem, name=name, offset=r)
    check_record(record, path=path)
    return record

