"""Extra backend modules loaded by ``bench`` (and by its worker processes).

A plugin is a module that registers backends with
:func:`qpbench.backends.register` when imported. It is named by
``--plugin MODULE_OR_FILE`` (repeatable) or by the environment variable
``QPBENCH_PLUGINS`` (comma-separated). A name ending in ``.py`` is a file path.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from pathlib import Path

from ..exceptions import ParamError

ENV_VAR = "QPBENCH_PLUGINS"


def plugin_specs(cli: list[str] | None = None) -> list[str]:
    """Plugin names from ``QPBENCH_PLUGINS`` then from the command line, without duplicates."""
    specs = [s.strip() for s in os.environ.get(ENV_VAR, "").split(",") if s.strip()]
    for s in cli or []:
        if s not in specs:
            specs.append(s)
    return specs


def load_plugins(specs: list[str]) -> None:
    """Import each plugin (a module name, or a path to a ``.py`` file).

    Raises:
        ParamError: a plugin cannot be found or fails to import.
    """
    for spec in specs:
        try:
            if spec.endswith(".py"):
                path = Path(spec).resolve()
                if not path.is_file():
                    raise ParamError("no such plugin file", path=path, key="plugin")
                mod_name = f"qpbench_plugin_{path.stem}"
                if mod_name in sys.modules:
                    continue
                spec_obj = importlib.util.spec_from_file_location(mod_name, path)
                module = importlib.util.module_from_spec(spec_obj)
                sys.modules[mod_name] = module
                spec_obj.loader.exec_module(module)
            else:
                importlib.import_module(spec)
        except ParamError:
            raise
        except Exception as exc:  # noqa: BLE001 - any import failure is a bad parameter
            raise ParamError(f"cannot load plugin '{spec}': {type(exc).__name__}: {exc}", key="plugin") from exc
