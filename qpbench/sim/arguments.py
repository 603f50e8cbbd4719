"""Checks of :func:`qpbench.sim.loop.simulate`'s arguments, and the backend instance for a scenario."""

from __future__ import annotations

import numpy as np

from ..backends import Backend, backend_class, get_backend
from ..control.controller import check_formulation
from ..exceptions import ParamError, positive_seconds
from .scenario import Scenario

__all__ = ["check_arguments", "resolve_backend"]


def resolve_backend(
    backend: str | Backend, scenario: Scenario, dt: float, profile: str = "default"
) -> Backend:
    """A backend instance for ``scenario``: by name, or the given instance checked.

    A backend class whose ``scenario_table`` names a table of the scenario (the ``rnn``
    backends) gets that table's settings; an online backend also the control period ``dt``
    [s], which an instance's own ``dt`` must match.
    """
    if isinstance(backend, str):
        cls = backend_class(backend)
        settings = {}
        if cls.scenario_table:
            settings.update(getattr(scenario, cls.scenario_table))
        if cls.online:
            settings.setdefault("dt", dt)
        return get_backend(backend, profile=profile, **settings)
    if not isinstance(backend, Backend):
        raise ParamError(
            f"expected a backend name or instance, got {type(backend).__name__}", key="backend"
        )
    own_dt = getattr(backend, "dt", None)
    if own_dt is not None and abs(float(own_dt) - dt) > 1e-15:
        raise ParamError(
            f"the backend integrates dt = {own_dt} s per call but the loop's dt is {dt} s", key="dt"
        )
    return backend


def check_arguments(formulation: str, every, deadline, wall_budget_s) -> None:
    """Check :func:`qpbench.sim.loop.simulate`'s arguments (:class:`ParamError` naming the key)."""
    check_formulation(formulation)
    if every is not None and (not isinstance(every, (int, np.integer)) or every < 1):
        raise ParamError(f"must be an integer >= 1, got {every!r}", key="every")
    for key, value in (("deadline", deadline), ("wall_budget_s", wall_budget_s)):
        if isinstance(value, str):  # float() would read it, but the API takes numbers
            raise ParamError(f"expected a positive number of seconds, got {value!r}", key=key)
        if value is not None:
            positive_seconds(value, key)
