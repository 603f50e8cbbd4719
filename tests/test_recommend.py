"""The recommendation (qpbench.report.recommend) on closed-loop tables built here, its place at the
top of report.md, and the ``--strict`` exit helper it feeds (qpbench.commands.options)."""

from __future__ import annotations

import argparse
import itertools
import math

import pandas as pd
import pytest
from test_report import every_column, parse_tables

from qpbench.cli import main
from qpbench.commands.options import strict_exit
from qpbench.harness.closed_loop import COLUMNS as LOOP_COLUMNS
from qpbench.report import recommend as rec
from qpbench.report.markdown_table import md_table


def run(scenario, backend, verdict="ok", realtime="yes", p99=50e-6, solver=20e-6, **extra):
    """One closed-loop row with the columns the recommendation reads (times in [s])."""
    row = {
        "scenario": scenario,
        "backend": backend,
        "formulation": "paper",
        "duration_s": 2.0,
        "simulated_s": 2.0,
        "status": "ok",
        "error": math.nan,
        "verdict": verdict,
        "verdict_reasons": math.nan,
        "realtime": realtime,
        "realtime_reason": math.nan,
        "realtime_solver": "yes",
        "rank_time_p99_s": p99,
        "solver_time_p99_s": solver,
        "min_body_distance": 0.02,
        "key_point_rule": "held",
        "log_file": f"logs/{scenario}__{backend}.parquet",
    }
    row.update(extra)
    return row


def test_ranked_by_p99_call_time_with_the_solvers_own_beside():
    table = pd.DataFrame(
        [
            run("wall", "slow", p99=300e-6, solver=100e-6),
            run("wall", "fast", p99=40e-6, solver=math.nan),
            run("wall", "mid", p99=90e-6, solver=30e-6),
            # a second run of 'fast' in wall (another formulation): its worse p99 counts
            run("wall", "fast", p99=120e-6, solver=math.nan, formulation="soft"),
        ]
    )
    answer = rec.recommend(table)
    assert answer.runs == 4 and [s.name for s in answer.scenarios] == ["wall"]
    assert answer.scenarios[0].backends == ["mid", "fast", "slow"]
    assert answer.overall.backends == ["mid", "fast", "slow"]
    fast = answer.overall.recommended[1]
    assert fast.call_p99_s == 120e-6 and math.isnan(fast.solver_p99_s)
    assert answer.overall.not_recommended == {}
    text = rec.render(answer)
    assert text.splitlines()[0] == "Recommendation"
    (table_md,) = parse_tables(rec.render(answer, markdown=True))
    assert table_md["header"] == [
        "rank", "backend", "controller p99 (us)", "95 % interval (us)", "solver p99 (us)",
        "perturbed ok", "ok bound",
    ]  # fmt: skip
    assert table_md["rows"] == [
        ["1", "mid", "90", "-", "30", "-", "-"],
        ["2", "fast", "120", "-", "-", "-", "-"],
        ["3", "slow", "300", "-", "100", "-", "-"],
    ]


def test_ok_in_one_scenario_but_not_another_is_not_recommended_overall():
    reason = "link 2 3.0 mm inside disk 'blob' at 1.20 s; d_min 4.1 mm < d_safe - 0.5 mm = 9.5 mm"
    table = pd.DataFrame(
        [
            run("wall", "a", p99=30e-6),
            run("wall", "b", p99=60e-6),
            run("narrow", "a", verdict="unsafe", verdict_reasons=reason, p99=35e-6),
            run("narrow", "b", p99=70e-6),
        ]
    )
    answer = rec.recommend(table)
    wall, narrow = answer.scenarios
    assert (wall.name, wall.backends) == ("wall", ["a", "b"])
    assert (narrow.name, narrow.backends) == ("narrow", ["b"])
    assert narrow.not_recommended == {
        "a": ("unsafe in narrow: link 2 3.0 mm inside disk 'blob' at 1.20 s",)
    }
    assert answer.overall.name == "all scenarios (wall, narrow)"
    assert answer.overall.backends == ["b"] and answer.overall.recommended[0].call_p99_s == 70e-6
    assert answer.overall.not_recommended == narrow.not_recommended
    text = rec.render(answer)
    assert "- wall: a 30 us (solver 20), b 60 us (solver 20)" in text
    assert "- narrow: b 70 us (solver 20)" in text
    assert [c.strip() for c in text.rstrip().splitlines()[-1].split("|")[1:3]] == [
        "a",
        "unsafe in narrow: link 2 3.0 mm inside disk 'blob' at 1.20 s",
    ]


