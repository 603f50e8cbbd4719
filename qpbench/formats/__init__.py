"""QP problems in the formats of the QP ecosystem.

The problem type is :class:`qpsolvers.Problem`::

    minimize    1/2 x^T P x + q^T x (+ offset)
    subject to  G x <= h,   A x = b,   lb <= x <= ub

:class:`ProblemRecord` puts a little metadata beside it (name, scenario, tick,
time in [s], formulation, constant term of the objective). Records move
through three formats:

- **One problem <-> .npz** (:func:`save_npz`, :func:`load_npz`): written by
  :meth:`qpsolvers.Problem.save` and read by :meth:`qpsolvers.Problem.load`,
  so qpsolvers and qpbenchmark read our files as they read the MPC test set.
  The metadata goes in one extra member ``qpbench_record`` (a 0-d unicode array
  holding JSON) that ``Problem.load`` ignores. A scipy.sparse matrix ``M`` is
  also stored as CSC (members ``M_csc_data, M_csc_indices, M_csc_indptr,
  M_csc_shape``), which :func:`load_npz` prefers (read back bit for bit); the
  dense copy for ``Problem.load`` is written only for problems whose ``P, G, A``
  hold at most ``DENSE_COPY_MAX`` (10^6) entries made dense.
- **A problem set <-> a folder** (:func:`write_problem_set`,
  :func:`read_problem_set`) holding ``problems.parquet`` and ``manifest.json``.
  The Parquet file has qpbenchmark's ``ProblemList`` columns
  ``P q G h A b lb ub name`` (``list<double>``, matrices flattened row-major, so
  ``rows = size / n``; null for an absent part) and the metadata columns
  ``scenario`` (string), ``tick`` (int64), ``t`` (double, [s]),
  ``formulation`` (string) and ``offset`` (double). ``qpbenchmark.ParquetTestSet``
  runs it as a test set. A set holding scipy.sparse matrices has, per such
  matrix ``M``, three more columns ``M_csc_data`` (list<double>),
  ``M_csc_indices`` (list<int32>) and ``M_csc_indptr`` (list<int64>): the
  reader prefers them (bit for bit the same CSC matrix); qpbenchmark's
  column holds the dense copy while the problem has at most ``DENSE_COPY_MAX``
  entries made dense, else null (such a row is read by qpbench only). A set
  without sparse matrices (the robot's) has no such column and the bytes of
  before. The writer options are pinned (zstd, no dictionary, no
  statistics, one row group, format 2.6) and nothing time-dependent is stored,
  so the same records give the same bytes with the same package versions.
  ``manifest.json`` records the generator and its parameters, the package
  versions, the row count and the SHA-256 of ``problems.parquet``; the reader
  checks that hash.
- **Maros-Meszaros .mat** (:func:`load_maros_meszaros`): keys ``P q r A l u n m``
  of the ``l <= A x <= u`` form with ``A = [C; I_n]``. Rows of ``C`` with
  ``l == u`` become equalities ``A x = b``; the other rows become one ``G x <= h``
  row per finite side (upper sides first, then lower sides as ``-C x <= -l``).
  The last ``n`` rows give ``lb, ub``. ``|value| >= 1e20`` means infinite.
  ``P`` is read as a symmetric full matrix (a triangular ``P`` is mirrored);
  ``P``, ``G`` and ``A`` stay scipy.sparse CSC (indices sorted) from the file
  to the solvers, never made dense here, and ``r`` is kept as :attr:`ProblemRecord.offset`, so that
  ``1/2 x'Px + q'x + r`` equals the published optimal values.

Data rules (checked by every reader; :func:`check_problem`, through the stored
values of a sparse matrix, never a dense copy): ``P`` is ``n x n`` and symmetric
(``max |P - P'| <= 1e-9 max |P|``); ``q`` has ``n`` entries; ``G, h`` and
``A, b`` come in pairs with matching rows; ``P q G h A b`` are finite (a row
without a limit is dropped rather than stored with ``h = +inf``, because several
solvers reject infinite ``h``); ``lb`` may hold ``-inf`` and ``ub`` may hold
``+inf`` (no bound), never NaN, ``lb = +inf`` or ``ub = -inf``. A violation raises
:class:`~qpbench.exceptions.ProblemFormatError` naming the file, the problem and
the field. Convexity is not a format rule: every reader records what
:func:`~qpbench.formats.convexity.assess_convexity` finds in
:attr:`ProblemRecord.convexity` (sparse methods, a tolerance for rounding), and
the bench solves a slightly indefinite problem with a warning and skips a
clearly nonconvex one with the reason.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from ..exceptions import ProblemFormatError
from .convexity import Convexity, assess_convexity
from .maros_meszaros import load_maros_meszaros
from .npz import load_npz, save_npz
from .parquet import (
    list_column,
    package_versions,
    read_manifest,
    read_parquet,
    read_problem_set,
    records_to_table,
    sha256_bytes,
    sha256_file,
    table_to_bytes,
    write_problem_set,
)
from .records import (
    ARRAY_KEYS,
    DENSE_COPY_MAX,
    FORMAT_VERSION,
    MANIFEST_NAME,
    META_KEYS,
    MM_INFINITY,
    NPZ_META_KEY,
    PARQUET_NAME,
    PROBLEM_KEYS,
    ProblemRecord,
    ProblemSet,
    check_problem,
    check_record,
    dense_entries,
    dense_problem,
    problem_sizes,
    solver_problem,
)


def _folder(folder: Path, kind: str, load) -> ProblemSet:
    """The ``*.<kind>`` files of ``folder``, sorted, each read by ``load``, as one set."""
    files = sorted(folder.glob(f"*.{kind}"))
    return ProblemSet(
        name=folder.resolve().name,
        path=folder,
        records=[load(f) for f in files],
        kind=kind,
        files=files,
    )


def load_problems(path: str | Path, verify_hash: bool = True) -> ProblemSet:
    """Read problems from any supported place.

    ``path`` may be: a problem-set folder (``problems.parquet`` + ``manifest.json``)
    or its ``problems.parquet``; a bare qpbenchmark ``.parquet``; a folder of
    ``.npz`` files; one ``.npz``; one Maros-Meszaros ``.mat``; a folder of ``.mat``.
    Files in a folder are read in sorted name order.

    Raises:
        ProblemFormatError: nothing readable at ``path``, or a bad file.
    """
    path = Path(path)
    if path.is_dir():
        if (path / PARQUET_NAME).exists():
            return read_problem_set(path, verify_hash=verify_hash)
        if any(path.glob("*.npz")):
            return _folder(path, "npz", load_npz)
        if any(path.glob("*.mat")):
            return _folder(path, "mat", load_maros_meszaros)
        raise ProblemFormatError(f"folder holds no {PARQUET_NAME}, .npz or .mat files", path=path)
    if not path.exists():
        raise ProblemFormatError("no such file or folder", path=path)
    suffix = path.suffix.lower()
    if suffix == ".parquet":
        if path.name == PARQUET_NAME and (path.parent / MANIFEST_NAME).exists():
            return read_problem_set(path.parent, verify_hash=verify_hash)
        return read_parquet(path)
    if suffix == ".npz":
        return ProblemSet(
            name=path.stem, path=path, records=[load_npz(path)], kind="npz", files=[path]
        )
    if suffix == ".mat":
        return ProblemSet(
            name=path.stem, path=path, records=[load_maros_meszaros(path)], kind="mat", files=[path]
        )
    raise ProblemFormatError(
        f"unknown file type '{suffix}' (expected a folder, .parquet, .npz or .mat)", path=path
    )


def content_sha256(problem_set: ProblemSet) -> str | None:
    """SHA-256 identifying the content of a set: the manifest hash for a
    problem-set folder, else a hash of the bytes of its files (sorted by name),
    else ``None`` (built in memory)."""
    if problem_set.sha256:
        return problem_set.sha256
    if not problem_set.files:
        return None
    h = hashlib.sha256()
    for f in sorted(problem_set.files, key=lambda p: p.name):
        h.update(f.name.encode() + b"\0" + sha256_file(f).encode())
    return h.hexdigest()


__all__ = [
    "DENSE_COPY_MAX",
    "Convexity",
    "assess_convexity",
    "dense_entries",
    "solver_problem",
    "ARRAY_KEYS",
    "FORMAT_VERSION",
    "MANIFEST_NAME",
    "META_KEYS",
    "MM_INFINITY",
    "NPZ_META_KEY",
    "PARQUET_NAME",
    "PROBLEM_KEYS",
    "ProblemRecord",
    "ProblemSet",
    "check_problem",
    "check_record",
    "content_sha256",
    "dense_problem",
    "load_maros_meszaros",
    "load_npz",
    "list_column",
    "load_problems",
    "package_versions",
    "problem_sizes",
    "read_manifest",
    "read_parquet",
    "read_problem_set",
    "records_to_table",
    "save_npz",
    "sha256_bytes",
    "sha256_file",
    "table_to_bytes",
    "write_problem_set",
]
