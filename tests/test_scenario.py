"""Scenario files: the shipped ones load, typos and impossible values fail naming the file and key."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from qpbench.exceptions import ScenarioError
from qpbench.sim.scenario import (
    load_scenario,
    paper_scenarios,
    parse_scenario,
    scenario_names,
    scenario_path,
)

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "qpbench" / "data" / "scenarios"
PAPER = ("free", "wall", "adaptive", "narrow")


def test_the_paper_scenarios_come_from_the_files_in_section_order(tmp_path, monkeypatch):
    assert paper_scenarios() == list(PAPER)
    OTHERS = [
        "adaptive_fast",
        "disk_on_path",
        "iiwa_wall",
        "moving_disk",
        "panda_shelf",
        "panda_table",
    ]
    assert scenario_names() == [*PAPER, *OTHERS]
    assert [load_scenario(n).in_paper for n in scenario_names()] == [True] * 4 + [False] * len(
        OTHERS
    )
    # a new file is a new scenario: in_paper and its section decide where it goes
    for f in SHIPPED.glob("*.toml"):
        (tmp_path / f.name).write_bytes(f.read_bytes())
    text = (SHIPPED / "wall.toml").read_text()
    (tmp_path / "corner.toml").write_text(
        text.replace('name = "wall"', 'name = "corner"').replace(
            'paper_section = "4.3"', 'paper_section = "4.10"'
        )
    )
    (tmp_path / "aside.toml").write_text(
        text.replace('name = "wall"', 'name = "aside"').replace(
            "in_paper = true", "in_paper = false"
        )
    )
    import qpbench.sim.scenario as files

    monkeypatch.setattr(files, "shipped_dir", lambda: tmp_path)
    assert paper_scenarios() == [*PAPER, "corner"]
    assert scenario_names() == [*PAPER, "corner", "adaptive_fast", "aside", *OTHERS[1:]]
    assert load_scenario("corner").name == "corner"


def test_in_paper_is_optional_and_typed(tmp_path):
    text = (SHIPPED / "wall.toml").read_text()
    f = tmp_path / "mine.toml"
    f.write_text(re.sub(r"^in_paper = .*$", "", text, flags=re.M))
    assert load_scenario(f).in_paper is False
    f.write_text(text.replace("in_paper = true", 'in_paper = "yes"'))
    with pytest.raises(ScenarioError, match="scenario.in_paper"):
        load_scenario(f)


def test_shipped_scenarios_load_with_the_paper_values():
    assert set(PAPER) | {"adaptive_fast"} <= set(scenario_names())
    for name in scenario_names():
        sc = load_scenario(name)
        assert sc.name == name
        assert sc.rnn["eps"] == 0.02
        assert sc.dt == 0.001 and sc.duration == 20.0
        if sc.spec.robot.kind != "planar":
            continue  # the paper's values are the planar arm's
        np.testing.assert_allclose(sc.spec.robot.link_lengths, [0.3, 0.4, 0.15, 0.15])
        c = sc.spec.controller
        assert (c.alpha, c.k, c.d_safe, c.desired_force) == (8.0, 10.0, 0.01, 20.0)
        assert (sc.spec.contact.stiffness, sc.spec.contact.damping) == (5000.0, 50.0)
    assert load_scenario("wall").spec.obstacles[0].point[0] == -0.05
    assert [o.name for o in load_scenario("narrow").spec.obstacles] == ["upper", "lower"]
    ad, fast = load_scenario("adaptive"), load_scenario("adaptive_fast")
    assert (ad.spec.controller.kp, ad.spec.controller.kd) == (4000.0, 80.0)
    np.testing.assert_array_equal(ad.spec.adaptive.gain, [500.0, 20.0])
    assert fast.spec.adaptive.gain[0] > ad.spec.adaptive.gain[0]
    assert load_scenario("free").make_adaptive() is None and ad.make_adaptive() is not None


def test_a_path_works_too(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text(
        (SHIPPED / "wall.toml")
        .read_text()
        .replace('name = "wall"\ndescription', 'name = "mine"\ndescription')
    )
    assert load_scenario(f).name == "mine"
    assert load_scenario(str(f)).path == f
    assert scenario_path("wall").read_bytes() == (SHIPPED / "wall.toml").read_bytes()


def edited(tmp_path, old, new, name="wall"):
    text = (SHIPPED / f"{name}.toml").read_text()
    assert re.search(old, text, flags=re.M), old
    f = tmp_path / "edited.toml"
    f.write_text(re.sub(old, new, text, count=1, flags=re.M))
    return f


@pytest.mark.parametrize(
    "old,new,key",
    [
        (
            r"^d_safe = ",
            "d_sefe = ",
            "controller.d_sefe",
        ),  # typo: unknown key (reported before the missing one)
        (r"^k = 10.0 .*$", "", "controller.k"),  # missing key
        (r"^alpha = 8.0", 'alpha = "eight"', "controller.alpha"),  # wrong type
        (r"^dt = 0.001", "dt = -0.001", "simulation.dt"),
        (r"^duration = 20.0", "duration = 0.0", "simulation.duration"),
        (r"^link_lengths = \[0.3,", "link_lengths = [0.0,", "robot.link_lengths"),
        (r"^theta0 = \[1.57,", "theta0 = [3.5,", "robot.theta0"),
        (r"^theta0 = \[1.57, ", "theta0 = [", "robot.theta0"),  # 3 values for 4 links
        (r"^\[controller\]", "[controler]", "controler"),  # misspelt table
        (r"^kind = \"line\"", 'kind = "wal"', "obstacles[0].kind"),
        # a kind that is not a string (a list cannot be looked up among the kinds)
        (r"^kind = \"line\"", 'kind = ["line"]', "obstacles[0].kind"),
        (r"^kind = \"cosine\"", 'kind = ["cosine"]', "path.kind"),
        (r"^link_radius = ", 'kind = ["paper"]\nlink_radius = ', "key_points.kind"),
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


def test_a_dh_robot_names_its_unknown_key_and_every_robot_kind(tmp_path):
    """An unknown key of a ``dh`` robot and an unknown robot kind are one-line errors listing
    the dh table's keys and every kind, dh included."""
    rows = "a = [0.0, 0.0, 0.0, 0.0]\nd = [0.333, 0.5, 0.5, 0.107]\nalpha = [0.0, 1.57, -1.57, 0.0]"
    f = edited(tmp_path, r'^kind = "iiwa14"', f'kind = "dh"\n{rows}\nbogus = 1', "iiwa_wall")
    with pytest.raises(ScenarioError, match="unknown key .*alpha") as err:
        load_scenario(f)
    assert err.value.key == "robot.bogus"
    f = edited(tmp_path, r'^kind = "iiwa14"', 'kind = "dhx"', "iiwa_wall")
    with pytest.raises(ScenarioError, match="planar, panda, iiwa14, dh, urdf"):
        load_scenario(f)


