"""Reading result CSVs for a report: bench or closed-loop (by their columns). A result key in
two files, or a backend's rows in one ``(profile, mode)`` from files timed with different
``repeat`` counts, is an error unless ``prefer`` (``first`` or ``last`` file) says which to keep."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..exceptions import InputError
from ..formats import sha256_file
from ..sim.summary import STRUCTURED_FIGURES

#: Columns that identify a bench result across CSVs.
DUPLICATE_KEY = ("problem", "scenario", "backend", "profile", "mode")
#: Columns that make a CSV a bench result.
BENCH_COLUMNS = (
    "problem",
    "backend",
    "profile",
    "found",
    "success",
    "wall_time_median_s",
    "primal_residual",
    "dual_residual",
    "duality_gap",
    "optimality_gap",
)
#: What reading a damaged CSV raises.
CSV_ERRORS = (
    pd.errors.ParserError,
    pd.errors.EmptyDataError,
    UnicodeDecodeError,
    OSError,
    EOFError,
)
#: Columns that make a CSV a closed-loop result.
CLOSED_LOOP_COLUMNS = ("scenario", "backend", "status", "log_file")


@dataclass
class ResultFile:
    """One CSV given to the report; ``kind``: ``bench`` or ``closed-loop``."""

    path: Path
    kind: str
    sha256: str
    rows: int


@dataclass
class Results:
    """All rows of the CSVs given to the report, by kind."""

    bench: pd.DataFrame
    closed_loop: pd.DataFrame
    files: list[ResultFile] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: The noise floor's closed-loop rows (``noop``), kept out of ``closed_loop``.
    noise_floor: pd.DataFrame = field(default_factory=pd.DataFrame)


def _from_json(text):
    """A list- or dict-valued cell of a closed-loop CSV (JSON text) as its value."""
    if not isinstance(text, str):
        return text
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text  # not JSON (a table written by hand): kept as text


def _as_bool(series: pd.Series, path: Path, key: str) -> pd.Series:
    if series.dtype == bool:
        return series
    falses = ("false", "0", "0.0", "nan", "", "none")  # "": a row whose solve crashed
    mapping = dict.fromkeys(("true", "1", "1.0"), True) | dict.fromkeys(falses, False)
    text = series.astype(str).str.strip().str.lower()
    bad = ~text.isin(list(mapping))
    if bad.any():
        row = int(np.flatnonzero(bad)[0]) + 2
        raise InputError(
            f"non-boolean value {series[bad].iloc[0]!r} in row {row}", path=path, key=key
        )
    return text.map(mapping).astype(bool)


def expand_paths(paths: list[str | Path]) -> list[Path]:
    """CSV files named, and every ``*.csv`` / ``*.csv.gz`` in a named folder (sorted);
    :class:`InputError` for a missing path or a folder without one."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = [q for q in p.rglob("*.csv*") if q.name.endswith((".csv", ".csv.gz"))]
            found = sorted(q for q in found if not q.name.startswith("."))
            if not found:
                raise InputError("folder holds no result CSV", path=p)
            out.extend(found)
        elif p.is_file():
            out.append(p)
        else:
            raise InputError("no such file or folder", path=p)
    return out


def read_results(paths: list[str | Path], prefer: str | None = None) -> Results:
    """Read bench and closed-loop CSVs (folders are searched). Rows get ``source`` (their file);
    bench rows :func:`scenario_key` as ``scenario``; closed-loop rows ``log_path``
    (:func:`log_path`). :class:`InputError`: unreadable CSV, one of neither kind, a duplicate
    key or mixed repeat counts without ``prefer``."""
    bench, loops, files = [], [], []
    for path in expand_paths(paths):
        try:
            df = pd.read_csv(path)
        except CSV_ERRORS as exc:
            raise InputError(f"not a readable CSV ({exc})", path=path) from None
        cols = set(df.columns)
        df["source"] = str(path)
        if set(BENCH_COLUMNS) <= cols:
            for key in ("found", "success", "isolated"):
                df[key] = _as_bool(df[key], path, key)
            bench.append(df)
            kind = "bench"
        elif set(CLOSED_LOOP_COLUMNS) <= cols:
            for column in set(STRUCTURED_FIGURES) & cols:  # a table of failed runs has none
                df[column] = df[column].map(_from_json)
            df["log_path"] = [log_path(path.parent, f) for f in df["log_file"]]
            loops.append(df)
            kind = "closed-loop"
        else:
            missing = ", ".join(sorted(set(BENCH_COLUMNS) - cols))
            raise InputError(
                f"neither a bench CSV (missing columns {missing}) nor a closed-loop CSV "
                "(needs scenario, backend, status, log_file)",
                path=path,
            )
        files.append(ResultFile(path, kind, sha256_file(path), len(df)))
    bench_df, notes = pd.DataFrame(), []
    if bench:
        bench_df = drop_duplicates(pd.concat(bench, ignore_index=True), prefer)
        bench_df["scenario"] = bench_df["scenario"].map(scenario_key)
        bench_df["mode"] = bench_df["mode"].fillna("")
        notes = check_repeats(bench_df, prefer)
    loop_df = pd.concat(loops, ignore_index=True) if loops else pd.DataFrame()
    floor = noise_floor_runs(loop_df)
    return Results(
        bench=bench_df,
        closed_loop=loop_df[~floor].reset_index(drop=True),
        files=files,
        notes=notes,
        noise_floor=loop_df[floor].reset_index(drop=True),
    )


