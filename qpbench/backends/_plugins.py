"""Backends from outside the package: entry points and plugin files.

Two ways, as the Python ecosystem does it:

- an installed distribution declares an entry point in the group
  ``qpbench.backends`` (``[project.entry-points."qpbench.backends"]`` in its
  ``pyproject.toml``); its value names a module that registers backends with
  :func:`qpbench.backends.register` when imported (``mine = "mypkg.backend"``)
  or a :class:`~qpbench.backends.base.Backend` subclass, registered here
  (``mine = "mypkg.backend:MyBackend"``);
- a Python file, named by ``qpbench --plugin FILE`` (repeatable) or by the
  environment variable ``QPBENCH_PLUGINS`` (files separated by
  :data:`os.pathsep`), registers backends when executed.

Each is loaded once per process (a file is keyed by its resolved path). A
plugin that cannot be loaded is a :class:`~qpbench.exceptions.ParamError`
naming the file or the entry point. Only :mod:`qpbench.backends` calls this
module; it holds no registry of its own.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from collections.abc import Callable, Iterable
from importlib.metadata import EntryPoint, entry_points
from pathlib import Path

from ..exceptions import ParamError

#: Entry-point group of installed backend plugins.
ENTRY_POINT_GROUP = "qpbench.backends"
#: Environment variable naming plugin files (separated by :data:`os.pathsep`).
ENV_VAR = "QPBENCH_PLUGINS"

#: Plugin files loaded in this process: resolved path -> module name.
_FILES: dict[Path, str] = {}
#: Entry points loaded in this process, as ``name = value``.
_ENTRY_POINTS: set[str] = set()


def env_files() -> list[str]:
    """The plugin files named by ``QPBENCH_PLUGINS`` (empty items dropped)."""
    return [item.strip() for item in os.environ.get(ENV_VAR, "").split(os.pathsep) if item.strip()]


def group_entry_points() -> list[EntryPoint]:
    """The installed entry points of :data:`ENTRY_POINT_GROUP`, sorted by name."""
    return sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda ep: (ep.name, ep.value))


def loaded_files() -> list[str]:
    """The plugin files loaded in this process, in load order (absolute paths)."""
    return [str(path) for path in _FILES]


def _one_line(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {' '.join(str(exc).split())}"


def load_entry_points(found: Iterable[EntryPoint], register: Callable, backend_type: type) -> None:
    """Import each entry point of ``found`` not loaded yet; register the backend classes they name.

    Raises:
        ParamError: an entry point fails to load (naming it and its distribution).
    """
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
                f"cannot load the entry point '{key}' of {dist}: {_one_line(exc)}",
                key=ENTRY_POINT_GROUP,
            ) from None
        if isinstance(obj, type) and issubclass(obj, backend_type):
            register(obj)


def _module_name(path: Path) -> str:
    """A module name for plugin file ``path`` that no other loaded file has."""
    base = f"qpbench_plugin_{''.join(c if c.isalnum() else '_' for c in path.stem)}"
    name, i = base, 1
    while name in sys.modules:
        i += 1
        name = f"{base}_{i}"
    return name


def load_files(files: Iterable[str | Path]) -> None:
    """Execute each plugin file not loaded yet in this process.

    Raises:
        ParamError: a file does not exist, is not a ``.py`` file, or raises
            while it is executed (the message names the file).
    """
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
        name = _module_name(path)
        module_spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[name] = module
        try:
            module_spec.loader.exec_module(module)
        except BaseException as exc:  # noqa: BLE001 - a plugin that fails is bad input, whatever it raised
            del sys.modules[name]
            if isinstance(exc, KeyboardInterrupt):
                raise
            raise ParamError(f"cannot load plugin: {_one_line(exc)}", path=path) from None
        _FILES[path] = name
