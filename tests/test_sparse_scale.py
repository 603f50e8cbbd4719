"""Published test sets at their real size: sparse end to end, a memory budget, convexity checks
that scale and tolerate rounding (issue: sparse from file to solver)."""

from __future__ import annotations

import csv
import math
import subprocess
import sys

import numpy as np
import pytest
import qpsolvers
import scipy.sparse as spa
from conftest import LIMITED_CLI, band_matrix, write_band_set

from qpbench.cli import main
from qpbench.formats import ProblemRecord, assess_convexity, load_problems, save_npz
from qpbench.memory import parse_size, skip_reason


def _rows(path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_convexity_dense_and_sparse_paths():
    # dense path (n <= 1000): the ratio is exact
    P = np.diag([10.8, 1.0, -1.27e-5])
    c = assess_convexity(P)
    assert c.verdict == "rounding" and math.isclose(c.ratio, -1.27e-5 / 10.8, rel_tol=1e-9)
    assert "lambda_min / lambda_max = -1.18e-06" in c.warning
    assert (
        assess_convexity(np.diag([1.0, -0.5])).skip_reason
        == "nonconvex (lambda_min / lambda_max = -0.5)"
    )
    assert assess_convexity(np.diag([1.0, 0.0])).verdict == "convex"
    # sparse path (n > 1000, not diagonally dominant): inertia of P + delta I, ratio to 2 %
    n = 5000
    assert assess_convexity(band_matrix(n)).verdict == "convex"
    c = assess_convexity(band_matrix(n, -1.2e-6))
    assert c.verdict == "rounding" and c.method == "inertia" and abs(c.ratio / -1.2e-6 - 1) < 0.05
    c = assess_convexity(band_matrix(n, -1e-3))
    assert c.verdict == "nonconvex" and abs(c.ratio / -1e-3 - 1) < 0.05
    # diagonal: Gershgorin decides without a factorization
    assert assess_convexity(spa.identity(200_000, format="csc")).method == "gershgorin"


def test_memory_sizes_and_dense_limit():
    assert (
        parse_size("2GB") == 2_000_000_000
        and parse_size("1.5GiB") == 3 * 2**29
        and parse_size("512") == 512
    )
    from qpbench.exceptions import ParamError

    with pytest.raises(ParamError, match="memory budget '2 parsecs'"):
        parse_size("2 parsecs")
    n = 100_000
    big = qpsolvers.Problem(band_matrix(n), np.zeros(n))
    assert skip_reason(big, sparse_backend=True, budget=2 * 10**9) is None
    assert skip_reason(big, sparse_backend=False, budget=2 * 10**9).startswith("dense-only backend")
    assert skip_reason(big, sparse_backend=True, budget=10**6).startswith("memory: needs about")


def _set_with_odd_problems(folder):
    """Three problems of one folder: convex, slightly indefinite (rounding), clearly nonconvex."""
    n = 6
    q = np.linspace(-1, 1, n)
    box = dict(lb=-np.ones(n), ub=np.ones(n))
    convex = np.diag(np.linspace(1, 10.8, n))
    rounding = convex.copy()
    rounding[0, 0] = -1.27e-5  # published data's rounding: lambda_min / lambda_max = -1.2e-6
    nonconvex = convex.copy()
    nonconvex[0, 0] = -5.4
    for name, P in (("a_convex", convex), ("b_rounding", rounding), ("c_nonconvex", nonconvex)):
        save_npz(
            ProblemRecord(qpsolvers.Problem(spa.csc_matrix(P), q, **box), name),
            folder / f"{name}.npz",
        )


def test_rounding_solved_with_warning_and_nonconvex_skipped(tmp_path):
    _set_with_odd_problems(tmp_path / "set")
    out = tmp_path / "rows.csv"
    code = main(
        ["bench", str(tmp_path / "set"), "--backends", "clarabel,osqp", "--out", str(out), "-q"]
    )
    assert code in (0, 1)  # never 2: one odd problem does not stop the set
    rows = {(r["problem"], r["backend"]): r for r in _rows(out)}
    assert len(rows) == 6
    for backend in ("clarabel", "osqp"):
        assert (
            rows[("a_convex", backend)]["status"] == "optimal"
            and not rows[("a_convex", backend)]["error"]
        )
        odd = rows[("b_rounding", backend)]
        assert odd["status"] != "skipped"
        assert odd["error"].startswith(
            "warning: P slightly indefinite (lambda_min / lambda_max = -1.18e-06"
        )
        skipped = rows[("c_nonconvex", backend)]
        assert skipped["status"] == "skipped" and skipped["success"] == "False"
        assert skipped["error"] == "nonconvex (lambda_min / lambda_max = -0.5)"
    assert rows[("b_rounding", "clarabel")]["status"] == "optimal"


def test_structural_corruption_still_exit_2(tmp_path, capsys):
    _set_with_odd_problems(tmp_path / "set")
    (tmp_path / "set" / "d_broken.npz").write_bytes(b"not a zip file")
    code = main(
        ["bench", str(tmp_path / "set"), "--backends", "osqp", "--out", str(tmp_path / "x.csv")]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "d_broken.npz" in err[0]
    assert not (tmp_path / "x.csv").exists()


def test_memory_budget_skips_with_the_reason(tmp_path):
    _set_with_odd_problems(tmp_path / "set")
    out = tmp_path / "rows.csv"
    code = main(
        [
            "bench",
            str(tmp_path / "set"),
            "--backends",
            "osqp,daqp",
            "--out",
            str(out),
            "-q",
            "--memory-budget",
            "1kB",
        ]
    )
    assert code == 0
    rows = _rows(out)
    assert {r["status"] for r in rows} == {"skipped"}
    assert all(r["error"].startswith(("memory: needs about", "nonconvex")) for r in rows)


@pytest.mark.slow
def test_100k_variables_through_inspect_bench_report_under_2gb(tmp_path):
    """inspect, bench and report of a 100,000-variable banded QP with ``ulimit -v 2GB``:
    sparse all the way (a dense P alone would be 80 GB), dense-only backends skipped."""
    write_band_set(tmp_path / "set")
    script = LIMITED_CLI.format(limit=2 * 1024**3)
    out = tmp_path / "rows.csv"

    def run(*args):
        return subprocess.run(
            [sys.executable, "-c", script, *args], capture_output=True, text=True, timeout=600
        )

    inspect = run("inspect", str(tmp_path / "set"), "--json")
    assert inspect.returncode == 0, inspect.stderr
    assert '"n": [\n    100000,' in inspect.stdout and '"convex": 1' in inspect.stdout
    bench = run(
        "bench",
        str(tmp_path / "set"),
        "--backends",
        "osqp,clarabel,daqp",
        "--out",
        str(out),
        "--memory-budget",
        "1GB",
    )
    assert bench.returncode == 0, bench.stderr
    rows = {r["backend"]: r for r in _rows(out)}
    assert rows["osqp"]["status"] == rows["clarabel"]["status"] == "optimal"
    assert rows["osqp"]["success"] == "True" and rows["osqp"]["reference_status"] == "optimal"
    assert rows["daqp"]["status"] == "skipped" and rows["daqp"]["error"].startswith(
        "dense-only backend"
    )
    report = run("report", str(out), "--out", str(tmp_path / "report"))
    assert report.returncode == 0, report.stderr
    assert "osqp" in (tmp_path / "report" / "report.md").read_text()


def test_maros_meszaros_large_files_are_read_sparse(tmp_path):
    """A few of the shipped-beside large published files, read without a dense copy."""
    from pathlib import Path

    folder = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "maros_meszaros_large"
    files = [folder / f for f in ("BOYD1.mat", "CONT-300.mat", "AUG2D.mat")]
    if not all(f.exists() for f in files):
        pytest.skip(f"{folder} not present")
    for f in files:
        rec = load_problems(f)[0]
        assert (
            spa.issparse(rec.problem.P)
            and rec.sizes[0] > 20_000
            and rec.convexity.verdict == "convex"
        )
