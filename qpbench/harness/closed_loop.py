"""Closed-loop comparison: each scenario with each backend in the loop.

For every (scenario, backend) pair :func:`qpbench.sim.loop.simulate` runs the
scenario with that backend solving every tick's QP. Each run writes its
per-tick log to ``OUT/logs/<scenario>__<backend>.parquet`` and one row to
``OUT/closed_loop.csv`` (long format, one row per (scenario, backend)):

==========================  =====================================================
column                      meaning
==========================  =====================================================
scenario, backend           the pair
formulation, duration_s     the QP formulation (``paper`` | ``soft``), asked duration [s]
simulated_s                 simulated time reached [s] (less than ``duration_s``
                            when the run's wall-time budget ran out)
status, error               ``ok``; ``budget`` (stopped early by the run's
                            wall-time budget, ``run_budget``; the rest as ``ok``),
                            ``error`` (and the exception's message),
                            ``crashed`` (the worker died; the signal),
                            ``time_limit`` (the run overran its deadline) or
                            ``skipped`` (and why)
verdict                     ``ok``, ``diverged``, ``limits``, ``unsafe`` or
                            ``failed`` (:mod:`qpbench.sim.verdict`: from the
                            simulator's summary as it is; ``failed`` for a run
                            without a result; empty for a skipped one)
verdict_reasons             why, plain text, ``"; "`` between reasons (a
                            budget-stopped run also says where it stopped)
ticks                       control ticks simulated
tracking_rms_after_2s       tangential tracking error RMS for t >= 2 s [m]
tracking_max_after_2s       its maximum [m]
force_error_rms_after_2s    contact-force error RMS for t >= 2 s [N]
force_error_max_after_2s    its maximum [N]
min_obstacle_distance       smallest key-point to obstacle distance [m]
joint_limit_violations      ticks with a joint angle outside its limits
infeasible_ticks            ticks whose QP the backend did not solve
fallback_ticks              ticks that used the soft fallback
v2_integral                 integral of ||v||^2 dt over the run [rad^2/s]
solve_time_p50_s            median per-tick solve time [s]
solve_time_p99_s            99th percentile [s] (a 1 kHz loop lives by its tail)
solve_time_max_s            worst tick [s]
real_time_factor            simulated time / wall time, over what was simulated
log_file                    the tick log, relative to the CSV's folder
==========================  =====================================================

followed by ``isolated`` (the run was made in a worker process with a
deadline), ``run_budget_s`` (the run's wall-time budget [s], empty when
none) and every other key of the simulator's summary, among them
``deadline_misses`` when the simulator counts them, the
per-tick guards' counts ``error_ticks``, ``time_limit_ticks``,
``invalid_ticks`` and ``first_error`` (see :func:`qpbench.sim.loop.simulate`:
an exception or a non-finite answer of the backend is a tick without a
solution, not the end of the run), ``deadline_misses`` (ticks whose solve
took longer than dt; the answer was applied all the same) and, with a
per-tick ``deadline`` (``--deadline``), ``deadline_dropped`` (answers
dropped for arriving later). The table is rewritten
atomically after each run (rows appear as they are produced); a run that
raises becomes a row with status ``error`` and the others continue.

Guards against a hang in native code and a process death (segfault, abort):
``isolate`` (``--isolate``) ``auto`` (the default: backends whose class has
``risky = True``, e.g. ``proxqp``), ``always`` or ``never``. An isolated run
is made in a worker process of its own (``multiprocessing``, ``forkserver``
context with qpbench preloaded, else ``spawn``) with a deadline
(``run_time_limit``, ``--run-time-limit``; default
``max(600 s, 50 s per simulated second)``, see :func:`run_deadline`). A
worker that dies gives a row with status ``crashed`` and the signal (``worker
process killed by SIGSEGV``), one that overruns the deadline is killed
(SIGKILL) and gives a row with status ``time_limit``; the other runs go on.
With ``jobs > 1`` every run is made in a worker process of its own (the
deadline only for isolated ones), so one crash loses no other run's row.
Isolation costs no timing accuracy: the worker times the run itself exactly
as this process would (warm-up run first); its start (a fork of the
forkserver, which already holds qpbench and the compiled kernels, then
importing the backend: well under a second) adds only to the total duration.
No worker compiles: the kernels are compiled (or loaded) in this process
before the first worker starts (:mod:`qpbench.jit`).
``resume`` keeps the rows already done with the same formulation and
duration (status ``ok``) and runs the rest (rows of pairs not asked for this
time stay in the table); ``force`` starts again.
"""

