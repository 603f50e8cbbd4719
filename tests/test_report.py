"""Tests of qpbench.report: report.md's numbers against independent recomputations.

The bench rows here are synthetic (random times, residuals, failures, missing
duals) so every branch of qpbenchmark's rules is exercised; the reference for
the ratios is qpbenchmark's own ``Results.get_shgeom_for_metric_and_settings``.
End-to-end runs on real problem sets are in tests/test_cli.py.
"""

from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from qpbench.cli import main
from qpbench.harness.closed_loop import COLUMNS as LOOP_COLUMNS
from qpbench.harness.results import bench_columns
from qpbench.profiles import get_profile
from qpbench.report import tables

BACKENDS = ("alpha", "beta", "gamma")
SCENARIOS = ("wall", "narrow", None)  # None: a Maros-Meszaros-like problem without scenario


# ----------------------------------------------------------------- helpers


def parse_tables(md: str) -> list[dict]:
    """Every Markdown table with its headings (h2..h5) and the caption line above it."""
    out = []
    headings: dict[int, str] = {}
    lines = md.splitlines()
    i = 0
    caption = None
    while i < len(lines):
        line = lines[i]
        m = re.match(r"^(#{1,6}) (.*)$", line)
        if m:
            level = len(m.group(1))
            headings = {k: v for k, v in headings.items() if k < level}
            headings[level] = m.group(2).strip()
            caption = None
        elif (
            line.startswith("|")
            and i + 1 < len(lines)
            and re.match(r"^\|[:\-| ]+\|$", lines[i + 1])
        ):
            header = [c.strip() for c in line.strip("|").split("|")]
            rows = []
            i += 2
            while i < len(lines) and lines[i].startswith("|"):
                rows.append([c.strip() for c in lines[i].strip("|").split("|")])
                i += 1
            out.append(
                {"headings": dict(headings), "caption": caption, "header": header, "rows": rows}
            )
            continue
        elif line.strip():
            caption = line.strip()
        i += 1
    return out


def cell_value(text: str) -> float:
    if text == "-":
        return math.nan
    return float(text)


def assert_close(shown: str, expected: float, what: str) -> None:
    value = cell_value(shown)
    if expected is None or (isinstance(expected, float) and math.isnan(expected)):
        assert math.isnan(value), f"{what}: shown {shown}, expected missing"
    elif math.isinf(expected):
        assert math.isinf(value), f"{what}: shown {shown}, expected inf"
    else:
        # 4 significant digits in the report
        assert value == pytest.approx(expected, rel=6e-4, abs=1e-300), (
            f"{what}: shown {shown}, expected {expected}"
        )


def every_column(df: pd.DataFrame, written: tuple[str, ...]) -> pd.DataFrame:
    """``df`` with every column the program writes (those it does not set: empty)."""
    return df.reindex(columns=[*df.columns, *(c for c in written if c not in df.columns)])


def synthetic_bench(rng: np.random.Generator, n_ticks: int = 30) -> pd.DataFrame:
    rows = []
    tol = get_profile("default").tolerance
    for scenario in SCENARIOS:
        for k in range(n_ticks if scenario else 6):
            name = f"{scenario}-{k:04d}" if scenario else f"MM{k}"
            for j, backend in enumerate(BACKENDS):
                found = bool(rng.random() > 0.12 * j)
                infeasible = scenario is not None and k < 3
                says_infeasible = infeasible and j == 1  # beta detects it
                found = found and not says_infeasible
                primal = float(10 ** rng.uniform(-12, -4)) if found else math.nan
                dual = float(10 ** rng.uniform(-12, -4)) if found else math.nan
                if backend == "gamma" and scenario == "narrow" and found:
                    dual = math.inf  # a backend without duals
                gap = float(10 ** rng.uniform(-12, -4)) if found else math.nan
                opt_gap = (
                    float(rng.choice([-1, 1]) * 10 ** rng.uniform(-11, -3)) if found else math.nan
                )
                success = found and primal < tol.primal and dual < tol.dual and gap < tol.gap
                wall = float(10 ** rng.uniform(-5.5, -3.5) * (1 + j))
                rows.append(
                    dict(
                        problem=name,
                        scenario=scenario,
                        tick=k * 10 if scenario else None,
                        t=k * 0.01 if scenario else None,
                        backend=backend,
                        profile="default",
                        mode="sequential",
                        status="optimal"
                        if found
                        else "primal_infeasible"
                        if says_infeasible
                        else "max_iter",
                        found=found,
                        success=success,
                        objective=1.0,
                        reference_objective=1.0,
                        reference_status="primal_infeasible" if infeasible else "optimal",
                        optimality_gap=opt_gap,
                        primal_residual=primal,
                        dual_residual=dual,
                        duality_gap=gap,
                        wall_time_min_s=wall * 0.9,
                        wall_time_median_s=wall,
                        solver_time_s=wall * 0.8 if j != 2 else None,
                        iterations=10,
                        isolated=False,
                        error="",
                    )
                )
    return every_column(pd.DataFrame(rows), bench_columns())


