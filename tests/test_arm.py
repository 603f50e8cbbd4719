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
    close = closest_approach(run.log, scenario)
    assert close["distance"] == pytest.approx(run.summary["min_obstacle_distance"], abs=1e-12)
    assert close["key_point"] == run.summary["min_obstacle_distance_key_point"]
    assert close["obstacle"] == run.summary["min_obstacle_distance_obstacle"]
    assert close["t"] == pytest.approx(run.summary["min_obstacle_distance_t"])


def test_closest_approach_without_obstacles():
    scenario = load_scenario("free").with_overrides(duration=0.05)
    run = simulate(scenario, "qpsolvers:daqp")
    assert closest_approach(run.log, scenario) is None


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