from __future__ import annotations

import logging
import math
import re
import shutil
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..atomic import atomic_path, check_output
from ..exceptions import ParamError

log = logging.getLogger("qpbench.harness")

#: Name of the table inside ``--out``.
CSV_NAME = "closed_loop.csv"
#: Folder of the per-tick logs inside ``--out``.
LOG_DIR = "logs"

#: Leading columns of the closed-loop table, in order.
COLUMNS = (
    "scenario",
    "backend",
    "formulation",
    "duration_s",
    "simulated_s",
    "status",
    "error",
    "verdict",
    "verdict_reasons",
    "ticks",
    "tracking_rms_after_2s",
    "tracking_max_after_2s",
    "force_error_rms_after_2s",
    "force_error_max_after_2s",
    "min_obstacle_distance",
    "joint_limit_violations",
    "infeasible_ticks",
    "fallback_ticks",
    "v2_integral",
    "solve_time_p50_s",
    "solve_time_p99_s",
    "solve_time_max_s",
    "real_time_factor",
    "log_file",
)

#: Ticks of the discarded warm-up run before each timed run.
WARMUP_TICKS = 3

#: Transient excluded from the tracking and force statistics [s].
TRANSIENT_S = 2.0

# Candidate names of per-tick log columns (the first present wins).
_T = ("t",)
_SOLVE_TIME = ("solve_time_s", "solve_time", "qp_time_s")
_V2 = ("v_sq", "v_norm2", "v2", "v_norm_sq", "norm_v2")
_TRACK = ("tracking_error", "tangential_error", "tracking_error_m")
_FORCE_ERR = ("force_error", "force_error_n")
_MIN_DIST = ("d_min", "min_distance", "min_obstacle_distance", "distance_min")


def find_column(log_df: pd.DataFrame, candidates: Iterable[str]) -> str | None:
    """First of ``candidates`` that is a column of ``log_df`` (``None`` if none is)."""
    for c in candidates:
        if c in log_df.columns:
            return c
    return None


def velocity_columns(log_df: pd.DataFrame) -> list[str]:
    """Joint-velocity columns of a tick log (``v0, v1, ...`` or ``v_0, v_1, ...``), in order."""
    cols = [c for c in log_df.columns if re.fullmatch(r"v_?\d+", str(c))]
    return sorted(cols, key=lambda c: int(re.sub(r"\D", "", c)))


def v_norm2(log_df: pd.DataFrame) -> np.ndarray | None:
    """``||v||^2`` per tick [rad^2/s^2], from a logged column or the joint velocities."""
    col = find_column(log_df, _V2)
    if col is not None:
        return log_df[col].to_numpy(dtype=float)
    vcols = velocity_columns(log_df)
    if vcols:
        return np.sum(log_df[vcols].to_numpy(dtype=float) ** 2, axis=1)
    if "v" in log_df.columns:
        return np.array([float(np.dot(v, v)) for v in log_df["v"]])
    return None


def _time_step(t: np.ndarray, fallback: float | None) -> float:
    if len(t) > 1:
        return float(np.median(np.diff(t)))
    return float(fallback) if fallback else math.nan