def synthetic_closed_loop(folder: Path, rng: np.random.Generator) -> Path:
    (folder / "logs").mkdir(parents=True)
    rows = []
    t = np.arange(0, 3.0, 0.001)
    for scenario in ("wall", "narrow"):
        for backend in ("qpsolvers:daqp", "pinv", "rnn"):
            log_name = f"logs/{scenario}__{backend.replace(':', '-')}.parquet"
            # the tick log's own columns (qpbench.sim.loop)
            df = pd.DataFrame(
                {
                    "t": t,
                    "tracking_error": 1e-3 * np.exp(-t) * rng.standard_normal(len(t)),
                    "force": 20 + np.exp(-t),
                    "force_error": np.exp(-t),
                    "v_0": np.sin(t),
                    "v_1": np.cos(t),
                    "v_2": 0.1 * t,
                    "v_3": -0.1 * t,
                    "d_A2_wall": 0.01 + 0.1 * np.exp(-t),
                    "d_min": 0.01 + 0.1 * np.exp(-t),
                    "v_sq": np.sin(t) ** 2 + np.cos(t) ** 2,
                    "fallback": t < 0.1,
                    "zero_velocity": False,
                    "solve_time_s": 10 ** rng.uniform(-5, -4, len(t)),
                    "kp_hat": 5000.0,
                }
            )
            df.to_parquet(folder / log_name)
            rows.append(
                dict(
                    scenario=scenario,
                    backend=backend,
                    formulation="paper",
                    duration_s=3.0,
                    status="ok",
                    error="",
                    ticks=len(t),
                    tracking_rms_after_2s=rng.uniform(1e-8, 1e-6),
                    tracking_max_after_2s=rng.uniform(1e-6, 1e-5),
                    force_error_rms_after_2s=rng.uniform(0, 1e-3),
                    force_error_max_after_2s=rng.uniform(1e-3, 1e-2),
                    min_obstacle_distance=rng.uniform(0.0099, 0.0101),
                    min_body_distance=rng.uniform(-0.03, 0.0101),
                    min_body_distance_link=int(rng.integers(1, 5)),
                    min_body_distance_obstacle=scenario,
                    min_body_distance_t=rng.uniform(0, 3),
                    key_point_rule="broken" if backend == "rnn" else "held",
                    joint_limit_violations=0,
                    infeasible_ticks=int(rng.integers(0, 200)),
                    fallback_ticks=int(rng.integers(0, 200)),
                    v2_integral=rng.uniform(0.5, 2),
                    solve_time_median_s=rng.uniform(1e-5, 2e-5),
                    solve_time_p99_s=rng.uniform(3e-5, 1e-4),
                    solve_time_max_s=rng.uniform(1e-4, 1e-3),
                    real_time_factor=rng.uniform(5, 80),
                    realtime="no" if backend == "rnn" else "yes",
                    realtime_solver="unknown" if backend == "rnn" else "yes",
                    over_dt_share=rng.uniform(0, 1e-3),
                    solver_time_p99_s=np.nan if backend == "rnn" else rng.uniform(1e-5, 5e-5),
                    log_file=log_name,
                    kp_hat_final=5000.0,
                    simulated_s=3.0,
                    verdict="unsafe" if backend == "rnn" else "ok",
                    verdict_reasons=f"d_min 3.5 mm < d_safe - 0.5 mm = 9.5 mm (A2/{scenario} at 2.510 s)"
                    if backend == "rnn"
                    else "",
                )
            )
    rows.append(
        dict(
            scenario="wall",
            backend="broken",
            formulation="paper",
            duration_s=3.0,
            status="error",
            error="RuntimeError: boom | bad",
            log_file="",
            verdict="incomplete",
            verdict_reasons="run raised: RuntimeError: boom | bad",
            realtime="no",
            realtime_solver="unknown",
        )
    )
    path = folder / "closed_loop.csv"
    every_column(pd.DataFrame(rows), LOOP_COLUMNS).to_csv(path, index=False)
    return path


