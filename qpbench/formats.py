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
  holding JSON) that ``Problem.load`` ignores. Sparse matrices are stored dense
  (``Problem.save`` turns a sparse ``G`` or ``A`` into an object array that
  ``Problem.load`` silently reads back as ``None``).
- **A problem set <-> a folder** (:func:`write_problem_set`,
  :func:`read_problem_set`) holding ``problems.parquet`` and ``manifest.json``.
  The Parquet file has qpbenchmark's ``ProblemList`` columns
  ``P q G h A b lb ub name`` (``list<double>``, matrices flattened row-major, so
  ``rows = size / n``; null for an absent part) and the metadata columns
  ``scenario`` (string), ``tick`` (int64), ``t`` (double, [s]),
  ``formulation`` (string) and ``offset`` (double). ``qpbenchmark.ParquetTestSet``
  runs it as a test set. The writer options are pinned (zstd, no dictionary, no
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
  all matrices are stored dense (the problems of interest are small), and
  ``r`` is kept as :attr:`ProblemRecord.offset`, so that
  ``1/2 x'Px + q'x + r`` equals the published optimal values.

Data rules (checked by every reader; :func:`check_problem`):
``P`` is ``n x n``, symmetric (to 1e-9 relative) and not clearly indefinite
(smallest eigenvalue >= -1e-8 max(1, |P|)); ``q`` has ``n`` entries; ``G, h`` and
``A, b`` come in pairs with matching rows; ``P q G h A b`` are finite (a row
without a limit is dropped rather than stored with ``h = +inf``, because several
solvers reject infinite ``h``); ``lb`` may hold ``-inf`` and ``ub`` may hold
``+inf`` (no bound), never NaN, ``lb = +inf`` or ``ub = -inf``. A violation raises
:class:`~qpbench.exceptions.ProblemFormatError` naming the file, the problem and
the field.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np
import qpsolvers
import scipy.sparse as spa

from .atomic import atomic_path, write_bytes, write_text
from .exceptions import ProblemFormatError

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
    """

    problem: qpsolvers.Problem
    name: str
    scenario: str | None = None
    tick: int | None = None
    t: float | None = None
    formulation: str | None = None
    offset: float = 0.0

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


# ---------------------------------------------------------------- validation


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
        raise ProblemFormatError(f"problem '{name}': not numeric ({exc})", path=path, key=key) from None


def dense_problem(problem: qpsolvers.Problem, path=None, name=None) -> qpsolvers.Problem:
    """A copy of ``problem`` with dense float64 arrays (a dense problem's arrays pass through
    unchanged when they already are float64)."""
    arrays = [_dense(getattr(problem, k), k, path, name) for k in ARRAY_KEYS]
    return qpsolvers.Problem(*arrays)


def check_problem(problem: qpsolvers.Problem, path=None, name: str | None = None) -> None:
    """Check shapes and values of a problem (see the module docstring for the rules).

    Raises:
        ProblemFormatError: naming ``path``, the problem ``name`` and the field.
    """

    def fail(key, msg):
        raise ProblemFormatError(f"problem '{name}': {msg}", path=path, key=key)

    arr = {k: getattr(problem, k) for k in ARRAY_KEYS}
    for k in ARRAY_KEYS:
        v = arr[k]
        if v is None:
            continue
        if spa.issparse(v):
            v = v.toarray()
        v = np.asarray(v)
        if v.dtype.kind not in "fiub":
            fail(k, f"dtype {v.dtype} is not numeric")
        arr[k] = v.astype(np.float64, copy=False)
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
            fail(M if arr[M] is None else v, f"'{M}' and '{v}' must both be given or both be absent")
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
        if arr[k] is not None and not np.all(np.isfinite(arr[k])):
            bad = "NaN" if np.any(np.isnan(arr[k])) else "Inf"
            fail(k, f"holds {bad} (only lb/ub may be infinite)")
    if arr["lb"] is not None and (np.any(np.isnan(arr["lb"])) or np.any(arr["lb"] == np.inf)):
        fail("lb", "holds NaN or +inf")
    if arr["ub"] is not None and (np.any(np.isnan(arr["ub"])) or np.any(arr["ub"] == -np.inf)):
        fail("ub", "holds NaN or -inf")
    scale = max(1.0, float(np.max(np.abs(P))) if P.size else 1.0)
    if np.max(np.abs(P - P.T), initial=0.0) > 1e-9 * scale:
        fail("P", "is not symmetric")
    if n <= 2000:
        lam_min = float(np.linalg.eigvalsh(P)[0])
        if lam_min < -1e-8 * scale:
            fail("P", f"is indefinite (smallest eigenvalue {lam_min:.3g})")


def check_record(record: ProblemRecord, path=None) -> None:
    """:func:`check_problem` plus the metadata types."""
    check_problem(record.problem, path=path, name=record.name)
    if not isinstance(record.name, str) or not record.name:
        raise ProblemFormatError(f"problem name {record.name!r} is not a non-empty string", path=path, key="name")
    if not np.isfinite(record.offset):
        raise ProblemFormatError(f"problem '{record.name}': offset {record.offset} is not finite", path=path, key="offset")


# ---------------------------------------------------------------- npz


def save_npz(record: ProblemRecord, path: str | Path) -> Path:
    """Write one record to ``path`` (``.npz``) through :meth:`qpsolvers.Problem.save`.

    The metadata is one extra member, ``qpbench_record`` (JSON in a 0-d unicode
    array). Sparse matrices are written dense. The write is atomic.

    Returns:
        The path written.
    """
    path = Path(path)
    check_record(record, path=path)
    problem = dense_problem(record.problem, path=path, name=record.name)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            problem.save(fh)
        meta = np.array(json.dumps(record.meta(), sort_keys=True))
        with zipfile.ZipFile(tmp, mode="a", compression=zipfile.ZIP_STORED) as zf:
            with zf.open(f"{NPZ_META_KEY}.npy", "w") as member:
                np.lib.format.write_array(member, meta, allow_pickle=False)
    return path


def load_npz(path: str | Path) -> ProblemRecord:
    """Read one record from a ``.npz`` written by :func:`save_npz` or by
    :meth:`qpsolvers.Problem.save` (then the name is the file stem).

    Raises:
        ProblemFormatError: unreadable, truncated or inconsistent file.
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in ("P", "q") if k not in data.files]
            if missing:
                raise ProblemFormatError("missing array", path=path, key=missing[0])
            meta = json.loads(str(data[NPZ_META_KEY])) if NPZ_META_KEY in data.files else {}
        problem = qpsolvers.Problem.load(str(path))
    except FileNotFoundError:
        raise ProblemFormatError("no such file", path=path) from None
    except ProblemFormatError:
        raise
    except Exception as exc:  # zipfile.BadZipFile, EOFError, OSError, ValueError, qpsolvers errors
        raise ProblemFormatError(f"unreadable .npz ({type(exc).__name__}: {exc})", path=path) from None
    name = meta.get("name") or path.stem
    if problem.P is None or problem.q is None:
        raise ProblemFormatError(f"problem '{name}': P or q is not a numeric array", path=path, key="P")
    problem = dense_problem(problem, path=path, name=name)
    record = ProblemRecord(
        problem=problem,
        name=name,
        scenario=meta.get("scenario"),
        tick=meta.get("tick"),
        t=meta.get("t"),
        formulation=meta.get("formulation"),
        offset=float(meta.get("offset", 0.0)),
    )
    check_record(record, path=path)
    return record