def row_from_run(
    scenario: str,
    backend: str,
    formulation: str,
    duration: float | None,
    log_df: pd.DataFrame,
    summary: dict,
    dt: float | None = None,
) -> dict:
    """The closed-loop table row of one run (see the module doc for the columns).

    Summary keys of the simulator are taken as they are (``verdict`` and
    ``verdict_reasons`` too: the verdict is the simulator's, never redone
    here; status ``budget`` when the summary says ``stopped_early``); what
    the table needs and the summary lacks is computed from the tick log: ``v2_integral``
    ``= sum_k ||v_k||^2 dt`` (rectangle rule, dt the control period [s]),
    solve-time percentiles, and the after-transient statistics.
    """
    t = log_df[find_column(log_df, _T)].to_numpy(dtype=float) if "t" in log_df.columns else np.array([])
    step = _time_step(t, dt or summary.get("dt"))
    row: dict = {
        "scenario": scenario,
        "backend": backend,
        "formulation": formulation,
        "duration_s": float(duration) if duration is not None else float(
            summary.get("duration", len(log_df) * step if len(t) else math.nan)),
        "simulated_s": float(summary.get("simulated_s", len(log_df) * step)),
        "status": "budget" if summary.get("stopped_early") else "ok",
        "error": "",
        "verdict": summary.get("verdict", ""),
        "verdict_reasons": summary.get("verdict_reasons", ""),
        "ticks": int(summary.get("ticks", len(log_df))),
    }
    after = t >= TRANSIENT_S - 1e-12 if len(t) else np.zeros(len(log_df), bool)

    def _rms_max(cols, key_rms, key_max):
        if key_rms in summary and key_max in summary:
            return summary[key_rms], summary[key_max]
        col = find_column(log_df, cols)
        if col is None or not after.any():
            return math.nan, math.nan
        e = np.abs(log_df[col].to_numpy(dtype=float)[after])
        return float(np.sqrt(np.mean(e**2))), float(e.max())

    row["tracking_rms_after_2s"], row["tracking_max_after_2s"] = _rms_max(
        _TRACK, "tracking_rms_after_2s", "tracking_max_after_2s"
    )
    row["force_error_rms_after_2s"], row["force_error_max_after_2s"] = _rms_max(
        _FORCE_ERR, "force_error_rms_after_2s", "force_error_max_after_2s"
    )
    if "min_obstacle_distance" in summary:
        row["min_obstacle_distance"] = summary["min_obstacle_distance"]
    else:
        col = find_column(log_df, _MIN_DIST)
        row["min_obstacle_distance"] = float(np.nanmin(log_df[col])) if col else math.nan
    for key in ("joint_limit_violations", "infeasible_ticks", "fallback_ticks"):
        row[key] = summary.get(key, math.nan)
    v2 = v_norm2(log_df)
    row["v2_integral"] = float(np.sum(v2) * step) if v2 is not None and np.isfinite(step) else math.nan
    col = find_column(log_df, _SOLVE_TIME)
    if col is not None and len(log_df):
        st = log_df[col].to_numpy(dtype=float)
        st = st[np.isfinite(st)]
    else:
        st = np.array([])
    row["solve_time_p50_s"] = float(np.percentile(st, 50)) if len(st) else math.nan
    row["solve_time_p99_s"] = float(np.percentile(st, 99)) if len(st) else math.nan
    row["solve_time_max_s"] = float(st.max()) if len(st) else math.nan
    if "real_time_factor" in summary:
        row["real_time_factor"] = summary["real_time_factor"]
    else:
        wall = summary.get("wall_time_s")
        row["real_time_factor"] = (len(log_df) * step / wall) if wall else math.nan
    row["log_file"] = ""
    for key, value in summary.items():
        if key not in row and key not in ("scenario", "backend"):
            row[key] = _scalar(value)
    return row


def _scalar(value):
    """A summary value as one CSV cell (lists and dicts as text)."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, np.generic):
        return value.item()
    return str(value)


def log_name(scenario: str, backend: str) -> str:
    """File name of a run's tick log (``:`` and ``/`` of backend names made safe)."""
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "-", f"{scenario}__{backend}")
    return f"{safe}.parquet"


