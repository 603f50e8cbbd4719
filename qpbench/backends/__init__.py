"""Registry of solver backends, keyed by name.

Registering a backend is one decorator::

    @register
    class MyBackend(Backend):
        name = "mine"
        ...

Built-in backends live one module each in this package and import their
solver lazily, so a missing optional package makes the backend
"unavailable (reason)" rather than an import error. Every solver that
:data:`qpsolvers.available_solvers` lists is also exposed as
``qpsolvers:<name>``.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from ..exceptions import BackendNotFound
from ..profiles import Profile
from .base import STATUSES, Backend, BackendSolution, objective

__all__ = [
    "STATUSES",
    "Backend",
    "BackendInfo",
    "BackendSolution",
    "backend_class",
    "backend_info",
    "backend_names",
    "get_backend",
    "objective",
    "register",
    "resolve_name",
]

_REGISTRY: dict[str, type[Backend]] = {}

#: Modules of this package that hold built-in backends (imported on first use).
_BUILTIN_MODULES = (
    "osqp_", "proxqp_", "clarabel_", "daqp_", "daqp_model", "piqp_", "qpoases_", "pinv", "cvxpy_", "rnn", "qpsolvers_",
)
_loaded = False


def register(cls: type[Backend]) -> type[Backend]:
    """Class decorator: add ``cls`` to the registry under ``cls.name``."""
    if not cls.name:
        raise ValueError(f"{cls.__name__} has no name")
    _REGISTRY[cls.name] = cls
    return cls


def _load_builtins() -> None:
    global _loaded
    if _loaded:
        return
    _loaded = True
    for module in _BUILTIN_MODULES:
        try:
            importlib.import_module(f"{__name__}.{module}")
        except ModuleNotFoundError as exc:
            # A built-in module not written yet (or removed) is simply absent;
            # a missing *solver* package is handled inside each module.
            if exc.name != f"{__name__}.{module}":
                raise


def _registry() -> dict[str, type[Backend]]:
    _load_builtins()
    return _REGISTRY


@dataclass(frozen=True)
class BackendInfo:
    """What ``qpbench backends`` prints for one backend."""

    name: str
    available: bool
    version: str | None
    family: str
    reason: str | None


def backend_info() -> list[BackendInfo]:
    """One :class:`BackendInfo` per registered backend, sorted by name."""
    infos = []
    for name, cls in sorted(_registry().items()):
        reason = cls.unavailable_reason()
        infos.append(
            BackendInfo(name, reason is None, cls.version() if reason is None else None, cls.family, reason)
        )
    return infos


def backend_names(available_only: bool = True) -> list[str]:
    """Registered backend names, sorted; only the available ones by default."""
    return [
        name
        for name, cls in sorted(_registry().items())
        if not available_only or cls.unavailable_reason() is None
    ]


def resolve_name(name: str) -> str:
    """The registered spelling of backend ``name``, matched without regard to case.

    Raises:
        BackendNotFound: no backend of that name; the message offers the
            closest names ("did you mean ...") and lists the available ones.
    """
    registry = _registry()
    if name in registry:
        return name
    folded = {key.casefold(): key for key in registry}
    key = folded.get(str(name).strip().casefold())
    if key is not None:
        return key
    import difflib

    close = difflib.get_close_matches(str(name).casefold(), list(folded), n=3, cutoff=0.6)
    hint = f"did you mean {' or '.join(repr(folded[c]) for c in close)}? " if close else ""
    raise BackendNotFound(f"unknown backend '{name}'; {hint}available: {', '.join(backend_names())}")


def backend_class(name: str) -> type[Backend]:
    """The registered class of backend ``name`` (case-insensitive; see :func:`resolve_name`)."""
    return _registry()[resolve_name(name)]


def get_backend(name: str, profile: str | Profile = "default", **settings) -> Backend:
    """A fresh backend instance called ``name`` (matched without regard to case).

    Raises:
        BackendNotFound: no such backend, or it is unavailable here; the
            message offers close names and lists the available ones.
    """
    registry = _registry()
    name = resolve_name(name)
    cls = registry[name]
    reason = cls.unavailable_reason()
    if reason is not None:
        raise BackendNotFound(
            f"backend '{name}' is unavailable ({reason}); available: {', '.join(backend_names())}"
        )
    return cls(profile=profile, **settings)
