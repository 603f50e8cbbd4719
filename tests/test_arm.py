"""Pictures of the arm: snapshot and animation of a closed-loop run."""

from __future__ import annotations

import pytest
from conftest import simulate_args
from PIL import Image

from qpbench.exceptions import ParamError
from qpbench.report.arm import animate, closest_approach, draw_snapshot
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario


@pytest.fixture(scope="module")
def wall_run():
    scenario = load_scenario("wall").with_overrides(duration=0.3)
    return scenario, simulate(scenario, "qpsolvers:daqp")


def test_closest_approach_is_the_summarys(wall_run):
    scenario, run = wall_run
    close = closest_approach(run.log)
    assert close["distance"] == pytest.approx(run.summary["min_obstacle_distance"], abs=1e-12)
    assert close["key_point"] == run.summary["min_obstacle_distance_key_point"]
    assert close["obstacle"] == run.summary["min_obstacle_distance_obstacle"]
    assert close["t"] == pytest.approx(run.summary["min_obstacle_distance_t"])


def test_closest_approach_without_obstacles():
    scenario = load_scenario("free").with_overrides(duration=0.05)
    run = simulate(scenario, "qpsolvers:daqp")
    assert closest_approach(run.log) is None


def test_snapshot_is_an_image(wall_run, tmp_path):
    scenario, run = wall_run
    out = draw_snapshot(scenario, run.log, tmp_path / "wall.png", instants=5)
    with Image.open(out) as img:
        assert img.format == "PNG"
        assert img.size[0] > 400 and img.size[1] > 300


def test_animation_has_one_frame_per_step(wall_run, tmp_path):
    scenario, run = wall_run
    # 300 ticks of 1 ms at 10 fps and 0.1 simulated s per second: a frame every 10 ticks
    out = animate(scenario, run.log, tmp_path / "wall.gif", fps=10, speed=0.1)
    with Image.open(out) as img:
        assert img.format == "GIF"
        assert img.n_frames == 30
    assert not list(tmp_path.glob(".*tmp*"))


@pytest.mark.parametrize("name", ["wall.avi", "wall.png"])
def test_animation_refuses_other_formats(wall_run, tmp_path, name):
    scenario, run = wall_run
    with pytest.raises(ParamError, match="gif"):
        animate(scenario, run.log, tmp_path / name)
    assert not (tmp_path / name).exists()


def test_simulate_writes_snapshot_and_animation(tmp_path):
    from qpbench.cli import main

    png, gif = tmp_path / "n.png", tmp_path / "n.gif"
    code = main(
        [
            "-q",
            *simulate_args("narrow", "qpsolvers:daqp", "0.2"),
            "--snapshot",
            str(png),
            "--animate",
            str(gif),
            "--fps",
            "10",
            "--speed",
            "0.5",
        ]
    )
    assert code == 0
    with Image.open(png) as img:
        assert img.format == "PNG"
    with Image.open(gif) as img:
        assert img.n_frames == 4  # 0.2 s at 0.5 simulated s per second and 10 fps
    assert sorted(p.name for p in tmp_path.iterdir()) == ["n.gif", "n.png"]


def test_simulate_refuses_a_snapshot_format_before_running(tmp_path, capsys):
    from qpbench.cli import main

    jpg = tmp_path / "a.jpg"
    assert (
        main(["simulate", "--scenario=wall", "--backend=qpsolvers:daqp", f"--snapshot={jpg}"]) == 2
    )
    assert "--snapshot" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def _lines_of(fig, colour: str) -> list:
    import matplotlib.colors as mcolors

    return [
        line
        for ax in fig.axes
        for line in ax.get_lines()
        if mcolors.to_hex(line.get_color()) == colour and len(line.get_xdata())
    ]


def test_snapshot_legend_of_a_long_run_is_not_cut(tmp_path, monkeypatch):
    """Past the closest approach (wall, 4 s in) the legend's longest line names it; the arm's
    view is the whole workspace: the legend beside it reaches past the figure's own width."""
    from conftest import figures_closed

    scenario = load_scenario("wall").with_overrides(duration=4.5)
    run = simulate(scenario, "daqp")
    figures = figures_closed(monkeypatch)
    out = draw_snapshot(scenario, run.log, tmp_path / "wall.png", backend="daqp")
    with Image.open(out) as img:
        size_px = img.size
    (fig,) = figures
    # wider than the figure at the 110 dpi it was written at: the legend is in, not cut
    assert size_px[0] > round(fig.get_figwidth() * 110) + 10


@pytest.mark.parametrize("backend", ["daqp", "rnn-tuned"])
def test_snapshot_follows_the_report_style(wall_run, tmp_path, monkeypatch, backend):
    """The backend's path and distance line in its one look, the arm in none of the backends'
    colours, the legend outside the data, d_safe readable, the PNG under the height limit."""
    from conftest import figures_closed, legends_over_data

    from qpbench.report import arm, style

    scenario, run = wall_run
    figures = figures_closed(monkeypatch)
    out = draw_snapshot(scenario, run.log, tmp_path / "wall.png", backend=backend)
    with Image.open(out) as img:
        assert img.size[1] <= style.MAX_HEIGHT_PX
    (fig,) = figures
    look = style.look(backend)
    coloured = _lines_of(fig, look.colour)
    labels = [str(line.get_label()) for line in coloured]
    assert f"{backend}: actual end-effector path" in labels
    assert f"{backend}: closest key point [mm]" in labels
    assert {line.get_marker() for line in coloured if line.get_label() in labels[:2]} == {
        look.marker
    }
    assert arm.ARM not in {lk.colour for lk in style.LOOKS.values()}
    assert legends_over_data(fig) == []
    workspace, distance = fig.axes
    assert distance.get_yscale() == "symlog"
    d_safe_mm = scenario.spec.controller.d_safe * 1e3
    lo, hi = distance.get_ylim()
    assert lo < d_safe_mm - 0.5 < d_safe_mm < hi
    # d_safe takes a readable share of the panel's height (not squashed against 0)
    to_px = distance.transData.transform
    share = (to_px((0, d_safe_mm))[1] - to_px((0, 0))[1]) / (to_px((0, hi))[1] - to_px((0, lo))[1])
    assert share > 0.15
    assert workspace.get_aspect() == 1.0


def test_snapshot_without_obstacles_has_no_distance_panel(tmp_path, monkeypatch):
    from conftest import figures_closed

    scenario = load_scenario("free").with_overrides(duration=0.05)
    run = simulate(scenario, "qpsolvers:daqp")
    figures = figures_closed(monkeypatch)
    draw_snapshot(scenario, run.log, tmp_path / "free.png", backend="daqp")
    (fig,) = figures
    assert len(fig.axes) == 1


def test_animation_takes_the_backend_look_and_stamps_time_outside_the_data(
    wall_run, tmp_path, monkeypatch
):
    from conftest import figures_closed

    from qpbench.report import style

    scenario, run = wall_run
    figures = figures_closed(monkeypatch)
    animate(scenario, run.log, tmp_path / "wall.gif", fps=10, speed=0.3, backend="osqp")
    (fig,) = figures
    (ax,) = fig.axes
    assert _lines_of(fig, style.look("osqp").colour)  # the end effector's trace
    assert "t =" in ax.get_title(loc="left")
    assert not [t for t in ax.texts if "t =" in t.get_text()]