def parse_list(value: str | list[str] | None, option: str) -> list[str]:
    """Split a comma-separated option value (empty items dropped, order kept, no duplicates).

    Raises:
        ParamError: the list is empty.
    """
    if value is None:
        return []
    items = value if isinstance(value, list) else value.split(",")
    out: list[str] = []
    for item in items:
        item = item.strip()
        if item and item not in out:
            out.append(item)
    if not out:
        raise ParamError("empty list", key=option)
    return out


def resolve_scenarios(value: str | list[str] | None) -> list[str]:
    """``all`` (or nothing) -> every shipped scenario; else the names or paths given."""
    names = parse_list(value or "all", "--scenarios")
    from ..sim.scenario import load_scenario, scenario_names

    if names == ["all"]:
        return scenario_names()

    for name in names:
        load_scenario(name)  # a typo or a broken file: one line naming it, before any run starts
    return names


def resolve_backends(value: str | list[str] | None) -> list[str]:
    """``all`` (or nothing) -> every available backend; else the names, each checked.

    Raises:
        BackendNotFound: a name is not registered or not available here.
    """
    from ..backends import backend_names, get_backend

    names = parse_list(value or "all", "--backends")
    if names == ["all"]:
        return list(backend_names(available_only=True))
    from ..backends import resolve_name

    names = [resolve_name(name) for name in names]  # canonical spelling; a typo gets a suggestion
    for name in names:
        get_backend(name)  # raises BackendNotFound with the reason
    return names


def simulate_one(scenario_name: str, backend: str, formulation: str, duration: float | None,
                 log_path: Path | None, deadline: float | None = None,
                 run_budget: float | None = None) -> tuple[dict, pd.DataFrame]:
    """Run one (scenario, backend) and return its table row and tick log.

    The tick log is written atomically to ``log_path`` (Parquet) when given.
    The backend is passed by name, so the ``rnn`` backends get the scenario's
    ``[rnn]`` table (eps, sub-steps, clipping) and the loop's ``dt`` from
    :func:`qpbench.sim.loop.resolve_backend`. ``deadline`` is the per-tick
    deadline [s] (default none: every answer is applied; see :func:`qpbench.sim.loop.simulate`).
    ``run_budget`` is the wall-time budget of the timed run [s] (``wall_budget_s``
    of :func:`qpbench.sim.loop.simulate`; the warm-up is outside it): the run
    stops between ticks once it is spent and the row says how far it got.
    Exceptions propagate (the caller turns them into an error row).
    """
    from ..sim.loop import simulate
    from ..sim.scenario import load_scenario

    scenario = load_scenario(scenario_name)
    # warm-up: a discarded run of a few ticks, so one-off costs (solver imports, first-call
    # allocations; the numba kernels are ready before, see qpbench.jit) stay out of the timed run
    simulate(scenario, backend, formulation=formulation, duration=WARMUP_TICKS * scenario.dt, deadline=deadline)
    start = time.perf_counter()
    # by name: the simulator gives the rnn backends the scenario's [rnn] settings and dt
    result = simulate(scenario, backend, formulation=formulation, duration=duration, deadline=deadline,
                      wall_budget_s=run_budget)
    wall = time.perf_counter() - start
    summary = dict(result.summary or {})
    summary.setdefault("wall_time_s", wall)
    log_df = result.log if isinstance(result.log, pd.DataFrame) else pd.DataFrame(result.log)
    dt = getattr(scenario, "dt", None)
    row = row_from_run(scenario_name, backend, formulation, duration, log_df, summary, dt=dt)
    if log_path is not None:
        with atomic_path(log_path) as tmp:
            log_df.to_parquet(tmp, index=False)
    return row, log_df


