"""Shared fixtures: random problems, the Maros-Meszaros subset."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from qpbench.cache import PACKAGE_DIR  # imports nothing compiled: safe before the cache is set

#: The checkout these tests run from: subprocesses import its package too (see below).
ROOT = Path(__file__).resolve().parents[1]


def _fresh_install() -> bool:
    """No kernel of qpbench is compiled yet where numba keeps them by default (a fresh install)."""
    return not os.environ.get("NUMBA_CACHE_DIR") and not any(PACKAGE_DIR.rglob("*.nbi"))


# On a fresh install (CI's clean clone) the suite's kernels go to one empty folder of the
# session, shared by the xdist workers and every subprocess (they inherit the environment) and
# removed at the end, rather than beside the sources. Set before numba is imported (it reads
# NUMBA_CACHE_DIR once). A checkout whose kernels are already compiled keeps its cache.
# Subprocesses (``python -m qpbench.cli`` in a temporary folder, the installed ``qpbench``
# script) import the checkout's package, as the tests do, not a copy installed elsewhere: the
# code under test, and its kernels compiled once (numba caches a kernel per source file).
SHARED_FRESH_CACHE = None
if _fresh_install():
    SHARED_FRESH_CACHE = tempfile.mkdtemp(prefix="qpbench-test-kernels-")
    os.environ["NUMBA_CACHE_DIR"] = SHARED_FRESH_CACHE
if os.environ.get("PYTHONPATH", "").split(os.pathsep)[0] != str(ROOT):
    os.environ["PYTHONPATH"] = os.pathsep.join(
        filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])
    )

import numpy as np  # noqa: E402  (after NUMBA_CACHE_DIR is set)
import pytest  # noqa: E402
import qpsolvers  # noqa: E402
from hypothesis import settings  # noqa: E402

from qpbench.formats import ProblemRecord  # noqa: E402


def pytest_unconfigure(config):
    if SHARED_FRESH_CACHE is not None:
        shutil.rmtree(SHARED_FRESH_CACHE, ignore_errors=True)


# CI draws the same hypothesis examples every run, so a red CI is reproducible;
# locally each run explores new ones.
settings.register_profile("ci", derandomize=True, database=None)
if os.environ.get("CI"):
    settings.load_profile("ci")


@pytest.fixture(autouse=True, scope="session")
def _own_user_cache(tmp_path_factory):
    """The user cache folder (reference caches of sets that are not ours) is the session's own:
    a test never reads what an earlier run left there, and the runs leave nothing behind."""
    previous = os.environ.get("XDG_CACHE_HOME")
    os.environ["XDG_CACHE_HOME"] = str(tmp_path_factory.mktemp("user-cache"))
    yield
    if previous is None:
        os.environ.pop("XDG_CACHE_HOME", None)
    else:
        os.environ["XDG_CACHE_HOME"] = previous


#: The ``qpbench`` loggers as the package leaves them (no handler, propagating to the root).
_PRISTINE_LOGGERS = ("qpbench", "qpbench.solves")


@pytest.fixture(autouse=True)
def _logging_restored():
    """The ``qpbench`` loggers as the package leaves them after each test: ``qpbench.cli.main``
    run in a test (or in a module fixture, outside any test) sets their handlers, levels and
    propagation for its command, and a later test that reads the log through ``caplog`` (the
    root logger) must see it whichever tests ran before."""
    import logging

    yield
    for name in _PRISTINE_LOGGERS:
        lg = logging.getLogger(name)
        lg.handlers[:] = []
        lg.setLevel(logging.NOTSET)
        lg.propagate = True


#: The Maros-Meszaros subset the repository ships.
MAROS_MESZAROS_DIR = ROOT / "problems" / "maros_meszaros"


def random_problem(rng, n=4, n_ineq=3, n_eq=2, bounds=True, lb=True, ub=True) -> qpsolvers.Problem:
    """A random strictly convex QP (dense float64) with the requested parts.

    ``n_ineq = None`` / ``n_eq = None`` leave out ``G, h`` / ``A, b``; ``bounds``
    adds ``lb`` and/or ``ub`` (with some infinite entries).
    """
    M = rng.standard_normal((n, n))
    P = M @ M.T + 0.1 * np.eye(n)
    q = rng.standard_normal(n)
    G = h = A = b = lo = up = None
    if n_ineq is not None:
        G = rng.standard_normal((n_ineq, n))
        h = rng.random(n_ineq) + 0.1
    if n_eq is not None:
        A = rng.standard_normal((n_eq, n))
        b = 0.1 * rng.standard_normal(n_eq)
    if bounds and lb:
        lo = -1.0 - rng.random(n)
        lo[0] = -np.inf
    if bounds and ub:
        up = 1.0 + rng.random(n)
        up[-1] = np.inf
    return qpsolvers.Problem(P, q, G, h, A, b, lo, up)


#: ``python -c LIMITED_CLI.format(limit=BYTES) ARGS...``: the CLI with its address space capped.
LIMITED_CLI = """
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, ({limit}, {limit}))
from qpbench.cli import main
sys.exit(main(sys.argv[1:]))
"""


def band_matrix(n: int, shift: float = 0.0):
    """``(L + shift 16 I)`` as CSC, ``L`` the square of the 1-D Laplacian (eigenvalues in [0, 16])."""
    import scipy.sparse as spa

    e = np.ones(n)
    L = spa.diags([-e[:-1], 2 * e, -e[:-1]], [-1, 0, 1], format="csc")
    return ((L @ L) + shift * 16 * spa.identity(n)).tocsc()


def write_band_set(folder: Path, n: int = 100_000) -> Path:
    """``folder/band100k.npz``: ``band_matrix(n, 1e-3)``, ``q = sin(i)``, one equality
    ``sum x = 1`` and the box ``[-1, 1]`` (a dense ``P`` of 100,000 variables is 80 GB)."""
    import scipy.sparse as spa

    from qpbench.formats import save_npz

    problem = qpsolvers.Problem(
        band_matrix(n, 1e-3),
        np.sin(np.arange(n)),
        None,
        None,
        spa.csc_matrix(np.ones((1, n))),
        np.ones(1),
        -np.ones(n),
        np.ones(n),
    )
    folder.mkdir()
    save_npz(ProblemRecord(problem, "band100k"), folder / "band100k.npz")
    return folder


from qpbench.sim.summary import CLOCKS  # noqa: E402

#: Summary keys of a closed-loop run that measure time; every other one must not depend on it.
SUMMARY_TIME_KEYS = frozenset(
    {
        "wall_time_s",
        "real_time_factor",
        "solve_time_median_s",
        "solve_time_p99_s",
        "solve_time_p99_lo_s",
        "solve_time_p99_hi_s",
        "solve_time_max_s",
        "deadline_misses",
        "over_dt_share",
        "solver_time_p99_s",
        "solver_over_dt_share",
        "realtime",
        "realtime_reason",
        "realtime_solver",
        "realtime_solver_reason",
        "rank_time_p99_s",
        "rank_time_p99_lo_s",
        "rank_time_p99_hi_s",
        "time_p99_without_infeasible_s",
        "time_median_infeasible_s",
        "certify_time_median_s",
        "certify_time_max_s",
        "noise_floor_over_dt_share",
        "noise_floor_tick_p99_s",
        *(f"over_dt_{kind}" for kind in ("optimal", "infeasible", "fallback", "other")),
        *(f"time_p99_{kind}_s" for kind in ("optimal", "infeasible", "fallback", "other")),
    }
    | {f"{clock}_{stat}_s" for clock in CLOCKS for stat in ("median", "p99", "max")}
)


def simulate_args(scenario: str, backend: str, duration: str, *options: str) -> list[str]:
    """``simulate --scenario S --backend B --duration D OPTIONS...`` as argv."""
    return [
        "simulate",
        "--scenario",
        scenario,
        "--backend",
        backend,
        "--duration",
        duration,
        *options,
    ]


def panda_adaptive(duration: float):
    """``panda_table`` with the adaptive law on, its gains, start estimates and clamps those of
    ``adaptive_fast`` (``Kp_hat`` from 4000 N/m against the table's 5000 N/m)."""
    from qpbench.sim.scenario import load_scenario

    fast = load_scenario("adaptive_fast").spec
    a, c = fast.adaptive, fast.controller
    overrides = {"adaptive.enabled": True, "adaptive.gain": a.gain.tolist()}
    overrides |= {"adaptive.kp_min": a.kp_min, "adaptive.kd_min": a.kd_min}
    overrides |= {"controller.kp": c.kp, "controller.kd": c.kd}
    return load_scenario("panda_table", overrides=overrides, duration=duration)


def sparse_copy(problem: qpsolvers.Problem) -> qpsolvers.Problem:
    """The same QP with ``P``, ``G`` and ``A`` as ``scipy.sparse`` CSC matrices (``None`` kept)."""
    import scipy.sparse as spa

    def csc(M):
        return None if M is None else spa.csc_matrix(M)

    P, q, G, h, A, b, lb, ub = problem.unpack()
    return qpsolvers.Problem(csc(P), q, csc(G), h, csc(A), b, lb, ub)


@pytest.fixture
def rng():
    return np.random.default_rng(20190101)


@pytest.fixture
def make_record(rng):
    """Factory: ``make_record(name, **random_problem kwargs)`` -> ProblemRecord with metadata."""

    def make(name="p", scenario="wall", tick=0, t=0.0, formulation="paper", offset=0.0, **kw):
        return ProblemRecord(
            random_problem(rng, **kw), name, scenario, tick, t, formulation, offset
        )

    return make


@pytest.fixture(scope="session")
def mm_dir():
    assert MAROS_MESZAROS_DIR.is_dir(), (
        f"the shipped Maros-Meszaros subset is missing: {MAROS_MESZAROS_DIR}"
    )
    return MAROS_MESZAROS_DIR


@pytest.fixture
def random_qp(rng):
    """Factory: ``random_qp(**random_problem kwargs)`` -> random strictly convex ``qpsolvers.Problem``."""

    def make(**kw):
        return random_problem(rng, **kw)

    return make


@pytest.fixture(scope="module")
def qpb():
    """The qpbenchmark module (the test skipped without it), the root-logger set-up it does
    at import undone."""
    import logging

    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    qpb = pytest.importorskip("qpbenchmark")
    root.handlers[:] = handlers
    root.setLevel(level)
    return qpb


def figures_closed(monkeypatch) -> list:
    """Every matplotlib figure closed from now on (as the code under test closes each one it
    saves), drawn, so that a test can read its artists and their extents afterwards."""
    import matplotlib.pyplot as plt

    seen: list = []
    real_close = plt.close

    def close(fig=None):
        if fig is not None and hasattr(fig, "axes"):
            seen.append(fig)
        return real_close(fig)

    monkeypatch.setattr(plt, "close", close)
    return seen


def legends_over_data(fig) -> list[str]:
    """The legends of ``fig`` that overlap the data area of one of its axes (none should)."""
    if not hasattr(fig.canvas, "get_renderer"):  # a closed figure keeps only a bare canvas
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        FigureCanvasAgg(fig).draw()
    renderer = fig.canvas.get_renderer()
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    legends += list(fig.legends)
    over = []
    for legend in legends:
        box = legend.get_window_extent(renderer)
        for ax in fig.axes:
            if box.overlaps(ax.get_window_extent(renderer)):
                over.append(f"legend {[t.get_text() for t in legend.get_texts()][:3]} over {ax}")
    return over
