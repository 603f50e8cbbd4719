"""References that scale: settled by residuals, time-limited, parallel, or given (none, a file)."""

from __future__ import annotations

import math
import shutil
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import qpsolvers
from conftest import random_problem

import qpbench.reference as reference_module
from qpbench.cli import main
from qpbench.formats import ProblemRecord, ProblemSet, load_problems
from qpbench.reference import cache_path, reference_solutions


def _record(seed=3, name="r"):
    return ProblemRecord(random_problem(np.random.default_rng(seed), n=30, n_ineq=40, n_eq=5), name)


@pytest.mark.parametrize("loose", ["clarabel", "piqp"])
def test_a_less_accurate_solver_loses_whatever_its_name(monkeypatch, loose):
    """One solver stopped at 1e-3: its answer is off by about 1e-4 and the other one's is kept."""
    settings = {
        "clarabel": dict(
            reference_module.CLARABEL_SETTINGS, tol_feas=1e-3, tol_gap_abs=1e-3, tol_gap_rel=1e-3
        ),
        "piqp": dict(reference_module.PIQP_SETTINGS, eps_abs=1e-3, eps_duality_gap_abs=1e-3),
    }
    record = _record()
    exact = reference_module.reference_solution(record)
    monkeypatch.setitem(reference_module.SOLVER_SETTINGS, loose, settings[loose])
    ref = reference_module.reference_solution(record)
    accurate = "piqp" if loose == "clarabel" else "clarabel"
    assert ref.status == "optimal" and ref.solver == accurate and ref.check_solver == loose
    assert ref.agree is False and ref.agreement > 1e-7
    assert ref.kkt < 1e-8 < ref.check_kkt
    assert ref.objective == pytest.approx(exact.objective, rel=1e-9)
    assert abs(ref.check_objective - exact.objective) > 1e-7 * abs(exact.objective)
    # the note names both objectives, both residuals and the reason of the choice
    assert f"{ref.objective:.10g}" in ref.note and f"{ref.check_objective:.10g}" in ref.note
    assert ref.note.endswith(f"kept {accurate}: smaller KKT residuals")
    # the kept answer satisfies the KKT conditions as qpsolvers measures them
    sol = qpsolvers.Solution(record.problem, found=True, x=ref.x, y=ref.y, z=ref.z, z_box=ref.z_box)
    assert max(sol.primal_residual(), sol.dual_residual(), sol.duality_gap()) == pytest.approx(
        ref.kkt
    )


def _bench(source: Path, out: Path, *options: str, quiet: bool = False) -> int:
    """``qpbench [-q] bench SOURCE --backends qpsolvers:clarabel --out OUT OPTIONS...``: its exit code."""
    argv = ["bench", str(source), "--backends", "qpsolvers:clarabel", "--out", str(out), *options]
    return main(["-q", *argv] if quiet else argv)


def _mm_copy(mm_dir, tmp_path, names):
    folder = tmp_path / "mm"
    folder.mkdir()
    for n in names:
        shutil.copy(mm_dir / f"{n}.mat", folder / f"{n}.mat")
    return folder


def test_parallel_references_equal_serial(mm_dir, tmp_path):
    """--jobs 2 (worker processes) gives the same references, bit for bit, as one worker and as this process."""
    ps = load_problems(mm_dir)
    infeasible = ProblemRecord(
        qpsolvers.Problem(
            np.eye(2), np.zeros(2), np.array([[1.0, 0.0], [-1.0, 0.0]]), np.array([-1.0, -1.0])
        ),
        "infeasible",
    )
    ps = replace(ps, records=ps.records + [infeasible], path=None, files=[])
    here = reference_solutions(ps, cache=False)
    one = reference_solutions(ps, cache=False, jobs=1, time_limit=120.0)
    two = reference_solutions(ps, cache=False, jobs=2, time_limit=120.0)
    assert [r.name for r in two] == [r.name for r in ps.records]
    assert two[-1].status == "primal_infeasible"
    for a, b, c in zip(here, one, two):
        assert a.status == b.status == c.status and a.solver == b.solver == c.solver, a.name
        assert a.note == b.note == c.note
        for k in ("objective", "check_objective", "kkt", "check_kkt", "agreement"):
            assert np.array_equal([getattr(a, k)], [getattr(b, k)], equal_nan=True), (a.name, k)
            assert np.array_equal([getattr(b, k)], [getattr(c, k)], equal_nan=True), (a.name, k)
        for k in ("x", "y", "z", "z_box"):
            va, vb, vc = getattr(a, k), getattr(b, k), getattr(c, k)
            assert (va is None) == (vb is None) == (vc is None)
            if va is not None:
                assert va.tobytes() == vb.tobytes() == vc.tobytes(), (a.name, k)


