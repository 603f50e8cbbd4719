"""One problem <-> one ``.npz`` file (:meth:`qpsolvers.Problem.save` / ``load``)."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import qpsolvers

from ..atomic import atomic_path
from ..exceptions import ProblemFormatError
from .records import NPZ_META_KEY, ProblemRecord, check_record, dense_problem


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

