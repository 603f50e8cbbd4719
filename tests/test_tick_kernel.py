"""The closed loop's compiled tick step (qpbench.sim.tick_kernel) against its Python references."""

from __future__ import annotations

import numpy as np
import pytest
from test_environment import contact_force


def test_post_kernel_force_matches_contact_surface():
    """The tick kernel's inline force law agrees with the numpy oracle."""
    from qpbench.sim.scenario import load_scenario
    from qpbench.sim.tick_kernel import APPLIED, get_post_kernel, post_constants

    scenario = load_scenario("wall")
    ctrl, surface = scenario.make_controller(), scenario.make_surface()
    assert surface.noise_std == 0.0
    cols, cidx, ci, cf = post_constants(ctrl, surface, scenario.dt)
    rng = np.random.default_rng(3)
    post = get_post_kernel()
    theta = scenario.theta0.astype(float)
    for _ in range(50):
        arrays = ctrl.build_arrays(theta.copy(), 0.0, ctrl.kp, ctrl.kd, False)
        ee = arrays.ee + rng.normal(0.0, 0.02, 2)
        previous = ee - rng.normal(0.0, 2e-4, 2)
        sensed = np.array([previous[0], previous[1], 0.0, 0.0])
        data = np.zeros((2, len(cols)))
        force = post(
            theta.copy(),
            np.zeros(ctrl.n),
            ee,
            sensed,
            arrays.J,
            arrays.b0,
            arrays.dist,
            arrays.xd,
            np.zeros(0),
            np.zeros(0),
            data,
            1,
            ci,
            cf,
            0.0,
            APPLIED,
            ctrl.kp,
            ctrl.kd,
            0.0,
        )
        expected = contact_force(surface, ee, (ee - previous) / scenario.dt)
        assert force == pytest.approx(expected, rel=1e-12, abs=1e-12)
        assert data[1, cidx["force"]] == force