def test_reasons_in_a_few_words():
    table = pd.DataFrame(
        [
            run("wall", "ok"),
            run(
                "wall",
                "cut",
                verdict="incomplete",
                status="budget",
                simulated_s=1.5,
                verdict_reasons="stopped by its wall-time budget at 1.5 s of 2 s",
            ),
            run(
                "wall",
                "crash",
                verdict="failed",
                status="crashed",
                simulated_s=math.nan,
                error="worker process killed by SIGSEGV",
            ),
            run("wall", "bad", verdict="failed", verdict_reasons="3 ticks whose solve raised"),
            run(
                "wall",
                "deep",
                verdict="unsafe",
                verdict_reasons="d_min -29.1 mm (A4/lower at 0.049 s; 47 ticks); joint speed",
            ),
            run(
                "wall",
                "late",
                realtime="no",
                realtime_reason="p99 1.8 ms > 1 ms; 12 % of ticks over dt",
            ),
            run(
                "wall",
                "both",
                verdict="limits",
                realtime="no",
                verdict_reasons="joint speed limit broken",
                realtime_reason="p99 2 ms > 1 ms",
            ),
            run("wall", "absent", status="skipped", verdict=math.nan, error="not installed"),
            run("narrow", "ok"),
            run("narrow", "everywhere", verdict="diverged", verdict_reasons="tracking error 9 mm"),
            run("wall", "everywhere", verdict="unsafe", verdict_reasons="link 4 inside"),
            run("free", "everywhere", verdict="limits", verdict_reasons="joint 2 limit"),
            run("free", "ok"),
        ]
    )
    why = rec.recommend(table).overall.not_recommended
    assert why["cut"] == ("incomplete in wall (stopped at 1.5 s)",)
    assert why["crash"] == ("failed in wall: run crashed (worker process killed by SIGSEGV)",)
    assert why["bad"] == ("failed in wall: 3 ticks whose solve raised",)
    assert why["deep"] == ("unsafe in wall: d_min -29.1 mm (A4/lower at 0.049 s; 47 ticks)",)
    assert why["late"] == ("not real time in wall: p99 1.8 ms > 1 ms; 12 % of ticks over dt",)
    assert why["both"] == (
        "limits in wall: joint speed limit broken",
        "not real time in wall: p99 2 ms > 1 ms",
    )
    assert why["absent"] == ("skipped in wall: not installed",)
    assert rec.recommend(table).overall.backends == ["ok"]
    assert len(why["everywhere"]) == 3
    shown = rec.render(rec.recommend(table))
    assert (
        "diverged in narrow: tracking error 9 mm; unsafe in wall: link 4 inside (and 1 more)"
        in shown
    )


def test_ok_where_it_ran_but_missing_from_a_scenario_is_not_recommended_overall():
    table = pd.DataFrame([run("wall", "a"), run("wall", "b"), run("narrow", "a")])
    answer = rec.recommend(table)
    assert answer.scenarios[0].backends == ["a", "b"]
    assert answer.overall.backends == ["a"]
    assert answer.overall.not_recommended == {"b": ("not run in narrow",)}


