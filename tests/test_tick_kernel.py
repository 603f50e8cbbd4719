"""The closed loop's compiled tick step (qpbench.sim.tick_kernel) against its Python references."""

from __future__ import annotations

import numpy as np
import pytest
from test_environment import contact_force


def test_post_kernel_force_matches_contact_surface():
    """The tick kernel's inline force law agrees with the numpy oracle."""
    from qpbench.engine.model import run_model
    from qpbench.sim.scenario import load_scenario
    from qpbench.sim.tick_kernel import APPLIED, get_post_kernel, log_columns

    scenario = load_scenario("wall")
    ctrl, surface = scenario.make_controller(), scenario.make_surface()
    assert surface.noise_std == 0.0
    model = run_model(scenario, ctrl, soft=False)
    names, cols = log_columns(ctrl)
    rng = np.random.default_rng(3)
    post = get_post_kernel()
    theta = scenario.theta0.astype(float)
    for _ in range(50):
        arrays = ctrl.build_arrays(theta.copy(), 0.0, ctrl.kp, ctrl.kd, False)
        ee = arrays.ee + rng.normal(0.0, 0.02, 2)
        previous = ee - rng.normal(0.0, 2e-4, 2)
        sensed = np.array([previous[0], previous[1], 0.0, 0.0])
        data = np.zeros((2, len(names)))
        geometry = (ee, sensed, arrays.J, arrays.b0, arrays.dist, arrays.xd)
        none = np.zeros(0)
        force = post(
            model, cols, theta.copy(), np.zeros(ctrl.n), *geometry, none, none, data, 1, 0.0,
            APPLIED, ctrl.kp, ctrl.kd,
        )  # fmt: skip
        expected = contact_force(surface, ee, (ee - previous) / scenario.dt)
        assert force == pytest.approx(expected, rel=1e-12, abs=1e-12)
        assert data[1, names.index("force")] == force
