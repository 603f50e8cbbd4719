"""Results rows: CSV round trip, half-written lines, the in-flight marker."""

from __future__ import annotations

import csv
import math

import pytest

from qpbench.exceptions import InputError
from qpbench.harness.results import (
    InflightMarker,
    ResultsWriter,
    csv_bytes,
    read_results,
    row_key,
)
from qpbench.harness.results import bench_columns as columns


def make_row(i: int, **kw) -> dict:
    row = {c: None for c in columns()}
    row.update(
        problem=f"wall/tick-{i:04d}",
        scenario="wall",
        tick=i,
        t=0.001 * i,
        backend="osqp",
        profile="default",
        mode="sequential",
        status="optimal",
        found=True,
        success=True,
        objective=-1.0 / 3.0 + i,
        primal_residual=math.inf,
        dual_residual=math.nan,
        wall_time_min_s=1.25e-5,
        error=None,
        state_reset=False,
    )
    row.update(kw)
    return row


def test_rows_round_trip_exactly(tmp_path):
    path = tmp_path / "r.csv"
    rows = [make_row(i) for i in range(3)] + [
        make_row(3, status="error", error='ValueError: bad "x",\nline two')
    ]
    with ResultsWriter(path, new=True) as writer:
        writer.write_rows(rows[:2])
        writer.write_rows(rows[2:])
    back = read_results(path).rows
    assert len(back) == 4
    assert [row_key(r) for r in back] == [row_key(r) for r in rows]
    assert float(back[0]["objective"]) == rows[0]["objective"]  # repr: no digits lost
    assert back[0]["primal_residual"] == "inf" and back[0]["dual_residual"] == ""
    assert back[3]["error"] == 'ValueError: bad "x", line two'  # one physical line
    assert path.read_text().count("\n") == 5
    # pandas reads it with the right types
    import pandas

    df = pandas.read_csv(path)
    assert list(df.columns) == list(columns())
    assert df["found"].dtype == bool and df["tick"].tolist() == [0, 1, 2, 3]


def test_append_keeps_existing_rows(tmp_path):
    path = tmp_path / "r.csv"
    with ResultsWriter(path, new=True) as writer:
        writer.write_rows([make_row(0)])
    with ResultsWriter(path, new=False) as writer:
        writer.write_rows([make_row(1)])
    assert [r["tick"] for r in read_results(path).rows] == ["0", "1"]


@pytest.mark.parametrize("cut", [1, 10, 40, -1])
def test_half_written_last_line_is_dropped_and_repaired(tmp_path, cut, caplog):
    path = tmp_path / "r.csv"
    with ResultsWriter(path, new=True) as writer:
        writer.write_rows([make_row(i) for i in range(3)])
    full = path.read_bytes()
    last = csv_bytes([make_row(3)], columns())
    path.write_bytes(full + last[:cut])  # killed while writing row 3
    res = read_results(path, repair=False)
    assert len(res.rows) == 3 and res.dropped == 1
    assert path.read_bytes() == full + last[:cut]  # not repaired without repair=True
    assert "half-written" in caplog.text
    read_results(path, repair=True)
    assert path.read_bytes() == full
    with ResultsWriter(path, new=False) as writer:
        writer.write_rows([make_row(3)])
    assert [r["tick"] for r in read_results(path).rows] == ["0", "1", "2", "3"]


def test_truncated_header_starts_again(tmp_path):
    path = tmp_path / "r.csv"
    path.write_bytes(b"problem,scen")
    res = read_results(path, repair=True)
    assert res.rows == [] and res.dropped == 1
    assert path.read_text().splitlines() == [",".join(columns())]


def test_complete_line_with_wrong_field_count_at_the_end_is_dropped(tmp_path):
    path = tmp_path / "r.csv"
    with ResultsWriter(path, new=True) as writer:
        writer.write_rows([make_row(0)])
    good = path.read_bytes()
    path.write_bytes(good + b"a,b,c\n")
    assert len(read_results(path, repair=True).rows) == 1
    assert path.read_bytes() == good


def test_foreign_csv_is_an_input_error(tmp_path):
    path = tmp_path / "other.csv"
    with open(path, "w", newline="") as fh:
        csv.writer(fh).writerows([["problem", "solver", "runtime"], ["a", "b", "1"]])
    with pytest.raises(InputError, match="not a bench CSV"):
        read_results(path)


def test_inflight_marker_records_key_and_isolation(tmp_path):
    marker = InflightMarker(tmp_path / "out.csv")
    assert marker.path.name == ".out.csv.inflight"
    assert marker.read() == ([], None, "")
    marker.open(["qpsolvers:scs"], catch_faults=False)
    marker.mark(("wall/tick-0001", "osqp", "default"))
    marker.mark(("p", "b", "default"))  # shorter: the file is truncated
    assert marker.read() == (["qpsolvers:scs"], ("p", "b", "default"), "")
    marker.close()
    with open(marker.path, "a") as fh:  # what faulthandler appends on a fatal signal
        fh.write("Fatal Python error: Segmentation fault\n")
    assert marker.read()[2] == "Fatal Python error: Segmentation fault"
    marker.remove()
    assert not marker.path.exists()