def qpbenchmark_ratios(df: pd.DataFrame, metric_column: str, not_found: float, floor) -> dict:
    """Ratios to the best by qpbenchmark's own code (Results bypassing its TestSet)."""
    from qpbenchmark.results import Results

    res = Results.__new__(Results)
    qdf = pd.DataFrame(
        {
            "solver": df["backend"].to_numpy(),
            "settings": df["profile"].to_numpy(),
            # qpbenchmark's "found"; for runtime a right infeasibility report also counts as answered
            "found": df["found"].to_numpy(bool)
            | (
                (metric_column == "wall_time_min_s")
                & (df["status"] == df["reference_status"]).to_numpy()
                & (df["reference_status"] == "primal_infeasible").to_numpy()
            ),
            "metric": np.abs(pd.to_numeric(df[metric_column]).to_numpy(float)),
        }
    )
    res.df = qdf
    return res.get_shgeom_for_metric_and_settings(
        "metric", "default", shift=10.0, not_found_value=not_found, floor=floor
    )


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory):
    rng = np.random.default_rng(7)
    folder = tmp_path_factory.mktemp("rep")
    bench = synthetic_bench(rng)
    bench.to_csv(folder / "bench.csv", index=False)
    cl = synthetic_closed_loop(folder / "cl", rng)
    out = folder / "out"
    code = main(["report", str(folder / "bench.csv"), str(cl), "--out", str(out)])
    assert code == 0
    return folder, out, bench, pd.read_csv(cl)


# ----------------------------------------------------------------- tests


def test_report_writes_markdown_and_plots(report_dir):
    _, out, _, _ = report_dir
    md = (out / "report.md").read_text()
    assert "# qpbench report" in md
    for png in re.findall(r"\]\((plots/[^)]+\.png)\)", md):
        assert (out / png).exists() and (out / png).stat().st_size > 1000, png
    assert (out / "plots" / "perf_profile_default_sequential.png").exists()
    assert (out / "plots" / "closed_loop_wall_paper.png").exists()
    assert (out / "plots" / "per_tick_default_sequential_wall.png").exists()
    # the error row's message is shown, with its pipe escaped
    assert "RuntimeError: boom \\| bad" in md


def test_ratio_table_equals_qpbenchmark(report_dir):
    _, out, bench, _ = report_dir
    md = (out / "report.md").read_text()
    tol = get_profile("default").tolerance
    table = next(t for t in parse_tables(md) if t["caption"].startswith("Success rate and shifted"))
    assert table["header"][:3] == ["backend", "problems", "success (%)"]
    shown = {r[0]: r for r in table["rows"]}
    assert set(shown) == set(BACKENDS)
    columns = {
        "runtime": ("wall_time_min_s", tol.runtime, None),
        "primal residual": ("primal_residual", tol.primal, tol.primal),
        "dual residual": ("dual_residual", tol.dual, tol.dual),
        "duality gap": ("duality_gap", tol.gap, tol.gap),
        "optimality gap": ("optimality_gap", tol.gap, tol.gap),
    }
    for name, (col, not_found, floor) in columns.items():
        expected = qpbenchmark_ratios(bench, col, not_found, floor)
        j = table["header"].index(name)
        for b in BACKENDS:
            if name == "dual residual" and b == "gamma":
                assert shown[b][j] == "inf", "an infinite residual must not look finite"
            assert_close(shown[b][j], expected[b], f"{name} ratio of {b}")
    feasible = bench[bench["reference_status"] == "optimal"]
    assert len(feasible) < len(bench)
    expected = qpbenchmark_ratios(feasible, "wall_time_min_s", tol.runtime, None)
    j = table["header"].index("runtime (feasible)")
    for b in BACKENDS:
        assert_close(shown[b][j], expected[b], f"feasible runtime ratio of {b}")
    for b in BACKENDS:
        rows = bench[bench["backend"] == b]
        assert int(shown[b][1]) == len(rows)
        assert_close(shown[b][2], 100.0 * rows["success"].mean(), f"success of {b}")


