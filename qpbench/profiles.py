"""Settings profiles: what accuracy a solve is asked for and judged against.

Each profile pairs the settings passed to every backend (absolute and relative
tolerances, iteration limit, time limit) with the thresholds used to call a
solve a success, as qpbenchmark pairs its ``low_accuracy``, ``mid_accuracy``
and ``high_accuracy`` settings with a ``Tolerance``.

============== ========= ======== ========== ===================================
profile        eps_abs   max_iter time_limit success: primal, dual, gap (each)
============== ========= ======== ========== ===================================
low_accuracy   1e-4      1e4      1 s        1e-3
default        1e-7      1e5      10 s       1e-6
high_accuracy  1e-10     1e6      10 s       1e-9
============== ========= ======== ========== ===================================

Solvers are asked for ten times the accuracy they are judged at: a solver's own
stopping test (scaled, relative, or on a different residual) does not match
qpsolvers' unscaled residuals exactly, and a solver that honours its own
tolerance should not fail ours by a hair. Relative tolerances are zero so that
every backend stops on the same absolute criterion. The success thresholds are
qpbenchmark's for ``low_accuracy``, ``mid_accuracy`` and ``high_accuracy``.
"""

from __future__ import annotations

from dataclasses import dataclass

from .exceptions import ParamError


@dataclass(frozen=True)
class Tolerance:
    """Thresholds a solution must meet to count as a success.

    Attributes:
        primal: Max primal residual (inf-norm of constraint violation).
        dual: Max dual residual (inf-norm of stationarity error).
        gap: Max absolute duality gap.
        runtime: Time limit in [s] (same meaning as qpbenchmark's ``Tolerance.runtime``).
    """

    primal: float
    dual: float
    gap: float
    runtime: float


@dataclass(frozen=True)
class Profile:
    """A named set of solver settings and success thresholds.

    Attributes:
        name: ``low_accuracy``, ``default`` or ``high_accuracy``.
        eps_abs: Absolute tolerance requested from solvers.
        eps_rel: Relative tolerance requested from solvers.
        max_iter: Iteration limit requested from solvers.
        time_limit: Per-solve time limit in [s].
        tolerance: Thresholds of a successful solve.
    """

    name: str
    eps_abs: float
    eps_rel: float
    max_iter: int
    time_limit: float
    tolerance: Tolerance


PROFILES: dict[str, Profile] = {
    "low_accuracy": Profile(
        "low_accuracy", 1e-4, 0.0, 10_000, 1.0, Tolerance(1e-3, 1e-3, 1e-3, 1.0)
    ),
    "default": Profile(
        "default", 1e-7, 0.0, 100_000, 10.0, Tolerance(1e-6, 1e-6, 1e-6, 10.0)
    ),
    "high_accuracy": Profile(
        "high_accuracy", 1e-10, 0.0, 1_000_000, 10.0, Tolerance(1e-9, 1e-9, 1e-9, 10.0)
    ),
}


def get_profile(name: str | Profile) -> Profile:
    """Return the profile called ``name`` (a :class:`Profile` passes through).

    Raises:
        ParamError: ``name`` is not a known profile.
    """
    if isinstance(name, Profile):
        return name
    try:
        return PROFILES[name]
    except KeyError:
        raise ParamError(
            f"unknown profile '{name}' (choose from {', '.join(PROFILES)})", key="profile"
        ) from None