def _run_job(args: tuple) -> dict:
    """One guarded run (module level so a process pool can call it)."""
    scenario, backend, formulation, duration, out, deadline, run_budget = args
    log_path = Path(out) / LOG_DIR / log_name(scenario, backend)
    try:
        row, _ = simulate_one(scenario, backend, formulation, duration, log_path, deadline, run_budget)
        row["log_file"] = f"{LOG_DIR}/{log_path.name}"
    except Exception as exc:  # noqa: BLE001 - one failing run must not stop the others
        log.warning("closed loop %s with %s failed: %s: %s", scenario, backend, type(exc).__name__, exc)
        row = error_row(scenario, backend, formulation, duration, exc)
    return row


def skipped_row(scenario: str, backend: str, formulation: str, duration: float | None,
                reason: str) -> dict:
    """The row of a run that was not made (status ``skipped``, the reason in ``error``, no verdict)."""
    row = {c: math.nan for c in COLUMNS}
    row.update(scenario=scenario, backend=backend, formulation=formulation,
               duration_s=float(duration) if duration is not None else math.nan,
               status="skipped", error=reason, verdict="", verdict_reasons="", log_file="")
    return row


def error_row(scenario: str, backend: str, formulation: str, duration: float | None,
              exc: BaseException) -> dict:
    """The row of a run that raised: status ``error`` and the message, in one line."""
    return failure_row(scenario, backend, formulation, duration, "error",
                       " ".join(f"{type(exc).__name__}: {exc}".split()))


def failure_row(scenario: str, backend: str, formulation: str, duration: float | None,
                status: str, message: str) -> dict:
    """The row of a run that produced no result: ``status`` (``error``, ``crashed``,
    ``time_limit``) and why in ``error``; verdict ``failed``."""
    from ..sim.verdict import failed_run

    verdict = failed_run(status, message)
    row = {c: math.nan for c in COLUMNS}
    row.update(scenario=scenario, backend=backend, formulation=formulation,
               duration_s=float(duration) if duration is not None else math.nan,
               status=status, error=message, verdict=verdict.verdict, verdict_reasons=verdict.text, log_file="")
    return row


#: Choices of ``isolate``: ``auto`` isolates backends whose class says ``risky = True``.
ISOLATE = ("auto", "always", "never")
#: Least deadline of an isolated run [s] (see :func:`run_deadline`).
RUN_TIME_LIMIT_MIN_S = 600.0
#: Deadline of an isolated run per simulated second [s] (a real-time factor of 1/50).
RUN_TIME_LIMIT_PER_SIM_S = 50.0
#: Statuses of a run that produced no result (counted in :attr:`ClosedLoopOutcome.errors`).
FAILED_RUN_STATUSES = ("error", "crashed", "time_limit")


def run_deadline(scenario: str, duration: float | None, run_time_limit: float | None = None) -> float:
    """Deadline [s] of one isolated run: ``run_time_limit`` when given, else
    ``max(RUN_TIME_LIMIT_MIN_S, RUN_TIME_LIMIT_PER_SIM_S * simulated seconds)``
    (600 s up to 12 s of simulated time). It covers the worker's start, the
    warm-up, the run and the writing of its tick log."""
    if run_time_limit is not None:
        return float(run_time_limit)
    if duration is None:
        try:
            from ..sim.scenario import load_scenario

            duration = load_scenario(scenario).duration
        except Exception:  # noqa: BLE001 - the run itself reports a bad scenario
            duration = 0.0
    return max(RUN_TIME_LIMIT_MIN_S, RUN_TIME_LIMIT_PER_SIM_S * float(duration))


def is_risky(backend: str) -> bool:
    """The backend's class says ``risky = True`` (``False`` for an unknown name)."""
    from ..backends import backend_class
    from ..exceptions import BackendNotFound

    try:
        return backend_class(backend).risky
    except BackendNotFound:
        return False


