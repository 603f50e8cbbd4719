"""Compiled solves of the backends whose solver is a native library, called as a C controller
calls it: ``qpoases`` (the shim's entry points, hotstart; :mod:`qpbench.backends.qpoases_`) and
``daqp``/``daqp-stateless`` (DAQP's C API, :mod:`qpbench.backends.daqp_c`; one solve for both,
as the state was made). The protocol:
:class:`qpbench.engine.compiled.CompiledSolver`; each mirrors its Python backend call for call.
"""

from __future__ import annotations

from ..backends import daqp_c, qpoases_
from ..backends.daqp_ import EXITFLAGS, UNKNOWN_EXITFLAG


def compiled_solve(name: str):
    """The compiled ``solve`` of backend ``name``."""
    return qpoases_.compiled()[0] if name == "qpoases" else daqp_c.kernels().either


def compiled_reset(name: str):
    """The compiled ``reset`` of backend ``name``."""
    return (qpoases_.compiled() if name == "qpoases" else daqp_c.compiled(name))[1]


def make_state(backend, model, n_rows: int):
    """The solve's state for ``backend`` (its profile and settings) on ``model``'s QPs: the
    paper QP (dim equality rows) and the soft fallback's (none), ``n_rows`` obstacle rows."""
    n, dim = model.theta0.shape[0], model.controller.normal.shape[0]
    if backend.name == "qpoases":
        return qpoases_.make_state(n, dim, n_rows, backend.profile, **backend.settings)
    stateless = backend.name == "daqp-stateless"
    return daqp_c.make_state(n, dim, n_rows, backend.options(), stateless)


def close_state(st) -> None:
    """Free what the solver allocated (safe twice)."""
    (qpoases_ if isinstance(st, qpoases_.State) else daqp_c).close_state(st)


def unavailable_reason(backend) -> str | None:
    """Why ``backend``'s compiled solve cannot run here (``None``: it can)."""
    if backend.name == "qpoases":
        return qpoases_.QpoasesBackend.unavailable_reason()
    return daqp_c.unavailable_reason()


def error_text(name: str, raw: float) -> str:
    """The message of an ``error`` tick's raw return value, as the backend words it."""
    if name == "qpoases":
        return qpoases_.raw_message(int(raw))
    return f"DAQP exit flag {int(raw)} ({EXITFLAGS.get(int(raw), UNKNOWN_EXITFLAG)[1]})"
