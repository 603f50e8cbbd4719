"""Reference solutions: published optima, infeasibility classification, cache."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
import qpsolvers
import scipy.io

import qpbench.reference as reference_module
from qpbench.formats import (
    ProblemRecord,
    load_maros_meszaros,
    load_problems,
    read_problem_set,
    write_problem_set,
)
from qpbench.reference import cache_path, reference_solution, reference_solutions

# Optimal objective values from the Maros-Meszaros table (Maros & Meszaros 1999), where
# the value is a known exact number (fractions such as HS35 = 1/9, HS52 = 1859/349,
# HS53 = 176/43, HS76 = -103/22) or given to 8 significant digits.
EXACT = {
    "HS21": -99.96,
    "HS35": 1.0 / 9.0,
    "HS35MOD": 0.25,
    "HS51": 0.0,
    "HS52": 1859.0 / 349.0,
    "HS53": 176.0 / 43.0,
    "HS76": -103.0 / 22.0,
    "QPTEST": 4.371875,
    "TAME": 0.0,
    "ZECEVIC2": -4.125,
}
PUBLISHED_8_DIGITS = {
    "HS118": 6.6482045e2,
    "QAFIRO": -1.5907818,
    "GENHS28": 9.2717369e-1,
    "LOTSCHD": 2.3984159e3,
}


@pytest.fixture(scope="module")
def mm_refs(mm_dir):
    ps = load_problems(mm_dir)
    return ps, reference_solutions(ps, cache=False)


def test_maros_meszaros_published_optima(mm_refs):
    ps, refs = mm_refs
    got = {r.name: ref for r, ref in zip(ps, refs)}
    assert set(EXACT) | set(PUBLISHED_8_DIGITS) == set(got)
    for name, f in EXACT.items():
        assert got[name].status == "optimal" and got[name].agree, name
        assert abs(got[name].objective - f) <= 1e-8 * max(1.0, abs(f)), (
            name,
            got[name].objective,
            f,
        )
    for name, f in PUBLISHED_8_DIGITS.items():
        assert got[name].status == "optimal" and got[name].agree, name
        assert abs(got[name].objective - f) <= 1e-7 * abs(f), (name, got[name].objective, f)


def test_maros_meszaros_reference_satisfies_original_form(mm_refs):
    """The reference x of the converted problem is feasible and optimal-valued in the
    original ``l <= A x <= u`` form, read straight from the .mat file."""
    ps, refs = mm_refs
    for rec, ref in zip(ps, refs):
        raw = scipy.io.loadmat(str(ps.path / f"{rec.name}.mat"))
        A = raw["A"].toarray()
        lo, up = raw["l"].ravel().astype(float), raw["u"].ravel().astype(float)
        Ax = A @ ref.x
        scale = 1e-7 * (1.0 + np.abs(Ax))
        assert np.all(Ax >= np.where(lo <= -1e20, -np.inf, lo) - scale), rec.name
        assert np.all(Ax <= np.where(up >= 1e20, np.inf, up) + scale), rec.name
        P = raw["P"].toarray()
        f = 0.5 * ref.x @ P @ ref.x + raw["q"].ravel() @ ref.x + float(raw["r"].item())
        assert f == pytest.approx(ref.objective, rel=1e-12, abs=1e-12)
        # second solver agrees on the objective
        assert abs(ref.check_objective - ref.objective) <= 1e-7 * max(1.0, abs(ref.objective))


def _infeasible_problems():
    eye = np.eye(2)
    return {
        "ineq": qpsolvers.Problem(
            eye, np.zeros(2), np.array([[1.0, 0.0], [-1.0, 0.0]]), np.array([-1.0, -1.0])
        ),
        "eq": qpsolvers.Problem(
            np.eye(3), np.zeros(3), A=np.array([[1.0, 1, 1], [1, 1, 1]]), b=np.array([1.0, 2.0])
        ),
        "bounds+eq": qpsolvers.Problem(
            eye,
            np.zeros(2),
            A=np.array([[1.0, 1.0]]),
            b=np.array([5.0]),
            lb=-np.ones(2),
            ub=np.ones(2),
        ),
    }


def _unbounded_problems():
    return {
        # f = -x2 with x2 >= 0 only: decreases without bound along x2
        "ineq": qpsolvers.Problem(
            np.diag([1.0, 0.0]), np.array([0.0, -1.0]), np.array([[0.0, -1.0]]), np.array([0.0])
        ),
        # x1 + x2 = 1, f = (x1 - x2)... linear along the line
        "eq": qpsolvers.Problem(
            np.zeros((2, 2)), np.array([1.0, -1.0]), A=np.array([[1.0, 1.0]]), b=np.array([1.0])
        ),
        "unconstrained": qpsolvers.Problem(np.diag([1.0, 0.0]), np.array([0.0, -1.0])),
    }


@pytest.mark.parametrize("case", list(_infeasible_problems()))
def test_primal_infeasible_is_classified(case):
    ref = reference_solution(ProblemRecord(_infeasible_problems()[case], case))
    assert ref.status == "primal_infeasible" and ref.x is None and math.isnan(ref.objective)


@pytest.mark.parametrize("case", list(_unbounded_problems()))
def test_unbounded_is_classified_dual_infeasible(case):
    ref = reference_solution(ProblemRecord(_unbounded_problems()[case], case))
    assert ref.status == "dual_infeasible" and ref.x is None


def test_unconstrained_optimal_and_known_kkt(random_qp):
    p = random_qp(n_ineq=None, n_eq=None, bounds=False)
    ref = reference_solution(ProblemRecord(p, "u", offset=2.0))
    x = np.linalg.solve(p.P, -p.q)
    assert ref.status == "optimal" and np.allclose(ref.x, x, atol=1e-10)
    assert ref.objective == pytest.approx(0.5 * x @ p.P @ x + p.q @ x + 2.0, rel=1e-12)
    # a constrained problem: qpsolvers' residuals of the reference are tiny
    p = random_qp(n=6, n_ineq=5, n_eq=2)
    ref = reference_solution(ProblemRecord(p, "c"))
    sol = qpsolvers.Solution(p, found=True, x=ref.x, y=ref.y, z=ref.z, z_box=ref.z_box)
    assert ref.agree and max(sol.primal_residual(), sol.dual_residual(), sol.duality_gap()) < 1e-8


def test_cache_beside_set_and_recomputed_on_change(make_record, tmp_path, monkeypatch):
    folder = tmp_path / "set"
    recs = [make_record(f"p{i}", tick=i) for i in range(3)]
    write_problem_set(folder, recs, {"name": "t"})
    ps = read_problem_set(folder)
    refs = reference_solutions(ps)
    path = cache_path(ps)
    assert path == folder / f"reference-{ps.sha256[:16]}.parquet" and path.exists()

    # second call reads the cache (the solver is not called) and gives the same numbers
    def boom(record):
        raise AssertionError("recomputed although cached")

    monkeypatch.setattr(reference_module, "reference_solution", boom)
    again = reference_solutions(read_problem_set(folder))
    for a, b in zip(refs, again):
        assert (
            a.status == b.status and a.objective == b.objective and a.x.tobytes() == b.x.tobytes()
        )
        assert a.z_box.tobytes() == b.z_box.tobytes()
    monkeypatch.undo()
    # a changed set gets a new cache; the stale one is removed
    write_problem_set(folder, recs[:2], {"name": "t"})
    ps2 = read_problem_set(folder)
    refs2 = reference_solutions(ps2)
    assert len(refs2) == 2 and cache_path(ps2).exists() and not path.exists()
    # a corrupt cache is recomputed, not trusted
    cache_path(ps2).write_bytes(b"garbage")
    refs3 = reference_solutions(ps2)
    assert [r.objective for r in refs3] == [r.objective for r in refs2]


@pytest.fixture
def user_cache(tmp_path, monkeypatch):
    """A throw-away user cache folder (``$XDG_CACHE_HOME``); returns where references go in it."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    return tmp_path / "xdg" / "qpbench" / "references"