def _worker_main(conn, args: tuple, plugins: list[str]) -> None:
    """Body of a run's worker process: load the parent's plugin files, make the run, send its row."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's business
    try:
        from ..backends import load_plugins

        load_plugins(plugins)
        row = _run_job(args)
    except BaseException as exc:  # noqa: BLE001 - a plugin that fails to load
        row = error_row(args[0], args[1], args[2], args[3], exc)
    conn.send(row)
    conn.close()


def _exit_text(exitcode: int | None) -> str:
    import signal

    if exitcode is not None and exitcode < 0:
        try:
            return f"worker process killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"worker process killed by signal {-exitcode}"
    return f"worker process exited with code {exitcode} without a result"


class _RunWorker:
    """One (scenario, backend) run in its own worker process, with an optional deadline."""

    def __init__(self, key: tuple[str, str], args: tuple, plugins: list[str], deadline_s: float | None):
        from .isolation import _context

        ctx = _context()  # forkserver (qpbench preloaded) where there is one, else spawn
        self.key, self.args = key, args
        self.conn, child = ctx.Pipe(duplex=False)
        self.proc = ctx.Process(target=_worker_main, args=(child, args, plugins), daemon=True,
                                name=f"qpbench-closed-loop-{key[0]}-{key[1]}")
        self.started = time.monotonic()
        self.deadline_s = deadline_s
        self.deadline = math.inf if deadline_s is None else self.started + deadline_s
        self.proc.start()
        child.close()

    def result(self, now: float) -> dict | None:
        """The run's row once it is over (finished, died or past its deadline), else ``None``."""
        scenario, backend, formulation, duration = self.args[:4]
        try:
            if self.conn.poll():
                row = self.conn.recv()
                self.proc.join(5)
                self._close()
                return row
        except (EOFError, OSError):
            pass
        if not self.proc.is_alive():
            self.proc.join()
            message = f"{_exit_text(self.proc.exitcode)} during the closed-loop run"
            log.warning("closed loop %s with %s: %s", scenario, backend, message)
            self._close()
            self._drop_partial_log()
            return failure_row(scenario, backend, formulation, duration, "crashed", message)
        if now >= self.deadline:
            self.kill()
            self._drop_partial_log()
            message = f"no result after {self.deadline_s:.3g} s (run time limit); worker killed"
            log.warning("closed loop %s with %s: %s", scenario, backend, message)
            return failure_row(scenario, backend, formulation, duration, "time_limit", message)
        return None

    def kill(self) -> None:
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join(5)
        self._close()

    def _drop_partial_log(self) -> None:
        """Remove the temporary tick log a dead worker may have left (never a complete one)."""
        scenario, backend, out = self.args[0], self.args[1], self.args[4]
        for tmp in (Path(out) / LOG_DIR).glob(f".{log_name(scenario, backend)}.*.tmp"):
            tmp.unlink(missing_ok=True)

    def _close(self) -> None:
        try:
            self.conn.close()
        except OSError:  # pragma: no cover
            pass


def _run_in_workers(items: list[tuple], jobs: int, plugins: list[str], emit: Callable) -> None:
    """Run ``items`` (key, args, deadline or None) in worker processes, ``jobs`` at a time.

    Each run has a process of its own: a run that dies or overruns its
    deadline becomes a ``crashed`` or ``time_limit`` row and takes no other
    run's row with it. ``emit(key, row)`` is called as each run ends.
    """
    from multiprocessing.connection import wait

    pending = list(items)
    active: list[_RunWorker] = []
    try:
        while pending or active:
            while pending and len(active) < jobs:
                key, args, deadline_s = pending.pop(0)
                active.append(_RunWorker(key, args, plugins, deadline_s))
            now = time.monotonic()
            timeout = min(w.deadline for w in active) - now
            wait([w.conn for w in active] + [w.proc.sentinel for w in active],
                 timeout=None if timeout == math.inf else max(timeout, 0.0))
            now = time.monotonic()
            for w in list(active):
                row = w.result(now)
                if row is not None:
                    active.remove(w)
                    emit(w.key, row)
    finally:
        for w in active:  # interrupted: no orphan workers
            w.kill()


