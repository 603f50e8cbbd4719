"""Registry of solver backends, keyed by name: one module each in this package (``_*``:
helpers), then plugins (docs/architecture.md, "Adding things"), which may replace one."""

from __future__ import annotations

import functools
import importlib
import importlib.util
import os
import pkgutil
import sys
from collections.abc import Iterable
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path

from ..exceptions import BackendNotFound, ParamError, did_you_mean
from ..profiles import Profile
from ..statuses import STATUSES as STATUSES
from ..statuses import describe_exception
from .base import Backend
from .base import BackendSolution as BackendSolution

#: Entry-point group of installed backend plugins.
ENTRY_POINT_GROUP = "qpbench.backends"
#: Environment variable naming plugin files (separated by :data:`os.pathsep`).
ENV_VAR = "QPBENCH_PLUGINS"
#: The backend every closed-loop run set runs once per scenario as the machine's noise floor.
NOISE_FLOOR = "noop"

_REGISTRY: dict[str, type[Backend]] = {}
_plugins_checked = False
#: Plugin files loaded in this process: resolved path -> module name.
_FILES: dict[Path, str] = {}
#: Entry points loaded in this process, as ``name = value``.
_ENTRY_POINTS: set[str] = set()


def register(cls: type[Backend]) -> type[Backend]:
    """Class decorator: add ``cls`` to the registry under ``cls.name``."""
    if not cls.name:
        raise ValueError(f"{cls.__name__} has no name")
    _REGISTRY[cls.name] = cls
    return cls


def builtin_modules() -> list[str]:
    """Names of this package's backend modules (every module not starting with ``_``), sorted."""
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))


@functools.cache
def _load_builtins() -> None:
    for module in builtin_modules():
        importlib.import_module(f"{__name__}.{module}")


def load_plugins(files: Iterable[str | Path] = ()) -> None:
    """Load the plugins not loaded yet: entry points, ``QPBENCH_PLUGINS`` files, then ``files``.

    Raises:
        ParamError: a plugin file or entry point cannot be loaded (naming it).
    """
    global _plugins_checked
    files = list(files)
    if not _plugins_checked:
        _plugins_checked = True
        found = sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda ep: (ep.name, ep.value))
        env = [f.strip() for f in os.environ.get(ENV_VAR, "").split(os.pathsep) if f.strip()]
        if found or env:
            _load_builtins()
            _load_entry_points(found)
            _load_files(env)
    if files:
        _load_builtins()
        _load_files(files)


def plugin_files() -> list[str]:
    """The plugin files loaded in this process (absolute paths): what a worker process loads."""
    return [str(path) for path in _FILES]


def _load_entry_points(found) -> None:
    for ep in found:
        key = f"{ep.name} = {ep.value}"
        if key in _ENTRY_POINTS:
            continue
        _ENTRY_POINTS.add(key)
        try:
            obj = ep.load()
        except Exception as exc:  # noqa: BLE001 - any import failure is a bad plugin
            dist = getattr(getattr(ep, "dist", None), "name", None) or "an installed distribution"
            raise ParamError(
                f"cannot load the entry point '{key}' of {dist}: {describe_exception(exc)}",
                key=ENTRY_POINT_GROUP,
            ) from None
        if isinstance(obj, type) and issubclass(obj, Backend):
            register(obj)


def _load_files(files: Iterable[str | Path]) -> None:
    for spec in files:
        path = Path(spec).expanduser().resolve()
        if path in _FILES:
            continue
        if not path.is_file():
            raise ParamError("no such plugin file", path=path)
        if path.suffix != ".py":
            raise ParamError(
                f"a plugin is a .py file (an installed package declares an entry point in group "
                f"'{ENTRY_POINT_GROUP}' instead)",
                path=path,
            )
        base = f"qpbench_plugin_{''.join(c if c.isalnum() else '_' for c in path.stem)}"
        name, i = base, 1
        while name in sys.modules:
            i += 1
            name = f"{base}_{i}"
        module_spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[name] = module
        try:
            module_spec.loader.exec_module(module)
        except BaseException as exc:  # noqa: BLE001 - a plugin that fails is bad input, whatever it raised
            del sys.modules[name]
            if isinstance(exc, KeyboardInterrupt):
                raise
            raise ParamError(f"cannot load plugin: {describe_exception(exc)}", path=path) from None
        _FILES[path] = name


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
        version = cls.version() if reason is None else None
        infos.append(BackendInfo(name, reason is None, version, cls.family, reason))
    return infos


def backend_names() -> list[str]:
    """The names of the available backends, sorted."""
    return [name for name, cls in sorted(_registry().items()) if cls.unavailable_reason() is None]


def resolve_name(name: str) -> str:
    """The registered spelling of backend ``name``, matched without regard to case.

    Raises:
        BackendNotFound: no such backend (offering the closest names).
    """
    registry = _registry()
    if name in registry:
        return name
    folded = {key.casefold(): key for key in registry}
    key = folded.get(str(name).strip().casefold())
    if key is not None:
        return key
    raise BackendNotFound(
        f"unknown backend '{name}'; {did_you_mean(name, registry)}"
        f"available: {', '.join(backend_names())}"
    )


def backend_class(name: str) -> type[Backend]:
    """The registered class of backend ``name`` (case-insensitive, :func:`resolve_name`)."""
    return _registry()[resolve_name(name)]


def get_backend(name: str, profile: str | Profile = "default", **settings: object) -> Backend:
    """A fresh instance of backend ``name`` (case-insensitive).

    Raises:
        BackendNotFound: no such backend, or it is unavailable here.
    """
    cls = backend_class(name)
    reason = cls.unavailable_reason()
    if reason is not None:
        raise BackendNotFound(
            f"backend '{cls.name}' is unavailable ({reason}); available: {', '.join(backend_names())}"
        )
    return cls(profile=profile, **settings)
