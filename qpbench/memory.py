"""A memory budget (``--memory-budget``) and estimates (orders of magnitude) of what a solve
needs: a solve whose estimate exceeds it is a ``skipped`` row, never an out-of-memory kill."""

from __future__ import annotations

import os
import re
import resource
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as spa

from .exceptions import ParamError

if TYPE_CHECKING:
    import qpsolvers

#: Default budget: this fraction of the machine's physical memory.
DEFAULT_FRACTION = 0.5
#: Largest ``n (n + m_eq + m_ineq)`` given to a dense-only backend.
DENSE_MAX_ENTRIES = 25_000_000
#: Factor fill-in assumed by :func:`sparse_solver_bytes`.
FILL = 10

#: Units of a size: ``kB``/``k`` (10^3) to ``TB``, ``KiB`` (2^10) to ``TiB``, any case.
_UNITS = {"": 1, "b": 1} | {
    prefix + suffix: base**power
    for power, prefix in enumerate("kmgt", start=1)
    for suffix, base in (("b", 1e3), ("ib", 2**10), ("", 1e3))
    if suffix or prefix != "t"
}


def parse_size(text: str) -> int:
    """Bytes of ``"2GB"`` (10^9), ``"1.5GiB"`` (2^30), ``"512MB"``, ``"100000"``."""
    match = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:e[0-9]+)?)\s*([a-zA-Z]*)\s*", str(text))
    unit = match.group(2).lower() if match else None
    if not match or unit not in _UNITS or float(match.group(1)) <= 0:
        raise ParamError(
            f"memory budget '{text}' is not a size like 2GB, 512MB or 1.5GiB", key="memory-budget"
        )
    return int(float(match.group(1)) * _UNITS[unit])


def format_size(n: float) -> str:
    """``1.2 GB`` (powers of 1000)."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} B"


def _mapped_bytes() -> int:
    """Virtual memory this process maps now (``VmSize``), 0 if unknown."""
    try:
        return int(Path("/proc/self/statm").read_text().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except OSError:
        return 0


def resolve_budget(text: str | None) -> int:
    """The budget in bytes of a ``--memory-budget`` value (``None``: :data:`DEFAULT_FRACTION`
    of physical memory, within what ``RLIMIT_AS`` leaves)."""
    if text is not None:
        return parse_size(text)
    budget = int(DEFAULT_FRACTION * os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        budget = min(budget, max(0, int(0.8 * (soft - _mapped_bytes()))))
    return budget


def problem_sizes(problem: qpsolvers.Problem) -> tuple[int, int, int]:
    """``(n, m_eq, m_ineq)`` of a problem (box bounds are not counted as rows)."""
    n = int(np.asarray(problem.q).shape[0])
    m_eq = 0 if problem.A is None else int(problem.A.shape[0])
    m_ineq = 0 if problem.G is None else int(problem.G.shape[0])
    return n, m_eq, m_ineq


def nnz(M) -> int:
    """Stored entries of a sparse matrix, non-zeros of a dense one, 0 for ``None``."""
    if M is None:
        return 0
    return int(M.nnz) if spa.issparse(M) else int(np.count_nonzero(M))


def sparse_solver_bytes(problem: qpsolvers.Problem) -> int:
    """What a sparse solver needs for ``problem`` (KKT matrix, its factor, vectors), in bytes."""
    n, m_eq, m_ineq = problem_sizes(problem)
    m = m_eq + m_ineq
    kkt = nnz(problem.P) + nnz(problem.A) + nnz(problem.G) + n + m
    return 12 * kkt * (1 + FILL) + 8 * 50 * (n + m)


def dense_entries(problem: qpsolvers.Problem) -> int:
    """``n (n + m_eq + m_ineq)``: entries of the problem's matrices made dense."""
    n, m_eq, m_ineq = problem_sizes(problem)
    return n * (n + m_eq + m_ineq)


def skip_reason(problem: qpsolvers.Problem, sparse_backend: bool, budget: int) -> str | None:
    """Why a backend cannot be given ``problem`` within ``budget`` bytes, or ``None``."""
    if not sparse_backend:
        entries = dense_entries(problem)
        if entries > DENSE_MAX_ENTRIES:
            return (
                f"dense-only backend: n (n + m) = {entries:.3g} entries > {DENSE_MAX_ENTRIES:.3g} "
                f"({format_size(8 * entries)} dense)"
            )
        n, m_eq, m_ineq = problem_sizes(problem)  # the problem's dense copy, the solver's
        need = 3 * 8 * (entries + 4 * (n + m_eq + m_ineq))  # and its workspace
    else:
        need = sparse_solver_bytes(problem)
    if need > budget:
        return f"memory: needs about {format_size(need)} > budget {format_size(budget)}"
    return None