def log_path(folder: Path, log_file: object) -> str | None:
    """A run's tick log (``log_file`` in ``folder``, the CSV's), else its figure log
    (:mod:`qpbench.sim.figure_log`), else ``None``."""
    from ..sim.figure_log import figure_log_path

    if not isinstance(log_file, str) or not log_file:
        return None
    found = [p for p in (folder / log_file, figure_log_path(folder / log_file)) if p.exists()]
    return str(found[0]) if found else None


def drop_duplicates(bench: pd.DataFrame, prefer: str | None) -> pd.DataFrame:
    """Bench rows with each result key once; :class:`InputError` without ``prefer``."""
    keys = pd.DataFrame({c: bench[c].map(scenario_key) for c in DUPLICATE_KEY}, index=bench.index)
    dup = keys.duplicated(keep=False)
    if not dup.any():
        return bench
    if prefer is None:
        key = keys.iloc[int(np.flatnonzero(dup.to_numpy())[0])]
        same = (keys == key).all(axis=1).to_numpy()
        sources = [*dict.fromkeys(bench.loc[same, "source"])] * 2  # twice: a row twice in a file
        text = ", ".join(f"{c}={key[c]}" for c in DUPLICATE_KEY)
        raise InputError(
            f"{sources[0]} and {sources[1]} both hold the row ({text}); "
            "pass --prefer first or --prefer last to keep one file's rows",
            key="--prefer",
        )
    keep = ~keys.duplicated(keep="first" if prefer == "first" else "last")
    return bench[keep.to_numpy()].reset_index(drop=True)


def check_repeats(bench: pd.DataFrame, prefer: str | None) -> list[str]:
    """Notes on backends timed with different ``repeat`` counts in one table (a file's count:
    the largest ``repeat`` of its rows); :class:`InputError` on a mix without ``prefer``."""
    notes = []
    df = bench.assign(_repeat=pd.to_numeric(bench["repeat"], errors="coerce"))
    for (profile, mode), table in df.groupby(["profile", "mode"], sort=True):
        per_backend = table.groupby("backend", sort=True)["_repeat"].max().dropna()
        if per_backend.nunique() > 1:
            counts = ", ".join(f"{b} {int(r)}" for b, r in per_backend.items())
            notes.append(
                f"backends timed with different --repeat counts in the tables of {group_label(profile, mode)} "
                f"({counts}): a single-shot time includes cold caches that a minimum over repeats does not"
            )
    for (profile, mode, backend), g in df.groupby(["profile", "mode", "backend"], sort=True):
        per_file = g.groupby("source", sort=False)["_repeat"].max().dropna()
        if per_file.nunique() <= 1:
            continue
        counts = ", ".join(f"{Path(f).name}: {int(r)}" for f, r in per_file.items())
        text = f"{backend} ({group_label(profile, mode)}) mixes rows timed with different --repeat ({counts})"
        if prefer is None:
            hint = "pass --prefer first|last to report them together anyway"
            raise InputError(f"{text}; {hint}", key="repeat")
        notes.append(text + ": single-shot and repeated times are in one table")
    return notes


def numbers(rows: pd.DataFrame, column: str) -> np.ndarray:
    """A column of ``rows`` as floats (NaN where not a number)."""
    return pd.to_numeric(rows[column], errors="coerce").to_numpy(dtype=float)


def group_label(profile: str, mode: str) -> str:
    """Heading of a (profile, mode) group, e.g. ``default, sequential``."""
    return f"{profile}, {mode}" if mode else str(profile)


def scenario_key(value: object) -> str:
    """Scenario label of a bench row (``-`` when the problem has no scenario): the ``scenario``
    of the rows :func:`read_results` returns."""
    if value is None or (isinstance(value, float) and math.isnan(value)) or value == "":
        return "-"
    return str(value)


def noise_floor_runs(table: pd.DataFrame) -> pd.Series:
    """Which rows are the noise floor's runs (``noise_floor`` true; none in a table without the
    column): measured beside the candidates, never one of them."""
    if "noise_floor" not in table.columns:
        return pd.Series(False, index=table.index)
    floor = table["noise_floor"].map(lambda v: str(v).strip().lower() in ("true", "1", "1.0"))
    return floor.astype(bool)  # bool even when empty: a mask, never a list of column names