@pytest.mark.parametrize(
    "setting,key",
    [
        ('obstacles[0].kind=["line"]', "obstacles[0].kind"),
        ('path.kind=["cosine"]', "path.kind"),
        ('key_points.kind=["paper"]', "key_points.kind"),
    ],
)
def test_a_list_for_a_kind_is_one_line_exit_2(tmp_path, capsys, setting, key):
    from qpbench.cli import main

    f = edited(tmp_path, r"^name = \"wall\"", 'name = "wall"')  # the shipped file, as a path
    args = ["simulate", "--scenario", str(f), "--backend", "pinv", "--duration", "0.01"]
    assert main([*args, "--set", setting]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(f) in err[0] and f"key '{key}'" in err[0], err
    assert "expected one of" in err[0]


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
    text = (SHIPPED / "free.toml").read_text()
    text = re.sub(
        r"\[path\].*?(?=\n\[contact\])",
        '[path]\nkind = "polyline"\ntimes = [0.0, 10.0]\npoints = [[0.4, 0.5], [0.5, 0.6]]\n',
        text,
        flags=re.S,
    )
    text = text.replace(
        "obstacles = []",
        'obstacles = [{kind = "disk", name = "ball", center = [0.9, 0.9], radius = 0.05, velocity = [0.0, 0.0]}, '
        '{kind = "points", name = "cloud", points = [[1.0, 1.0], [1.1, 1.0]], velocity = [0.0, 0.0]}, '
        '{kind = "segment", name = "bar", a = [-1.0, -1.0], b = [-0.9, -1.0], velocity = [0.0, 0.01]}]',
    )
    sc = parse_scenario(text, tmp_path / "x.toml")
    ctrl = sc.make_controller()
    assert ctrl.n_rows == 7 * 4
    assert sc.make_path()(5.0) == pytest.approx((0.45, 0.55, 0.01, 0.01))


# ------------------------------------------------------------------ qpbench scenarios


def test_scenarios_lists_every_shipped_file(capsys):
    from qpbench.cli import main

    assert main(["scenarios"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:4] == ["name", "paper", "duration", "obstacles"]
    assert [line.split()[0] for line in lines[1:]] == scenario_names()
    narrow = next(line for line in lines if line.startswith("narrow "))
    assert (
        "upper, lower" in narrow
        and "20 s" in narrow
        and load_scenario("narrow").description in narrow
    )
    assert main(["scenarios", "--json"]) == 0
    items = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [i["name"] for i in items] == scenario_names()
    assert items[0] == {
        "name": "free",
        "paper_section": "4.2",
        "in_paper": True,
        "duration_s": 20.0,
        "obstacles": [],
        "description": load_scenario("free").description,
    }


def test_scenarios_show_prints_a_file_to_start_from(tmp_path, capsys):
    from qpbench.cli import main

    assert main(["scenarios", "show", "wall"]) == 0
    text = capsys.readouterr().out
    assert text == (SHIPPED / "wall.toml").read_text()
    mine = tmp_path / "mine.toml"
    mine.write_text(
        text.replace('name = "wall"', 'name = "mine"').replace("d_safe = 0.01 ", "d_safe = 0.02 ")
    )
    assert load_scenario(mine).spec.controller.d_safe == 0.02
    assert main(["scenarios", "show", "narrow", "--json"]) == 0
    tables = json.loads(capsys.readouterr().out)
    assert tables["scenario"]["name"] == "narrow" and [o["name"] for o in tables["obstacles"]] == [
        "upper",
        "lower",
    ]


@pytest.mark.parametrize(
    "args, what",
    [
        (["show"], "which scenario"),
        (["show", "nope"], "no shipped scenario"),
        (["wall"], "show wall"),
        (["list", "wall"], "show wall"),
    ],
)
def test_scenarios_bad_input_is_one_line_and_exit_2(capsys, args, what):
    from qpbench.cli import main

    assert main(["scenarios", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and what in err
