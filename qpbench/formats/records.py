"""Problem records and sets, and the data rules every reader checks.

See :mod:`qpbench.formats` for the formats and the rules.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np
import qpsolvers
import scipy.sparse as spa

from ..exceptions import ProblemFormatError

#: Columns of qpbenchmark's ``ProblemList`` (order kept).
PROBLEM_KEYS = ("P", "q", "G", "h", "A", "b", "lb", "ub", "name")
#: Array columns, in qpsolvers' argument order.
ARRAY_KEYS = ("P", "q", "G", "h", "A", "b", "lb", "ub")
#: Metadata columns added by qpbench.
META_KEYS = ("scenario", "tick", "t", "formulation", "offset")
#: File names inside a problem-set folder.
PARQUET_NAME = "problems.parquet"
MANIFEST_NAME = "manifest.json"
#: npz member that carries the record metadata (ignored by ``Problem.load``).
NPZ_META_KEY = "qpbench_record"
#: Version of the problem-set layout written in the manifest.
FORMAT_VERSION = 1
#: Maros-Meszaros convention: a bound with ``|value| >= 1e20`` is infinite.
MM_INFINITY = 1e20
#: A sparse problem whose matrices hold more entries than this (P, G and A made dense;
#: 8 MB of float64) is not also written dense for qpsolvers / qpbenchmark readers.
DENSE_COPY_MAX = 1_000_000
#: ``P`` is symmetric when ``max |P - P'| <= SYMMETRY_RTOL max |P|``.
SYMMETRY_RTOL = 1e-9

_MATRIX_KEYS = ("P", "G", "A")


@dataclass
class ProblemRecord:
    """One QP and where it comes from.

    Attributes:
        problem: The QP (``qpsolvers.Problem``).
        name: Unique name within its set (e.g. ``wall/tick-000123`` or ``HS21``).
        scenario: Scenario that produced it, if any.
        tick: Control tick index, if any.
        t: Simulated time of the tick in [s], if any.
        formulation: ``"paper"`` (hard task equality, paper eq. 11), ``"soft"``
            (task as a weighted cost) or ``None``.
        offset: Constant term of the objective (Maros-Meszaros ``r``).
        convexity: What :func:`~qpbench.formats.convexity.assess_convexity` found
            (set by :func:`check_record`, which every reader calls).
    """

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
        """``(n, m_eq, m_ineq)``: variables, equality rows, inequality rows (bounds excluded)."""
        return problem_sizes(self.problem)

    def meta(self) -> dict:
        """The metadata as a JSON-able dict (everything but the problem)."""
        return {
            "name": self.name,
            "scenario": self.scenario,
            "tick": self.tick,
            "t": self.t,
            "formulation": self.formulation,
            "offset": self.offset,
        }


@dataclass
class ProblemSet:
    """A sequence of problem records read from (or written to) disk.

    Attributes:
        name: Folder or file stem.
        path: Where it was read from (a folder or a file), ``None`` if built in memory.
        records: The problems, in file order.
        manifest: Content of ``manifest.json`` (``None`` for other formats).
        sha256: SHA-256 of ``problems.parquet`` (``None`` for other formats).
        kind: ``"set"``, ``"parquet"``, ``"npz"`` or ``"mat"``.
        files: The files the records were read from.
        hash_ok: Whether the manifest hash matched (``None`` if not checked).
    """

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


def problem_sizes(problem: qpsolvers.Problem) -> tuple[int, int, int]:
    """``(n, m_eq, m_ineq)`` of a problem (box bounds are not counted as rows)."""
    n = int(np.asarray(problem.q).shape[0])
    m_eq = 0 if problem.A is None else int(problem.A.shape[0])
    m_ineq = 0 if problem.G is None else int(problem.G.shape[0])
    return n, m_eq, m_ineq


def _dense(M, key: str, path, name) -> np.ndarray | None:
    if M is None:
        return None
    if spa.issparse(M):
        M = M.toarray()
    try:
        return np.asarray(M, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ProblemFormatError(
            f"problem '{name}': not numeric ({exc})", path=path, key=key
        ) from None


def dense_problem(
    problem: qpsolvers.Problem, path: str | Path | None = None, name: str | None = None
) -> qpsolvers.Problem:
    """A copy of ``problem`` with dense float64 arrays (a dense problem's arrays pass through
    unchanged when they already are float64)."""
    arrays = [_dense(getattr(problem, k), k, path, name) for k in ARRAY_KEYS]
    return qpsolvers.Problem(*arrays)


def dense_entries(problem: qpsolvers.Problem) -> int:
    """Entries of ``P``, ``G`` and ``A`` made dense: ``n (n + m_ineq + m_eq)``."""
    n, m_eq, m_ineq = problem_sizes(problem)
    return n * (n + m_eq + m_ineq)


def solver_problem(problem: qpsolvers.Problem) -> qpsolvers.Problem:
    """``problem`` with float64 arrays, its sparse matrices kept sparse (CSC): what a
    solver with a sparse API is given. A dense problem of float64 arrays passes through."""
    parts = []
    for k in ARRAY_KEYS:
        v = getattr(problem, k)
        if v is not None:
            v = (
                spa.csc_matrix(v, dtype=np.float64)
                if spa.issparse(v)
                else np.asarray(v, dtype=np.float64)
            )
        parts.append(v)
    return qpsolvers.Problem(*parts)


def _numeric(v, key: str, fail):
    """``v`` as float64 (CSC for a sparse matrix), or a failure naming ``key``."""
    if spa.issparse(v):
        if v.dtype.kind not in "fiub":
            fail(key, f"dtype {v.dtype} is not numeric")
        return (
            spa.csc_matrix(v, dtype=np.float64) if v.format != "csc" or v.dtype != np.float64 else v
        )
    v = np.asarray(v)
    if v.dtype.kind not in "fiub":
        fail(key, f"dtype {v.dtype} is not numeric")
    return v.astype(np.float64, copy=False)


def _values(M) -> np.ndarray:
    """The stored values of a dense or sparse array (never a dense copy of a sparse one)."""
    return M.data if spa.issparse(M) else M


def _asymmetry(P) -> float:
    """``max |P - P'|`` without a dense copy of a sparse ``P``."""
    D = P - P.T
    if spa.issparse(D):
        return float(abs(D).max()) if D.nnz else 0.0
    return float(np.max(np.abs(D), initial=0.0))


