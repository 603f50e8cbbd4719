"""A problem set <-> a folder holding ``problems.parquet`` and ``manifest.json``."""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import qpsolvers
import scipy.sparse as spa

from ..atomic import write_bytes, write_text
from ..exceptions import ProblemFormatError
from .records import (
    ARRAY_KEYS,
    CSC_TYPES,
    FORMAT_VERSION,
    MANIFEST_NAME,
    MATRIX_KEYS,
    META_KEYS,
    META_TYPES,
    PARQUET_NAME,
    ProblemRecord,
    ProblemSet,
    check_record,
    checked_csc,
    dense_copy,
    reading,
    sorted_csc,
)

if TYPE_CHECKING:
    import pyarrow as pa


def list_column(values: list[np.ndarray | None], kind: str = "float64"):
    """A pyarrow list column of ``kind`` holding each array flattened (null for ``None``)."""
    import pyarrow as pa

    flat = [None if v is None else v.ravel() for v in values]
    return pa.array(flat, type=pa.list_(getattr(pa, kind)()))


def write_problem_set(
    folder: str | Path, records: list[ProblemRecord], generator: dict, extra: dict | None = None
) -> Path:
    """Write ``records`` to ``folder/problems.parquet`` and ``manifest.json`` (with
    ``generator``, what made the set, and ``extra``), atomically, Parquet first."""
    import pyarrow as pa

    folder = Path(folder)
    path = folder / PARQUET_NAME
    for r in records:
        check_record(r, path=path)
    names = [r.name for r in records]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise ProblemFormatError(f"problem name '{dup}' is not unique", path=path, key="name")
    dense = [dense_copy(r.problem) for r in records]
    cols = {k: list_column([d[k] for d in dense]) for k in ARRAY_KEYS}
    for k, t in META_TYPES.items():
        cols[k] = pa.array([getattr(r, k) for r in records], type=getattr(pa, t)())
    for k in MATRIX_KEYS:
        matrices = [getattr(r.problem, k) for r in records]
        if not any(spa.issparse(M) for M in matrices):
            continue
        parts = [sorted_csc(M) if spa.issparse(M) else None for M in matrices]
        for part, kind in CSC_TYPES.items():
            values = [None if p is None else getattr(p, part) for p in parts]
            cols[f"{k}_csc_{part}"] = list_column(values, kind)
    table = pa.table(cols)
    data = table_to_bytes(table)
    manifest = {
        "format": "qpbench-problem-set",
        "format_version": FORMAT_VERSION,
        "file": PARQUET_NAME,
        "count": len(records),
        "sha256": hashlib.sha256(data).hexdigest(),
        "generator": generator,
        "extra": extra or {},
        "versions": package_versions(),
        "columns": list(table.column_names),
    }
    text = json.dumps(manifest, indent=2, sort_keys=True, allow_nan=False) + "\n"
    write_bytes(path, data)
    write_text(folder / MANIFEST_NAME, text)
    return folder


def table_to_bytes(table: pa.Table) -> bytes:
    """The table as Parquet with pinned writer options (deterministic bytes)."""
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


