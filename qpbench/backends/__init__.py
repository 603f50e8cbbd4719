"""Registry of solver backends, keyed by name.

Registering a backend is one decorator::

    @register
    class MyBackend(Backend):
        name = "mine"
        ...

Built-in backends live one module each in this package, found by listing
the package (:func:`pkgutil.iter_modules`; modules whose name starts with
``_`` are helpers, not backends): a new backend is one file. Each imports its
solver lazily, so a missing optional package makes the backend
"unavailable (reason)" rather than an import error. Every solver that
:data:`qpsolvers.available_solvers` lists is also exposed as
``qpsolvers:<name>``.

Backends from outside the package (:mod:`._plugins`): the entry points of
group ``qpbench.backends`` of installed distributions, and plugin files named
by ``qpbench --plugin FILE`` or ``QPBENCH_PLUGINS``; :func:`load_plugins`
loads them once per process, after the built-in backends. Worker processes
load :func:`plugin_files` of their parent.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from ..exceptions import BackendNotFound
from ..profiles import Profile
from . import _plugins
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
    "load_plugins",
    "objective",
    "plugin_files",
    "register",
    "resolve_name",
]

_REGISTRY: dict[str, type[Backend]] = {}
_builtins_loaded = False
_plugins_checked = False


def register(cls: type[Backend]) -> type[Backend]:
    """Class decorator: add ``cls`` to the registry under ``cls.name``."""
    if not cls.name:
        raise ValueError(f"{cls.__name__} has no name")
    _REGISTRY[cls.name] = cls
    return cls


def builtin_modules() -> list[str]:
    """Names of this package's backend modules (every module not starting with ``_``), sorted."""
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))


def _load_builtins() -> None:
    global _builtins_loaded
    if not _builtins_loaded:
        _builtins_loaded = True
        for module in builtin_modules():
            importlib.import_module(f"{__name__}.{module}")


def load_plugins(files: Iterable[str | Path] = ()) -> None:
    """Load the plugins: entry points, ``QPBENCH_PLUGINS`` files, then ``files``.

    Each is loaded once per process, after the built-in backends (a plugin's
    backend may replace a built-in of the same name). Nothing is imported
    when there is no plugin at all.

    Raises:
        ParamError: a plugin file or entry point cannot be loaded (naming it).
    """
    global _plugins_checked
    files = list(files)
    if not _plugins_checked:
        _plugins_checked = True
        found, env = _plugins.group_entry_points(), _plugins.env_files()
        if found or env:
            _load_builtins()
            _plugins.load_entry_points(found, register, Backend)
            _plugins.load_files(env)
    if files:
        _load_builtins()
        _plugins.load_files(files)


def plugin_files() -> list[str]:
    """The plugin files loaded in this process (absolute paths): what a worker process loads."""
    return _plugins.loaded_files()


def _registry() -> dict[str, type[Backend]]:
    _load_builtins()
    load_plugins()
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
            BackendInfo(
                name, reason is None, cls.version() if reason is None else None, cls.family, reason
            )
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
    raise BackendNotFound(
        f"unknown backend '{name}'; {hint}available: {', '.join(backend_names())}"
    )


def backend_class(name: str) -> type[Backend]:
    """The registered class of backend ``name`` (case-insensitive; see :func:`resolve_name`).

    Raises:
        BackendNotFound: no backend of that name.
    """
    return _registry()[resolve_name(name)]


def get_backend(name: str, profile: str | Profile = "default", **settings: object) -> Backend:
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
