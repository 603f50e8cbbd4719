"""Problem records and sets, and the data rules every reader checks."""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np
import qpsolvers
import scipy.sparse as spa

from ..exceptions import ProblemFormatError
from ..memory import dense_entries, problem_sizes

#: Array columns, in qpsolvers' argument order.
ARRAY_KEYS = ("P", "q", "G", "h", "A", "b", "lb", "ub")
#: A record's metadata and its Arrow types (Parquet columns after the arrays).
META_TYPES = {
    "name": "string",
    "scenario": "string",
    "tick": "int64",
    "t": "float64",
    "formulation": "string",
    "offset": "float64",
}
#: Metadata columns added by qpbench.
META_KEYS = tuple(META_TYPES)[1:]
#: File names inside a problem-set folder.
PARQUET_NAME = "problems.parquet"
MANIFEST_NAME = "manifest.json"
#: npz member that carries the record metadata (ignored by ``Problem.load``).
NPZ_META_KEY = "qpbench_record"
#: Version of the problem-set layout written in the manifest.
FORMAT_VERSION = 1
#: Entries of ``P, G, A`` made dense above which a sparse problem is not also written dense.
DENSE_COPY_MAX = 1_000_000
#: ``P`` is symmetric when ``max |P - P'| <= SYMMETRY_RTOL max |P|``.
SYMMETRY_RTOL = 1e-9

#: The matrices of a problem (the parts that may be scipy.sparse).
MATRIX_KEYS = ("P", "G", "A")
#: How a sparse matrix ``M`` is stored: members or columns ``M_csc_<part>`` of these types.
CSC_TYPES = {"data": "float64", "indices": "int32", "indptr": "int64"}


@dataclass
class ProblemRecord:
    """One QP and where it comes from: ``name`` unique in its set; ``t`` the tick's time [s];
    ``formulation`` ``paper`` (eq. 11) or ``soft``; ``offset`` the objective's constant."""

    problem: qpsolvers.Problem
    name: str
    scenario: str | None = None
    tick: int | None = None
    t: float | None = None
    formulation: str | None = None
    offset: float = 0.0
    convexity: object = field(default=None, compare=False, repr=False)

    @property
    def sizes(self) -> tuple[int, int, int]:
        return problem_sizes(self.problem)

    def meta(self) -> dict:
        """The metadata as a JSON-able dict (everything but the problem)."""
        return {k: getattr(self, k) for k in META_TYPES}


@dataclass
class ProblemSet:
    """Problem records read from ``path`` (``None``: built in memory); ``kind``: ``set``,
    ``parquet``, ``npz`` or ``mat``; ``manifest``, ``sha256``, ``hash_ok``: a set's folder."""

    name: str
    path: Path | None
    records: list[ProblemRecord]
    manifest: dict | None = None
    sha256: str | None = None
    kind: str = "set"
    files: list[Path] = field(default_factory=list)
    hash_ok: bool | None = None

    def __iter__(self) -> Iterator[ProblemRecord]:
        return iter(self.records)

    def __len__(self) -> int:
        return len(self.records)

    def __getitem__(self, i: int) -> ProblemRecord:
        return self.records[i]


def box_bounds(problem: qpsolvers.Problem) -> int:
    """Finite bounds (``lb`` and ``ub`` entries) of a problem."""
    bounds = [b for b in (problem.lb, problem.ub) if b is not None]
    return sum(int(np.isfinite(np.asarray(b, dtype=float)).sum()) for b in bounds)


def solver_problem(problem: qpsolvers.Problem) -> qpsolvers.Problem:
    """``problem`` with float64 arrays, sparse matrices as CSC (what a sparse API is given)."""
    parts = (getattr(problem, k) for k in ARRAY_KEYS)
    return qpsolvers.Problem(*(None if v is None else _float64(v) for v in parts))


def _float64(v):
    """``v`` as float64, a sparse matrix as CSC."""
    if not spa.issparse(v):
        return np.asarray(v, dtype=np.float64)
    return v if v.format == "csc" and v.dtype == np.float64 else spa.csc_matrix(v, dtype=np.float64)


def dense_copy(problem: qpsolvers.Problem) -> dict[str, np.ndarray | None]:
    """Each array dense float64 (``None``: absent, or sparse above ``DENSE_COPY_MAX`` entries)."""
    small = dense_entries(problem) <= DENSE_COPY_MAX
    out = {}
    for k in ARRAY_KEYS:
        v = getattr(problem, k)
        if spa.issparse(v):
            v = v.toarray() if small else None
        out[k] = None if v is None else np.asarray(v, dtype=np.float64)
    return out


