"""Settings profiles: what accuracy a solve is asked for and judged against.

Each profile pairs the settings given to every backend with the thresholds of a success,
as qpbenchmark pairs its settings with a ``Tolerance``:

============== ========= ======== ========== ===================================
profile        eps_abs   max_iter time_limit success: primal, dual, gap (each)
============== ========= ======== ========== ===================================
low_accuracy   1e-4      1e4      1 s        1e-3
default        1e-7      1e5      10 s       1e-6
high_accuracy  1e-9      1e6      10 s       1e-9
============== ========= ======== ========== ===================================

``low_accuracy`` and ``default`` ask for ten times the accuracy they judge (a solver's
own stopping test does not match qpsolvers' unscaled residuals exactly); ``high_accuracy``
asks for what it judges, as qpbenchmark does (``bench/accuracy_margin.py`` compares the
margins). Relative tolerances are zero so that every backend stops on the same absolute
criterion. A solve succeeds when each residual is at most its threshold and, against an
optimal reference, so is the optimality gap (:mod:`qpbench.metrics`).
``reference_time_limit`` [s] bounds each reference solve.

``qpbenchmark:<settings>`` (:func:`qpbenchmark_profile`) applies qpbenchmark's runner as
read from its installed modules (:func:`qpbench.published.qpbenchmark_settings`): a
``qpsolvers:<name>`` backend gets its keyword arguments verbatim (``--set`` still adds);
the time limit is its ``Tolerance.runtime`` (``--time-limit`` replaces it in the solvers'
arguments too, as its ``set_time_limit`` does); success is its strict rule (``rule =
"qpbenchmark"``), the reference playing no part. The own-API backends of those solvers
get the same arguments (:func:`qpbench.backends._common.solver_options`); other
backends get ``eps_abs`` (qpbench's ``default`` where qpbenchmark asks for none),
``eps_rel = 0``, ``max_iter`` 1e6 and the time limit.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace

from .exceptions import ParamError

#: Prefix of the profiles that apply qpbenchmark's own settings.
QPBENCHMARK_PREFIX = "qpbenchmark:"
#: Success rules: ``qpbench`` (thresholds included, optimality gap and infeasibility
#: verdicts of the reference) and ``qpbenchmark`` (its rule, strict, no reference).
RULES = ("qpbench", "qpbenchmark")


@dataclass(frozen=True)
class Tolerance:
    """Thresholds of a success: max primal residual, dual residual and absolute duality gap
    (inf-norms), the time limit ``runtime`` [s] (as qpbenchmark's) and the ``rule``."""

    primal: float
    dual: float
    gap: float
    runtime: float
    rule: str = "qpbench"


@dataclass(frozen=True)
class Profile:
    """A named set of solver settings (``time_limit`` [s] per solve) and success thresholds.

    ``reference_time_limit`` [s] bounds each reference solve; ``solver_options`` (a
    qpbenchmark profile's) are the keyword arguments its runner passes per solver.
    """

    name: str
    eps_abs: float
    eps_rel: float
    max_iter: int
    time_limit: float
    tolerance: Tolerance
    reference_time_limit: float = 60.0
    solver_options: dict | None = field(default=None, hash=False)

    @property
    def is_qpbenchmark(self) -> bool:
        return self.name.startswith(QPBENCHMARK_PREFIX)

    def with_time_limit(self, time_limit: float) -> Profile:
        """The same profile with another per-solve time limit [s] (a qpbenchmark profile's
        solver arguments change with it, as its ``set_time_limit`` makes them)."""
        if self.is_qpbenchmark:
            rebuilt = qpbenchmark_profile(self.name[len(QPBENCHMARK_PREFIX) :], time_limit)
            return replace(rebuilt, reference_time_limit=self.reference_time_limit)
        return replace(
            self,
            time_limit=float(time_limit),
            tolerance=replace(self.tolerance, runtime=float(time_limit)),
        )


PROFILES: dict[str, Profile] = {
    "low_accuracy": Profile(
        "low_accuracy", 1e-4, 0.0, 10_000, 1.0, Tolerance(1e-3, 1e-3, 1e-3, 1.0)
    ),
    "default": Profile("default", 1e-7, 0.0, 100_000, 10.0, Tolerance(1e-6, 1e-6, 1e-6, 10.0)),
    "high_accuracy": Profile(
        "high_accuracy", 1e-9, 0.0, 1_000_000, 10.0, Tolerance(1e-9, 1e-9, 1e-9, 10.0)
    ),
}


def profile_names() -> tuple[str, ...]:
    """Every profile name ``--profile`` accepts: qpbench's, then qpbenchmark's."""
    from .published import SETTINGS_NAMES

    return tuple(PROFILES) + tuple(QPBENCHMARK_PREFIX + s for s in SETTINGS_NAMES)


@functools.lru_cache(maxsize=None)
def qpbenchmark_profile(settings: str, time_limit: float | None = None) -> Profile:
    """The profile ``qpbenchmark:<settings>``; ``time_limit`` [s] per solve (``None``:
    qpbenchmark's default runtime)."""
    from .published import SETTINGS_NAMES, qpbenchmark_settings

    if settings not in SETTINGS_NAMES:
        raise ParamError(
            f"unknown qpbenchmark settings '{settings}' (choose from {', '.join(SETTINGS_NAMES)})",
            key="profile",
        )
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
    if isinstance(name, str) and name.startswith(QPBENCHMARK_PREFIX):
        return qpbenchmark_profile(name[len(QPBENCHMARK_PREFIX) :])
    try:
        return PROFILES[name]
    except KeyError:
        raise ParamError(
            f"unknown profile '{name}' (choose from {', '.join(profile_names())})", key="profile"
        ) from None