def test_cache_of_file_folder_goes_to_the_user_cache(mm_dir, tmp_path, make_record, user_cache):
    from qpbench.formats import save_npz

    for i in range(2):
        save_npz(make_record(f"n{i}"), tmp_path / "npz" / f"n{i}.npz")
    ps = load_problems(tmp_path / "npz")
    reference_solutions(ps)
    # a folder of .npz files is not ours (no manifest.json): nothing is written into it
    assert not list((tmp_path / "npz").glob("reference-*")) and cache_path(ps).parent == user_cache
    assert len(list(user_cache.glob("reference-*.parquet"))) == 1
    save_npz(make_record("n2"), tmp_path / "npz" / "n2.npz")  # content changes -> new key
    ps = load_problems(tmp_path / "npz")
    assert cache_path(ps) not in list(user_cache.glob("reference-*.parquet"))
    assert len(reference_solutions(ps)) == 3
    # a single .mat: cached in the user cache folder under its stem
    shutil.copy(mm_dir / "HS21.mat", tmp_path / "HS21.mat")
    one = load_problems(tmp_path / "HS21.mat")
    assert reference_solutions(one)[0].objective == pytest.approx(-99.96, rel=1e-9)
    assert cache_path(one).parent == user_cache and cache_path(one).name.startswith(
        "HS21.reference-"
    )
    assert cache_path(one).exists() and not list(tmp_path.glob("*reference-*"))