def checked_csc(data, indices, indptr, shape: tuple[int, int]) -> spa.csc_matrix:
    """The CSC matrix of stored arrays, every index checked (ValueError if one is not)."""
    M = spa.csc_matrix((data, indices, indptr), shape=shape)
    M.check_format(full_check=True)
    return M


def sorted_csc(M) -> spa.csc_matrix:
    """``M`` as float64 CSC with sorted indices."""
    M = spa.csc_matrix(M, dtype=np.float64)
    M.sort_indices()
    return M


@contextmanager
def reading(path: Path, what: str, errors: tuple[type[Exception], ...] = (Exception,)):
    """Reading ``path``: a missing file or one of ``errors`` is a :class:`ProblemFormatError`."""
    try:
        yield
    except FileNotFoundError:
        raise ProblemFormatError("no such file", path=path) from None
    except ProblemFormatError:
        raise
    except errors as exc:
        msg = f"unreadable {what} ({type(exc).__name__}: {exc})"
        raise ProblemFormatError(msg, path=path) from None


def _values(M) -> np.ndarray:
    """The stored values of a dense or sparse array (never a dense copy of a sparse one)."""
    return M.data if spa.issparse(M) else M


def check_record(record: ProblemRecord, path: str | Path | None = None) -> None:
    """Check shapes and values (sparse matrices never made dense): ``P`` ``n x n`` and symmetric
    (to ``SYMMETRY_RTOL``), ``G, h`` and ``A, b`` in pairs, all finite but ``lb = -inf``, ``ub =
    +inf``; a :class:`ProblemFormatError` names the field. Sets ``record.convexity``."""
    from .convexity import assess_convexity

    problem, name, offset = record.problem, record.name, record.offset

    def fail(key, msg):
        raise ProblemFormatError(f"problem '{name}': {msg}", path=path, key=key)

    arr = {}  # float64, CSC for a sparse matrix
    for k in ARRAY_KEYS:
        v = getattr(problem, k)
        if v is not None:
            v = v if spa.issparse(v) else np.asarray(v)
            if v.dtype.kind not in "fiub":
                fail(k, f"dtype {v.dtype} is not numeric")
            v = _float64(v)
        arr[k] = v
    P, q = arr["P"], arr["q"]
    for k in ("P", "q"):
        if arr[k] is None:
            fail(k, "missing")
    if q.ndim != 1:
        fail("q", f"shape {q.shape} is not a vector")
    n = q.shape[0]
    if n == 0:
        fail("q", "no variables (n = 0)")
    if P.shape != (n, n):
        fail("P", f"shape {P.shape} does not match n = {n} (expected {(n, n)})")
    for M, v in (("G", "h"), ("A", "b")):
        if (arr[M] is None) != (arr[v] is None):
            absent = M if arr[M] is None else v
            fail(absent, f"'{M}' and '{v}' must both be given or both be absent")
        if arr[M] is None:
            continue
        if arr[M].ndim != 2 or arr[M].shape[1] != n:
            fail(M, f"shape {arr[M].shape} does not have n = {n} columns")
        if arr[v].ndim != 1 or arr[v].shape[0] != arr[M].shape[0]:
            fail(v, f"shape {arr[v].shape} does not match {M} rows = {arr[M].shape[0]}")
    for k in ("lb", "ub"):
        if arr[k] is not None and arr[k].shape != (n,):
            fail(k, f"shape {arr[k].shape} does not match n = {n}")
    for k in ("P", "q", "G", "h", "A", "b"):
        if arr[k] is not None and not np.all(np.isfinite(_values(arr[k]))):
            bad = "NaN" if np.any(np.isnan(_values(arr[k]))) else "Inf"
            fail(k, f"holds {bad} (only lb/ub may be infinite)")
    for k, wrong in (("lb", np.inf), ("ub", -np.inf)):
        if arr[k] is not None and (np.any(np.isnan(arr[k])) or np.any(arr[k] == wrong)):
            fail(k, f"holds NaN or {wrong:+}")
    scale = float(np.max(np.abs(_values(P)), initial=0.0))
    asym = float(np.max(np.abs(_values(P - P.T)), initial=0.0))
    if asym > SYMMETRY_RTOL * scale:
        fail("P", f"is not symmetric (max |P - P'| = {asym:.3g} > {SYMMETRY_RTOL:g} max |P|)")
    if not isinstance(name, str) or not name:
        msg = f"problem name {name!r} is not a non-empty string"
        raise ProblemFormatError(msg, path=path, key="name")
    if not np.isfinite(offset):
        fail("offset", f"offset {offset} is not finite")
    if record.convexity is None:
        record.convexity = assess_convexity(record.problem.P)