class SlowToArrive(qpsolvers.Problem):
    """A problem that takes 60 s to unpickle: a worker receiving it does not answer in time."""

    def __reduce__(self):
        return (_slow_rebuild, (self.unpack(),))


def _slow_rebuild(parts):
    time.sleep(60.0)
    return qpsolvers.Problem(*parts)


def test_a_reference_that_times_out_is_recorded_and_the_others_go_on(tmp_path):
    good = _record(1, "good")
    slow = ProblemRecord(SlowToArrive(*_record(2).problem.unpack()), "slow")
    ps = ProblemSet("s", None, [good, slow, _record(4, "after")])
    started = time.perf_counter()
    refs = reference_solutions(ps, cache=False, time_limit=0.5, jobs=1)
    assert time.perf_counter() - started < 50.0  # the worker was stopped, not waited for
    by = {r.name: r for r in refs}
    assert by["good"].status == by["after"].status == "optimal"
    assert by["slow"].status == "unknown" and by["slow"].timed_out and by["slow"].x is None
    assert "time limit of 0.5 s; worker stopped" in by["slow"].note
    assert by["slow"].time_limit_s == 0.5 and not by["good"].timed_out


def test_bench_rows_of_a_timed_out_reference_have_an_empty_gap_and_the_reason(mm_dir, tmp_path):
    folder = _mm_copy(mm_dir, tmp_path, ["HS21", "HS35", "QAFIRO"])
    out = tmp_path / "out.csv"
    code = _bench(folder, out, "--reference-time-limit", "1e-9", "--no-warmup", quiet=True)
    assert code == 0
    df = pd.read_csv(out)
    assert len(df) == 3 and df["reference_status"].eq("unknown").all()
    assert df["optimality_gap"].isna().all() and df["success"].all()
    assert df["reference_note"].str.contains("time limit of 1e-09 s").all()
    # cached as timed out under that limit: a larger limit computes them again
    ps = load_problems(folder)
    refs = reference_solutions(ps, time_limit=None)
    assert all(r.status == "optimal" and not r.timed_out for r in refs)
    assert cache_path(ps).exists()


def test_reference_file_gives_published_objectives(mm_dir, tmp_path):
    folder = _mm_copy(mm_dir, tmp_path, ["HS21", "HS35", "HS76"])
    objectives = tmp_path / "optima.csv"
    # HS21 and HS76 as published; HS35's deliberately wrong; extra column ignored; HS35MOD not in the set
    objectives.write_text(
        "problem,objective,source\nHS21,-99.96,MM\nHS76,-4.681818181818182,MM\n"
        "HS35,1.0,wrong\nHS35MOD,0.25,MM\n"
    )
    out = tmp_path / "out.csv"
    assert _bench(folder, out, "--reference", str(objectives), "--no-warmup", quiet=True) in (0, 1)
    df = pd.read_csv(out).set_index("problem")
    assert (
        df.loc["HS21", "reference_objective"] == -99.96 and df.loc["HS21", "optimality_gap"] < 1e-8
    )
    assert df.loc["HS21", "success"] and df.loc["HS76", "success"]
    # the wrong objective is believed: clarabel's 1/9 is off by (1 - 1/9) / 1
    assert (
        df.loc["HS35", "optimality_gap"] == pytest.approx(1 - 1 / 9, rel=1e-8)
        and not df.loc["HS35", "success"]
    )
    assert "from " + str(objectives) in df.loc["HS21", "reference_note"]
    assert not list(folder.glob("reference-*"))  # nothing computed, nothing cached
    # a problem the file does not list: no reference, an empty gap and why
    objectives.write_text("problem,objective\nHS21,-99.96\n")
    assert (
        _bench(folder, out, "--force", "--reference", str(objectives), "--no-warmup", quiet=True)
        == 0
    )
    df = pd.read_csv(out).set_index("problem")
    assert df.loc["HS35", "reference_status"] == "unknown" and math.isnan(
        df.loc["HS35", "optimality_gap"]
    )
    assert "'HS35' is not in" in df.loc["HS35", "reference_note"]


