"""Power laws fitted to solve times, and where the curves cross (scaling study).

A backend's median solve time ``T`` against a size ``s`` (variables or rows)
is fitted as ``T = C s^k``: least squares of ``log10 T`` on ``log10 s`` over one grid axis, the
slope's standard error ``sqrt(RSS / (N - 2) / sum((x - mean x)^2))`` (NaN for N = 2 sizes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PowerFit:
    """``T = 10**intercept * s**slope``, from ``points`` sizes; ``slope_se`` its standard error."""

    slope: float
    slope_se: float
    intercept: float
    points: int

    def predict(self, s: float | np.ndarray) -> np.ndarray:
        """Fitted time at size(s) ``s`` (same units as the data)."""
        return 10.0 ** (self.intercept + self.slope * np.log10(np.asarray(s, dtype=float)))

    def text(self) -> str:
        """``1.23 +- 0.05`` (``+- n/a`` with two points)."""
        if math.isnan(self.slope):
            return "-"
        se = "n/a" if math.isnan(self.slope_se) else f"{self.slope_se:.2f}"
        return f"{self.slope:.2f} +- {se}"


def fit_power_law(sizes: np.ndarray, times: np.ndarray) -> PowerFit:
    """Least squares of ``log10 times`` on ``log10 sizes``, non-positive or non-finite pairs left
    out (NaN with fewer than two distinct sizes)."""
    s = np.asarray(sizes, dtype=float)
    t = np.asarray(times, dtype=float)
    keep = np.isfinite(s) & np.isfinite(t) & (s > 0) & (t > 0)
    x, y = np.log10(s[keep]), np.log10(t[keep])
    if x.size < 2 or np.ptp(x) == 0:
        return PowerFit(math.nan, math.nan, math.nan, int(x.size))
    xm = x.mean()
    sxx = float(((x - xm) ** 2).sum())
    slope = float(((x - xm) * (y - y.mean())).sum() / sxx)
    intercept = float(y.mean() - slope * xm)
    if x.size > 2:
        rss = float(((y - intercept - slope * x) ** 2).sum())
        se = math.sqrt(rss / (x.size - 2) / sxx)
    else:
        se = math.nan
    return PowerFit(slope, se, intercept, int(x.size))


def first_above(sizes: np.ndarray, values: np.ndarray, limit: float) -> float | None:
    """The first size (in increasing order) from which every value exceeds ``limit``, else None."""
    order = np.argsort(np.asarray(sizes, dtype=float), kind="stable")
    s = np.asarray(sizes)[order]
    v = np.asarray(values, dtype=float)[order]
    for i in range(s.size):
        if np.all(v[i:] > limit):
            return s[i].item()
    return None


def crossing(sizes: np.ndarray, slower: np.ndarray, faster: np.ndarray) -> float | None:
    """The first size from which time ``faster`` stays strictly below ``slower`` (NaN: not
    measured, left out), else None."""
    s = np.asarray(sizes, dtype=float)
    a = np.asarray(slower, dtype=float)
    b = np.asarray(faster, dtype=float)
    keep = np.isfinite(a) & np.isfinite(b)
    return first_above(s[keep], (a - b)[keep], 0.0)


def extrapolated_crossing(fit_a: PowerFit, fit_b: PowerFit) -> float | None:
    """Size where two fitted lines meet (``None`` when parallel or not fitted)."""
    if any(math.isnan(v) for v in (fit_a.slope, fit_b.slope)) or fit_a.slope == fit_b.slope:
        return None
    x = (fit_b.intercept - fit_a.intercept) / (fit_a.slope - fit_b.slope)
    return float(10.0**x)
