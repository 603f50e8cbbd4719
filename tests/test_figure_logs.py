"""Figure logs: the report from the CSVs and what ``closed-loop`` keeps, pictures of the arm, no stale figures."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pandas as pd
import pytest

from qpbench.cli import main
from qpbench.sim import log as tick_log
from qpbench.sim.figure_log import BUCKETS, figure_log, write_figure_log


def _synthetic_log(ticks: int = 20_000, seed: int = 3) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    t = np.arange(ticks) * 1e-3
    frame = pd.DataFrame(
        {
            tick_log.T: t,
            "theta_0": np.sin(t),
            "theta_1": np.cos(t),
            "v_0": rng.standard_normal(ticks),
            "v_1": rng.standard_normal(ticks),
            tick_log.EE_X: np.cos(t),
            tick_log.EE_Y: np.sin(t),
            tick_log.XD_X: np.cos(t),
            tick_log.XD_Y: np.sin(t),
            tick_log.TRACKING_ERROR: 1e-4 * rng.standard_normal(ticks),
            tick_log.FORCE: rng.random(ticks),
            tick_log.FORCE_ERROR: 1e-3 * rng.standard_normal(ticks),
            "d_A1_wall": 0.05 + 0.01 * rng.random(ticks),
            tick_log.D_MIN: 0.05 + 0.01 * rng.random(ticks),
            tick_log.V_SQ: rng.random(ticks),
            tick_log.TASK_RESIDUAL: rng.random(ticks),
            tick_log.STATUS: np.full(ticks, "optimal", dtype=object),
            tick_log.FALLBACK: np.zeros(ticks, dtype=bool),
            tick_log.ZERO_VELOCITY: np.zeros(ticks, dtype=bool),
            tick_log.SOLVE_TIME: 1e-5 * (1 + rng.random(ticks)),
            tick_log.Y_0: rng.random(ticks),
            tick_log.KP_HAT: np.full(ticks, 1e4),
        }
    )
    if ticks < 20_000:
        return frame
    frame.loc[7001:7040, tick_log.STATUS] = "primal_infeasible"
    frame.loc[7001:7040, tick_log.FALLBACK] = True
    frame.loc[12345, tick_log.ZERO_VELOCITY] = True
    frame.loc[15555, tick_log.TRACKING_ERROR] = -0.2  # the worst points, each on a tick of its own
    frame.loc[4321, tick_log.SOLVE_TIME] = 3e-3
    frame.loc[9876, tick_log.D_MIN] = 0.0095
    return frame


def test_figure_log_keeps_every_special_tick_and_the_worst_points(tmp_path):
    full = _synthetic_log()
    small = figure_log(full)
    assert len(small) < len(full) / 4
    kept = set(np.round(small[tick_log.T].to_numpy(float) * 1e3).astype(int))
    special = set(range(7001, 7041)) | {12345}
    assert special <= kept and {15555, 4321, 9876} <= kept
    assert small[tick_log.FALLBACK].sum() == 40 and small[tick_log.ZERO_VELOCITY].sum() == 1
    assert (small[tick_log.STATUS] == "primal_infeasible").sum() == 40
    # the extremes are the full log's, to float32 rounding of the kept mantissa
    assert np.abs(small[tick_log.TRACKING_ERROR]).max() == pytest.approx(0.2, rel=1e-3)
    assert small[tick_log.SOLVE_TIME].max() == pytest.approx(3e-3, rel=1e-3)
    assert small[tick_log.D_MIN].min() == pytest.approx(0.0095, rel=1e-3)
    # only the drawn columns, floats in float32
    assert (
        tick_log.TASK_RESIDUAL not in small
        and tick_log.Y_0 not in small
        and tick_log.FORCE not in small
    )
    assert all(small[c].dtype == np.float32 for c in small.columns if small[c].dtype.kind == "f")
    path = write_figure_log(full, tmp_path / "figure_logs" / "x.parquet")
    full.to_parquet(tmp_path / "full.parquet", index=False)
    assert path.stat().st_size < (tmp_path / "full.parquet").stat().st_size / 10
    back = pd.read_parquet(path)
    assert len(back) == len(small) and list(back.columns) == list(small.columns)


def test_short_log_is_kept_whole():
    full = _synthetic_log(ticks=3 * BUCKETS)
    small = figure_log(full)
    assert len(small) == len(full)
    assert np.allclose(small[tick_log.T], full[tick_log.T], atol=1e-6)


def _image_links(report_md: str) -> list[str]:
    return re.findall(r"\]\((plots/[^)]+\.png)\)", report_md)


@pytest.fixture(scope="module")
def loop_dir(tmp_path_factory):
    """A closed-loop run of the wall scenario by an exact backend and the network, its logs kept."""
    out = tmp_path_factory.mktemp("loop") / "cl"
    code = main(
        [
            "closed-loop",
            "--scenarios",
            "wall",
            "--backends",
            "daqp,rnn-tuned,pinv",
            "--duration",
            "1.5",
            "--out",
            str(out),
        ]
    )
    verdicts = pd.read_csv(out / "closed_loop.csv").set_index("backend")["verdict"]
    assert verdicts["daqp"] == verdicts["rnn-tuned"] == "ok"
    assert code == 0  # outputs written: 0 whatever pinv's verdict (1 only with --strict)
    return out


def test_report_from_the_csv_and_figure_logs_links_the_same_figures(loop_dir, tmp_path):
    assert sorted(p.name for p in (loop_dir / "figure_logs").iterdir()) == sorted(
        p.name for p in (loop_dir / "logs").iterdir()
    )
    assert main(["report", str(loop_dir / "closed_loop.csv"), "--out", str(tmp_path / "full")]) == 0
    bare = tmp_path / "bare"  # as a fresh clone has it: the CSV and figure_logs/, no logs/
    bare.mkdir()
    shutil.copy(loop_dir / "closed_loop.csv", bare)
    shutil.copytree(loop_dir / "figure_logs", bare / "figure_logs")
    assert main(["report", str(bare / "closed_loop.csv"), "--out", str(tmp_path / "bare_out")]) == 0
    full = _image_links((tmp_path / "full" / "report.md").read_text())
    compact = _image_links((tmp_path / "bare_out" / "report.md").read_text())
    assert full == compact
    assert {
        "plots/closed_loop_wall_paper.png",
        "plots/closed_loop_v_wall_paper.png",
        "plots/closed_loop_d_wall_paper.png",
    } <= set(compact)
    # without either log, the closed-loop figures are gone: the figure logs are what drew them
    shutil.rmtree(bare / "figure_logs")
    assert main(["report", str(bare / "closed_loop.csv"), "--out", str(tmp_path / "none")]) == 0
    assert not [
        p for p in _image_links((tmp_path / "none" / "report.md").read_text()) if "wall" in p
    ]


def test_report_shows_the_arm_for_the_fastest_exact_backend_and_the_network_side_by_side(
    loop_dir, tmp_path
):
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(loop_dir / "closed_loop.csv", bare)
    shutil.copytree(loop_dir / "figure_logs", bare / "figure_logs")
    assert main(["report", str(bare / "closed_loop.csv"), "--out", str(tmp_path / "out")]) == 0
    md = (tmp_path / "out" / "report.md").read_text()
    row = (
        "| ![fastest exact backend, wall](plots/snapshot_exact_wall_paper.png) "
        "| ![network, wall](plots/snapshot_network_wall_paper.png) |"
    )
    assert "| fastest exact backend | network |" in md and row in md
    for name in ("snapshot_exact_wall_paper.png", "snapshot_network_wall_paper.png"):
        assert (tmp_path / "out" / "plots" / name).stat().st_size > 10_000


def test_snapshot_roles(loop_dir):
    from qpbench.report.inputs import read_results
    from qpbench.report.plots import snapshot_runs

    runs = read_results([loop_dir / "closed_loop.csv"]).closed_loop
    chosen = snapshot_runs(runs)
    # pinv ignores the obstacles: it is never the exact backend, however fast
    assert chosen["exact"]["backend"] == "daqp" and chosen["network"]["backend"] == "rnn-tuned"
    slow = runs.assign(
        solve_time_median_s=np.where(runs["backend"] == "daqp", 1.0, runs["solve_time_median_s"])
    )
    assert snapshot_runs(slow)["exact"]["backend"] == "daqp"  # the only exact one
    rnn = runs.assign(backend=runs["backend"].replace({"rnn-tuned": "rnn"}))
    assert snapshot_runs(rnn)["network"]["backend"] == "rnn"


def test_report_removes_only_its_own_figures_it_no_longer_links(loop_dir, tmp_path):
    out = tmp_path / "out"
    assert main(["report", str(loop_dir / "closed_loop.csv"), "--out", str(out)]) == 0
    plots = out / "plots"
    stale = [
        plots / "closed_loop_narrow_paper.png",
        plots / "snapshot_exact_old_paper.png",
        plots / "perf_profile_gone.png",
        plots / "per_tick_gone_wall.png",
    ]
    mine = [
        plots / "notes.png",
        plots / "closed_loop_wall_paper.svg",
        out / "closed_loop_narrow_paper.png",
    ]
    for path in stale + mine:
        path.write_bytes(b"x")
    linked = _image_links((out / "report.md").read_text())
    assert main(["report", str(loop_dir / "closed_loop.csv"), "--out", str(out), "--force"]) == 0
    assert not [p for p in stale if p.exists()]
    assert all(p.exists() for p in mine)
    assert _image_links((out / "report.md").read_text()) == linked
    assert all((out / p).exists() for p in linked)