@pytest.mark.parametrize(
    "text, key",
    [
        ("name,objective\nHS21,1\n", "problem"),
        ("problem,objective\nHS21,abc\n", "objective"),
        ("problem,objective\nHS21,1\nHS21,2\n", "problem"),
        ("problem,objective\nHS21,nan\n", "objective"),
    ],
)
def test_a_bad_reference_file_is_an_input_error_and_nothing_is_written(
    mm_dir, tmp_path, capsys, text, key
):
    folder = _mm_copy(mm_dir, tmp_path, ["HS21"])
    objectives = tmp_path / "optima.csv"
    objectives.write_text(text)
    out = tmp_path / "out.csv"
    assert _bench(folder, out, "--reference", str(objectives)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(objectives) in err[0] and f"key '{key}'" in err[0]
    assert not out.exists()
    assert _bench(folder, out, "--reference", str(tmp_path / "missing.csv")) == 2
    assert "neither auto, clarabel, piqp, none nor a file" in capsys.readouterr().err


def test_single_solver_references_are_cached_apart(mm_dir, tmp_path):
    folder = _mm_copy(mm_dir, tmp_path, ["HS21", "HS35"])
    ps = load_problems(folder)
    auto = reference_solutions(ps)
    only = reference_solutions(ps, method="piqp")
    assert (
        cache_path(ps).exists()
        and cache_path(ps, "piqp").exists()
        and cache_path(ps) != cache_path(ps, "piqp")
    )
    assert all(
        r.solver == "piqp"
        and r.check_solver is None
        and r.note.endswith("piqp alone (no cross-check)")
        for r in only
    )
    assert [r.objective for r in only] == pytest.approx([r.objective for r in auto], rel=1e-8)
    out = tmp_path / "none.csv"  # --reference none: no reference at all
    assert _bench(folder, out, "--reference", "none", quiet=True) in (0, 1)
    assert pd.read_csv(out)["reference_status"].isna().all()


@pytest.mark.parametrize(
    "option, value, key",
    [
        ("--jobs", "0", "jobs"),
        ("--reference-time-limit", "-1", "reference-time-limit"),
        ("--reference-time-limit", "inf", "reference-time-limit"),
    ],
)
def test_bad_reference_options_are_input_errors(mm_dir, tmp_path, capsys, option, value, key):
    out = tmp_path / "out.csv"
    assert _bench(mm_dir / "HS21.mat", out, option, value) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"key '{key}'" in err[0] and not out.exists()


def _our_set(folder: Path, make_record) -> Path:
    from qpbench.formats import write_problem_set

    write_problem_set(folder, [make_record(f"p{i}", tick=i) for i in range(2)], {"name": "t"})
    return folder


def test_bench_says_first_where_a_read_only_set_caches(tmp_path, make_record, monkeypatch, capsys):
    """``bench`` on our set in a read-only folder: the cache goes to the user cache folder, said first."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    folder = _our_set(tmp_path / "ro", make_record)
    folder.chmod(0o555)
    try:
        code = _bench(folder, tmp_path / "o.csv", "--no-warmup")
        assert code == 0
        users = tmp_path / "xdg" / "qpbench" / "references"
        first = capsys.readouterr().err.splitlines()[0]
        assert first == f"INFO: reference cache: {users}"
        assert len(list(users.glob("reference-*.parquet"))) == 1 and not list(
            folder.glob("reference-*")
        )
    finally:
        folder.chmod(0o755)


def test_bench_cache_dir_is_honoured(tmp_path, make_record, monkeypatch, capsys):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    folder = _our_set(tmp_path / "set", make_record)
    cache = tmp_path / "cache"
    argv = [
        "bench",
        str(folder),
        "--backends",
        "qpsolvers:clarabel",
        "--no-warmup",
        "--cache-dir",
        str(cache),
    ]
    assert main(argv + ["--out", str(tmp_path / "a.csv")]) == 0
    assert capsys.readouterr().err.splitlines()[0] == f"INFO: reference cache: {cache}"
    assert len(list(cache.glob("reference-*.parquet"))) == 1
    assert not list(folder.glob("reference-*")) and not (tmp_path / "xdg").exists()
    # without --cache-dir, our writable set keeps its cache beside it
    assert main(argv[:-2] + ["--out", str(tmp_path / "b.csv")]) == 0
    assert capsys.readouterr().err.splitlines()[0] == f"INFO: reference cache: {folder}"
    assert len(list(folder.glob("reference-*.parquet"))) == 1
