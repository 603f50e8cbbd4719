"""A new backend is one file: dropped in ``qpbench/backends/``, installed as an entry point, or a plugin file.

The first two run in fresh processes (the registry lists the package and the
entry points once per process) through ``qpbench backends``, ``simulate``,
``bench`` and ``closed-loop``; the entry-point backend is marked ``risky``, so
the harness solves it in a worker process, which must find it too.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import faulty_backends as fb
import pandas as pd
import pytest
from conftest import simulate_args

import qpbench.backends
from qpbench.backends import (
    backend_class,
    backend_names,
    builtin_modules,
    load_plugins,
    plugin_files,
)
from qpbench.cli import main

QPBENCH = [sys.executable, "-m", "qpbench.cli"]

#: One backend in one file: DAQP through qpsolvers, the smallest complete backend.
BACKEND_SOURCE = '''
"""A backend of the plugin tests: DAQP through qpsolvers.solve_problem."""

import qpsolvers

from qpbench.backends import Backend, BackendSolution, register


{decorator}class {cls}(Backend):
    name = "{name}"
    family = "active set (test)"
    risky = {risky}
    certifies_infeasibility = False
    infeasibility_note = "qpsolvers drops DAQP's exit flag"

    def _solve(self, problem, warm_start):
        result = qpsolvers.solve_problem(problem, "daqp")
        sol = BackendSolution(problem, status="optimal" if result.found else "not_solved")
        sol.x, sol.y, sol.z, sol.z_box = result.x, result.y, result.z, result.z_box
        return sol
'''


def _source(name: str, cls: str, register: bool, risky: bool = False) -> str:
    return BACKEND_SOURCE.format(
        name=name, cls=cls, decorator="@register\n" if register else "", risky=risky
    )


def _run(args: list[str], env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(QPBENCH + args, capture_output=True, text=True, env=env, timeout=600)


def _runs_everywhere(name: str, tmp_path: Path, env: dict | None = None) -> None:
    """``name`` is listed by ``qpbench backends`` and runs in ``simulate``, ``bench`` and ``closed-loop``."""
    listed = _run(["backends", "--available", "--json"], env)
    assert listed.returncode == 0, listed.stderr
    assert name in [json.loads(line)["name"] for line in listed.stdout.splitlines()]

    summary = tmp_path / "sim.json"
    sim = _run(
        [
            "-q",
            *simulate_args("wall", name, "0.2"),
            "--summary",
            str(summary),
        ],
        env,
    )
    assert sim.returncode == 0, sim.stderr
    assert json.loads(summary.read_text())["verdict"] == "ok"

    problems = fb.write_tick_set(tmp_path / "set", 3)
    csv = tmp_path / "bench.csv"
    bench = _run(
        ["-q", "bench", str(problems), "--backends", f"{name},daqp", "--out", str(csv)], env
    )
    assert bench.returncode == 0, bench.stderr
    rows = pd.read_csv(csv)
    mine = rows[rows["backend"] == name]
    assert len(mine) == 3 and mine["success"].all()

    loop = _run(
        [
            "-q",
            "closed-loop",
            "--scenarios",
            "wall",
            "--backends",
            name,
            "--duration",
            "0.2",
            "--out",
            str(tmp_path / "loop"),
        ],
        env,
    )
    assert loop.returncode == 0, loop.stderr
    row = pd.read_csv(tmp_path / "loop" / "closed_loop.csv").iloc[1]  # after the noise floor's
    assert row["backend"] == name and row["status"] == "ok" and row["verdict"] == "ok"
    return mine, row


@pytest.mark.slow
def test_a_module_dropped_in_the_package_is_a_backend(tmp_path):
    package = Path(qpbench.backends.__file__).parent
    module = package / "zz_plugin_test_dropped.py"
    assert not module.exists()
    try:
        module.write_text(_source("test-dropped-in", "DroppedIn", register=True))
        _, row = _runs_everywhere("test-dropped-in", tmp_path)
        assert not bool(row["isolated"])
    finally:
        module.unlink(missing_ok=True)
    assert "zz_plugin_test_dropped" not in builtin_modules()


@pytest.mark.slow
def test_an_installed_entry_point_is_a_backend(tmp_path):
    """A distribution on sys.path declaring ``[qpbench.backends]`` in its entry_points.txt; a worker finds it too."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "qpbench_test_entry_point.py").write_text(
        _source("test-entry-point", "EntryPoint", register=False, risky=True)
    )
    info = site / "qpbench_test_entry_point-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: qpbench-test-entry-point\nVersion: 0.1\n"
    )
    (info / "entry_points.txt").write_text(
        "[qpbench.backends]\ntest-entry-point = qpbench_test_entry_point:EntryPoint\n"
    )
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]).rstrip(
            os.pathsep
        ),
    )
    env.pop("QPBENCH_PLUGINS", None)
    mine, row = _runs_everywhere("test-entry-point", tmp_path, env)
    assert mine["isolated"].all() and bool(row["isolated"])  # risky: solved in worker processes

    # a broken entry point: one line naming it, exit 2
    (site / "qpbench_test_entry_point.py").write_text("raise ImportError('missing dependency')\n")
    broken = _run(["backends"], env)
    assert broken.returncode == 2
    assert (
        broken.stderr.count("\n") == 1
        and "test-entry-point" in broken.stderr
        and "missing dependency" in broken.stderr
    )


