"""Problems in the ecosystem's formats: npz, Parquet problem sets, Maros-Meszaros, inspect."""

from __future__ import annotations

import itertools
import json
import shutil

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import qpsolvers
import scipy.io
import scipy.sparse as spa

from qpbench.cli import main
from qpbench.exceptions import ProblemFormatError
from qpbench.formats import (
    ARRAY_KEYS,
    ProblemRecord,
    load_maros_meszaros,
    load_npz,
    load_problems,
    read_problem_set,
    save_npz,
    sha256_file,
    write_problem_set,
)

# Every combination of present/absent G, A, lb, ub.
PARTS = list(itertools.product([True, False], repeat=4))


def _records(random_qp):
    out = []
    for i, (g, a, lo, up) in enumerate(PARTS):
        p = random_qp(
            n=3 + i % 4,
            n_ineq=2 + i % 3 if g else None,
            n_eq=1 + i % 2 if a else None,
            bounds=lo or up,
            lb=lo,
            ub=up,
        )
        out.append(
            ProblemRecord(
                p,
                f"p{i:02d}",
                "wall" if i % 2 else None,
                i if i % 3 else None,
                0.001 * i if i % 5 else None,
                ["paper", "soft", None][i % 3],
                -0.5 * i,
            )
        )
    # an empty inequality block (0 rows) and a signed zero survive too
    p = random_qp(n=2, n_ineq=None, n_eq=None, bounds=False)
    p.G, p.h = np.zeros((0, 2)), np.zeros(0)
    p.q[0] = -0.0
    out.append(ProblemRecord(p, "empty-G"))
    return out


def assert_bit_exact(r1: ProblemRecord, r2: ProblemRecord):
    """Same arrays bit for bit; a sparse matrix comes back sparse (CSC, same pattern and values)."""
    for k in ARRAY_KEYS:
        a, b = getattr(r1.problem, k), getattr(r2.problem, k)
        assert (a is None) == (b is None), k
        if a is None:
            continue
        assert spa.issparse(a) == spa.issparse(b), k
        if spa.issparse(a):
            a = spa.csc_matrix(a)
            a.sort_indices()
            assert b.format == "csc" and b.dtype == np.float64 and a.shape == b.shape, k
            assert np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices), k
            assert a.data.astype(np.float64).tobytes() == b.data.tobytes(), k
        else:
            a = np.asarray(a, dtype=np.float64)
            assert b.dtype == np.float64 and a.shape == b.shape, k
            assert a.tobytes() == b.tobytes(), k
    assert r1.meta() == r2.meta()


