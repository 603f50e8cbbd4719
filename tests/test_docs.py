"""The commands that list, export and bench problems, and the top-level help and version.

(The snippets of problems/README.md run in tests/test_examples.py, with every other README's.)"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import qpsolvers

from qpbench.cli import main
from qpbench.formats import load_problems, read_problem_set

ROOT = Path(__file__).resolve().parents[1]


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert re.fullmatch(r"qpbench \d+\.\d+\.\d+\n", capsys.readouterr().out)


def test_top_level_help_has_examples(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    assert out.count("\n  qpbench ") >= 3


def test_list_selects_and_prints_json(capsys):
    assert (
        main(["list", str(ROOT / "problems" / "wall"), "--every", "100", "--limit", "3", "--json"])
        == 0
    )
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [r["tick"] for r in rows] == [0, 1000, 2000]
    assert rows[0] == {
        "name": "wall_paper_000000",
        "n": 4,
        "m_eq": 2,
        "m_ineq": 7,
        "n_box": 8,
        "scenario": "wall",
        "tick": 0,
        "t": 0.0,
        "formulation": "paper",
    }


def test_list_pattern_that_matches_nothing(capsys):
    assert main(["list", str(ROOT / "problems" / "maros_meszaros"), "--problems", "HS9*"]) == 2
    assert "HS9*" in capsys.readouterr().err


@pytest.mark.parametrize("fmt", ["npz", "parquet"])
def test_export_round_trip(tmp_path, fmt):
    src = read_problem_set(ROOT / "problems" / "narrow")
    out = tmp_path / "out"
    assert (
        main(
            [
                "export",
                str(ROOT / "problems" / "narrow"),
                "--format",
                fmt,
                "--problems",
                "narrow_paper_0001*",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    back = load_problems(out)
    expected = [r for r in src.records if r.name.startswith("narrow_paper_0001")]
    assert [r.name for r in back.records] == [r.name for r in expected]
    for a, b in zip(back.records, expected):
        for key in ("P", "q", "G", "h", "A", "b", "lb", "ub"):
            np.testing.assert_array_equal(getattr(a.problem, key), getattr(b.problem, key))
        assert (a.scenario, a.tick, a.t) == (b.scenario, b.tick, b.t)
    if fmt == "npz":  # qpsolvers reads them itself, and the arrays are writable (DAQP needs that)
        first = sorted(out.glob("*.npz"))[0]
        problem = qpsolvers.Problem.load(str(first))
        assert problem.A.flags.writeable
        assert qpsolvers.solve_problem(problem, "daqp").found in (True, False)


def test_export_refuses_existing_and_missing_parent(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    src = str(ROOT / "problems" / "maros_meszaros")
    assert main(["export", src, "--format", "npz", "--out", str(out)]) == 2
    assert (out / "keep.txt").read_text() == "mine"
    assert main(["export", src, "--format", "npz", "--out", str(tmp_path / "no" / "such")]) == 2
    assert not (tmp_path / "no").exists()
    assert "parent folder" in capsys.readouterr().err


def test_export_failure_leaves_nothing(tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    assert main(["export", str(bad), "--format", "parquet", "--out", str(tmp_path / "out")]) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.npz"]


def test_bench_on_a_selection(tmp_path, capsys):
    """`bench --problems PATTERN --limit N`: only those problems, backend names in any case."""
    import csv

    out = tmp_path / "hs.csv"
    cache = sorted((ROOT / "problems" / "maros_meszaros").glob("reference-*.parquet"))
    before = [p.read_bytes() for p in cache]
    assert (
        main(
            [
                "-q",
                "bench",
                str(ROOT / "problems" / "maros_meszaros"),
                "--problems",
                "HS*",
                "--limit",
                "3",
                "--backends",
                "DAQP,Clarabel",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    rows = list(csv.DictReader(out.open()))
    assert sorted({r["problem"] for r in rows}) == ["HS118", "HS21", "HS35"]
    assert {r["backend"] for r in rows} == {"daqp", "clarabel"}
    assert [
        p.read_bytes() for p in cache
    ] == before  # the set's reference cache is read, not shrunk
