"""The report's figures: one look per backend in every figure, at most eight highlighted
backends a panel, legends outside the data, no PNG over 2,000 px tall.

Drawn from the shipped results of ``narrow`` (20 backends, their figure logs in
``results/figure_logs/``), the scenario whose figures were the hardest to read.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import matplotlib.colors as mcolors
import numpy as np
import pandas as pd
import pytest
from PIL import Image

from qpbench.report import style
from qpbench.report.inputs import Results, read_results
from qpbench.report.plots import write_plots

RESULTS = Path(__file__).resolve().parent.parent / "results"


def _hex(colour) -> str:
    return mcolors.to_hex(colour).lower()


@pytest.fixture(scope="module")
def narrow(tmp_path_factory):
    """The report's figures of narrow: files, and per figure the colour of each labelled backend line."""
    if not (RESULTS / "figure_logs").is_dir():
        pytest.skip("no shipped figure logs")
    import matplotlib.pyplot as plt

    results = read_results([RESULTS / "bench" / "narrow.csv.gz", RESULTS / "closed_loop.csv"])
    cl = results.closed_loop
    results = Results(results.bench, cl[cl["scenario"].astype(str) == "narrow"].copy())
    out = tmp_path_factory.mktemp("report")
    seen: dict[int, dict] = {}
    real_close = plt.close

    def close(fig=None):  # record every figure's lines before it is closed
        if fig is not None and hasattr(fig, "axes"):
            seen[id(fig)] = [
                [(str(line.get_label()), _hex(line.get_color())) for line in ax.get_lines()]
                for ax in fig.axes
            ]
        return real_close(fig)

    mp = pytest.MonkeyPatch()
    mp.setattr(plt, "close", close)
    handler = _Records()
    logging.getLogger("qpbench.report").addHandler(handler)
    try:
        files = write_plots(results, out / "plots", out)
    finally:
        mp.undo()
        logging.getLogger("qpbench.report").removeHandler(handler)
    backends = sorted(set(results.closed_loop["backend"].astype(str)))
    return {
        "out": out,
        "files": files,
        "lines": list(seen.values()),
        "backends": backends,
        "warnings": handler.messages,
    }


class _Records(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record):
        self.messages.append(record.getMessage())


def test_every_figure_is_drawn_and_under_the_height_limit(narrow):
    keys = set(narrow["files"])
    for key in (
        "perf_profile_default_sequential",
        "per_tick_default_sequential_narrow",
        "closed_loop_narrow_paper",
        "closed_loop_v_narrow_paper",
        "closed_loop_d_narrow_paper",
    ):
        assert key in keys, key
    assert len(narrow["backends"]) == 20
    for rel in narrow["files"].values():
        with Image.open(narrow["out"] / rel) as img:
            w, h = img.size
        assert h <= style.MAX_HEIGHT_PX, (rel, h)
        assert w <= 2 * style.MAX_HEIGHT_PX, (rel, w)
    # designed to fit: no figure had to be scaled down to the limit
    assert not [m for m in narrow["warnings"] if "px" in m], narrow["warnings"]


def test_figures_drawn_in_worker_processes_are_those_drawn_here(narrow, tmp_path):
    """Two at a time in worker processes: the same figures, byte for byte, as one at a time here."""
    results = read_results([RESULTS / "bench" / "narrow.csv.gz", RESULTS / "closed_loop.csv"])
    cl = results.closed_loop
    results = Results(results.bench, cl[cl["scenario"].astype(str) == "narrow"].copy())
    files = write_plots(results, tmp_path / "plots", tmp_path, jobs=2)
    assert files == narrow["files"]
    for rel in files.values():
        assert (tmp_path / rel).read_bytes() == (narrow["out"] / rel).read_bytes(), rel


def test_a_backend_has_one_colour_in_every_figure_and_no_two_share_one(narrow):
    colours: dict[str, set[str]] = {}
    for fig in narrow["lines"]:
        for ax in fig:
            for label, colour in ax:
                name = (
                    label.split(":", 1)[0]
                    if label.split(":", 1)[0] in narrow["backends"]
                    else label
                )
                if name in narrow["backends"]:
                    colours.setdefault(name, set()).add(colour)
    assert set(colours) == set(narrow["backends"])
    for backend, seen in colours.items():
        assert seen == {style.look(backend).colour}, (backend, seen)
    assert len({next(iter(c)) for c in colours.values()}) == len(colours)


def test_at_most_eight_highlighted_backends_a_panel(narrow):
    for fig in narrow["lines"]:
        for ax in fig:
            named = {label.split(": ")[0] for label, _ in ax} & set(narrow["backends"])
            assert len(named) <= style.MAX_SERIES, named


def test_the_distance_axis_shows_d_safe(narrow):
    """Linear up to d_safe: the 10 mm line is not squashed against 0 by a 300 mm excursion."""
    import matplotlib.pyplot as plt

    from qpbench.report.loop_figure import distance_axis

    fig, ax = plt.subplots()
    ax.plot([0, 1], [-150.0, 300.0])
    distance_axis(ax, 0.01, -150.0)
    fig.canvas.draw()
    to_px = ax.transData.transform
    lo, hi = ax.get_ylim()
    span = to_px((0, hi))[1] - to_px((0, lo))[1]
    band = to_px((0, 10.0))[1] - to_px((0, 9.5))[1]
    plt.close(fig)
    assert lo < -150.0 and hi >= 300.0
    assert band / span > 0.005  # on a linear 0-300 mm axis it would be 0.5 / 450


