"""The figure log: what the closed-loop figures and the arm's pictures draw, small enough to keep.

The figure log (``<out>/figure_logs/<same name as in logs/>.parquet``) keeps of a full tick
log the drawn columns (floats as float32 with :data:`MANTISSA_BITS` of mantissa, far below a
pixel) and, of each of :data:`BUCKETS` equal spans of ticks, its first tick and the ticks of
the smallest and largest value of each drawn quantity (min-max decimation: no peak is lost),
plus every tick not solved, failed or without the backend's own answer and its neighbours (the
shaded bands keep their edges). A log of at most ``3 * BUCKETS`` ticks is kept whole.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy.ndimage import binary_dilation

from ..statuses import CERTIFIED_INFEASIBLE, FAILURE_STATUSES
from . import log as tick_log

#: Folder of the figure logs in a closed-loop output folder (beside ``logs/``).
FIGURE_LOG_DIR = "figure_logs"
#: Spans of ticks a run is cut into (a figure is about 1,000 pixels wide).
BUCKETS = 300

#: Mantissa bits kept of each drawn value (a relative step of 2**-12).
MANTISSA_BITS = 12

#: Quantities whose smallest and largest value in each span are kept (absolute value for signed errors).
_EXTREMES = (
    (tick_log.TRACKING_ERROR, True),
    (tick_log.FORCE_ERROR, True),
    (tick_log.D_MIN, False),
    (tick_log.SOLVE_TIME, False),
    (tick_log.V_SQ, False),
)
#: Columns kept besides the per-joint and per-distance ones: those and these.
_KEPT = (
    *(column for column, _ in _EXTREMES),
    tick_log.T,
    tick_log.EE_X,
    tick_log.EE_Y,
    tick_log.XD_X,
    tick_log.XD_Y,
    tick_log.KP_HAT,
    tick_log.STATUS,
    tick_log.FALLBACK,
    tick_log.ZERO_VELOCITY,
)

#: Statuses of a tick kept whatever its span.
_NOT_SOLVED = frozenset(CERTIFIED_INFEASIBLE) | {"not_solved"} | FAILURE_STATUSES


def _columns(frame: pd.DataFrame) -> list[str]:
    n = tick_log.joint_count(frame)
    wanted = set(_KEPT) | set(tick_log.theta_columns(n)) | set(tick_log.velocity_columns(n))
    wanted |= set(tick_log.distance_columns(frame))
    return [c for c in frame.columns if c in wanted]


def _special(frame: pd.DataFrame) -> np.ndarray:
    """Ticks not solved, failed, or without the backend's own answer, and their neighbours."""
    flags = frame[[tick_log.FALLBACK, tick_log.ZERO_VELOCITY]].to_numpy(bool).any(axis=1)
    mask = frame[tick_log.STATUS].astype(str).isin(_NOT_SOLVED).to_numpy() | flags
    return binary_dilation(mask)  # and each one's neighbours


def _extremes(frame: pd.DataFrame) -> np.ndarray:
    """Each span's first tick and the ticks of each quantity's smallest and largest value."""
    n = len(frame)
    edges = np.linspace(0, n, BUCKETS + 1).astype(int)
    starts = edges[:-1][np.diff(edges) > 0]
    keep = [starts, np.array([n - 1])]
    for col, absolute in _EXTREMES:
        x = frame[col].to_numpy(float)
        x = np.abs(x) if absolute else x
        lo = np.where(np.isfinite(x), x, np.inf)
        hi = np.where(np.isfinite(x), x, -np.inf)
        keep += [
            s + np.array([np.argmin(lo[s:e]), np.argmax(hi[s:e])])
            for s, e in zip(starts, np.r_[starts[1:], n])
        ]
    return np.unique(np.concatenate(keep))


def _coarse(x: np.ndarray) -> np.ndarray:
    """float32 with the mantissa rounded to :data:`MANTISSA_BITS` bits (the low bits zero, so they compress)."""
    bits = np.ascontiguousarray(x, dtype=np.float32).view(np.uint32)
    drop = 23 - MANTISSA_BITS
    rounded = ((bits + np.uint32(1 << (drop - 1))) & ~np.uint32((1 << drop) - 1)).view(np.float32)
    return np.where(np.isfinite(x), rounded, x.astype(np.float32))


def figure_log(frame: pd.DataFrame) -> pd.DataFrame:
    """The figure log of a full tick log (rule in the module docstring)."""
    frame = frame[_columns(frame)]
    if len(frame) > 3 * BUCKETS:
        keep = np.zeros(len(frame), dtype=bool)
        keep[_extremes(frame)] = True
        frame = frame[keep | _special(frame)]
    out = frame.reset_index(drop=True).copy()
    for col in out.columns:
        if col == tick_log.T:
            out[col] = out[col].astype(np.float32)
        elif out[col].dtype == np.float64:
            out[col] = _coarse(out[col].to_numpy())
    out[tick_log.STATUS] = out[tick_log.STATUS].astype(str)
    return out


def write_figure_log(frame: pd.DataFrame, path: str | Path) -> Path:
    """Write the figure log of ``frame`` to ``path`` (Parquet, zstd), atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from ..atomic import atomic_path

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    table = pa.Table.from_pandas(figure_log(frame), preserve_index=False)
    floats = [f.name for f in table.schema if pa.types.is_floating(f.type)]
    with atomic_path(path) as tmp:
        # byte-stream split puts the (mostly zero) low bytes of the floats together, where they compress
        pq.write_table(
            table,
            tmp,
            compression="zstd",
            compression_level=19,
            use_byte_stream_split=floats,
            use_dictionary=[tick_log.STATUS],
        )
    return path


def figure_log_path(log_path: str | Path) -> Path:
    """Where the figure log of the full log ``<out>/logs/<name>`` is: ``<out>/figure_logs/<name>``."""
    log_path = Path(log_path)
    return log_path.parent.parent / FIGURE_LOG_DIR / log_path.name