# ---------------------------------------------------------------- parquet


def _schema():
    import pyarrow as pa

    lst = pa.list_(pa.float64())
    return pa.schema(
        [(k, lst) for k in ARRAY_KEYS]
        + [
            ("name", pa.string()),
            ("scenario", pa.string()),
            ("tick", pa.int64()),
            ("t", pa.float64()),
            ("formulation", pa.string()),
            ("offset", pa.float64()),
        ]
    )


def _list_column(values: list[np.ndarray | None]):
    import pyarrow as pa

    lengths = [0 if v is None else v.size for v in values]
    offsets = np.zeros(len(values) + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    flat = [v.ravel(order="C") for v in values if v is not None]
    data = np.concatenate(flat) if flat else np.zeros(0)
    mask = pa.array([v is None for v in values], type=pa.bool_())
    return pa.ListArray.from_arrays(pa.array(offsets, type=pa.int32()), pa.array(data, type=pa.float64()), mask=mask)


def records_to_table(records: list[ProblemRecord], path=None):
    """The records as a ``pyarrow.Table`` in the problem-set schema."""
    import pyarrow as pa

    problems = []
    for r in records:
        check_record(r, path=path)
        problems.append(dense_problem(r.problem, path=path, name=r.name))
    names = [r.name for r in records]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise ProblemFormatError(f"problem name '{dup}' is not unique", path=path, key="name")
    cols = [_list_column([getattr(p, k) for p in problems]) for k in ARRAY_KEYS]
    cols += [
        pa.array(names, type=pa.string()),
        pa.array([r.scenario for r in records], type=pa.string()),
        pa.array([None if r.tick is None else int(r.tick) for r in records], type=pa.int64()),
        pa.array([None if r.t is None else float(r.t) for r in records], type=pa.float64()),
        pa.array([r.formulation for r in records], type=pa.string()),
        pa.array([float(r.offset) for r in records], type=pa.float64()),
    ]
    return pa.Table.from_arrays(cols, schema=_schema())


def table_to_bytes(table) -> bytes:
    """Serialise a table to Parquet with pinned writer options (deterministic bytes)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    sink = pa.BufferOutputStream()
    pq.write_table(
        table,
        sink,
        row_group_size=max(1, table.num_rows),
        version="2.6",
        data_page_version="1.0",
        compression="zstd",
        compression_level=3,
        use_dictionary=False,
        write_statistics=False,
        write_page_index=False,
        write_page_checksum=False,
        store_schema=True,
    )
    return sink.getvalue().to_pybytes()


def package_versions(names: tuple[str, ...] = ("qpbench", "numpy", "scipy", "qpsolvers", "pyarrow")) -> dict[str, str | None]:
    """Installed version of each distribution in ``names`` (``None`` when absent); by default
    the packages that shape the files and the numbers."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for pkg in names:
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = None
    return out


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def write_problem_set(
    folder: str | Path, records: list[ProblemRecord], generator: dict, extra: dict | None = None
) -> Path:
    """Write ``records`` to ``folder/problems.parquet`` and ``folder/manifest.json``.

    Args:
        folder: Output folder (created if needed; existing files are replaced).
        records: The problems, in order; names must be unique.
        generator: What produced the set, e.g. ``{"name": "simulate", "scenario":
            "wall", "backend": "clarabel", "duration": 2.0}`` (JSON-able).
        extra: More JSON-able information for the manifest.

    Returns:
        The folder.

    Both files are written atomically, Parquet first, so a manifest never
    describes a Parquet file that is not complete.
    """
    folder = Path(folder)
    table = records_to_table(records, path=folder / PARQUET_NAME)
    data = table_to_bytes(table)
    digest = sha256_bytes(data)
    manifest = {
        "format": "qpbench-problem-set",
        "format_version": FORMAT_VERSION,
        "file": PARQUET_NAME,
        "count": len(records),
        "sha256": digest,
        "generator": generator,
        "extra": extra or {},
        "versions": package_versions(),
        "columns": list(PROBLEM_KEYS) + list(META_KEYS),
    }
    try:
        text = json.dumps(manifest, indent=2, sort_keys=True, allow_nan=False) + "\n"
    except (TypeError, ValueError) as exc:
        raise ProblemFormatError(f"generator/extra is not JSON-able ({exc})", path=folder / MANIFEST_NAME, key="generator") from None
    write_bytes(folder / PARQUET_NAME, data)
    write_text(folder / MANIFEST_NAME, text)
    return folder


def _read_parquet_records(path: Path, require_meta: bool) -> list[ProblemRecord]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except FileNotFoundError:
        raise ProblemFormatError("no such file", path=path) from None
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise ProblemFormatError(f"unreadable Parquet file ({type(exc).__name__}: {exc})", path=path) from None
    required = list(PROBLEM_KEYS) + (list(META_KEYS) if require_meta else [])
    for k in required:
        if k not in table.column_names:
            raise ProblemFormatError("missing column", path=path, key=k)
    rows = table.num_rows
    arrays: dict[str, list] = {}
    for k in ARRAY_KEYS:
        col = table.column(k)
        if pa.types.is_null(col.type):
            arrays[k] = [None] * rows
            continue
        if not (pa.types.is_list(col.type) or pa.types.is_large_list(col.type)):
            raise ProblemFormatError(f"type {col.type} is not a list of numbers", path=path, key=k)
        chunk = col.combine_chunks() if col.num_chunks != 1 else col.chunk(0)
        if not (pa.types.is_floating(chunk.type.value_type) or pa.types.is_integer(chunk.type.value_type)):
            raise ProblemFormatError(f"type {col.type} is not a list of numbers", path=path, key=k)
        offsets = chunk.offsets.to_numpy()
        values = chunk.values.cast(pa.float64()).to_numpy(zero_copy_only=False)
        nulls = chunk.is_null().to_numpy(zero_copy_only=False)
        arrays[k] = [
            None if nulls[i] else np.array(values[offsets[i] : offsets[i + 1]], dtype=np.float64)
            for i in range(rows)
        ]
    names = table.column("name").to_pylist()

    def meta(key):
        return table.column(key).to_pylist() if key in table.column_names else [None] * rows

    scen, tick, t, form, off = (meta(k) for k in META_KEYS)
    records = []
    for i in range(rows):
        name = names[i] if names[i] is not None else f"{path.stem}-{i}"
        q = arrays["q"][i]
        if q is None:
            raise ProblemFormatError(f"problem '{name}' (row {i}): missing", path=path, key="q")
        n = q.size
        if n == 0:
            raise ProblemFormatError(f"problem '{name}' (row {i}): no variables", path=path, key="q")
        data = {}
        for k in ARRAY_KEYS:
            v = arrays[k][i]
            if v is not None and k in _MATRIX_KEYS:
                if v.size % n:
                    raise ProblemFormatError(
                        f"problem '{name}' (row {i}): {v.size} values is not a multiple of n = {n}", path=path, key=k
                    )
                v = v.reshape((v.size // n, n))
            data[k] = v
        if data["P"] is None:
            raise ProblemFormatError(f"problem '{name}' (row {i}): missing", path=path, key="P")
        offset = off[i]
        rec = ProblemRecord(
            problem=qpsolvers.Problem(**data),
            name=name,
            scenario=scen[i],
            tick=None if tick[i] is None else int(tick[i]),
            t=t[i],
            formulation=form[i],
            offset=0.0 if offset is None else float(offset),
        )
        check_record(rec, path=path)
        records.append(rec)
    return records


def read_manifest(folder: str | Path) -> dict:
    """Read and check ``folder/manifest.json``."""
    mpath = Path(folder) / MANIFEST_NAME
    try:
        manifest = json.loads(mpath.read_text())
    except FileNotFoundError:
        raise ProblemFormatError("no such file", path=mpath) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ProblemFormatError(f"unreadable manifest ({exc})", path=mpath) from None
    if not isinstance(manifest, dict):
        raise ProblemFormatError("manifest is not a JSON object", path=mpath)
    for k in ("sha256", "count"):
        if k not in manifest:
            raise ProblemFormatError("missing key", path=mpath, key=k)
    return manifest


def read_problem_set(folder: str | Path, verify_hash: bool = True) -> ProblemSet:
    """Read a problem-set folder written by :func:`write_problem_set`.

    Args:
        folder: The folder (or its ``problems.parquet``).
        verify_hash: Check the SHA-256 and row count against the manifest.

    Raises:
        ProblemFormatError: missing file, hash or count mismatch, corrupt
            Parquet, missing column, bad shapes or values.
    """
    folder = Path(folder)
    if folder.name == PARQUET_NAME:
        folder = folder.parent
    ppath = folder / PARQUET_NAME
    if not ppath.is_file():
        raise ProblemFormatError("no such file", path=ppath)
    manifest = read_manifest(folder)
    digest = sha256_file(ppath)
    hash_ok = digest == manifest["sha256"]
    if verify_hash and not hash_ok:
        raise ProblemFormatError(
            f"SHA-256 {digest[:16]}... does not match manifest's {str(manifest['sha256'])[:16]}... "
            "(file changed or truncated after it was written)",
            path=ppath,
            key="sha256",
        )
    records = _read_parquet_records(ppath, require_meta=True)
    if verify_hash and len(records) != manifest["count"]:
        raise ProblemFormatError(
            f"{len(records)} rows but manifest says {manifest['count']}", path=ppath, key="count"
        )
    return ProblemSet(
        name=folder.resolve().name,
        path=folder,
        records=records,
        manifest=manifest,
        sha256=digest,
        kind="set",
        files=[ppath],
        hash_ok=hash_ok,
    )


def read_parquet(path: str | Path) -> ProblemSet:
    """Read a bare qpbenchmark Parquet file (``ProblemList.to_parquet``); the
    metadata columns are read when present."""
    path = Path(path)
    records = _read_parquet_records(path, require_meta=False)
    return ProblemSet(name=path.stem, path=path, records=records, kind="parquet", files=[path])


# ---------------------------------------------------------------- Maros-Meszaros


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


# ---------------------------------------------------------------- dispatch


def _npz_folder(folder: Path) -> ProblemSet:
    files = sorted(folder.glob("*.npz"))
    return ProblemSet(
        name=folder.resolve().name, path=folder, records=[load_npz(f) for f in files], kind="npz", files=files
    )


def _mat_folder(folder: Path) -> ProblemSet:
    files = sorted(folder.glob("*.mat"))
    return ProblemSet(
        name=folder.resolve().name,
        path=folder,
        records=[load_maros_meszaros(f) for f in files],
        kind="mat",
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
            return _npz_folder(path)
        if any(path.glob("*.mat")):
            return _mat_folder(path)
        raise ProblemFormatError(
            f"folder holds no {PARQUET_NAME}, .npz or .mat files", path=path
        )
    if not path.exists():
        raise ProblemFormatError("no such file or folder", path=path)
    suffix = path.suffix.lower()
    if suffix == ".parquet":
        if path.name == PARQUET_NAME and (path.parent / MANIFEST_NAME).exists():
            return read_problem_set(path.parent, verify_hash=verify_hash)
        return read_parquet(path)
    if suffix == ".npz":
        return ProblemSet(name=path.stem, path=path, records=[load_npz(path)], kind="npz", files=[path])
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