def test_a_table_without_real_time_recommends_nothing_and_says_why():
    table = pd.DataFrame([run("wall", "a"), run("wall", "b", verdict="unsafe")]).drop(
        columns=["realtime", "realtime_reason", "solver_time_p99_s"]
    )
    answer = rec.recommend(table)
    assert answer.overall.backends == []
    assert answer.overall.not_recommended == {
        "a": ("real time not judged in wall",),
        "b": ("unsafe in wall",),
    }
    assert "No backend was ok and real time in every run of all scenarios (wall)." in rec.render(
        answer
    )
    assert rec.shortfalls(table) == ["1 of 2 runs not ok (unsafe 1)"]


def test_empty_table():
    answer = rec.recommend(pd.DataFrame())
    assert answer.runs == 0 and "nothing to recommend" in rec.render(answer)


def test_text_and_markdown_are_the_same_lines_but_the_heading():
    table = pd.DataFrame(
        [run("wall", "a"), run("narrow", "a"), run("wall", "b", realtime="no"), run("narrow", "b")]
    )
    answer = rec.recommend(table)
    text, md = rec.render(answer), rec.render(answer, markdown=True)
    assert md.startswith("## Recommendation\n")
    assert [x for x in md.splitlines()[1:] if x] == [x for x in text.splitlines()[1:] if x]
    # padded tables: every line of a table is as wide as its header
    tables = itertools.groupby(text.splitlines(), key=lambda x: x.startswith("|"))
    widths = [{len(x) for x in lines} for is_table, lines in tables if is_table]
    assert len(widths) == 2 and all(len(w) == 1 for w in widths)


def test_md_table_pad_changes_spacing_only():
    rows = [["daqp", 1.5, "x"], ["qpoases-long-name", 12345.678, "yy"]]
    plain, padded = (
        md_table(["backend", "t", "c"], rows),
        md_table(["backend", "t", "c"], rows, True),
    )
    assert plain == "| backend | t | c |\n|:-------|---:|---:|\n| daqp | 1.5 | x |\n" + (
        "| qpoases-long-name | 1.235e+04 | yy |\n"
    )
    assert [[c.strip() for c in x.split("|")] for x in padded.splitlines()] == [
        [c.strip() for c in x.split("|")] for x in plain.splitlines()
    ][:1] + [
        ["", ":" + "-" * 18, "-" * 10 + ":", "----:", ""],
    ] + [[c.strip() for c in x.split("|")] for x in plain.splitlines()][2:]
    assert len({len(x) for x in padded.splitlines()}) == 1


def test_shortfalls_count_verdicts_real_time_and_failed_solves():
    table = pd.DataFrame(
        [
            run("wall", "a"),
            run("wall", "b", verdict="unsafe"),
            run("wall", "c", verdict="incomplete"),
            run("wall", "d", realtime="no"),
            run("wall", "e", verdict="unsafe", realtime="no"),
            run("wall", "f", status="skipped", verdict=math.nan),
        ]
    )
    assert rec.shortfalls(table) == [
        "4 of 6 runs not ok (unsafe 2, incomplete 1, no verdict 1)",
        "2 of 6 runs not real time",
    ]
    assert rec.shortfalls(failed_solves=3) == ["3 failed solves"]
    assert rec.shortfalls(pd.DataFrame([run("wall", "a")])) == []


def test_strict_exit(capsys):
    def args(strict):
        return argparse.Namespace(strict=strict, command="closed-loop")

    bad = pd.DataFrame([run("wall", "a"), run("wall", "b", realtime="no")])
    good = pd.DataFrame([run("wall", "a")])
    assert strict_exit(args(False), runs=bad, failed_solves=2) == 0
    assert capsys.readouterr().err == ""
    assert strict_exit(args(True), runs=good) == 0
    assert strict_exit(args(True)) == 0
    assert capsys.readouterr().err == ""
    assert strict_exit(args(True), runs=bad, failed_solves=2) == 1
    assert capsys.readouterr().err == (
        "qpbench closed-loop: --strict: 2 failed solves; 1 of 2 runs not real time\n"
    )


