"""Every command that writes files lists them once when it ends (``wrote: ...``), through the
one record in :mod:`qpbench.atomic`; ``scaling`` keeps its problem sets only when asked and
says in one line why it exits 1."""

from __future__ import annotations

import re
from pathlib import Path

from qpbench import atomic
from qpbench.cli import main

ROOT = Path(__file__).resolve().parents[1]
PLUGIN = str(Path(__file__).with_name("faulty_backends.py"))


def _wrote(err: str) -> str:
    lines = [line for line in err.splitlines() if "wrote: " in line]
    assert len(lines) == 1, err  # once, at the end
    assert err.rstrip().splitlines()[-1] == lines[0], err
    return lines[0].split("wrote: ", 1)[1]


def test_listing_names_files_and_counts_a_folder_of_many(tmp_path):
    files = [tmp_path / "a.csv", *(tmp_path / "logs" / f"{i}.parquet" for i in range(5))]
    text = atomic.listing([*files, Path("/elsewhere/b.md")], cwd=tmp_path)
    assert text == "wrote: a.csv, logs/ (5 files), /elsewhere/b.md"


def test_a_staging_folder_renamed_into_place_is_listed_under_its_final_name(tmp_path):
    staging, final = tmp_path / ".partial", tmp_path / "out"
    with atomic.recording() as written:
        atomic.write_text(staging / "report.md", "x")
        atomic.write_text(tmp_path / "top.txt", "y")
        atomic.rename(staging, final)
        assert written() == [final / "report.md", tmp_path / "top.txt"]
    atomic.write_text(tmp_path / "later.txt", "z")  # not recording: nothing kept
    assert written() == [final / "report.md", tmp_path / "top.txt"]
    with atomic.recording() as written:
        assert written() == []


def test_export_lists_its_files(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = ["export", str(ROOT / "problems" / "wall"), "--format", "npz", "--out", "ticks"]
    assert main([*args, "--problems", "wall_paper_001*", "--limit", "10"]) == 0
    assert _wrote(capsys.readouterr().err) == "ticks/ (10 files)"
    assert main([*args, "--problems", "wall_paper_0010[01]0", "--force"]) == 0
    assert (
        _wrote(capsys.readouterr().err)
        == "ticks/wall_paper_001000.npz, ticks/wall_paper_001010.npz"
    )


def test_simulate_and_bench_list_their_files(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    sim = ["simulate", "--scenario", "wall", "--backend", "daqp", "--duration", "0.02"]
    assert main([*sim, "--summary", "s.json", "--plot", "p.png"]) == 0
    assert _wrote(capsys.readouterr().err) == "s.json, p.png"
    maros = str(ROOT / "problems" / "maros_meszaros")
    assert main(["bench", maros, "--problems", "HS21", "--backends", "daqp", "--out", "b.csv"]) == 0
    assert _wrote(capsys.readouterr().err) == "b.csv"  # the set's reference cache is read only
    # an input error writes nothing, and so lists nothing
    assert main(["bench", maros, "--backends", "daqp", "--out", "b.csv"]) == 2
    assert "wrote" not in capsys.readouterr().err


def test_closed_loop_and_report_list_their_files(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    loop = ["closed-loop", "--scenarios", "free", "--backends", "daqp", "--duration", "0.02"]
    assert main([*loop, "--out", "loop"]) == 0
    listed = _wrote(capsys.readouterr().err).split(", ")
    logs = [
        f"loop/{d}/{p.name}"
        for d in ("logs", "figure_logs")
        for p in (tmp_path / "loop" / d).iterdir()
    ]
    # daqp's logs and the noise floor's (noop)
    assert len(logs) == 4 and sorted(listed) == sorted(["loop/closed_loop.csv", *logs])
    assert main(["report", "loop/closed_loop.csv", "--out", "rep"]) == 0
    err = capsys.readouterr().err
    listed = _wrote(err)
    assert "rep/report.md" in listed and re.search(r"rep/plots/", listed), listed
    # its phases, off a terminal as lines: the tables read, then the figures as they are drawn
    figures = len(list((tmp_path / "rep" / "plots").glob("*.png")))
    assert "report: 0 bench rows and 1 closed-loop runs read in" in err, err
    assert f"report: {figures} figures in" in err.splitlines()[-2], err


def _scaling(out: Path, *extra: str) -> list[str]:
    return [
        "scaling",
        "--sizes",
        "n4-p1-m1",
        "--out",
        str(out),
        "--duration",
        "0.02",
        "--every",
        "10",
        "--repeat",
        "1",
        "--no-report",
        *extra,
    ]


def test_scaling_keeps_its_problem_sets_only_when_asked(tmp_path, capsys):
    assert main(_scaling(tmp_path / "a", "--backends", "daqp")) == 0
    assert not (tmp_path / "a" / "sets").exists()
    assert (tmp_path / "a" / "bench" / "n4-p1-m1.csv").is_file()
    assert "scaling.csv" in _wrote(capsys.readouterr().err)
    assert main(_scaling(tmp_path / "b", "--backends", "daqp", "--keep-sets")) == 0
    assert (tmp_path / "b" / "sets" / "n4-p1-m1" / "problems.parquet").is_file()


def test_scaling_says_in_one_line_why_it_exits_1(tmp_path, capsys):
    args = _scaling(
        tmp_path / "s", "--backends", "daqp,faulty:raise", "--plugin", PLUGIN, "--strict"
    )
    assert main(args) == 1
    err = capsys.readouterr().err
    why = [line for line in err.splitlines() if "exit 1:" in line]
    assert len(why) == 1, err
    assert "faulty:raise 2 on n4-p1-m1" in why[0] and "daqp" not in why[0], why[0]


def test_bench_progress_off_a_terminal_is_a_line_with_the_time_left():
    import logging

    from qpbench.harness.bench import LogBar

    lines: list[str] = []
    handler = logging.Handler()
    handler.emit = lambda record: lines.append(record.getMessage())
    logger = logging.getLogger("qpbench.harness")
    logger.addHandler(handler)
    level, logger.level = logger.level, logging.INFO
    try:
        bar = LogBar(4, "x.csv", every_s=0.0)
        bar.update(1)
        bar.update(3)  # the last solve: no line (the bench's own summary follows)
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
    assert len(lines) == 1 and re.fullmatch(
        r"bench x\.csv: 1/4 solves in \d+ s, about \d+ s left", lines[0]
    ), lines