def check_problem(
    problem: qpsolvers.Problem, path: str | Path | None = None, name: str | None = None
) -> None:
    """Check shapes and values of a problem (see :mod:`qpbench.formats` for the rules).

    Sparse matrices are checked through their stored values: nothing is made dense.
    Convexity is not a format rule (:func:`~qpbench.formats.convexity.assess_convexity`).

    Raises:
        ProblemFormatError: naming ``path``, the problem ``name`` and the field.
    """

    def fail(key, msg):
        raise ProblemFormatError(f"problem '{name}': {msg}", path=path, key=key)

    arr = {
        k: None if getattr(problem, k) is None else _numeric(getattr(problem, k), k, fail)
        for k in ARRAY_KEYS
    }
    P, q = arr["P"], arr["q"]
    if P is None:
        fail("P", "missing")
    if q is None:
        fail("q", "missing")
    if q.ndim != 1:
        fail("q", f"shape {q.shape} is not a vector")
    n = q.shape[0]
    if n == 0:
        fail("q", "no variables (n = 0)")
    if P.shape != (n, n):
        fail("P", f"shape {P.shape} does not match n = {n} (expected {(n, n)})")
    for M, v in (("G", "h"), ("A", "b")):
        if (arr[M] is None) != (arr[v] is None):
            fail(
                M if arr[M] is None else v, f"'{M}' and '{v}' must both be given or both be absent"
            )
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
    if arr["lb"] is not None and (np.any(np.isnan(arr["lb"])) or np.any(arr["lb"] == np.inf)):
        fail("lb", "holds NaN or +inf")
    if arr["ub"] is not None and (np.any(np.isnan(arr["ub"])) or np.any(arr["ub"] == -np.inf)):
        fail("ub", "holds NaN or -inf")
    values = _values(P)
    scale = float(np.max(np.abs(values))) if values.size else 0.0
    if _asymmetry(P) > SYMMETRY_RTOL * scale:
        fail(
            "P",
            f"is not symmetric (max |P - P'| = {_asymmetry(P):.3g} > {SYMMETRY_RTOL:g} max |P|)",
        )


def check_record(record: ProblemRecord, path: str | Path | None = None) -> None:
    """:func:`check_problem` plus the metadata types; sets :attr:`ProblemRecord.convexity`."""
    from .convexity import assess_convexity

    check_problem(record.problem, path=path, name=record.name)
    if not isinstance(record.name, str) or not record.name:
        raise ProblemFormatError(
            f"problem name {record.name!r} is not a non-empty string", path=path, key="name"
        )
    if not np.isfinite(record.offset):
        raise ProblemFormatError(
            f"problem '{record.name}': offset {record.offset} is not finite",
            path=path,
            key="offset",
        )
    if record.convexity is None:
        record.convexity = assess_convexity(record.problem.P)