@pytest.fixture
def closed_loop_csv(tmp_path):
    table = pd.DataFrame(
        [
            run("wall", "daqp", p99=45e-6, solver=12e-6),
            run("wall", "pinv", verdict="unsafe", verdict_reasons="link 4 (end effector) inside"),
            run("narrow", "daqp", p99=50e-6, solver=13e-6),
            run("narrow", "pinv", realtime="no", realtime_reason="p99 1.8 ms > 1 ms"),
        ]
    )
    path = tmp_path / "closed_loop.csv"
    every_column(table, LOOP_COLUMNS).to_csv(path, index=False)
    return path, table


def test_the_report_opens_with_the_answer(closed_loop_csv, tmp_path):
    path, table = closed_loop_csv
    assert main(["-q", "report", str(path), "--out", str(tmp_path / "r"), "--no-plots"]) == 0
    md = (tmp_path / "r" / "report.md").read_text()
    answer = rec.render(rec.recommend(table), markdown=True)
    assert md.startswith("# qpbench report\n\n" + answer)
    how = md.index("## How to read this\n")
    assert how == len("# qpbench report\n\n" + answer) + 1
    lines = md[how:].split("\n\n")[1].splitlines()
    assert lines == [f"- {line}" for line in rec.HOW_TO_READ] and len(lines) == 5
    assert how < md.index("## Machine") < md.index("## Closed loop")
    tables = parse_tables(md)
    assert tables[0]["headings"] == {1: "qpbench report", 2: "Recommendation"}
    assert [r[1] for r in tables[0]["rows"]] == ["daqp"]
    assert tables[1]["rows"] == [
        [
            "pinv",
            "unsafe in wall: link 4 (end effector) inside; not real time in narrow: "
            "p99 1.8 ms > 1 ms",
        ],
    ]


def timed(scenario, backend, p99, lo, hi, **extra):
    """A run whose p99 call time [s] has the interval ``[lo, hi]``."""
    return run(scenario, backend, p99=p99, rank_time_p99_lo_s=lo, rank_time_p99_hi_s=hi, **extra)


def test_overlapping_intervals_share_a_rank():
    table = pd.DataFrame(
        [
            timed("wall", "a", 10e-6, 8e-6, 12e-6),
            timed("wall", "b", 11e-6, 9e-6, 14e-6),  # overlaps a
            timed("wall", "c", 30e-6, 28e-6, 33e-6),  # apart
            timed("wall", "d", 40e-6, 34e-6, 45e-6),  # overlaps e only
            timed("wall", "e", 44e-6, 42e-6, 60e-6),  # overlaps d and f: d, e, f chain
            timed("wall", "f", 58e-6, 55e-6, 70e-6),
            timed("wall", "g", 90e-6, 90e-6, 95e-6),
        ]
    )
    picks = rec.recommend(table).overall.recommended
    assert [(p.backend, p.rank_text) for p in picks] == [
        ("a", "1="), ("b", "1="), ("c", "3"), ("d", "4="), ("e", "4="), ("f", "4="), ("g", "7"),
    ]  # fmt: skip
    (md,) = parse_tables(rec.render(rec.recommend(table), markdown=True))
    assert [r[0] for r in md["rows"]] == ["1=", "1=", "3", "4=", "4=", "4=", "7"]
    assert md["rows"][1][3] == "9-14"


def test_a_backend_interval_is_that_of_its_largest_p99():
    """The largest of several p99s, each in its interval, lies in [largest low, largest high]."""
    table = pd.DataFrame(
        [
            timed("wall", "a", 10e-6, 5e-6, 30e-6),
            timed("narrow", "a", 20e-6, 18e-6, 22e-6),
            timed("wall", "b", 25e-6, 24e-6, 26e-6),
            timed("narrow", "b", 23e-6, 23e-6, 25e-6),
        ]
    )
    a, b = rec.recommend(table).overall.recommended
    assert (a.call_p99_s, a.call_p99_lo_s, a.call_p99_hi_s) == (20e-6, 18e-6, 30e-6)
    assert (b.call_p99_s, b.call_p99_lo_s, b.call_p99_hi_s) == (25e-6, 24e-6, 26e-6)
    assert a.rank == b.rank == 1 and a.tied and b.tied


