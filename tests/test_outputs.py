"""Output paths are checked before any work: a folder where a file is expected is one line, exit 2."""

from __future__ import annotations

from pathlib import Path

import pytest

from qpbench.atomic import check_output
from qpbench.cli import main
from qpbench.exceptions import OutputExistsError, ParamError

ROOT = Path(__file__).resolve().parents[1]


def test_folder_where_a_file_is_expected_even_with_force(tmp_path, capsys):
    out = tmp_path / "somedir"
    out.mkdir()
    (out / "mine.txt").write_text("keep")
    code = main(["bench", str(ROOT / "problems" / "maros_meszaros"), "--backends", "pinv", "--out", str(out), "--force"])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is a folder" in err[0] and str(out) in err[0]
    assert (out / "mine.txt").read_text() == "keep"


def test_file_where_a_folder_is_expected(tmp_path):
    f = tmp_path / "f"
    f.write_text("x")
    with pytest.raises(ParamError, match="is a file"):
        check_output(f, kind="dir", force=True)
    with pytest.raises(ParamError, match="is a file"):
        check_output(f / "x.csv", force=True)


def test_existing_output_needs_force(tmp_path):
    f = tmp_path / "x.csv"
    f.write_text("")
    with pytest.raises(OutputExistsError):
        check_output(f)
    check_output(f, force=True)
