"""Output paths are checked before any work: a folder where a file is expected is one line, exit 2."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import simulate_args

from qpbench.atomic import check_output
from qpbench.cli import main
from qpbench.exceptions import OutputExistsError, ParamError

ROOT = Path(__file__).resolve().parents[1]


def test_folder_where_a_file_is_expected_even_with_force(tmp_path, capsys):
    out = tmp_path / "somedir"
    out.mkdir()
    (out / "mine.txt").write_text("keep")
    code = main(
        [
            "bench",
            str(ROOT / "problems" / "maros_meszaros"),
            "--backends",
            "pinv",
            "--out",
            str(out),
            "--force",
        ]
    )
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


@pytest.mark.parametrize(
    "argv",
    [
        [
            "bench",
            "problems/wall",
            "--backends",
            "daqp",
            "--limit",
            "2",
            "--out",
            "{tmp}/no/such/x.csv",
        ],
        [
            *simulate_args("wall", "daqp", "0.01"),
            "--summary",
            "{tmp}/no/such/s.json",
        ],
        [
            *simulate_args("wall", "daqp", "0.01"),
            "--dump",
            "{tmp}/no/such",
        ],
        [
            "closed-loop",
            "--scenarios",
            "wall",
            "--backends",
            "daqp",
            "--duration",
            "0.01",
            "--out",
            "{tmp}/no/such",
        ],
        ["report", "results/closed_loop.csv", "--out", "{tmp}/no/such"],
        ["export", "problems/wall", "--format", "npz", "--limit", "1", "--out", "{tmp}/no/such"],
    ],
    ids=["bench", "simulate-summary", "simulate-dump", "closed-loop", "report", "export"],
)
def test_a_missing_parent_folder_is_refused_and_nothing_is_created(argv, tmp_path, capsys):
    """qpbench creates an output file or folder, never the folders above it: a typo
    in a path is one line and exit 2, not a new tree of folders."""
    from qpbench.cli import main

    root = Path(__file__).resolve().parents[1]
    argv = [
        a.replace("{tmp}", str(tmp_path))
        if "{tmp}" in a
        else str(root / a)
        if a.startswith(("problems/", "results/"))
        else a
        for a in argv
    ]
    assert main(["-q", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1 and f"parent folder {tmp_path}/no" in err[0] and "does not exist" in err[0]
    ), err
    assert not (tmp_path / "no").exists()
