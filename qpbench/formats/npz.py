"""One problem <-> one ``.npz`` file (:meth:`qpsolvers.Problem.save` / ``load``)."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import qpsolvers
import scipy.sparse as spa

from ..atomic import atomic_path
from ..exceptions import ProblemFormatError
from ..memory import dense_entries
from .records import (
    ARRAY_KEYS,
    DENSE_COPY_MAX,
    MATRIX_KEYS,
    NPZ_META_KEY,
    ProblemRecord,
    check_record,
    solver_problem,
    sorted_csc,
)

#: Stored arrays of a sparse matrix ``M``: ``M_csc_data``, ``M_csc_indices``, ``M_csc_indptr``,
#: ``M_csc_shape`` (scipy's CSC, indices sorted).
CSC_PARTS = ("data", "indices", "indptr", "shape")


def _csc_members(key: str, M) -> dict[str, np.ndarray]:
    M = sorted_csc(M)
    parts = (M.data, M.indices, M.indptr, np.asarray(M.shape, dtype=np.int64))
    return {f"{key}_csc_{part}": v for part, v in zip(CSC_PARTS, parts)}


def _append(path: Path, members: dict[str, np.ndarray]) -> None:
    with zipfile.ZipFile(path, mode="a", compression=zipfile.ZIP_STORED) as zf:
        for key, value in members.items():
            with zf.open(f"{key}.npy", "w") as member:
                np.lib.format.write_array(member, value, allow_pickle=False)


def save_npz(record: ProblemRecord, path: str | Path) -> Path:
    """Write one record to ``path`` atomically, through :meth:`qpsolvers.Problem.save`
    while the problem is at most ``DENSE_COPY_MAX`` entries dense (a larger one is read by
    qpbench only), then the metadata and CSC members."""
    path = Path(path)
    check_record(record, path=path)
    sparse = {
        k: getattr(record.problem, k)
        for k in MATRIX_KEYS
        if spa.issparse(getattr(record.problem, k))
    }
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            if dense_entries(record.problem) <= DENSE_COPY_MAX:
                solver_problem(record.problem, dense=True).save(fh)
            else:
                np.savez(
                    fh,
                    **{
                        k: np.asarray(getattr(record.problem, k), dtype=np.float64)
                        for k in ARRAY_KEYS
                        if k not in sparse and getattr(record.problem, k) is not None
                    },
                )
        members = {NPZ_META_KEY: np.array(json.dumps(record.meta(), sort_keys=True))}
        for key, M in sparse.items():
            members.update(_csc_members(key, M))
        _append(tmp, members)
    return path


def _read_members(data) -> qpsolvers.Problem:
    """The problem of a file with CSC members (dense members for the other parts)."""
    parts = []
    for k in ARRAY_KEYS:
        if f"{k}_csc_data" in data.files:
            d, i, p, shape = (data[f"{k}_csc_{part}"] for part in CSC_PARTS)
            parts.append(spa.csc_matrix((d, i, p), shape=tuple(int(v) for v in shape)))
        elif k in data.files:
            try:
                v = data[k]
            except ValueError:  # qpsolvers writes an absent part as a pickled None
                v = None
            parts.append(None if v is None or v.dtype == object else v)
        else:
            parts.append(None)
    return qpsolvers.Problem(*parts)


def load_npz(path: str | Path) -> ProblemRecord:
    """One record of a ``.npz`` of :func:`save_npz` or :meth:`qpsolvers.Problem.save`
    (named by the file stem)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [
                k for k in ("P", "q") if k not in data.files and f"{k}_csc_data" not in data.files
            ]
            if missing:
                raise ProblemFormatError("missing array", path=path, key=missing[0])
            meta = json.loads(str(data[NPZ_META_KEY])) if NPZ_META_KEY in data.files else {}
            compact = any(f.endswith("_csc_data") for f in data.files)
            problem = _read_members(data) if compact else None
        if problem is None:
            problem = qpsolvers.Problem.load(str(path))
    except FileNotFoundError:
        raise ProblemFormatError("no such file", path=path) from None
    except ProblemFormatError:
        raise
    except Exception as exc:  # zipfile.BadZipFile, EOFError, OSError, ValueError, qpsolvers errors
        raise ProblemFormatError(
            f"unreadable .npz ({type(exc).__name__}: {exc})", path=path
        ) from None
    name = meta.get("name") or path.stem
    if problem.P is None or problem.q is None:
        raise ProblemFormatError(
            f"problem '{name}': P or q is not a numeric array", path=path, key="P"
        )
    try:
        problem = solver_problem(problem)
    except (TypeError, ValueError) as exc:
        raise ProblemFormatError(f"problem '{name}': not numeric ({exc})", path=path) from None
    record = ProblemRecord(
        problem,
        name,
        **{k: meta.get(k) for k in ("scenario", "tick", "t", "formulation")},
        offset=float(meta.get("offset", 0.0)),
    )
    check_record(record, path=path)
    return record
