"""QP problems in the formats of the QP ecosystem (docs/formats.md): one problem <-> ``.npz``;
a problem set <-> a folder of ``problems.parquet`` and ``manifest.json``; Maros-Meszaros
``.mat``. Sparse matrices stay sparse from file to solver. Every reader checks the data rules
(:func:`~.records.check_record`), a violation a :class:`~qpbench.exceptions.ProblemFormatError`
naming the file, the problem and the field.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from ..exceptions import ProblemFormatError
from .convexity import assess_convexity as assess_convexity
from .maros_meszaros import load_maros_meszaros
from .npz import load_npz
from .npz import save_npz as save_npz
from .parquet import package_versions as package_versions
from .parquet import read_parquet, read_problem_set, sha256_file
from .parquet import table_to_bytes as table_to_bytes
from .parquet import write_problem_set as write_problem_set
from .records import ARRAY_KEYS as ARRAY_KEYS
from .records import MANIFEST_NAME, PARQUET_NAME, ProblemSet
from .records import ProblemRecord as ProblemRecord
from .records import solver_problem as solver_problem

#: Reader of one file, by file type.
LOADERS = {"npz": load_npz, "mat": load_maros_meszaros}


def load_problems(path: str | Path, verify_hash: bool = True) -> ProblemSet:
    """Problems of a problem-set folder (or its ``problems.parquet``), a bare qpbenchmark
    ``.parquet``, one ``.npz`` or ``.mat``, or a folder of them (read in name order)."""
    path = Path(path)
    if path.is_dir():
        if (path / PARQUET_NAME).exists():
            return read_problem_set(path, verify_hash=verify_hash)
        for kind, load in LOADERS.items():
            files = sorted(path.glob(f"*.{kind}"))
            if files:
                records = [load(f) for f in files]
                return ProblemSet(path.resolve().name, path, records, kind=kind, files=files)
        raise ProblemFormatError(f"folder holds no {PARQUET_NAME}, .npz or .mat files", path=path)
    if not path.exists():
        raise ProblemFormatError("no such file or folder", path=path)
    kind = path.suffix.lower()[1:]
    if kind == "parquet":
        if path.name == PARQUET_NAME and (path.parent / MANIFEST_NAME).exists():
            return read_problem_set(path.parent, verify_hash=verify_hash)
        return read_parquet(path)
    if kind in LOADERS:
        return ProblemSet(path.stem, path, [LOADERS[kind](path)], kind=kind, files=[path])
    raise ProblemFormatError(
        f"unknown file type '.{kind}' (expected a folder, .parquet, .npz or .mat)", path=path
    )


def content_sha256(problem_set: ProblemSet) -> str | None:
    """SHA-256 of a set's content: its manifest's, else of its files' names and bytes."""
    if problem_set.sha256:
        return problem_set.sha256
    if not problem_set.files:
        return None
    h = hashlib.sha256()
    for f in sorted(problem_set.files, key=lambda p: p.name):
        h.update(f.name.encode() + b"\0" + sha256_file(f).encode())
    return h.hexdigest()
