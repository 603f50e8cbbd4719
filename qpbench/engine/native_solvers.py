"""Compiled solves of the backends whose solver is a native library, called as a C controller
calls it: ``qpoases`` (the shim's entry points, hotstart; :mod:`qpbench.backends.qpoases_`) and
``daqp``/``daqp-stateless`` (DAQP's C API, :mod:`qpbench.backends.daqp_c`; one solve for both,
as the state was made). The protocol:
:class:`qpbench.engine.compiled.CompiledSolver`; each mirrors its Python backend call for call.
"""

from __future__ import annotations


def _qpoases():
    from ..backends import qpoases_

    return qpoases_


def _daqp():
    from ..backends import daqp_c

    return daqp_c


def compiled_solve(name: str):
    """The compiled ``solve`` of backend ``name``."""
    return _qpoases().compiled()[0] if name == "qpoases" else _daqp().kernels().either


def compiled_reset(name: str):
    """The compiled ``reset`` of backend ``name``."""
    return (_qpoases().compiled() if name == "qpoases" else _daqp().compiled(name))[1]


def make_state(backend, model, n_rows: int):
    """The solve's state for ``backend`` (its profile and settings) on ``model``'s QPs: the
    paper QP (dim equality rows) and the soft fallback's (none), ``n_rows`` obstacle rows."""
    n, dim = model.theta0.shape[0], model.controller.normal.shape[0]
    if backend.name == "qpoases":
        return _qpoases().make_state(n, dim, n_rows, backend.profile, **backend.settings)
    stateless = backend.name == "daqp-stateless"
    return _daqp().make_state(n, dim, n_rows, backend.options(), stateless)


def close_state(st) -> None:
    """Free what the solver allocated (safe twice)."""
    module = _qpoases() if isinstance(st, _qpoases().State) else _daqp()
    module.close_state(st)


def unavailable_reason(backend) -> str | None:
    """Why ``backend``'s compiled solve cannot run here (``None``: it can)."""
    if backend.name == "qpoases":
        return _qpoases().QpoasesBackend.unavailable_reason()
    return _daqp().unavailable_reason()


def error_text(name: str, raw: float) -> str:
    """The message of an ``error`` tick's raw return value, as the backend words it."""
    if name == "qpoases":
        return _qpoases().raw_message(int(raw))
    from ..backends.daqp_ import EXITFLAGS, UNKNOWN_EXITFLAG

    return f"DAQP exit flag {int(raw)} ({EXITFLAGS.get(int(raw), UNKNOWN_EXITFLAG)[1]})"
