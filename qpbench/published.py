"""qpbenchmark's own rules and published numbers, read from its installed modules and files."""

from __future__ import annotations

import csv
import functools
import logging
import math
from pathlib import Path
from typing import TYPE_CHECKING

from .exceptions import InputError

if TYPE_CHECKING:
    from types import ModuleType

    import pandas as pd


#: qpbenchmark's settings names, in the order of increasing accuracy asked ("default": the solvers' own).
SETTINGS_NAMES = ("default", "low_accuracy", "mid_accuracy", "high_accuracy")
#: Columns of a qpbenchmark results file.
RESULTS_COLUMNS = (
    "problem",
    "solver",
    "settings",
    "runtime",
    "found",
    "primal_residual",
    "dual_residual",
    "duality_gap",
)


def import_qpbenchmark() -> ModuleType:
    """Import qpbenchmark, leaving the root logger as it was (it adds a handler at import)."""
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    import qpbenchmark

    root.handlers[:] = handlers
    root.setLevel(level)
    return qpbenchmark


@functools.lru_cache(maxsize=None)
def qpbenchmark_settings(runtime: float | None = None) -> tuple[dict, dict]:
    """``(kwargs, tolerances)`` of a ``qpbenchmark.TestSet`` per settings name (its runner's
    arguments per solver, shared: do not modify), under a time limit ``runtime`` [s]."""
    qpb = import_qpbenchmark()

    class _Settings(qpb.TestSet):
        description = "qpbenchmark's settings, read by qpbench"
        title = "qpbench"
        sparse_only = False

        def __iter__(self):
            return iter(())

        def define_tolerances(self) -> None:
            super().define_tolerances(**({} if runtime is None else {"runtime": float(runtime)}))

    previous = logging.root.manager.disable
    # "solver X is available but skipped as its settings are unknown"
    logging.disable(logging.WARNING)
    try:
        test_set = _Settings()
    finally:
        logging.disable(previous)
    solvers = sorted(qpb.solver_settings.SolverSettings.IMPLEMENTED_SOLVERS)
    kwargs = {
        name: {solver: dict(settings[solver]) for solver in solvers}
        for name, settings in test_set.solver_settings.items()
    }
    return kwargs, dict(test_set.tolerances)


def qpbenchmark_success(
    found: bool, primal: float, dual: float, gap: float, tolerance: object
) -> bool:
    """qpbenchmark's success rule (its ``build_success_rate_df``): ``found`` and each
    residual strictly below ``tolerance``'s."""
    return (
        bool(found) and primal < tolerance.primal and dual < tolerance.dual and gap < tolerance.gap
    )


def read_published_results(path: str | Path) -> pd.DataFrame:
    """A qpbenchmark results file (CSV or Parquet, as its ``Results`` writes them)."""
    import pandas as pd

    path = Path(path)
    try:
        df = pd.read_parquet(path) if path.suffix == ".parquet" else pd.read_csv(path)
    except Exception as exc:  # pandas raises many types for a bad file
        raise InputError(
            f"unreadable results file ({type(exc).__name__}: {exc})", path=path
        ) from None
    missing = [c for c in RESULTS_COLUMNS if c not in df.columns]
    if missing:
        raise InputError(
            f"not a qpbenchmark results file (missing columns: {', '.join(missing)})",
            path=path,
            key=missing[0],
        )
    df["found"] = df["found"].map(lambda v: str(v).strip().lower() in ("true", "1"))
    return df


def read_objectives(path: str | Path) -> dict[str, float]:
    """Known optimal objectives ``1/2 x'Px + q'x + r`` of a CSV with a header
    ``problem,objective``; an :class:`InputError` names a bad line."""
    path = Path(path)
    try:
        rows = list(csv.reader(path.read_text(encoding="utf-8").splitlines()))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"unreadable reference file ({exc})", path=path) from None
    header = [c.strip() for c in rows[0]] if rows else []
    for key in ("problem", "objective"):
        if key not in header:
            raise InputError(
                "reference file needs a header with columns problem,objective", path=path, key=key
            )
    ip, io = header.index("problem"), header.index("objective")
    out: dict[str, float] = {}
    for line, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue

        def bad(message: str, key: str = "objective", line=line):
            raise InputError(f"line {line}: {message}", path=path, key=key)

        if len(row) <= max(ip, io):
            bad(f"{len(row)} fields, expected {len(header)}")
        name, value = row[ip].strip(), row[io].strip()
        try:
            f = float(value)
        except ValueError:
            f = math.nan
        if not math.isfinite(f):
            bad(f"objective of '{name}' is not a finite number: '{value}'")
        if name in out:
            bad(f"problem '{name}' listed twice", key="problem")
        out[name] = f
    return out