def test_the_distance_axis_labels_data_close_above_d_safe():
    """A run between d_safe (30 mm) and the first 1-2-5 tick above it (100 mm) still gets a
    labelled tick at its data; a run reaching 300 mm gets the 1-2-5 ticks only."""
    import matplotlib.pyplot as plt

    from qpbench.report.loop_figure import distance_axis

    def labelled(data):
        fig, ax = plt.subplots()
        ax.plot([0, 1], data)
        distance_axis(ax, 0.03, min(data))
        fig.canvas.draw()
        lo, hi = ax.get_ylim()
        ticks = [v for v in ax.yaxis.get_major_locator()() if lo <= v <= hi]
        plt.close(fig)
        return ticks

    close = labelled([43.0, 45.0])  # without the extra tick: 0 and 30 only
    assert close[:2] == [0.0, 30.0] and len(close) == 3 and 40.0 <= close[2] <= 60.0
    assert labelled([43.0, 300.0]) == [0.0, 30.0, 100.0, 200.0]


def test_looks_are_distinct_and_fixed():
    colours = [look.colour.lower() for look in style.LOOKS.values()]
    assert len(set(colours)) == len(colours)
    assert _hex(style.GREY) not in colours
    looks = [(lk.colour, lk.marker, lk.linestyle) for lk in style.LOOKS.values()]
    assert len(set(looks)) == len(looks)
    # a name not in the table: the same look in every process (no salted hash())
    code = "from qpbench.report.style import look; print(look('my-plugin'))"
    runs = {
        subprocess.run(
            [sys.executable, "-c", code],
            capture_output=True,
            text=True,
            check=True,
            env=os.environ | {"PYTHONHASHSEED": seed},
        ).stdout
        for seed in ("1", "2")
    }
    assert runs == {repr(style.look("my-plugin")) + "\n"}


def test_groups_cover_every_backend_once_at_most_eight_each():
    names = list(style.LOOKS) + [f"plugin-{i}" for i in range(11)]
    groups = style.groups(names)
    flat = [b for _, g in groups for b in g]
    assert sorted(flat) == sorted(names)
    assert all(1 <= len(g) <= style.MAX_SERIES for _, g in groups)
    assert style.groups(["osqp", "daqp"]) == [("", ["daqp", "osqp"])]
    assert style.groups([]) == []


def test_save_keeps_a_tall_figure_under_the_limit(tmp_path, caplog):
    plt = style.pyplot()
    fig, ax = plt.subplots(figsize=(4, 30))
    ax.plot(np.arange(3), np.arange(3))
    with caplog.at_level(logging.WARNING, logger="qpbench.report"):
        style.save(fig, tmp_path / "tall.png", dpi=110)
    with Image.open(tmp_path / "tall.png") as img:
        assert img.size[1] <= style.MAX_HEIGHT_PX
    assert "over 2000 px" in caplog.text


def test_ecdf_and_scaling_figures_take_the_backend_looks(tmp_path, monkeypatch):
    """The sweep's and the scaling study's figures draw each backend in its look too."""
    import matplotlib.pyplot as plt

    from qpbench.scaling.report import plot as scaling_plot
    from qpbench.sweep.report import ecdf_plot

    colours: dict[str, set[str]] = {}
    real_close = plt.close

    def close(fig=None):
        if fig is not None and hasattr(fig, "axes"):
            for ax in fig.axes:
                for line in ax.get_lines():
                    name = str(line.get_label()).split(" (")[0]
                    colours.setdefault(name, set()).add(_hex(line.get_color()))
        return real_close(fig)

    monkeypatch.setattr(plt, "close", close)
    rng = np.random.default_rng(0)
    backends = ["daqp", "osqp", "qpoases", "rnn-tuned"]
    df = pd.DataFrame(
        {
            "backend": np.repeat(backends, 30),
            "status": "ok",
            "tracking_max_after_2s": rng.uniform(1e-6, 1e-3, 120),
            "force_error_max_after_2s": rng.uniform(1e-3, 1.0, 120),
            "min_obstacle_distance": rng.uniform(0.005, 0.05, 120),
            "solve_time_p99_s": rng.uniform(1e-5, 1e-3, 120),
            "d_safe": 0.01,
        }
    )
    ecdf_plot(df, tmp_path / "ecdf.png", "sweep")
    sizes = [4, 8, 16]
    frame = pd.DataFrame(
        [
            {
                "status": "measured",
                "backend": b,
                "axis": axis,
                "n": n,
                "rows": 10 * n,
                "time_median_s": 1e-6 * n * (i + 1),
                "matrix_format": "sparse" if b == "osqp" else "dense",
            }
            for i, b in enumerate(backends)
            for axis in ("arm", "cloud")
            for n in sizes
        ]
    )
    scaling_plot(frame, {}, tmp_path / "scaling.png")
    for b in backends:
        assert colours[b] == {style.look(b).colour}, (b, colours.get(b))
    for name in ("ecdf.png", "scaling.png"):
        with Image.open(tmp_path / name) as img:
            assert img.size[1] <= style.MAX_HEIGHT_PX
