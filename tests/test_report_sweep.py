"""The report's sweep statistics against known values."""

from __future__ import annotations

import pandas as pd
import pytest

from qpbench.sweep.report import mcnemar_exact, paired_rows, rate_rows, wilson


def test_wilson_known_values():
    # Wilson (1927) / Newcombe (1998) table: 0/10, 5/10, 81/263
    assert wilson(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)
    assert wilson(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert wilson(81, 263) == pytest.approx((0.2553, 0.3662), abs=1e-4)
    lo, hi = wilson(0, 0)
    assert lo != lo and hi != hi  # nan


def test_mcnemar_exact_is_the_binomial_of_discordant_pairs():
    assert mcnemar_exact(0, 6) == pytest.approx(2 * 0.5**6)
    assert mcnemar_exact(3, 3) == pytest.approx(1.0)
    assert mcnemar_exact(0, 0) == 1.0
    assert mcnemar_exact(1, 9) == pytest.approx(2 * (1 + 10) / 2**10)


def _rows(verdicts: dict[str, list[str]]) -> pd.DataFrame:
    rows = []
    for backend, vs in verdicts.items():
        for i, v in enumerate(vs):
            rows.append({"instance": f"i{i:05d}", "backend": backend, "verdict": v, "status": "ok"})
    return pd.DataFrame(rows)


def test_rates_and_pairs_count_per_instance():
    df = _rows({"a": ["ok", "ok", "unsafe", "ok"], "b": ["unsafe", "ok", "unsafe", "diverged"]})
    rates = {r[0]: r for r in rate_rows(df)}
    assert rates["a"][1:4] == [4, 0, 3] and rates["a"][4].startswith("1 (25.0 %")
    assert rates["b"][3] == 1 and rates["b"][5].startswith("1 (25.0 %")
    [pair] = paired_rows(df)
    assert pair[:7] == ["a", "b", 4, 1, 2, 0, 1]
    assert pair[7] == pytest.approx(mcnemar_exact(2, 0))


def test_a_sweep_table_without_rows_reads_as_no_runs(tmp_path):
    """A perturbed run whose budget ran no instance leaves a header-only table: no runs, no crash
    (an empty mask of the noise floor's rows once selected columns instead of rows)."""
    from qpbench.sweep.report import split_sweep_paths, sweep_section
    from qpbench.sweep.runner import COLUMNS

    folder = tmp_path / "perturbed" / "wall"
    folder.mkdir(parents=True)
    (folder / "sweep.csv").write_text(",".join(COLUMNS) + "\n")
    _, tables = split_sweep_paths([tmp_path / "perturbed"])
    assert len(tables) == 1 and tables[0].rows == 0
    lines = sweep_section(tables, tmp_path, plots=False)
    assert lines[-1] == "`wall`: no run in this table.\n"


def test_the_shipped_sweeps_render_as_shipped(tmp_path, monkeypatch):
    """docs/sweeps.md's report command on the shipped tables, which were written before later
    columns were added to ``sweep.csv``: read as a sweep (not refused as a foreign CSV), with the
    same rates, pairs and worst runs as the shipped report."""
    from pathlib import Path

    from qpbench.cli import main

    repo = Path(__file__).resolve().parent.parent
    monkeypatch.chdir(repo)
    out = tmp_path / "sweeps"
    args = ["report", "results/sweeps/wall", "results/sweeps/narrow", "--out", str(out)]
    assert main([*args, "--no-plots"]) == 0
    shipped = (repo / "results" / "sweeps" / "report.md").read_text().splitlines()
    rendered = (out / "report.md").read_text().splitlines()

    def tables(lines):
        return [x for x in lines if x.startswith("| ") and "| OS |" not in x]

    assert len(tables(rendered)) > 40
    assert tables(rendered) == tables(shipped)