def test_cache_dir_is_honoured(make_record, tmp_path, user_cache):
    folder = tmp_path / "set"
    write_problem_set(folder, [make_record(f"p{i}", tick=i) for i in range(2)], {"name": "t"})
    ps = read_problem_set(folder)
    reference_solutions(ps, cache_dir=tmp_path / "elsewhere" / "refs")  # created when missing
    assert cache_path(ps, cache_dir=tmp_path / "elsewhere" / "refs").exists()
    assert not list(folder.glob("reference-*")) and not user_cache.exists()


def test_unwritable_folder_is_not_cached(mm_dir, tmp_path, monkeypatch, user_cache):
    shutil.copy(mm_dir / "HS35.mat", tmp_path / "HS35.mat")

    def refuse(path, data):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(reference_module, "write_bytes", refuse)
    ps = load_problems(tmp_path)
    refs = reference_solutions(ps)
    assert refs[0].objective == pytest.approx(1 / 9, rel=1e-8)
    assert not list(tmp_path.glob("reference-*")) and not list(user_cache.glob("*"))


def test_read_only_set_is_cached_in_the_user_cache(make_record, tmp_path, user_cache):
    ro = tmp_path / "ro"
    write_problem_set(ro, [make_record(f"p{i}", tick=i) for i in range(2)], {"name": "t"})
    ro.chmod(0o555)
    try:
        ps = read_problem_set(ro)
        refs = reference_solutions(ps)
        assert all(r.status == "optimal" for r in refs)
        assert not list(ro.glob("reference-*")) and not list(ro.glob(".*"))
        assert cache_path(ps).parent == user_cache and cache_path(ps).exists()
    finally:
        ro.chmod(0o755)


def test_reference_of_loaded_record_matches_direct(mm_dir):
    rec = load_maros_meszaros(mm_dir / "HS118.mat")
    ref = reference_solution(rec)
    assert ref.solver in ("clarabel", "piqp") and ref.check_solver in ("clarabel", "piqp")
    assert ref.check_status == "optimal"


def _candidates(problem, record):
    from qpbench.metrics import objective
    from qpbench.reference import Candidate

    good = qpsolvers.solve_problem(
        problem, solver="clarabel", tol_gap_abs=1e-10, tol_feas=1e-10, tol_gap_rel=1e-10
    )
    bad = qpsolvers.Solution(
        problem, found=True, x=good.x + 1e-3, y=good.y, z=good.z, z_box=good.z_box
    )
    return (
        lambda name: Candidate(name, "optimal", good, objective(record, good.x)),
        lambda name: Candidate(name, "optimal", bad, objective(record, bad.x)),
    )


