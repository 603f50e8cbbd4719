"""Compiled solves of the backends whose solver is a native library, called as a C controller
calls it: ``qpoases`` (the shim's entry points, hotstart; :mod:`qpbench.backends.qpoases_`) and
``daqp``/``daqp-stateless`` (DAQP's C API). The protocol:
:class:`qpbench.engine.compiled.CompiledSolver`; each mirrors its Python backend call for call.
"""

from __future__ import annotations


def compiled_solve(name: str):
    """The compiled ``solve`` of backend ``name``."""
    return _module(name).compiled()[0]


def compiled_reset(name: str):
    """The compiled ``reset`` of backend ``name``."""
    return _module(name).compiled()[1]


def make_state(backend, model, n_rows: int):
    """The solve's state for ``backend`` (its profile and settings) on ``model``'s QPs: the
    paper QP (2 equality rows) and the soft fallback's (none), ``n_rows`` obstacle rows."""
    n = model.theta0.shape[0]
    return _module(backend.name).make_state(n, 2, n_rows, backend.profile, **backend.settings)


def close_state(st) -> None:
    """Free the solver's memory (safe twice)."""
    st_module = _STATE_OWNERS.get(type(st))
    if st_module is not None:
        st_module.close_state(st)


def unavailable_reason(backend) -> str | None:
    """Why ``backend``'s compiled solve cannot run here (``None``: it can)."""
    return _module(backend.name).compiled_unavailable_reason()


def error_text(name: str, raw: float) -> str:
    """The message of an ``error`` tick's raw return value."""
    return _module(name).raw_message(int(raw))


_STATE_OWNERS: dict = {}


def _module(name: str):
    if name == "qpoases":
        from ..backends import qpoases_ as module
    else:
        from ..backends import daqp_c as module
    _STATE_OWNERS[module.State] = module
    return module
