"""Is ``P`` positive semidefinite? By ``ratio = lambda_min(P) / lambda_max(P)``: ``convex``,
``rounding`` (solved, with a warning) or ``nonconvex`` (skipped). Up to ``DENSE_EIG_MAX_N``
variables ``eigvalsh``; else Gershgorin discs, else the inertia of ``P + delta I`` (sparse
``L D L'``) at the two thresholds, then the ratio to 2 % by bisection on the shift.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as spa

#: Ratios ``lambda_min / lambda_max`` above ``-ROUNDING_RATIO`` are convex.
ROUNDING_RATIO = 1e-10
#: Ratios below ``-NONCONVEX_RATIO`` are nonconvex (the problem is skipped).
NONCONVEX_RATIO = 1e-5
#: Up to this many variables the eigenvalues are computed densely.
DENSE_EIG_MAX_N = 1000


@dataclass(frozen=True)
class Convexity:
    """A ``verdict`` (``convex``, ``rounding``, ``nonconvex``), the ``ratio`` (NaN when only a
    ``bound`` above it is known) and the ``method``."""

    verdict: str
    ratio: float = math.nan
    bound: float = math.nan
    method: str = ""

    @property
    def text(self) -> str:
        """``lambda_min / lambda_max = -1.2e-06`` (or ``< -1e-05`` when only bounded)."""
        if math.isnan(self.ratio) and math.isnan(self.bound):
            return "lambda_min / lambda_max undecided (a sparse LDL' pivoted off the diagonal)"
        if math.isnan(self.ratio):
            return f"lambda_min / lambda_max < {self.bound:.3g}"
        return f"lambda_min / lambda_max = {self.ratio:.3g}"

    @property
    def warning(self) -> str | None:
        if self.verdict != "rounding":
            return None
        return f"P slightly indefinite ({self.text}, within {NONCONVEX_RATIO:g}); solved as given"

    @property
    def skip_reason(self) -> str | None:
        return f"nonconvex ({self.text})" if self.verdict == "nonconvex" else None


def _verdict(ratio: float) -> str:
    if ratio >= -ROUNDING_RATIO:
        return "convex"
    return "rounding" if ratio >= -NONCONVEX_RATIO else "nonconvex"


def assess_convexity(P: np.ndarray | spa.spmatrix | spa.sparray) -> Convexity:
    """The convexity of ``x'Px`` for a symmetric ``P`` (dense or scipy.sparse)."""
    sparse = spa.issparse(P)
    if not sparse:
        P = np.asarray(P, dtype=np.float64)
    if not np.any(P.data if sparse else P):
        return Convexity("convex", 0.0, method="zero")
    if P.shape[0] > DENSE_EIG_MAX_N:
        return _sparse(spa.csc_matrix(P))
    eig = np.linalg.eigvalsh(P.toarray() if sparse else P)
    lo, hi = float(eig[0]), float(eig[-1])
    scale = max(abs(lo), abs(hi))
    ratio = lo / scale if scale > 0 else 0.0
    return Convexity(_verdict(ratio), ratio, method="eigvalsh")


def _bisect_ratio(P, hi: float, low: float, high: float, rtol: float = 0.02) -> float | None:
    """``lambda_min / hi`` in ``[-high, -low]`` by bisection on the inertia of ``P + t hi I``."""
    while high / low > 1 + rtol:
        mid = math.sqrt(low * high)
        count = negative_eigenvalues(P, mid * hi)
        if count is None:
            return None
        if count:
            low = mid  # an eigenvalue below -mid hi
        else:
            high = mid
    return -math.sqrt(low * high)


def _top_eigenvalue(P, d: np.ndarray, steps: int = 30) -> float:
    """A lower bound of ``lambda_max``: ``max_i P_ii`` or a power iteration's Rayleigh quotient."""
    v = np.random.default_rng(0).standard_normal(P.shape[0])
    for _ in range(steps):
        w = P @ v
        norm = np.linalg.norm(w)
        if norm == 0:
            break
        v = w / norm
    v /= np.linalg.norm(v)
    return max(float(d.max()), float(v @ (P @ v)))


def negative_eigenvalues(P: spa.spmatrix | spa.sparray, shift: float) -> int | None:
    """How many eigenvalues of a symmetric sparse ``P`` lie below ``-shift`` (``None``: unknown)."""
    from scipy.sparse.linalg import splu

    M = (P + shift * spa.identity(P.shape[0], format="csc")).tocsc()
    try:
        lu = splu(
            M, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
        )
    except RuntimeError:  # exactly singular: an eigenvalue at -shift, so none below is not proven
        return None
    if not np.array_equal(lu.perm_r, lu.perm_c):
        return None
    return int(np.count_nonzero(lu.U.diagonal() < 0))


def _sparse(P: spa.csc_matrix) -> Convexity:
    d = P.diagonal()
    off = np.asarray(abs(P).sum(axis=1)).ravel() - np.abs(d)
    if np.all(d >= off):
        return Convexity("convex", 0.0, method="gershgorin")
    hi = _top_eigenvalue(P, d)
    if hi <= 0:
        return Convexity("nonconvex", -1.0, method="gershgorin")
    floor = max(1.0, -float((d - off).min()) / hi) * 1.01  # lambda_min >= -floor hi (Gershgorin)
    for low, high, verdict in (
        (NONCONVEX_RATIO, floor, "nonconvex"),
        (ROUNDING_RATIO, NONCONVEX_RATIO, "rounding"),
    ):
        count = negative_eigenvalues(P, low * hi)
        if count is None:
            return Convexity("rounding", method="undecided")
        if count:
            ratio = _bisect_ratio(P, hi, low, high)
            return Convexity(
                verdict, math.nan if ratio is None else ratio, bound=-low, method="inertia"
            )
    return Convexity("convex", math.nan, bound=-ROUNDING_RATIO, method="inertia")