def test_disagreeing_references_are_settled_by_kkt_residuals_not_by_name(make_record):
    from qpbench.reference import Candidate, assemble

    record = make_record("r")
    good, bad = _candidates(record.problem, record)
    for first, second in (("clarabel", "piqp"), ("piqp", "clarabel")):
        # the worse answer comes first, under either name
        ref = assemble("r", [bad(first), good(second)])
        assert ref.solver == second and ref.check_solver == first
        assert (
            ref.objective == good(second).objective and ref.check_objective == bad(first).objective
        )
        assert ref.agree is False and ref.kkt < ref.check_kkt
        expected = abs(good(second).objective - bad(first).objective) / max(
            1.0, abs(good(second).objective), abs(bad(first).objective)
        )
        assert ref.agreement == pytest.approx(expected, rel=1e-12) and ref.agreement > 1e-7
        np.testing.assert_array_equal(ref.x, good(second).solution.x)
    # agreeing answers: agreement tiny, still the smaller residuals kept
    ref = assemble("r", [good("clarabel"), good("piqp")])
    assert ref.agree is True and ref.agreement == 0.0
    # an optimal answer that satisfies the KKT conditions refutes an infeasibility claim ...
    ref = assemble("r", [Candidate("clarabel", "primal_infeasible", None), good("piqp")])
    assert ref.status == "optimal" and ref.solver == "piqp" and ref.agree is False
    assert math.isnan(ref.agreement)
    # ... one that does not, does not
    ref = assemble("r", [bad("clarabel"), Candidate("piqp", "primal_infeasible", None)])
    assert ref.status == "primal_infeasible" and ref.solver == "piqp" and ref.x is None
    # no verdict vs a verdict: the verdict; two different verdicts: unknown
    ref = assemble(
        "r", [Candidate("clarabel", "unknown", None), Candidate("piqp", "dual_infeasible", None)]
    )
    assert ref.status == "dual_infeasible" and ref.solver == "piqp"
    ref = assemble(
        "r",
        [
            Candidate("clarabel", "primal_infeasible", None),
            Candidate("piqp", "dual_infeasible", None),
        ],
    )
    assert ref.status == "unknown"


def test_cache_keeps_agreement_and_both_residuals(make_record, tmp_path):
    records = [make_record(f"p{i}", tick=i) for i in range(3)]
    folder = write_problem_set(tmp_path / "set", records, generator={"name": "test"})
    pset = load_problems(folder)
    refs = reference_solutions(pset)
    assert cache_path(pset).exists()
    again = reference_solutions(load_problems(folder))
    for a, b in zip(refs, again):
        assert a.agreement == b.agreement and a.kkt == b.kkt and a.check_kkt == b.check_kkt
        assert a.agreement <= 1e-7 and a.kkt <= a.check_kkt


def test_a_subset_reads_the_sets_cache_and_never_shrinks_it(tmp_path):
    """`bench --limit` on a set: the references come from the set's cache, which keeps every problem."""
    from dataclasses import replace as dc_replace
    from pathlib import Path

    from qpbench.formats import load_problems
    from qpbench.reference import cache_path, reference_solutions

    src = Path(__file__).resolve().parents[1] / "problems" / "maros_meszaros"
    folder = tmp_path / "mm"
    folder.mkdir()
    for f in sorted(src.glob("*.mat"))[:4]:
        shutil.copy(f, folder / f.name)
    full = load_problems(folder)
    sub = dc_replace(full, records=full.records[1:3])
    first = reference_solutions(sub)  # computes two, caches two
    assert [r.name for r in first] == [r.name for r in sub.records]
    refs = reference_solutions(full)  # computes the other two, keeps all four
    assert [r.name for r in refs] == [r.name for r in full.records]
    again = reference_solutions(sub)
    assert [(r.name, r.objective) for r in again] == [(r.name, r.objective) for r in refs[1:3]]
    path = cache_path(full)
    stamp = path.stat().st_mtime_ns
    assert [r.name for r in reference_solutions(full)] == [r.name for r in full.records]
    assert path.stat().st_mtime_ns == stamp  # read, not rewritten