def package_versions(
    names: tuple[str, ...] = ("qpbench", "numpy", "scipy", "qpsolvers", "pyarrow"),
) -> dict[str, str | None]:
    """Installed version of each distribution (``None`` when absent)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for pkg in names:
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = None
    return out


def sha256_file(path: str | Path) -> str:
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def _list_values(table, key: str, path: Path, dtype=np.float64) -> list:
    """Per row, the values of a list column as a numpy array (``None`` for a null)."""
    import pyarrow as pa

    col = table.column(key)
    if pa.types.is_null(col.type):
        return [None] * table.num_rows
    if not (pa.types.is_list(col.type) or pa.types.is_large_list(col.type)) or not (
        pa.types.is_floating(col.type.value_type) or pa.types.is_integer(col.type.value_type)
    ):
        raise ProblemFormatError(f"type {col.type} is not a list of numbers", path=path, key=key)
    return [None if v is None else np.array(v, dtype=dtype) for v in col.to_numpy()]


def _matrix(arrays: dict, csc: dict, k: str, i: int, n: int, fail):
    """Matrix ``k`` of row ``i``: from its CSC columns when they hold it, else the dense column."""
    parts = csc.get(k)
    if parts is not None and parts[0][i] is not None:
        data, indices, indptr = (p[i] for p in parts)
        vector = None if k == "P" else arrays["h" if k == "G" else "b"][i]
        rows = n if k == "P" else (0 if vector is None else vector.size)
        if len(indptr) != n + 1 or len(indices) != len(data):
            held = f"{len(indptr) - 1} columns and {len(indices)} indices for {len(data)} values"
            fail(k, f"CSC columns hold {held}, expected n = {n} columns")
        try:
            return checked_csc(data, indices.astype(np.int32), indptr, (rows, n))
        except ValueError as exc:
            fail(k, f"CSC columns are inconsistent ({exc})")
    v = arrays[k][i]
    if v is not None:
        if v.size % n:
            fail(k, f"{v.size} values is not a multiple of n = {n}")
        v = v.reshape((v.size // n, n))
    return v


def read_parquet(path: str | Path, require_meta: bool = False) -> ProblemSet:
    """Read a Parquet file of problems: qpbenchmark's (``ProblemList.to_parquet``), its
    metadata columns read when present, or a problem set's (``require_meta``)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    with reading(path, "Parquet file", (pa.ArrowException, OSError, ValueError)):
        table = pq.read_table(path)
    for k in (*ARRAY_KEYS, "name", *(META_KEYS if require_meta else ())):
        if k not in table.column_names:
            raise ProblemFormatError("missing column", path=path, key=k)
    rows = table.num_rows
    arrays = {k: _list_values(table, k, path) for k in ARRAY_KEYS}
    csc = {
        k: [_list_values(table, f"{k}_csc_{part}", path, kind) for part, kind in CSC_TYPES.items()]
        for k in MATRIX_KEYS
        if f"{k}_csc_data" in table.column_names
    }
    meta = {
        k: table.column(k).to_pylist() if k in table.column_names else [None] * rows
        for k in META_TYPES
    }
    records = []
    for i in range(rows):
        name = meta["name"][i] if meta["name"][i] is not None else f"{path.stem}-{i}"

        def fail(key, msg, name=name, i=i):
            raise ProblemFormatError(f"problem '{name}' (row {i}): {msg}", path=path, key=key)

        q = arrays["q"][i]
        if q is None:
            fail("q", "missing")
        n = q.size
        if n == 0:
            fail("q", "no variables")
        data = {
            k: _matrix(arrays, csc, k, i, n, fail) if k in MATRIX_KEYS else arrays[k][i]
            for k in ARRAY_KEYS
        }
        fields = {k: meta[k][i] for k in META_KEYS}
        if fields["tick"] is not None:
            fields["tick"] = int(fields["tick"])
        fields["offset"] = 0.0 if fields["offset"] is None else float(fields["offset"])
        rec = ProblemRecord(qpsolvers.Problem(**data), name, **fields)
        check_record(rec, path=path)
        records.append(rec)
    return ProblemSet(name=path.stem, path=path, records=records, kind="parquet", files=[path])


def read_problem_set(folder: str | Path, verify_hash: bool = True) -> ProblemSet:
    """Read a problem-set folder (``verify_hash``: its SHA-256 and row count, the manifest's)."""
    folder = Path(folder)
    ppath, mpath = folder / PARQUET_NAME, folder / MANIFEST_NAME
    if not ppath.is_file():
        raise ProblemFormatError("no such file", path=ppath)
    with reading(mpath, "manifest", (OSError, ValueError)):
        manifest = json.loads(mpath.read_text())
    if not isinstance(manifest, dict):
        raise ProblemFormatError("manifest is not a JSON object", path=mpath)
    for k in ("sha256", "count"):
        if k not in manifest:
            raise ProblemFormatError("missing key", path=mpath, key=k)
    digest = sha256_file(ppath)
    hash_ok = digest == manifest["sha256"]
    if verify_hash and not hash_ok:
        raise ProblemFormatError(
            f"SHA-256 {digest[:16]}... does not match manifest's {str(manifest['sha256'])[:16]}... "
            "(file changed or truncated after it was written)",
            path=ppath,
            key="sha256",
        )
    pset = read_parquet(ppath, require_meta=True)
    if verify_hash and len(pset) != manifest["count"]:
        raise ProblemFormatError(
            f"{len(pset)} rows but manifest says {manifest['count']}", path=ppath, key="count"
        )
    name = folder.resolve().name
    return replace(
        pset, name=name, path=folder, manifest=manifest, sha256=digest, kind="set", hash_ok=hash_ok
    )
