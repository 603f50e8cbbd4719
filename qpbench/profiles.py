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
high_accuracy  1e-9      1e6      10 s       1e-9
============== ========= ======== ========== ===================================

``low_accuracy`` and ``default`` ask solvers for ten times the accuracy they
are judged at: a solver's own stopping test (scaled, relative, or on a
different residual) does not match qpsolvers' unscaled residuals exactly, and
a solver that honours its own tolerance should not fail ours by a hair.
``high_accuracy`` asks for what it judges (1e-9, as qpbenchmark does): a tenfold
margin there bought no success on the robot's ticks or the Maros-Meszaros
problems and made published problems that qpbenchmark solves at 1e-9 end at the
time limit (``bench/accuracy_margin.py`` compares the two). At ``default`` the
margin buys ProxQP's successes (without it, its duality-gap check, on at
``eps_abs <= 1e-7``, is off and some ticks and published problems fail at 1e-6),
for a few OSQP and SCS rows that end at the time limit. Relative tolerances are zero so that
every backend stops on the same absolute criterion. The success thresholds are
qpbenchmark's for ``low_accuracy``, ``mid_accuracy`` and ``high_accuracy``; a
solve succeeds when each residual is at most its threshold and, against an
optimal reference, so is the optimality gap (:mod:`qpbench.metrics`).

``reference_time_limit`` [s] bounds each reference solve (:mod:`qpbench.reference`):
60 s in every profile.

qpbenchmark's own settings: ``qpbenchmark:low_accuracy``, ``qpbenchmark:mid_accuracy``,
``qpbenchmark:high_accuracy`` and ``qpbenchmark:default`` (:func:`qpbenchmark_profile`)
apply what qpbenchmark's runner does, read from its installed modules
(:func:`qpbench.published.qpbenchmark_settings`), not copied here:

- a ``qpsolvers:<name>`` backend passes qpbenchmark's keyword arguments for
  ``<name>`` to ``qpsolvers.solve_problem`` verbatim (no iteration limit, no
  polishing, nothing of ours added; ``--set`` still adds or overrides);
- the time limit is its ``Tolerance.runtime`` (10 s, the default of its
  ``TestSet.define_tolerances``; ``--time-limit`` replaces it in the solvers'
  arguments too, as qpbenchmark's ``set_time_limit`` does: 1000 s reproduces
  its Maros-Meszaros runs);
- success is its rule (``rule = "qpbenchmark"``): ``found`` and the primal
  residual, dual residual and duality gap each strictly below its tolerance
  (1, 1e-3, 1e-6, 1e-9); the reference plays no part (its optimality gap is
  still reported).

The own-API backends of those solvers (``osqp``, ``clarabel``, ``proxqp``,
``piqp``, ``daqp``) get the same arguments as their ``qpsolvers:`` route and
nothing else (:func:`qpbench.backends._common.qpbenchmark_options`), so the two
routes of one solver do the same work and differ only by the API (a cold solve
of a Maros-Meszaros problem: same status, iterations and objective; under
``qpbenchmark:default`` each solver's own tolerances, e.g. OSQP's 1e-3). Other
backends (``cvxpy``, ``qpoases``, ``pinv``, the network) get the generic numbers
``eps_abs`` (the tolerance qpbenchmark asks its solvers for; under
``qpbenchmark:default``, which asks for nothing, qpbench's ``default`` 1e-7),
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
    """Thresholds a solution must meet to count as a success.

    Attributes:
        primal: Max primal residual (inf-norm of constraint violation).
        dual: Max dual residual (inf-norm of stationarity error).
        gap: Max absolute duality gap.
        runtime: Time limit in [s] (same meaning as qpbenchmark's ``Tolerance.runtime``).
        rule: ``qpbench`` or ``qpbenchmark`` (:data:`RULES`; :func:`qpbench.metrics.evaluate`).
    """

    primal: float
    dual: float
    gap: float
    runtime: float
    rule: str = "qpbench"


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
        reference_time_limit: Limit of each reference solve in [s].
        solver_options: For qpbenchmark's profiles, the keyword arguments its runner
            passes per qpsolvers solver name (``None`` for qpbench's own profiles).
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
        """Whether this profile applies qpbenchmark's own settings."""
        return self.name.startswith(QPBENCHMARK_PREFIX)

    def with_time_limit(self, time_limit: float) -> Profile:
        """The same profile with another per-solve time limit in [s].

        For a qpbenchmark profile the solvers' arguments change with it, as
        qpbenchmark's ``set_time_limit`` makes them.
        """
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
    """The profile ``qpbenchmark:<settings>`` (see the module docstring).

    Args:
        settings: ``low_accuracy``, ``mid_accuracy``, ``high_accuracy`` or ``default``.
        time_limit: Per-solve limit in [s]; ``None``: qpbenchmark's default runtime.
    """
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
    """Return the profile called ``name`` (a :class:`Profile` passes through).

    Raises:
        ParamError: ``name`` is not a known profile.
    """
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