def test_absolute_table_recomputed(report_dir):
    from qpbenchmark.shgeom import shgeom

    _, out, bench, _ = report_dir
    md = (out / "report.md").read_text()
    tol = get_profile("default").tolerance
    table = next(
        t for t in parse_tables(md) if t["caption"].startswith("Shifted geometric means, absolute")
    )
    shown = {r[0]: r for r in table["rows"]}
    for b in BACKENDS:
        rows = bench[bench["backend"] == b]
        found = rows["found"].to_numpy(bool)
        right = (
            (rows["status"] == "primal_infeasible")
            & (rows["reference_status"] == "primal_infeasible")
        ).to_numpy()
        if b == "beta":
            assert right.any()  # the case is exercised
        t = np.where(found | right, rows["wall_time_min_s"], tol.runtime)
        assert_close(shown[b][1], shgeom(t, 10.0) * 1e6, f"runtime of {b}")
        ok = (rows["reference_status"] == "optimal").to_numpy()
        assert_close(shown[b][2], shgeom(t[ok], 10.0) * 1e6, f"feasible runtime of {b}")
        p = np.maximum(np.where(found, rows["primal_residual"], tol.primal), tol.primal)
        assert_close(shown[b][3], shgeom(p, 10.0), f"primal of {b}")
        g = np.maximum(np.where(found, np.abs(rows["optimality_gap"]), tol.gap), tol.gap)
        assert_close(shown[b][6], shgeom(g, 10.0), f"optimality gap of {b}")
        overhead = (rows["wall_time_min_s"] - rows["solver_time_s"]).dropna()
        assert_close(
            shown[b][7], overhead.median() * 1e6 if len(overhead) else math.nan, f"overhead of {b}"
        )


def test_scenario_tables_recomputed(report_dir):
    _, out, bench, _ = report_dir
    md = (out / "report.md").read_text()
    found_tables = {
        t["headings"].get(4): t
        for t in parse_tables(md)
        if t["headings"].get(4, "").startswith("Scenario")
        and t["caption"].startswith("Per backend, runtime")
    }
    assert set(found_tables) == {
        f"Scenario {s} (default, sequential)" for s in ("wall", "narrow", "-")
    }
    for scenario in SCENARIOS:
        label = scenario or "-"
        table = found_tables[f"Scenario {label} (default, sequential)"]
        shown = {r[0]: r for r in table["rows"]}
        sel = bench["scenario"].isna() if scenario is None else bench["scenario"] == scenario
        for b in BACKENDS:
            rows = bench[sel & (bench["backend"] == b)]
            t = rows["wall_time_min_s"].to_numpy(float)
            assert int(shown[b][1]) == len(rows)
            assert_close(shown[b][2], 100 * rows["success"].mean(), "success")
            assert_close(shown[b][4], np.percentile(t, 50) * 1e6, "p50")
            assert_close(shown[b][5], np.percentile(t, 99) * 1e6, "p99")
            assert_close(shown[b][6], t.max() * 1e6, "max")
            gaps = np.abs(rows.loc[rows["found"], "optimality_gap"].dropna())
            assert_close(shown[b][7], gaps.max() if len(gaps) else math.nan, "gap max")


def test_closed_loop_tables_equal_csv(report_dir):
    from qpbench.report.markdown import CLOSED_LOOP_TABLE

    _, out, _, cl = report_dir
    md = (out / "report.md").read_text()
    tabs = [
        t
        for t in parse_tables(md)
        if t["caption"] and t["caption"].startswith("Closed-loop metrics")
    ]
    assert len(tabs) == 2
    for t in tabs:
        scenario = re.match(r"Scenario (\S+) ", t["headings"][3]).group(1)
        for r in t["rows"]:
            csv_row = cl[(cl["scenario"] == scenario) & (cl["backend"] == r[0])].iloc[0]
            for col, shown in zip(CLOSED_LOOP_TABLE, r[1:]):
                head, column, scale = col.header, col.key, col.scale
                assert head in t["header"]
                if column == "min_body_where":  # link, obstacle and time of three columns
                    where = (
                        "-"
                        if pd.isna(csv_row["min_body_distance_t"])
                        else (
                            f"link {int(csv_row['min_body_distance_link'])} / "
                            f"{csv_row['min_body_distance_obstacle']} at "
                            f"{float(csv_row['min_body_distance_t']):.2f} s"
                        )
                    )
                    assert shown == where
                elif scale is None:
                    value = csv_row[column]
                    assert shown == ("-" if pd.isna(value) else str(value))
                else:
                    assert_close(
                        shown, float(csv_row[column]) * scale, f"{scenario}/{r[0]}/{column}"
                    )