def _sparse_record(n: int, name: str, seed: int = 0) -> ProblemRecord:
    """A banded sparse QP (CSC P, G, A; some explicit zeros kept, signed zero in q)."""
    rng = np.random.default_rng(seed)
    e = np.ones(n)
    P = spa.diags([-e[:-1], 2.5 * e, -e[:-1]], [-1, 0, 1], format="csc")
    G = spa.random(max(1, n // 3), n, density=min(1.0, 4 / n), random_state=seed, format="csc")
    A = spa.csc_matrix(spa.eye(2, n))
    A.data[0] = 0.0  # an explicit zero is part of the pattern and survives
    q = rng.standard_normal(n)
    q[0] = -0.0
    lb = np.full(n, -1.0)
    lb[1] = -np.inf
    problem = qpsolvers.Problem(P, q, G, np.ones(G.shape[0]), A, np.zeros(2), lb, None)
    return ProblemRecord(problem, name, offset=0.25)


# ---------------------------------------------------------------- npz


def test_npz_round_trip_bit_exact(random_qp, tmp_path):
    for rec in _records(random_qp):
        path = save_npz(rec, tmp_path / f"{rec.name}.npz")
        back = load_npz(path)
        assert_bit_exact(rec, back)
        # qpsolvers reads our file as its own
        plain = qpsolvers.Problem.load(str(path))
        for k in ARRAY_KEYS:
            a, b = getattr(rec.problem, k), getattr(plain, k)
            assert (a is None) == (b is None)
            if a is not None:
                assert np.array_equal(a, b)


def test_npz_sparse_round_trip_bit_exact(random_qp, tmp_path):
    p = random_qp(n=5)
    sparse = qpsolvers.Problem(
        spa.csc_matrix(p.P), p.q, spa.csc_matrix(p.G), p.h, spa.csr_matrix(p.A), p.b, p.lb, p.ub
    )
    back = load_npz(save_npz(ProblemRecord(sparse, "s"), tmp_path / "s.npz"))
    assert_bit_exact(ProblemRecord(sparse, "s"), back)
    # a small problem is also written dense: qpsolvers reads it (Problem.save alone loses a sparse G)
    plain = qpsolvers.Problem.load(str(tmp_path / "s.npz"))
    assert np.array_equal(plain.G, p.G) and np.array_equal(plain.A, p.A)
    # a large one stays compact on disk (no dense copy) and comes back the same
    big = _sparse_record(3000, "big")
    path = save_npz(big, tmp_path / "big.npz")
    assert path.stat().st_size < 1_000_000  # dense P alone would be 72 MB
    assert_bit_exact(big, load_npz(path))


def test_csc_index_out_of_range_is_a_format_error_not_a_crash(tmp_path):
    # scipy's constructor checks only the lengths; a solver given such a matrix reads out of
    # bounds, so a corrupted file must fail on reading, naming the file
    rec = _sparse_record(40, "bad")
    path = save_npz(rec, tmp_path / "bad.npz")
    with np.load(path, allow_pickle=True) as data:
        members = {k: data[k] for k in data.files}
    members["P_csc_indices"] = members["P_csc_indices"] + 1000
    np.savez(path, **members)
    with pytest.raises(ProblemFormatError, match="bad.npz"):
        load_npz(path)
    folder = tmp_path / "set"
    write_problem_set(folder, [rec], {"name": "test"})
    parquet = folder / "problems.parquet"
    table = pq.read_table(parquet)
    column = table.column_names.index("P_csc_indices")
    shifted = [[i + 1000 for i in row] for row in table.column("P_csc_indices").to_pylist()]
    table = table.set_column(
        column, table.schema.field(column), pa.array(shifted, table.schema.field(column).type)
    )
    pq.write_table(table, parquet)
    with pytest.raises(ProblemFormatError, match="P"):
        read_problem_set(folder, verify_hash=False)


def test_npz_written_by_qpsolvers_is_read(random_qp, tmp_path):
    p = random_qp()
    p.save(str(tmp_path / "tick_0001.npz"))
    rec = load_npz(tmp_path / "tick_0001.npz")
    assert rec.name == "tick_0001" and rec.offset == 0.0 and rec.scenario is None
    assert np.array_equal(rec.problem.G, p.G)


def test_npz_folder_and_single_file(random_qp, tmp_path):
    recs = _records(random_qp)[:5]
    for r in reversed(recs):
        save_npz(r, tmp_path / f"{r.name}.npz")
    ps = load_problems(tmp_path)
    assert ps.kind == "npz" and ps.sha256 is None and len(ps) == 5
    for a, b in zip(recs, ps):  # sorted by file name
        assert_bit_exact(a, b)
    one = load_problems(tmp_path / "p00.npz")
    assert len(one) == 1 and one[0].name == "p00"


def test_npz_truncated_and_garbage(random_qp, tmp_path):
    path = save_npz(ProblemRecord(random_qp(), "x"), tmp_path / "x.npz")
    data = path.read_bytes()
    (tmp_path / "trunc.npz").write_bytes(data[: len(data) // 2])
    (tmp_path / "garbage.npz").write_bytes(b"not a zip file")
    for name in ("trunc.npz", "garbage.npz", "missing.npz"):
        with pytest.raises(ProblemFormatError) as e:
            load_npz(tmp_path / name)
        assert name in str(e.value) and "\n" not in str(e.value)


def test_npz_nan_and_missing_key(random_qp, tmp_path):
    p = random_qp()
    p.h[1] = np.nan
    np.savez(tmp_path / "nan.npz", P=p.P, q=p.q, G=p.G, h=p.h, A=p.A, b=p.b, lb=p.lb, ub=p.ub)
    with pytest.raises(ProblemFormatError) as e:
        load_npz(tmp_path / "nan.npz")
    assert "nan.npz" in str(e.value) and "'h'" in str(e.value) and "NaN" in str(e.value)
    np.savez(tmp_path / "noq.npz", P=p.P)
    with pytest.raises(ProblemFormatError) as e:
        load_npz(tmp_path / "noq.npz")
    assert "noq.npz" in str(e.value) and "'q'" in str(e.value)


# ---------------------------------------------------------------- problem sets


def test_problem_set_round_trip_bit_exact(random_qp, tmp_path):
    recs = _records(random_qp)
    write_problem_set(tmp_path / "set", recs, {"name": "test", "seed": 1})
    ps = read_problem_set(tmp_path / "set")
    assert len(ps) == len(recs) and ps.hash_ok and ps.kind == "set"
    for a, b in zip(recs, ps):
        assert_bit_exact(a, b)
    m = ps.manifest
    assert m["count"] == len(recs) and m["sha256"] == sha256_file(
        tmp_path / "set" / "problems.parquet"
    )
    assert m["generator"] == {"name": "test", "seed": 1}
    assert {"qpbench", "numpy", "qpsolvers", "pyarrow"} <= set(m["versions"])
    # load_problems on the folder and on the parquet file inside it
    for where in (tmp_path / "set", tmp_path / "set" / "problems.parquet"):
        again = load_problems(where)
        assert again.sha256 == ps.sha256 and len(again) == len(recs)


def test_problem_set_deterministic_bytes(random_qp, tmp_path):
    recs = _records(random_qp)
    write_problem_set(tmp_path / "a", recs, {"name": "test"})
    write_problem_set(tmp_path / "b", recs, {"name": "test"})
    for f in ("problems.parquet", "manifest.json"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes()
    write_problem_set(tmp_path / "c", recs[::-1], {"name": "test"})
    assert (tmp_path / "c" / "problems.parquet").read_bytes() != (
        tmp_path / "a" / "problems.parquet"
    ).read_bytes()
    assert not list(tmp_path.glob("*/.*.tmp"))  # atomic writes leave no temporary file


def test_qpbenchmark_parquet_test_set_reads_our_file(random_qp, tmp_path):
    qpbenchmark = pytest.importorskip("qpbenchmark")

    class RobotTicks(qpbenchmark.ParquetTestSet):
        description = "per-tick QPs"
        title = "robot ticks"
        sparse_only = False

    recs = _records(random_qp)
    write_problem_set(tmp_path / "set", recs, {"name": "test"})
    theirs = list(RobotTicks(tmp_path / "set" / "problems.parquet"))
    assert len(theirs) == len(recs)
    for rec, prob in zip(recs, theirs):
        assert prob.name == rec.name
        assert_bit_exact(ProblemRecord(rec.problem, rec.name), ProblemRecord(prob, prob.name))


def test_bare_qpbenchmark_parquet_is_read(random_qp, tmp_path):
    pytest.importorskip("qpbenchmark")
    from qpbenchmark.problem import Problem as BenchProblem
    from qpbenchmark.problem_list import ProblemList

    recs = _records(random_qp)
    plist = ProblemList()
    for r in recs:
        plist.append(BenchProblem.from_qpsolvers(r.problem, r.name))
    plist.to_parquet(str(tmp_path / "theirs.parquet"))
    ps = load_problems(tmp_path / "theirs.parquet")
    assert ps.kind == "parquet" and ps.manifest is None
    for r, b in zip(recs, ps):
        assert_bit_exact(ProblemRecord(r.problem, r.name), b)


def _rewrite(folder, table, fix_manifest=True):
    pq.write_table(table, folder / "problems.parquet")
    if fix_manifest:
        m = json.loads((folder / "manifest.json").read_text())
        m["sha256"] = sha256_file(folder / "problems.parquet")
        (folder / "manifest.json").write_text(json.dumps(m))


def _one_line(exc_info, *needles):
    msg = str(exc_info.value)
    assert "\n" not in msg
    for n in needles:
        assert n in msg, (n, msg)


def test_problem_set_hash_mismatch(random_qp, tmp_path):
    write_problem_set(tmp_path / "a", _records(random_qp)[:3], {"name": "a"})
    write_problem_set(tmp_path / "b", _records(random_qp)[3:6], {"name": "b"})
    shutil.copy(tmp_path / "b" / "problems.parquet", tmp_path / "a" / "problems.parquet")
    with pytest.raises(ProblemFormatError) as e:
        read_problem_set(tmp_path / "a")
    _one_line(e, str(tmp_path / "a" / "problems.parquet"), "sha256")
    ps = read_problem_set(tmp_path / "a", verify_hash=False)
    assert ps.hash_ok is False and len(ps) == 3


def test_problem_set_truncated_and_missing_files(random_qp, tmp_path):
    folder = tmp_path / "set"
    write_problem_set(folder, _records(random_qp)[:4], {"name": "t"})
    data = (folder / "problems.parquet").read_bytes()
    (folder / "problems.parquet").write_bytes(data[: len(data) // 2])
    with pytest.raises(ProblemFormatError) as e:
        read_problem_set(folder)
    _one_line(e, "problems.parquet", "sha256")
    with pytest.raises(ProblemFormatError) as e:
        read_problem_set(folder, verify_hash=False)
    _one_line(e, "problems.parquet", "unreadable")
    (folder / "manifest.json").write_text("{not json")
    with pytest.raises(ProblemFormatError) as e:
        read_problem_set(folder)
    _one_line(e, "manifest.json")
    (folder / "manifest.json").unlink()
    with pytest.raises(ProblemFormatError) as e:
        read_problem_set(folder)
    _one_line(e, "manifest.json")


def test_problem_set_missing_column_nan_and_shape(random_qp, tmp_path):
    folder = tmp_path / "set"
    recs = _records(random_qp)[:3]
    write_problem_set(folder, recs, {"name": "t"})
    table = pq.read_table(folder / "problems.parquet")

    _rewrite(folder, table.drop_columns(["tick"]))
    with pytest.raises(ProblemFormatError) as e:
        read_problem_set(folder)
    _one_line(e, "problems.parquet", "'tick'", "missing column")

    q = table.column("q").to_pylist()
    q[1][0] = float("nan")
    _rewrite(folder, table.set_column(1, "q", pa.array(q, type=pa.list_(pa.float64()))))
    with pytest.raises(ProblemFormatError) as e:
        read_problem_set(folder)
    _one_line(e, "problems.parquet", "'q'", "p01", "NaN")

    P = table.column("P").to_pylist()
    P[2] = P[2][:-1]
    _rewrite(folder, table.set_column(0, "P", pa.array(P, type=pa.list_(pa.float64()))))
    with pytest.raises(ProblemFormatError) as e:
        read_problem_set(folder)
    _one_line(e, "problems.parquet", "'P'", "p02")

    h = table.column("h").to_pylist()
    h[0] = h[0] + [1.0]
    _rewrite(folder, table.set_column(3, "h", pa.array(h, type=pa.list_(pa.float64()))))
    with pytest.raises(ProblemFormatError) as e:
        read_problem_set(folder)
    _one_line(e, "problems.parquet", "'h'", "p00")


def test_write_rejects_bad_records(random_qp, tmp_path):
    p = random_qp()
    bad = [
        ("P", qpsolvers.Problem(p.P, np.append(p.q, 1.0), p.G, p.h)),  # n is read from q
        ("G", qpsolvers.Problem(p.P, p.q, p.G[:, :3], p.h)),  # wrong columns
        ("q", qpsolvers.Problem(p.P, p.q + np.inf, p.G, p.h)),  # Inf
        ("h", qpsolvers.Problem(p.P, p.q, p.G, p.h + np.inf)),  # infinite h is not allowed
        ("P", qpsolvers.Problem(p.P + np.triu(np.ones_like(p.P), 1), p.q)),  # not symmetric
        ("lb", qpsolvers.Problem(p.P, p.q, lb=np.full(4, np.inf))),
        ("G", qpsolvers.Problem(p.P, p.q, p.G, None)),  # G without h
    ]
    for key, prob in bad:
        with pytest.raises(ProblemFormatError) as e:
            write_problem_set(tmp_path / "set", [ProblemRecord(prob, "bad")], {"name": "t"})
        _one_line(e, f"'{key}'", "bad")
    good = ProblemRecord(p, "same")
    with pytest.raises(ProblemFormatError) as e:
        write_problem_set(tmp_path / "set", [good, good], {"name": "t"})
    _one_line(e, "'name'", "same")
    assert not (tmp_path / "set" / "problems.parquet").exists()


def test_nonconvex_is_recorded_not_refused(random_qp, tmp_path):
    """Convexity is not a format rule: a nonconvex P is written and read with its verdict."""
    p = random_qp()
    write_problem_set(
        tmp_path / "s", [ProblemRecord(qpsolvers.Problem(-np.eye(4), p.q), "neg")], {"name": "t"}
    )
    back = read_problem_set(tmp_path / "s")[0]
    assert back.convexity.verdict == "nonconvex" and back.convexity.ratio == -1.0


def test_sparse_problem_set_round_trip_bit_exact(random_qp, tmp_path):
    """Sparse and dense records in one set: CSC columns for the sparse ones, read back bit for bit;
    a set without sparse matrices has no CSC column (the robot's sets keep their bytes)."""
    records = [
        _sparse_record(6, "small"),
        _sparse_record(2000, "large", seed=1),
        ProblemRecord(random_qp(), "dense"),
    ]
    write_problem_set(tmp_path / "s", records, {"name": "t"})
    back = read_problem_set(tmp_path / "s")
    for a, b in zip(records, back):
        assert_bit_exact(a, b)
    import pyarrow.parquet as pq

    table = pq.read_table(tmp_path / "s" / "problems.parquet")
    assert {"P_csc_data", "G_csc_indices", "A_csc_indptr"} <= set(table.column_names)
    dense_P = table.column("P").to_pylist()
    assert dense_P[0] is not None and dense_P[1] is None  # large: compact only
    assert (tmp_path / "s" / "problems.parquet").stat().st_size < 1_000_000
    write_problem_set(tmp_path / "d", [ProblemRecord(random_qp(), "dense")], {"name": "t"})
    assert not any(
        c.endswith("_csc_data")
        for c in pq.read_table(tmp_path / "d" / "problems.parquet").column_names
    )


def test_maros_meszaros_read_is_sparse_and_exact(mm_dir, tmp_path):
    """.mat -> CSC kept as the file holds it (no dense copy), through npz and Parquet bit for bit."""
    ps = load_problems(mm_dir)
    write_problem_set(tmp_path / "set", ps.records, {"name": "t"})
    for a, b in zip(ps, read_problem_set(tmp_path / "set")):
        assert_bit_exact(a, b)
        assert_bit_exact(a, load_npz(save_npz(a, tmp_path / f"{a.name}.npz")))
    for rec in ps:
        raw = scipy.io.loadmat(str(mm_dir / f"{rec.name}.mat"))
        P = rec.problem.P
        assert spa.isspmatrix_csc(P) and P.has_sorted_indices
        full = raw["P"].toarray()
        if not np.array_equal(full, full.T):
            full = full + full.T - np.diag(np.diag(full))
        assert np.array_equal(P.toarray(), full)


def test_infinite_bounds_are_allowed(random_qp, tmp_path):
    p = random_qp()
    p.lb[:] = -np.inf
    p.ub[1] = np.inf
    write_problem_set(tmp_path / "s", [ProblemRecord(p, "inf")], {"name": "t"})
    back = read_problem_set(tmp_path / "s")[0].problem
    assert np.all(back.lb == -np.inf) and back.ub[1] == np.inf


# ---------------------------------------------------------------- Maros-Meszaros


def test_maros_meszaros_subset_loads(mm_dir):
    ps = load_problems(mm_dir)
    assert ps.kind == "mat" and len(ps) == len(list(mm_dir.glob("*.mat"))) == 14
    for rec in ps:
        raw = scipy.io.loadmat(str(mm_dir / f"{rec.name}.mat"))
        n, m = int(raw["n"].item()), int(raw["m"].item())
        n_, m_eq, m_ineq = rec.sizes
        assert n_ == n
        P = rec.problem.P.toarray()
        assert spa.issparse(rec.problem.P) and np.array_equal(P, P.T)
        assert np.array_equal(P, raw["P"].toarray())  # stored full and symmetric
        assert rec.offset == float(raw["r"].item())
        lo, up = raw["l"].ravel()[: m - n], raw["u"].ravel()[: m - n]
        n_eq = int(np.sum(lo == up))
        n_ineq = int(
            np.sum((lo != up) & (np.abs(up) < 1e20)) + np.sum((lo != up) & (np.abs(lo) < 1e20))
        )
        assert (m_eq, m_ineq) == (n_eq, n_ineq), rec.name
        for v in (rec.problem.lb, rec.problem.ub):
            assert v is None or not np.any(np.abs(v[np.isfinite(v)]) >= 1e20)


def test_maros_meszaros_hs21_by_hand(mm_dir):
    # HS21: min 0.01 x1^2 + x2^2 - 100, 10 x1 - x2 >= 10, 2 <= x1 <= 50, -50 <= x2 <= 50
    rec = load_maros_meszaros(mm_dir / "HS21.mat")
    p = rec.problem
    assert np.allclose(p.P.toarray(), np.diag([0.02, 2.0])) and np.array_equal(p.q, [0.0, 0.0])
    assert rec.offset == -100.0 and p.A is None
    assert np.allclose(p.G.toarray(), [[-10.0, 1.0]]) and np.allclose(p.h, [-10.0])
    assert np.array_equal(p.lb, [2.0, -50.0]) and np.array_equal(p.ub, [50.0, 50.0])


def test_maros_meszaros_bad_files(mm_dir, tmp_path):
    raw = scipy.io.loadmat(str(mm_dir / "HS21.mat"))
    scipy.io.savemat(
        str(tmp_path / "NOR.mat"), {k: v for k, v in raw.items() if k in "P q A l u n m".split()}
    )
    with pytest.raises(ProblemFormatError) as e:
        load_maros_meszaros(tmp_path / "NOR.mat")
    _one_line(e, "NOR.mat", "'r'")
    data = (mm_dir / "QAFIRO.mat").read_bytes()
    (tmp_path / "TRUNC.mat").write_bytes(data[: len(data) // 2])
    with pytest.raises(ProblemFormatError) as e:
        load_maros_meszaros(tmp_path / "TRUNC.mat")
    _one_line(e, "TRUNC.mat")


def test_load_problems_unknown_inputs(tmp_path):
    (tmp_path / "x.txt").write_text("hello")
    for where in (tmp_path / "x.txt", tmp_path / "nothing", tmp_path):
        with pytest.raises(ProblemFormatError) as e:
            load_problems(where)
        _one_line(e, str(where))


# ---------------------------------------------------------------- qpbench inspect


def test_inspect_problem_set(random_qp, tmp_path, capsys):
    recs = _records(random_qp)
    write_problem_set(tmp_path / "set", recs, {"name": "test"})
    assert main(["inspect", str(tmp_path / "set")]) == 0
    out = capsys.readouterr().out
    assert f"problems     {len(recs)}" in out
    assert "matches manifest" in out and "paper" in out and "soft" in out and "wall" in out
    ns = [r.sizes[0] for r in recs]
    assert f"n            {min(ns)}-{max(ns)}" in out


def test_inspect_maros_meszaros(mm_dir, capsys):
    assert main(["inspect", str(mm_dir)]) == 0
    out = capsys.readouterr().out
    assert "problems     14" in out and "n            2-32" in out and "manifest     none" in out


def test_inspect_bad_input_exit_2(random_qp, tmp_path, capsys):
    assert main(["inspect", str(tmp_path / "missing")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing" in err and err.startswith("qpbench inspect: error:")
    write_problem_set(tmp_path / "a", _records(random_qp)[:2], {"name": "a"})
    write_problem_set(tmp_path / "b", _records(random_qp)[2:4], {"name": "b"})
    shutil.copy(tmp_path / "b" / "problems.parquet", tmp_path / "a" / "problems.parquet")
    assert main(["inspect", str(tmp_path / "a")]) == 2
    captured = capsys.readouterr()
    assert "DOES NOT MATCH" in captured.out and "sha256" in captured.err
