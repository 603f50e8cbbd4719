"""One problem <-> one ``.npz`` file (:meth:`qpsolvers.Problem.save`); a sparse matrix ``M``
also as members ``M_csc_<part>`` (:data:`~.records.CSC_TYPES`) and ``M_csc_shape``."""

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
    CSC_TYPES,
    DENSE_COPY_MAX,
    META_KEYS,
    NPZ_META_KEY,
    ProblemRecord,
    check_record,
    checked_csc,
    dense_copy,
    reading,
    solver_problem,
    sorted_csc,
)


def save_npz(record: ProblemRecord, path: str | Path) -> Path:
    """Write one record to ``path`` atomically: :meth:`qpsolvers.Problem.save`'s members (up
    to ``DENSE_COPY_MAX`` entries dense), then the metadata and CSC members."""
    path = Path(path)
    check_record(record, path=path)
    problem = record.problem
    members = {NPZ_META_KEY: np.array(json.dumps(record.meta(), sort_keys=True))}
    for key in ARRAY_KEYS:
        M = getattr(problem, key)
        if spa.issparse(M):
            S = sorted_csc(M)
            members.update({f"{key}_csc_{p}": getattr(S, p) for p in CSC_TYPES})
            members[f"{key}_csc_shape"] = np.asarray(M.shape, dtype=np.int64)
    dense = dense_copy(problem)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            if dense_entries(problem) <= DENSE_COPY_MAX:
                qpsolvers.Problem(*dense.values()).save(fh)
            else:
                np.savez(fh, **{k: v for k, v in dense.items() if v is not None})
        with zipfile.ZipFile(tmp, mode="a", compression=zipfile.ZIP_STORED) as zf:
            for key, value in members.items():
                with zf.open(f"{key}.npy", "w") as member:
                    np.lib.format.write_array(member, value, allow_pickle=False)
    return path


def _read_members(data, compact: bool) -> qpsolvers.Problem:
    """The problem of a file: CSC members, else dense ones (only a ``compact`` file, one with
    CSC members, may lack a part: in a file of :meth:`qpsolvers.Problem.save` a KeyError)."""
    parts = []
    for k in ARRAY_KEYS:
        if f"{k}_csc_data" in data.files:
            d, i, p, shape = (data[f"{k}_csc_{part}"] for part in (*CSC_TYPES, "shape"))
            parts.append(checked_csc(d, i, p, tuple(int(v) for v in shape)))
        elif compact and k not in data.files:
            parts.append(None)
        else:
            try:
                parts.append(data[k])
            except ValueError:  # qpsolvers writes an absent part as a pickled None
                parts.append(None)
    return qpsolvers.Problem(*parts)


def load_npz(path: str | Path) -> ProblemRecord:
    """One record of a ``.npz`` of :func:`save_npz` or :meth:`qpsolvers.Problem.save`."""
    path = Path(path)
    with reading(path, ".npz"):
        with np.load(path, allow_pickle=False) as data:
            for k in ("P", "q"):
                if k not in data.files and f"{k}_csc_data" not in data.files:
                    raise ProblemFormatError("missing array", path=path, key=k)
            meta = json.loads(str(data[NPZ_META_KEY])) if NPZ_META_KEY in data.files else {}
            problem = _read_members(data, any(f.endswith("_csc_data") for f in data.files))
    fields = {k: meta.get(k) for k in META_KEYS} | {"offset": float(meta.get("offset", 0.0))}
    record = ProblemRecord(problem, meta.get("name") or path.stem, **fields)
    check_record(record, path=path)
    record.problem = solver_problem(problem)
    return record