def test_runs_that_failed_their_verdict_are_listed(report_dir, tmp_path):
    _, out, _, cl = report_dir
    md = (out / "report.md").read_text()
    tabs = [t for t in parse_tables(md) if t["headings"].get(3) == "Runs that failed their verdict"]
    assert len(tabs) == 1
    bad = cl[cl["verdict"] != "ok"]
    assert [r[:4] for r in tabs[0]["rows"]] == [
        [s, b, "paper", v] for s, b, v in zip(bad["scenario"], bad["backend"], bad["verdict"])
    ]
    assert [r[4] for r in tabs[0]["rows"][:-1]] == list(bad["verdict_reasons"])[:-1]
    assert "| incomplete | run raised: RuntimeError: boom \\| bad |" in md  # a "|" escaped
    # a table of runs that are all ok says so
    from qpbench.report.markdown import failed_verdicts

    assert failed_verdicts(cl[cl["verdict"] == "ok"]) == ["Every run's verdict is ok.\n"]


def test_report_refuses_overwrite_and_bad_input(report_dir, tmp_path, capsys):
    folder, out, _, _ = report_dir
    assert main(["report", str(folder / "bench.csv"), "--out", str(out)]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["report", str(folder / "bench.csv"), "--out", str(tmp_path), "--no-plots"]) == 0
    assert (
        main(["report", str(folder / "bench.csv"), "--out", str(tmp_path), "--force", "--no-plots"])
        == 0
    )
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\n1,2\n")
    assert main(["report", str(bad), "--out", str(tmp_path / "x")]) == 2
    assert "bad.csv" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "missing.csv"), "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x" / "report.md").exists()


def test_performance_profile_known_values():
    # problem p1: a 1 us, b 2 us; p2: a 4 us, b 2 us; p3: a fails, b 1 us
    rows = pd.DataFrame(
        {
            "problem": ["p1", "p1", "p2", "p2", "p3", "p3"],
            "scenario": [None] * 6,
            "backend": ["a", "b"] * 3,
            "wall_time_min_s": [1e-6, 2e-6, 4e-6, 2e-6, 5e-6, 1e-6],
            "success": [True, True, True, True, False, True],
        }
    )
    taus, prof = tables.performance_profile(rows, taus=np.array([1.0, 1.99, 2.0, 10.0]))
    np.testing.assert_allclose(prof["a"], [1 / 3, 1 / 3, 2 / 3, 2 / 3])
    np.testing.assert_allclose(prof["b"], [2 / 3, 2 / 3, 1.0, 1.0])


def test_same_problem_name_in_two_scenarios_kept_apart():
    rows = pd.DataFrame(
        {
            "problem": ["p", "p", "p", "p"],
            "scenario": ["s1", "s1", "s2", "s2"],
            "backend": ["a", "b", "a", "b"],
            "wall_time_min_s": [1e-6, 2e-6, 4e-6, 2e-6],
            "success": [True] * 4,
        }
    )
    _, prof = tables.performance_profile(rows, taus=np.array([1.0]))
    np.testing.assert_allclose(prof["a"], [0.5])
    np.testing.assert_allclose(prof["b"], [0.5])


