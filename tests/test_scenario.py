"""Scenario files: the shipped ones load, typos and impossible values fail naming the file and key."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from qpbench.exceptions import ScenarioError
from qpbench.sim.scenario import load_scenario, parse_scenario, scenario_names, scenario_path

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTED = ROOT / "problems" / "scenarios"
PACKAGED = ROOT / "qpbench" / "data" / "scenarios"
PAPER = ("free", "wall", "adaptive", "narrow")


def test_shipped_copies_are_identical():
    """problems/scenarios/ (documented place) and the package's copy must not drift apart."""
    doc = sorted(p.name for p in DOCUMENTED.glob("*.toml"))
    pkg = sorted(p.name for p in PACKAGED.glob("*.toml"))
    assert doc == pkg
    for name in doc:
        assert (DOCUMENTED / name).read_bytes() == (PACKAGED / name).read_bytes(), name


def test_shipped_scenarios_load_with_the_paper_values():
    assert set(PAPER) | {"adaptive_fast"} <= set(scenario_names())
    for name in scenario_names():
        sc = load_scenario(name)
        assert sc.name == name
        assert sc.rnn["eps"] == 0.02
        assert sc.dt == 0.001 and sc.duration == 20.0
        np.testing.assert_allclose(sc.data["robot"]["link_lengths"], [0.3, 0.4, 0.15, 0.15])
        c = sc.data["controller"]
        assert (c["alpha"], c["k"], c["d_safe"], c["desired_force"]) == (8.0, 10.0, 0.01, 20.0)
        assert (sc.data["contact"]["stiffness"], sc.data["contact"]["damping"]) == (5000.0, 50.0)
    assert load_scenario("wall").data["obstacles"][0]["point"][0] == -0.05
    assert [o["name"] for o in load_scenario("narrow").data["obstacles"]] == ["upper", "lower"]
    ad, fast = load_scenario("adaptive"), load_scenario("adaptive_fast")
    assert (ad.data["controller"]["kp"], ad.data["controller"]["kd"]) == (4000.0, 80.0)
    np.testing.assert_array_equal(ad.data["adaptive"]["gain"], [500.0, 20.0])
    assert fast.data["adaptive"]["gain"][0] > ad.data["adaptive"]["gain"][0]
    assert load_scenario("free").make_adaptive() is None and ad.make_adaptive() is not None


def test_a_path_works_too(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text((DOCUMENTED / "wall.toml").read_text().replace('name = "wall"\ndescription', 'name = "mine"\ndescription'))
    assert load_scenario(f).name == "mine"
    assert load_scenario(str(f)).path == f
    assert scenario_path("wall").read_bytes() == (DOCUMENTED / "wall.toml").read_bytes()


def edited(tmp_path, old, new, name="wall"):
    text = (DOCUMENTED / f"{name}.toml").read_text()
    assert re.search(old, text, flags=re.M), old
    f = tmp_path / "edited.toml"
    f.write_text(re.sub(old, new, text, count=1, flags=re.M))
    return f


@pytest.mark.parametrize(
    "old,new,key",
    [
        (r"^d_safe = ", "d_sefe = ", "controller.d_sefe"),  # typo: unknown key (reported before the missing one)
        (r"^k = 10.0 .*$", "", "controller.k"),  # missing key
        (r"^alpha = 8.0", 'alpha = "eight"', "controller.alpha"),  # wrong type
        (r"^dt = 0.001", "dt = -0.001", "simulation.dt"),
        (r"^duration = 20.0", "duration = 0.0", "simulation.duration"),
        (r"^link_lengths = \[0.3,", "link_lengths = [0.0,", "robot.link_lengths"),
        (r"^theta0 = \[1.57,", "theta0 = [3.5,", "robot.theta0"),
        (r"^theta0 = \[1.57, ", "theta0 = [", "robot.theta0"),  # 3 values for 4 links
        (r"^\[controller\]", "[controler]", "controler"),  # misspelt table
        (r"^kind = \"line\"", 'kind = "wal"', "obstacles[0].kind"),
        (r"^velocity = \[0.0, 0.0\]", "velocity = [0.0]", "obstacles[0].velocity"),
        (r"^normal = \[1.0, 0.0\]", "normal = [0.0, 0.0]", "obstacles.wall.normal"),
        (r"^eps = 0.02", "eps = -1.0", "rnn.eps"),
        (r"^alpha = 8.0", "alpha = 2000.0", "controller.alpha"),  # alpha dt >= 1
        (r"^kd = 50.0", "kd = 0.0", "controller.kd"),
    ],
)
def test_bad_files_name_the_file_and_key(tmp_path, old, new, key):
    f = edited(tmp_path, old, new)
    with pytest.raises(ScenarioError) as err:
        load_scenario(f)
    msg = str(err.value)
    assert str(f) in msg
    assert f"key '{key}'" in msg, msg
    assert err.value.key == key


def test_unknown_name_and_bad_toml(tmp_path):
    with pytest.raises(ScenarioError, match="shipped"):
        load_scenario("wal")
    with pytest.raises(ScenarioError, match="no such"):
        load_scenario(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[robot\n")
    with pytest.raises(ScenarioError, match="TOML"):
        load_scenario(bad)


def test_overrides_are_validated():
    sc = load_scenario("wall")
    short = sc.with_overrides(duration=1.5, dt=0.002)
    assert (short.duration, short.dt) == (1.5, 0.002)
    assert sc.duration == 20.0  # the original is untouched
    with pytest.raises(ScenarioError, match="simulation.dt"):
        sc.with_overrides(dt=-1.0)


def test_polyline_path_and_other_obstacles(tmp_path):
    text = (DOCUMENTED / "free.toml").read_text()
    text = re.sub(r"\[path\].*?(?=\n\[contact\])", '[path]\nkind = "polyline"\ntimes = [0.0, 10.0]\npoints = [[0.4, 0.5], [0.5, 0.6]]\n', text, flags=re.S)
    text = text.replace("obstacles = []", 'obstacles = [{kind = "disk", name = "ball", center = [0.9, 0.9], radius = 0.05, velocity = [0.0, 0.0]}, {kind = "points", name = "cloud", points = [[1.0, 1.0], [1.1, 1.0]], velocity = [0.0, 0.0]}, {kind = "segment", name = "bar", a = [-1.0, -1.0], b = [-0.9, -1.0], velocity = [0.0, 0.01]}]')
    sc = parse_scenario(text, tmp_path / "x.toml")
    ctrl = sc.make_controller()
    assert ctrl.n_rows == 7 * 4
    assert sc.make_path()(5.0) == pytest.approx((0.45, 0.55, 0.01, 0.01))