@dataclass
class ClosedLoopOutcome:
    """What :func:`run_closed_loop` did: the full table, the runs that failed
    (``errors``: status ``error``, ``crashed`` or ``time_limit``), the runs made
    now (``ran``), those kept or skipped, and the rows of the table whose
    verdict is not ``ok`` (``not_ok``: failed, unsafe, limits or diverged;
    the failed runs among them)."""

    table: pd.DataFrame
    csv_path: Path
    errors: int
    ran: int
    skipped: int
    not_ok: int = 0


#: Verdicts that fail a run (every verdict but ``ok``).
BAD_VERDICTS = ("failed", "unsafe", "limits", "diverged")


def _same_run(row: dict, formulation: str, duration: float | None, run_budget: float | None = None) -> bool:
    status = str(row.get("status"))
    if str(row.get("formulation")) != formulation:
        return False
    if status == "budget":  # a budget-stopped run is the same run only under the same budget
        try:
            if run_budget is None or not math.isclose(float(row.get("run_budget_s")), float(run_budget)):
                return False
        except (TypeError, ValueError):
            return False
    elif status != "ok":
        return False
    d = row.get("duration_s")
    if duration is None:
        return True
    try:
        return math.isclose(float(d), float(duration), rel_tol=1e-9, abs_tol=1e-12)
    except (TypeError, ValueError):
        return False


def write_table(rows: list[dict], path: Path) -> pd.DataFrame:
    """Write the closed-loop table atomically (leading :data:`COLUMNS`, then the rest sorted)."""
    df = pd.DataFrame(rows)
    extra = sorted(c for c in df.columns if c not in COLUMNS)
    for c in COLUMNS:
        if c not in df.columns:
            df[c] = math.nan
    df = df[list(COLUMNS) + extra]
    with atomic_path(path) as tmp:
        df.to_csv(tmp, index=False)
    return df