def test_import_has_no_side_effects():
    code = (
        "import sys, logging, qpbench.report, qpbench.report.plots, qpbench.harness.closed_loop; "
        "assert 'matplotlib.pyplot' not in sys.modules; "
        "assert not logging.getLogger('qpbench').handlers; print('ok')"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr


# ----------------------------------------------------------------- honest tables, duplicates


def _honest_bench(rng: np.random.Generator) -> pd.DataFrame:
    """``alpha`` finds everything in process; ``net`` never finds (the network); ``iso`` runs in a worker."""
    rows = []
    for k in range(20):
        for backend in ("alpha", "net", "iso"):
            found = backend != "net"
            rows.append(
                dict(
                    problem=f"wall-{k:04d}",
                    scenario="wall",
                    tick=k,
                    t=k * 0.01,
                    backend=backend,
                    profile="default",
                    mode="sequential",
                    status="optimal" if found else "max_iter",
                    found=found,
                    success=found,
                    objective=1.0,
                    reference_objective=1.0,
                    reference_status="optimal",
                    reference_agreement=1e-12,
                    optimality_gap=1e-9 if found else 0.3,
                    primal_residual=1e-9 if found else math.inf,
                    dual_residual=1e-9 if found else math.inf,
                    duality_gap=1e-9 if found else math.inf,
                    constraint_violation=1e-9 if found else 0.01 * (k + 1),
                    wall_time_min_s=1e-5 * (1 + rng.random()),
                    wall_time_median_s=2e-5,
                    solver_time_s=None,
                    iterations=1,
                    error="",
                    isolated=backend == "iso",
                    position=k % 3,
                    order_seed=0,
                    repeat=1,
                )
            )
    return pd.DataFrame(rows)


def test_never_found_backend_is_not_the_best_and_isolated_rows_are_marked(tmp_path):
    bench = _honest_bench(np.random.default_rng(1))
    bench.to_csv(tmp_path / "b.csv", index=False)
    assert (
        main(["report", str(tmp_path / "b.csv"), "--out", str(tmp_path / "out"), "--no-plots"]) == 0
    )
    md = (tmp_path / "out" / "report.md").read_text()
    tabs = parse_tables(md)
    ratios = next(t for t in tabs if t["caption"].startswith("Success rate and shifted"))
    shown = {r[0]: r for r in ratios["rows"]}
    assert set(shown) == {"alpha", "net", "iso \u2020"}  # the worker's rows are marked
    for col in ("primal residual", "dual residual", "duality gap", "optimality gap"):
        j = ratios["header"].index(col)
        assert shown["net"][j] == "-", col  # not "1": it never found a solution
        assert shown["alpha"][j] == "1" and shown["iso \u2020"][j] == "1"
    assert shown["net"][ratios["header"].index("runtime")] != "-"  # its time is a time
    absolute = next(t for t in tabs if t["caption"].startswith("Shifted geometric means, absolute"))
    net = next(r for r in absolute["rows"] if r[0] == "net")
    assert net[3:7] == ["-", "-", "-", "-"]
    assert (
        "A `-` in a residual or gap column: net never found a solution (0 rows with status optimal)"
        in md
    )
    assert "\u2020 solved in a worker process (iso 20 of 20 rows)" in md
    scenario = next(t for t in tabs if t["headings"].get(4, "").startswith("Scenario wall"))
    assert "iso \u2020" in {r[0] for r in scenario["rows"]}
    # violation: per backend max and p99, and the sentence for the backend without a found solution
    viol = next(t for t in tabs if t["caption"].startswith("Constraint violation"))
    row = next(r for r in viol["rows"] if r[0] == "net")
    v = 0.01 * np.arange(1, 21)
    assert_close(row[viol["header"].index("max")], v.max(), "max violation")
    assert_close(row[viol["header"].index("p99")], np.percentile(v, 99), "p99 violation")
    assert re.search(
        r"net never found a solution \(0 of 20 rows\): its constraint violation is the only "
        r"accuracy figure it has: max 0\.2, p99 0\.1981",
        md,
    )


def test_report_refuses_duplicate_rows_unless_told_which_to_keep(tmp_path, capsys):
    bench = _honest_bench(np.random.default_rng(2))
    first, last = bench.copy(), bench[bench["problem"] < "wall-0010"].copy()
    last["success"] = False  # tells the two files' rows apart
    first.to_csv(tmp_path / "first.csv", index=False)
    last.to_csv(tmp_path / "last.csv", index=False)
    files = [str(tmp_path / "first.csv"), str(tmp_path / "last.csv")]
    out = tmp_path / "out"
    assert main(["report", *files, "--out", str(out), "--no-plots"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert (
        "first.csv" in err
        and "last.csv" in err
        and "problem=wall-0000" in err
        and "backend=alpha" in err
    )
    assert not (out / "report.md").exists()

    def success(prefer):
        target = tmp_path / prefer
        assert main(["report", *files, "--out", str(target), "--no-plots", "--prefer", prefer]) == 0
        table = next(
            t
            for t in parse_tables((target / "report.md").read_text())
            if t["caption"].startswith("Success rate and shifted")
        )
        row = next(r for r in table["rows"] if r[0] == "alpha")
        return int(row[1]), float(row[2])

    assert success("first") == (20, 100.0)
    assert success("last") == (20, 50.0)  # 10 rows of last.csv (success false) over 10 of first.csv


def test_report_refuses_mixed_repeat_counts_unless_told(tmp_path, capsys):
    bench = _honest_bench(np.random.default_rng(3))
    one, three = bench[bench["tick"] < 10].copy(), bench[bench["tick"] >= 10].copy()
    three["repeat"] = 3
    three.loc[three["backend"] == "net", "repeat"] = 1  # a failed solve is not repeated: not a mix
    one.loc[one["backend"] == "net", "repeat"] = 1
    one.to_csv(tmp_path / "one.csv", index=False)
    three.to_csv(tmp_path / "three.csv", index=False)
    files = [str(tmp_path / "one.csv"), str(tmp_path / "three.csv")]
    assert main(["report", *files, "--out", str(tmp_path / "o"), "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert "alpha" in err and "one.csv: 1" in err and "three.csv: 3" in err and "net" not in err
    assert (
        main(["report", *files, "--out", str(tmp_path / "o"), "--no-plots", "--prefer", "last"])
        == 0
    )
    md = (tmp_path / "o" / "report.md").read_text()
    assert "Note: alpha (default, sequential) mixes rows timed with different --repeat" in md


def test_backends_with_different_repeat_counts_in_one_table_are_noted(tmp_path):
    bench = _honest_bench(np.random.default_rng(4))
    bench.loc[bench["backend"] == "alpha", "repeat"] = 3
    bench.to_csv(tmp_path / "b.csv", index=False)
    assert (
        main(["report", str(tmp_path / "b.csv"), "--out", str(tmp_path / "o"), "--no-plots"]) == 0
    )
    md = (tmp_path / "o" / "report.md").read_text()
    assert (
        "different --repeat counts in the tables of default, sequential (alpha 3, iso 1, net 1)"
        in md
    )


def test_solver_time_against_call_time_per_scenario(tmp_path):
    """The table of what the solver reports for itself against the call equals the rows' percentiles."""
    rng = np.random.default_rng(3)
    bench = _honest_bench(rng)
    solver = np.where(bench["backend"] == "alpha", 4e-6 * (1 + rng.random(len(bench))), np.nan)
    bench["solver_time_s"] = solver
    bench.to_csv(tmp_path / "b.csv", index=False)
    assert (
        main(["report", str(tmp_path / "b.csv"), "--out", str(tmp_path / "out"), "--no-plots"]) == 0
    )
    tabs = parse_tables((tmp_path / "out" / "report.md").read_text())
    t = next(t for t in tabs if t["caption"].startswith("What the solver reports for its own work"))
    assert [r[0] for r in t["rows"]] == ["alpha"]  # the others report no time of their own
    alpha = bench[bench["backend"] == "alpha"]
    call = alpha["wall_time_min_s"].to_numpy()
    own = alpha["solver_time_s"].to_numpy()
    row = t["rows"][0]
    for header, values, q in (
        ("call p50 (us)", call, 50),
        ("solver p99 (us)", own, 99),
        ("call - solver p50 (us)", call - own, 50),
        ("call - solver p99 (us)", call - own, 99),
    ):
        assert_close(row[t["header"].index(header)], np.percentile(values, q) * 1e6, header)


def test_per_tick_plot_of_a_scenario_without_any_solution(tmp_path):
    """A short run whose ticks are all infeasible (narrow's start) has no gap to draw: no crash."""
    from qpbench.report.plots import per_tick_plot

    rows = _honest_bench(np.random.default_rng(0))
    rows = rows[rows["backend"] == "net"]  # never found
    assert per_tick_plot(rows, "narrow", tmp_path / "p.png")
    assert (tmp_path / "p.png").stat().st_size > 0
