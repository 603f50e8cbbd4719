"""The closed-loop figure: panels for what matters, drawn from the tick log's own columns."""

from __future__ import annotations

import matplotlib
import pytest
from PIL import Image

from qpbench.report import loop_figure
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario

matplotlib.use("Agg")


@pytest.fixture(scope="module")
def wall_logs():
    sc = load_scenario("wall").with_overrides(duration=0.3)
    return {b: simulate(sc, b).log for b in ("qpsolvers:daqp", "pinv")}


def panels_drawn(monkeypatch):
    """The y labels of the figure's axes (the figure is captured before it is closed)."""
    import matplotlib.pyplot as plt

    seen = {}
    real_close = plt.close

    def close(fig=None):
        if fig is not None and hasattr(fig, "axes"):
            seen["labels"] = [ax.get_ylabel() for ax in fig.axes]
            seen["scales"] = [ax.get_yscale() for ax in fig.axes]
        return real_close(fig)

    monkeypatch.setattr(plt, "close", close)
    return seen


def test_panels_and_scales(wall_logs, tmp_path, monkeypatch):
    seen = panels_drawn(monkeypatch)
    out = loop_figure.closed_loop_figure(wall_logs, tmp_path / "f.png", title="wall", d_safe=0.01)
    with Image.open(out) as img:
        assert img.format == "PNG"
    labels = " | ".join(seen["labels"])
    assert "solve time" in labels and "µs" in labels
    assert "closest key point" in labels
    assert "Kp_hat" not in labels  # wall does not adapt
    assert seen["scales"][0] == "log"


def test_adaptive_panel_only_when_adapting(tmp_path, monkeypatch):
    sc = load_scenario("adaptive_fast").with_overrides(duration=0.2)
    seen = panels_drawn(monkeypatch)
    loop_figure.closed_loop_figure(
        {"daqp": simulate(sc, "qpsolvers:daqp").log}, tmp_path / "a.png", title="a"
    )
    assert any("Kp_hat" in label for label in seen["labels"])


def test_free_has_no_distance_panel(tmp_path, monkeypatch):
    sc = load_scenario("free").with_overrides(duration=0.05)
    seen = panels_drawn(monkeypatch)
    loop_figure.closed_loop_figure(
        {"pinv": simulate(sc, "pinv").log}, tmp_path / "f.png", title="f", d_safe=0.01
    )
    assert not any("closest key point" in label for label in seen["labels"])


def test_no_log_is_an_error(tmp_path):
    with pytest.raises(ValueError):
        loop_figure.closed_loop_figure({}, tmp_path / "x.png", title="x")
    assert not (tmp_path / "x.png").exists()


def test_simulate_plot_follows_the_report_style(tmp_path, monkeypatch):
    """``simulate --plot``: the backend in its one look, legends outside the data, the distance
    panel against d_safe on the report's axis, the PNG under the height limit."""
    import matplotlib.colors as mcolors
    from conftest import figures_closed, legends_over_data, simulate_args

    from qpbench.cli import main
    from qpbench.report import style

    figures = figures_closed(monkeypatch)
    png = tmp_path / "wall.png"
    assert main(["-q", *simulate_args("wall", "daqp", "0.3", "--plot", str(png))]) == 0
    with Image.open(png) as img:
        assert img.size[1] <= style.MAX_HEIGHT_PX
    (fig,) = figures
    assert legends_over_data(fig) == []
    named = [line for ax in fig.axes for line in ax.get_lines() if line.get_label() == "daqp"]
    assert named
    assert {mcolors.to_hex(line.get_color()) for line in named} == {style.look("daqp").colour}
    (distance,) = [ax for ax in fig.axes if "closest key point" in ax.get_ylabel()]
    assert distance.get_yscale() == "symlog"
    assert "10" in [t.get_text() for t in distance.get_yticklabels()]  # d_safe, in mm