def wilson_closed_form(k, n, z=1.959963984540054):
    """The Wilson score interval's lower end, from its formula."""
    p = k / n
    centre = p + z * z / (2 * n)
    spread = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (centre - spread) / (1 + z * z / n)


@pytest.mark.parametrize("k, n", [(19, 20), (73, 73), (140, 142), (0, 5), (497, 500)])
def test_the_wilson_bound_is_the_formula(k, n):
    from qpbench.report.tables import wilson

    assert wilson(k, n)[0] == pytest.approx(wilson_closed_form(k, n), abs=1e-12)


def test_least_runs_is_the_first_count_whose_bound_reaches():
    assert [rec.least_runs(0.95, f) for f in (0, 1, 2)] == [73, 110, 142]
    assert rec.least_runs(0.99) == 381
    for bound, f in ((0.95, 0), (0.95, 2), (0.99, 0), (0.9, 1)):
        n = rec.least_runs(bound, f)
        assert wilson_closed_form(n - f, n) >= bound > wilson_closed_form(n - 1 - f, n - 1)
    with pytest.raises(Exception, match="between 0 and 1"):
        rec.check_bound(1.0)


def sweep_rows(scenario, backend, ok, not_ok=0, verdict="diverged"):
    """Perturbed runs of ``backend`` around ``scenario``: ``ok`` ok, ``not_ok`` with ``verdict``."""
    rows = []
    for i in range(ok + not_ok):
        bad = i >= ok
        rows.append(
            {
                "instance": f"i{i:05d}",
                "backend": backend,
                "instance_file": f"instances/i{i:05d}.toml",
                "sample": i,
                "base_scenario": scenario,
                "status": "ok",
                "error": math.nan,
                "verdict": verdict if bad else "ok",
                "verdict_reasons": "force error 9 N > 2 N after 2 s" if bad else math.nan,
                "min_obstacle_distance": 0.0102 - (0.0001 if i == 3 else 0.0),
                "d_safe": 0.01,
                "tracking_max_after_2s": 1e-7,
                "folder": f"out/perturbed/{scenario}",
                "seed": 7,
            }
        )
    return rows


def test_nineteen_of_twenty_ok_perturbed_runs_are_not_enough_at_095():
    table = pd.DataFrame([run("wall", "a", p99=20e-6), run("wall", "b", p99=30e-6)])
    sweeps = pd.DataFrame(sweep_rows("wall", "a", 19, 1) + sweep_rows("wall", "b", 80))
    answer = rec.recommend(table, sweeps, 0.95)
    assert answer.swept == ("wall",)
    assert answer.overall.backends == ["b"]  # 80 of 80: bound 0.954
    (short,) = answer.overall.short
    e = short.weakest
    assert (short.backend, e.runs, e.ok) == ("a", 20, 19)
    assert e.bound == pytest.approx(wilson_closed_form(19, 20)) and e.bound < 0.95
    # the worst perturbed run: the not-ok one, with the command that re-runs it
    assert e.worst["instance"] == "i00019" and e.worst["verdict"] == "diverged"
    text = rec.render(answer)
    assert "Not enough evidence" in text
    assert (
        "qpbench simulate --scenario out/perturbed/wall/instances/i00019.toml --backend a" in text
    )
    assert "wall i00003 (seed 7, sample 3)" in text  # b's worst: the closest to d_safe
    # with as many runs as the threshold asks and still below it: not recommended, and why
    sweeps = pd.DataFrame(sweep_rows("wall", "a", 130, 12) + sweep_rows("wall", "b", 80))
    answer = rec.recommend(table, sweeps, 0.95)
    assert answer.overall.not_recommended["a"] == (
        f"perturbed wall: 130 of 142 ok, bound {wilson_closed_form(130, 142):.3f} < 0.95",
    )
    # a stricter threshold: 80 all ok are too few for 0.99
    assert rec.recommend(table, sweeps, 0.99).overall.backends == []