def _plugin_file(path: Path, name: str) -> Path:
    path.write_text(_source(name, "PluginFile", register=True))
    return path


def test_plugin_file_before_or_after_the_command_and_from_the_environment(tmp_path, capsys):
    a = _plugin_file(tmp_path / "a_backend.py", "test-plugin-a")
    b = _plugin_file(tmp_path / "b_backend.py", "test-plugin-b")
    c = _plugin_file(tmp_path / "c_backend.py", "test-plugin-c")
    env = dict(os.environ, QPBENCH_PLUGINS=os.pathsep.join([str(c), ""]))
    proc = _run(["--plugin", str(a), "backends", "--plugin", str(b), "--json"], env)
    assert proc.returncode == 0, proc.stderr
    names = [json.loads(line)["name"] for line in proc.stdout.splitlines()]
    assert {"test-plugin-a", "test-plugin-b", "test-plugin-c"} <= set(names)


def test_a_plugin_is_loaded_once_and_simulated(tmp_path):
    plugin = _plugin_file(tmp_path / "once_backend.py", "test-plugin-once")
    summary = tmp_path / "s.json"
    for _ in range(2):
        assert (
            main(
                [
                    "-q",
                    "--plugin",
                    str(plugin),
                    *simulate_args("free", "test-plugin-once", "0.05"),
                    "--summary",
                    str(summary),
                    "--force",
                ]
            )
            == 0
        )
    assert plugin_files().count(str(plugin.resolve())) == 1
    assert sum(1 for m in sys.modules if m.startswith("qpbench_plugin_once_backend")) == 1
    assert (
        "test-plugin-once" in backend_names()
        and backend_class("TEST-PLUGIN-ONCE").name == "test-plugin-once"
    )
    load_plugins([plugin])  # again: nothing happens
    assert plugin_files().count(str(plugin.resolve())) == 1


@pytest.mark.parametrize(
    "body, what",
    [
        ("raise RuntimeError('broken\\nplugin')", "RuntimeError: broken plugin"),
        ("def f(:\n", "SyntaxError"),
        (None, "no such plugin file"),
    ],
)
def test_a_broken_plugin_file_is_one_line_and_exit_2(tmp_path, capsys, body, what):
    plugin = tmp_path / "broken_backend.py"
    if body is not None:
        plugin.write_text(textwrap.dedent(body))
    out = tmp_path / "never.csv"
    assert (
        main(
            [
                "--plugin",
                str(plugin),
                "bench",
                str(tmp_path),
                "--backends",
                "daqp",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(plugin) in err and what in err, err
    assert not out.exists()


def test_a_module_name_is_not_a_plugin_file(capsys):
    assert main(["--plugin", "some.module", "backends"]) == 2
    assert "no such plugin file" in capsys.readouterr().err
