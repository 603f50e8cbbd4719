"""The compiled engine against the Python engine: the same trajectory, statuses and verdict
for the same backend and settings (the only difference is who calls the solver)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import panda_adaptive

from qpbench.engine.compiled import SOLVERS
from qpbench.sim.log import TIME_COLUMNS
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import run_scenarios

#: The largest difference allowed between the two engines' logs, relative to the value where it
#: is above 1 (an adaptive gain of 5,000 N/m carries 1e-12 of rounding in its last bits).
TOLERANCE = 1e-12


def engines_agree(scenario, backend: str, duration: float, **terms) -> dict:
    """Both engines' runs of ``scenario`` with ``backend``; asserts logs and verdicts agree and
    returns the compiled run's summary."""
    python = simulate(scenario, backend, duration=duration, engine="python", **terms)
    compiled = simulate(scenario, backend, duration=duration, engine="compiled", **terms)
    assert python.summary["engine"] == "python"
    assert compiled.summary["engine"] == "compiled", compiled.summary["engine_note"]
    a, b = python.log, compiled.log
    assert list(a.columns) == list(b.columns)
    assert (a["status"] == b["status"]).all()
    for flag in ("fallback", "zero_velocity"):
        assert (a[flag] == b[flag]).all()
    numbers = [c for c in a.columns if c not in TIME_COLUMNS and a[c].dtype.kind == "f"]
    x, y = a[numbers].to_numpy(), b[numbers].to_numpy()
    assert (np.isnan(x) == np.isnan(y)).all()
    assert np.nanmax(np.abs(x - y) / np.maximum(1.0, np.abs(x))) <= TOLERANCE
    for key in ("verdict", "verdict_reasons", "fallback_ticks", "infeasible_ticks"):
        assert python.summary[key] == compiled.summary[key], key
    for column in TIME_COLUMNS:  # every clock is read on both engines
        if column != "solver_time_s" and "fallback" not in column:
            assert b[column].notna().all() and (b[column] >= 0).all(), column
    return compiled.summary


#: The backends with a compiled solve that the engines are compared on.
BACKENDS = ("daqp", "daqp-stateless", "qpoases", "pinv", "rnn-tuned")
#: Every scenario ``qpbench run`` runs with two of :data:`BACKENDS`, taken in turn (the second
#: two places on): every scenario meets two backends and every backend two scenarios; the
#: full product would compare the same code paths two and a half times over.
PAIRS = [
    (scenario, BACKENDS[(i + step) % len(BACKENDS)])
    for i, scenario in enumerate(run_scenarios())
    for step in (0, 2)
]


def test_the_pairs_cover_every_scenario_and_backend():
    assert {s for s, _ in PAIRS} == set(run_scenarios())
    assert {b for _, b in PAIRS} == set(BACKENDS) <= set(SOLVERS)


@pytest.mark.parametrize("scenario, backend", PAIRS)
def test_engines_give_the_same_run(scenario, backend):
    engines_agree(scenario, backend, duration=2.0)


@pytest.mark.parametrize("backend", ["daqp", "qpoases", "pinv"])
def test_engines_give_the_same_spatial_run(backend):
    """The Panda of ``panda_table``: 3 task rows, closest-point rows against a ball."""
    summary = engines_agree("panda_table", backend, duration=3.0)
    assert summary["ticks"] == 3000


def test_engines_give_the_same_spatial_adaptive_run():
    """The adaptive law along the table's normal: the same ``Kp_hat``, ``Kd_hat`` every tick."""
    summary = engines_agree(panda_adaptive(duration=2.0), "daqp", duration=2.0)
    assert summary["kp_hat_final"] > 4500.0  # the law ran (from 4000 N/m)


def test_engines_agree_with_the_paper_network_and_the_soft_formulation():
    engines_agree("narrow", "rnn", duration=1.0)
    engines_agree("wall", "rnn-tuned", duration=1.0, formulation="soft")
    engines_agree("wall", "pinv", duration=0.5, formulation="soft")


def test_a_backend_without_a_compiled_solve_runs_on_the_python_engine():
    result = simulate("wall", "osqp", duration=0.01, engine="compiled")
    assert result.summary["engine"] == "python"
    assert result.summary["engine_note"] == "no compiled solve"


def test_the_wall_time_budget_stops_the_compiled_engine_between_ticks():
    result = simulate("wall", "rnn-tuned", duration=20.0, wall_budget_s=1e-4, engine="compiled")
    assert result.summary["engine"] == "compiled"
    assert result.summary["stopped_early"]
    assert 0 < len(result.log) < 20_000


def test_every_compiled_solve_has_a_python_backend():
    from qpbench.backends import backend_class

    for name in SOLVERS:
        assert backend_class(name).name == name


def test_the_fallback_solves_on_its_own_instance_on_both_engines(monkeypatch):
    """The soft fallback has a solver instance of its own (a controller keeps one solver per QP
    it solves): the tick's instance sees only paper QPs, the fallback's only soft ones, so a
    persistent solver is never rebuilt for a change of shape; the compiled engine likewise."""
    from qpbench import backends
    from qpbench.backends.daqp_ import DaqpModelBackend

    monkeypatch.setattr(backends, "_REGISTRY", dict(backends._registry()))  # restored after

    shapes: dict[int, set] = {}

    @backends.register
    class ShapeCounting(DaqpModelBackend):
        name = "test-shape-counting"

        def _attempt(self, problem, warm_start):
            shapes.setdefault(id(self), set()).add(problem.A is None)
            return super()._attempt(problem, warm_start)

    result = simulate("free", "test-shape-counting", duration=0.2, warmup_ticks=0)
    assert result.summary["fallback_ticks"] > 50
    assert sorted(len(seen) for seen in shapes.values()) == [1, 1]
    # and the compiled engine, with a state per instance, gives the same run
    engines_agree("free", "daqp", duration=0.2)
