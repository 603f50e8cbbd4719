"""The one model of a closed-loop run, as named data: built once per run from the scenario and
read by both engines (:mod:`qpbench.engine.compiled`, :mod:`qpbench.sim.loop`) and the summary.

It holds the controller's constants (:class:`~qpbench.control.build_kernel.ControllerModel`:
kinematics, key points, obstacles, limits, path), the plant and contact surface, the adaptive
law and the force-sensor noise, drawn before the run so that both engines see the same numbers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..control.build_kernel import ControllerModel

if TYPE_CHECKING:
    from ..control.controller import Controller
    from ..sim.scenario import Scenario


class RunModel(NamedTuple):
    """One run: ``controller`` constants; control period ``dt`` [s] and ``ticks``; start angles
    ``theta0`` [rad]; ``soft``: the tick's QP is the soft formulation (no fallback then);
    ``online``: the backend's answer is applied whatever its status (the network);
    ``deadline`` [s]: a later answer is dropped (``inf``: none). Contact surface (the
    environment's spring-damper): penetration ``normal . x - surface_offset`` [m],
    ``stiffness`` [N/m], ``damping`` [N s/m]; ``tangent`` (dim,) of a planar arm's tracking
    error (zero on a spatial arm, whose error is the one in the contact plane).
    ``adaptive``: the law of section 4.4 runs with constants ``law``
    (:meth:`~qpbench.control.adaptive.AdaptiveImpedance.law`); ``kp0, kd0``: the first tick's
    coefficients. ``noise`` (ticks,) [N]: the force sensor's noise of every tick."""

    controller: ControllerModel
    dt: float
    ticks: int
    theta0: np.ndarray
    soft: bool
    online: bool
    deadline: float
    surface_offset: float
    stiffness: float
    damping: float
    tangent: np.ndarray
    adaptive: bool
    law: np.ndarray
    kp0: float
    kd0: float
    noise: np.ndarray


def run_model(
    scenario: Scenario,
    controller: Controller,
    soft: bool,
    online: bool = False,
    deadline: float | None = None,
) -> RunModel:
    """The model of ``scenario``'s run with ``controller`` (its own, made once by the caller)."""
    dt = scenario.dt
    ticks = int(round(scenario.duration / dt))
    surface = scenario.make_surface()
    normal = controller.model.normal
    adaptive = scenario.make_adaptive()
    noise = np.zeros(ticks)
    if surface.noise_std > 0.0:
        noise = surface.noise_std * np.random.default_rng(surface.seed).standard_normal(ticks)
    return RunModel(
        controller=controller.model,
        dt=float(dt),
        ticks=ticks,
        theta0=np.ascontiguousarray(scenario.theta0, dtype=np.float64),
        soft=bool(soft),
        online=bool(online),
        deadline=np.inf if deadline is None else float(deadline),
        surface_offset=float(normal @ surface.point),
        stiffness=float(surface.stiffness),
        damping=float(surface.damping),
        tangent=np.array([-normal[1], normal[0]]) if normal.size == 2 else np.zeros(3),
        adaptive=adaptive is not None,
        law=np.zeros(5 + normal.size) if adaptive is None else adaptive.law(),
        kp0=float(controller.kp),
        kd0=float(controller.kd),
        noise=noise,
    )
