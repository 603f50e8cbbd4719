"""The figure log: what the closed-loop figures and the arm's pictures draw, small enough to keep.

A run's full tick log (:mod:`qpbench.sim.log`, ``<out>/logs/*.parquet``) holds
every column of every tick in float64: about 4 MB a run. The figures of a
report (:mod:`qpbench.report.loop_figure`, :mod:`qpbench.report.plots`) and the
arm's snapshot (:mod:`qpbench.report.arm`) need less: the columns they draw,
at the detail a figure about 1,000 pixels wide can show. The figure log
(``<out>/figure_logs/<same name>.parquet``) keeps:

- the columns drawn: ``t``, ``theta_i``, ``v_i``, ``ee_x``, ``ee_y``,
  ``xd_x``, ``xd_y``, ``tracking_error``, ``force_error``, every
  ``d_<A>_<obstacle>``, ``d_min``, ``v_sq``, ``solve_time_s``, ``kp_hat``,
  ``status``, ``fallback``, ``zero_velocity`` (floats as float32: 7
  significant digits, far below a pixel);
- the ticks: the run cut into :data:`BUCKETS` equal spans of ticks, and of
  each span its first tick and the ticks of the smallest and the largest
  value of every drawn quantity (``|tracking error|``, ``|force error|``,
  ``d_min``, ``solve_time_s``, ``v_sq``), so no peak, dip or worst point is
  lost (min-max decimation); and every tick whose QP was infeasible or not
  solved, failed, or whose backend answer was not applied (fallback, zero
  velocity), with its neighbours, so the shaded bands keep their edges;
- written with zstd compression, the floats' bytes split by stream: about 50 kB a
  run of 20,000 ticks.

A log of at most ``3 * BUCKETS`` ticks is kept whole.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..statuses import CERTIFIED_INFEASIBLE, FAILURE_STATUSES
from . import log as tick_log

__all__ = ["BUCKETS", "FIGURE_LOG_DIR", "figure_log", "figure_log_path", "write_figure_log"]

#: Folder of the figure logs in a closed-loop output folder (beside ``logs/``).
FIGURE_LOG_DIR = "figure_logs"
#: Spans of ticks a run is cut into (a figure is about 1,000 pixels wide).
BUCKETS = 300

#: Mantissa bits kept of each drawn value: a relative step of 2**-12 = 2.4e-4, below a pixel.
MANTISSA_BITS = 12

#: Columns kept besides the per-joint and per-distance ones.
_KEPT = (
    tick_log.T,
    tick_log.EE_X,
    tick_log.EE_Y,
    tick_log.XD_X,
    tick_log.XD_Y,
    tick_log.TRACKING_ERROR,
    tick_log.FORCE_ERROR,
    tick_log.D_MIN,
    tick_log.V_SQ,
    tick_log.SOLVE_TIME,
    tick_log.KP_HAT,
    tick_log.STATUS,
    tick_log.FALLBACK,
    tick_log.ZERO_VELOCITY,
)
#: Quantities whose smallest and largest value in each span are kept (absolute value for signed errors).
_EXTREMES = (
    (tick_log.TRACKING_ERROR, True),
    (tick_log.FORCE_ERROR, True),
    (tick_log.D_MIN, False),
    (tick_log.SOLVE_TIME, False),
    (tick_log.V_SQ, False),
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
    mask = np.zeros(len(frame), dtype=bool)
    if tick_log.STATUS in frame.columns:
        mask |= frame[tick_log.STATUS].astype(str).isin(_NOT_SOLVED).to_numpy()
    for col in (tick_log.FALLBACK, tick_log.ZERO_VELOCITY):
        if col in frame.columns:
            mask |= frame[col].to_numpy(bool)
    near = mask.copy()
    near[1:] |= mask[:-1]
    near[:-1] |= mask[1:]
    return near


def _extremes(frame: pd.DataFrame, buckets: int) -> np.ndarray:
    """Each span's first tick and the ticks of each quantity's smallest and largest value."""
    n = len(frame)
    edges = np.linspace(0, n, buckets + 1).astype(int)
    starts = edges[:-1][np.diff(edges) > 0]
    keep = [starts, np.array([n - 1])]
    for col, absolute in _EXTREMES:
        if col not in frame.columns:
            continue
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
    finite = np.isfinite(x)
    rounded = ((bits + np.uint32(1 << (drop - 1))) & ~np.uint32((1 << drop) - 1)).view(np.float32)
    return np.where(finite, rounded, x.astype(np.float32))


def figure_log(frame: pd.DataFrame, buckets: int = BUCKETS) -> pd.DataFrame:
    """The figure log of a full tick log (rule in the module docstring)."""
    frame = frame[_columns(frame)]
    if len(frame) > 3 * buckets:
        keep = np.zeros(len(frame), dtype=bool)
        keep[_extremes(frame, buckets)] = True
        frame = frame[keep | _special(frame)]
    out = frame.reset_index(drop=True).copy()
    for col in out.columns:
        if col == tick_log.T:
            out[col] = out[col].astype(np.float32)
        elif out[col].dtype == np.float64:
            out[col] = _coarse(out[col].to_numpy())
    if tick_log.STATUS in out.columns:
        out[tick_log.STATUS] = out[tick_log.STATUS].astype(str)
    return out


def write_figure_log(frame: pd.DataFrame, path: str | Path, buckets: int = BUCKETS) -> Path:
    """Write the figure log of ``frame`` to ``path`` (Parquet, zstd), atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from ..atomic import atomic_path

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    table = pa.Table.from_pandas(figure_log(frame, buckets), preserve_index=False)
    floats = [f.name for f in table.schema if pa.types.is_floating(f.type)]
    with atomic_path(path) as tmp:
        # byte-stream split puts the (mostly zero) low bytes of the floats together: half the size
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