def test_a_swept_scenario_without_runs_of_a_backend_gives_no_evidence():
    table = pd.DataFrame([run("wall", "a"), run("narrow", "a")])
    sweeps = pd.DataFrame(sweep_rows("wall", "a", 80))
    sweeps.attrs["swept"] = ["wall", "narrow"]
    answer = rec.recommend(table, sweeps)
    assert answer.overall.backends == [] and [p.backend for p in answer.overall.short] == ["a"]
    sentence = rec.no_answer(answer)
    assert sentence.startswith("No recommendation: a passed every run") and "\n" not in sentence
    assert "a in narrow: 0 of 0 ok" in sentence and "--sweep-budget" in sentence
    # without perturbed runs the answer rests on the nominal runs and says so
    assert rec.recommend(table).overall.backends == ["a"]
    assert "no perturbed runs" in rec.render(rec.recommend(table))


def test_no_answer_is_one_sentence_saying_why():
    late = pd.DataFrame(
        [
            run("wall", "a", realtime="no", realtime_reason="3 of 1000 ticks over dt"),
            run("wall", "b", verdict="unsafe"),
        ]
    )
    sentence = rec.no_answer(rec.recommend(late))
    assert sentence.startswith("No recommendation from this machine: a had verdict ok")
    assert "(a in wall: 3 of 1000 ticks over dt)" in sentence and sentence.count(". ") == 0
    unsafe = pd.DataFrame([run("wall", "b", verdict="unsafe")])
    assert rec.no_answer(rec.recommend(unsafe)) == (
        "No backend was ok and real time in every run of all scenarios (wall)."
    )


def test_each_arm_family_is_answered_alone_and_overall_is_what_both_recommend():
    """Planar and spatial runs: each family ranked on its own scenarios and perturbed runs; a
    backend ok in one family only is recommended there and not overall; the ranking can turn
    round between families; a table without the family column has no families."""
    planar, spatial = dict(family="planar", joints=4), dict(family="spatial", joints=7)
    table = pd.DataFrame(
        [
            run("wall", "a", p99=10e-6, **planar),
            run("wall", "b", p99=30e-6, **planar),
            run("wall", "c", p99=40e-6, **planar),
            run("panda_table", "a", p99=90e-6, **spatial),
            run("panda_table", "b", p99=50e-6, **spatial),
            run(
                "panda_table", "c", verdict="unsafe", verdict_reasons="body 2 mm inside", **spatial
            ),
        ]
    )
    sweeps = pd.DataFrame(
        sweep_rows("wall", "a", 80) + sweep_rows("wall", "b", 80) + sweep_rows("wall", "c", 80)
    )
    answer = rec.recommend(table, sweeps, 0.95)
    fam = {f.name: f for f in answer.families}
    assert list(fam) == ["planar (n = 4) (wall)", "spatial (n = 7) (panda_table)"]
    assert fam["planar (n = 4) (wall)"].backends == ["a", "b", "c"]
    assert fam["spatial (n = 7) (panda_table)"].backends == ["b", "a"]  # turned round
    assert answer.overall.backends == ["b", "a"]  # on its slowest family: b 50 us, a 90 us
    assert "c" in answer.overall.not_recommended
    text = rec.render(answer, markdown=True)
    (table_md,) = [t for t in parse_tables(text) if "planar (n = 4)" in t["header"]]
    assert table_md["header"] == ["backend", "planar (n = 4)", "spatial (n = 7)"]
    rows = {r[0]: r[1:] for r in table_md["rows"]}
    assert rows["a"] == ["1: 10", "2: 90"] and rows["b"] == ["2: 30", "1: 50"]
    assert rows["c"][0] == "3: 40" and rows["c"][1].startswith("unsafe in panda_table")
    assert rec.recommend(table.drop(columns=["family", "joints"]), sweeps).families == ()
