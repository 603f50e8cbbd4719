"""Settings profiles: the settings given to every backend (relative tolerances zero, so that
every backend stops on the same absolute criterion) and the thresholds of a success, as
qpbenchmark pairs its settings with a ``Tolerance``; ``qpbenchmark:<settings>`` applies
qpbenchmark's runner as read from its installed modules (docs/methodology.md).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace

from .exceptions import check_choice
from .published import SETTINGS_NAMES, qpbenchmark_settings

#: Prefix of the profiles that apply qpbenchmark's own settings.
QPBENCHMARK_PREFIX = "qpbenchmark:"


@dataclass(frozen=True)
class Tolerance:
    """Thresholds of a success: max primal and dual residual, absolute duality gap (inf-norms),
    time limit ``runtime`` [s]; ``rule``: ``qpbench`` or ``qpbenchmark`` (:func:`metrics.evaluate`)."""

    primal: float
    dual: float
    gap: float
    runtime: float
    rule: str = "qpbench"


@dataclass(frozen=True)
class Profile:
    """A named set of solver settings (``time_limit`` [s] per solve) and success thresholds;
    ``reference_time_limit`` [s] bounds each reference solve; ``solver_options`` (a
    qpbenchmark profile's) are the keyword arguments its runner passes per solver."""

    name: str
    eps_abs: float
    eps_rel: float
    max_iter: int
    time_limit: float
    tolerance: Tolerance
    reference_time_limit: float = 60.0
    solver_options: dict | None = field(default=None, hash=False)

    def with_time_limit(self, time_limit: float) -> Profile:
        """The same profile with another per-solve time limit [s] (and solver arguments)."""
        if self.name.startswith(QPBENCHMARK_PREFIX):
            rebuilt = qpbenchmark_profile(self.name.removeprefix(QPBENCHMARK_PREFIX), time_limit)
            return replace(rebuilt, reference_time_limit=self.reference_time_limit)
        return replace(
            self,
            time_limit=float(time_limit),
            tolerance=replace(self.tolerance, runtime=float(time_limit)),
        )


PROFILES: dict[str, Profile] = {
    p.name: p
    for p in (
        Profile("low_accuracy", 1e-4, 0.0, 10_000, 1.0, Tolerance(1e-3, 1e-3, 1e-3, 1.0)),
        Profile("default", 1e-7, 0.0, 100_000, 10.0, Tolerance(1e-6, 1e-6, 1e-6, 10.0)),
        Profile("high_accuracy", 1e-9, 0.0, 1_000_000, 10.0, Tolerance(1e-9, 1e-9, 1e-9, 10.0)),
    )
}


def profile_names() -> tuple[str, ...]:
    """Every profile name ``--profile`` accepts: qpbench's, then qpbenchmark's."""
    return tuple(PROFILES) + tuple(QPBENCHMARK_PREFIX + s for s in SETTINGS_NAMES)


@functools.lru_cache(maxsize=None)
def qpbenchmark_profile(settings: str, time_limit: float | None = None) -> Profile:
    """The profile ``qpbenchmark:<settings>`` (``settings`` one of :data:`SETTINGS_NAMES`);
    ``time_limit`` [s] per solve (``None``: qpbenchmark's default runtime)."""
    kwargs, tolerances = qpbenchmark_settings(time_limit)
    tol = tolerances[settings]
    options = kwargs[settings]
    # the tolerance qpbenchmark asks of its solvers (its set_eps_abs / set_eps_rel), read from OSQP's arguments
    eps_abs = float(options["osqp"].get("eps_abs", PROFILES["default"].eps_abs))
    eps_rel = float(options["osqp"].get("eps_rel", 0.0))
    runtime = float(tol.runtime)
    return Profile(
        QPBENCHMARK_PREFIX + settings,
        eps_abs,
        eps_rel,
        PROFILES["high_accuracy"].max_iter,
        runtime,
        Tolerance(float(tol.primal), float(tol.dual), float(tol.gap), runtime, rule="qpbenchmark"),
        solver_options={solver: dict(kw) for solver, kw in options.items()},
    )


def get_profile(name: str | Profile) -> Profile:
    """The profile called ``name`` (a :class:`Profile` passes through)."""
    if isinstance(name, Profile):
        return name
    check_choice(name, profile_names(), "profile", "profile")
    if name.startswith(QPBENCHMARK_PREFIX):
        return qpbenchmark_profile(name.removeprefix(QPBENCHMARK_PREFIX))
    return PROFILES[name]