def run_closed_loop(
    scenarios: list[str],
    backends: list[str],
    out: str | Path,
    *,
    duration: float | None = None,
    formulation: str = "paper",
    force: bool = False,
    resume: bool = False,
    jobs: int = 1,
    on_row: Callable[[dict], None] | None = None,
    skip: dict[str, str] | None = None,
    isolate: str = "auto",
    run_time_limit: float | None = None,
    deadline: float | None = None,
    run_budget: float | None = None,
) -> ClosedLoopOutcome:
    """Run every (scenario, backend) pair in the loop and tabulate them into ``out``.

    Args:
        scenarios: Scenario names or TOML paths.
        backends: Backend names.
        out: Output folder (``closed_loop.csv`` and ``logs/``).
        duration: Simulated time per run [s]; ``None`` keeps each scenario's ``T``.
        formulation: ``paper`` (hard task, eq. 11) or ``soft``.
        force: Replace an existing table and its logs.
        resume: Keep the rows already done (same formulation and duration).
        jobs: Runs in parallel, each in a worker process of its own; with 1 the
            runs that are not isolated run in this process.
        on_row: Called with each new row as soon as it is written.
        skip: Backend -> reason: those backends get a ``skipped`` row per scenario
            instead of a run.
        isolate: ``auto`` (backends whose class has ``risky = True``),
            ``always`` or ``never``: an isolated run is made in a worker process
            with a deadline; its death is a ``crashed`` row (with the signal),
            its overrun a ``time_limit`` row (the worker killed).
        run_time_limit: Deadline of an isolated run [s] (default: see
            :func:`run_deadline`).
        deadline: Per-tick deadline [s]: a later answer is dropped (default
            none: every answer is applied; see :func:`qpbench.sim.loop.simulate`).
        run_budget: Wall-time budget of each run [s] (default: none): a run
            stops between ticks once it is spent (status ``budget``,
            ``simulated_s`` how far it got; its log is the uncut run's first
            ticks), the verdict judged on what was simulated.

    Raises:
        OutputExistsError: the table exists and neither ``force`` nor ``resume``.
        ParamError: a bad formulation, duration or job count.
    """
    if formulation not in ("paper", "soft"):
        raise ParamError(f"unknown formulation '{formulation}' (choose paper or soft)", key="--formulation")
    if duration is not None and not (duration > 0 and math.isfinite(duration)):
        raise ParamError(f"duration must be a positive number of seconds, got {duration}", key="--duration")
    if jobs < 1:
        raise ParamError(f"jobs must be >= 1, got {jobs}", key="--jobs")
    if isolate not in ISOLATE:
        raise ParamError(f"unknown isolation '{isolate}' (choose from {', '.join(ISOLATE)})", key="--isolate")
    for value, key in ((run_time_limit, "--run-time-limit"), (deadline, "--deadline"),
                       (run_budget, "--run-budget")):
        if value is not None and not (value > 0 and math.isfinite(value)):
            raise ParamError(f"must be a positive number of seconds, got {value}", key=key)
    from ..backends import plugin_files

    plugins = plugin_files()  # loaded by the CLI or the caller (qpbench.backends.load_plugins); workers load them too
    out = Path(out)
    csv_path = out / CSV_NAME
    check_output(csv_path, force=force, resume=resume)
    done: dict[tuple[str, str], dict] = {}
    previous_rows: list[dict] = []
    if csv_path.exists() and resume and not force:
        previous = pd.read_csv(csv_path, keep_default_na=True)
        for rec in previous.to_dict("records"):
            rec = {k: ("" if k in ("error", "log_file", "verdict", "verdict_reasons") and isinstance(v, float) and math.isnan(v) else v)
                   for k, v in rec.items()}
            previous_rows.append(rec)
            if _same_run(rec, formulation, duration, run_budget):
                done[(str(rec["scenario"]), str(rec["backend"]))] = rec
    elif force:
        if csv_path.exists():
            csv_path.unlink()
        if (out / LOG_DIR).exists():
            shutil.rmtree(out / LOG_DIR)
    (out / LOG_DIR).mkdir(parents=True, exist_ok=True)

    order = [(s, b) for s in scenarios for b in backends]
    # rows of other pairs in a resumed table are kept, after this run's
    others = [r for r in previous_rows if (str(r["scenario"]), str(r["backend"])) not in set(order)]
    rows: dict[tuple[str, str], dict] = {k: done[k] for k in order if k in done}
    skip = skip or {}
    for key in order:
        if key not in rows and key[1] in skip:
            rows[key] = skipped_row(key[0], key[1], formulation, duration, skip[key[1]])
    todo = [k for k in order if k not in rows]

    def _table_rows():
        return [rows[k] for k in order if k in rows] + others

    def _emit(key, row):
        rows[key] = row
        write_table(_table_rows(), csv_path)
        if on_row is not None:
            on_row(row)

    def _isolated(backend: str) -> bool:
        return isolate == "always" or (isolate == "auto" and is_risky(backend))

    # (key, args, deadline of an isolated run or None)
    items = [((s, b), (s, b, formulation, duration, str(out), deadline, run_budget),
              run_deadline(s, duration, run_time_limit) if _isolated(b) else None) for s, b in todo]

    def _emit_run(key, row):
        row["isolated"] = _isolated(key[1])
        row["run_budget_s"] = run_budget
        _emit(key, row)

    if jobs == 1:
        for key, args, deadline_s in items:
            if deadline_s is None:
                _emit_run(key, _run_job(args))
            else:
                _run_in_workers([(key, args, deadline_s)], 1, plugins, _emit_run)
    else:
        # every run in a worker of its own: a crash is that run's row, not the pool's end
        _run_in_workers(items, jobs, plugins, _emit_run)
    write_table(_table_rows(), csv_path)
    table = pd.read_csv(csv_path)
    errors = int(table["status"].isin(FAILED_RUN_STATUSES).sum()) if len(table) else 0
    not_ok = int((table["verdict"].isin(BAD_VERDICTS) | table["status"].isin(FAILED_RUN_STATUSES)).sum()) if len(table) else 0
    return ClosedLoopOutcome(table, csv_path, errors, len(todo), len(order) - len(todo), not_ok)
