"""The package's import graph: no cycle between modules, and no import upward.

Every ``import`` statement of the package counts, at module level or inside
a function. Layers, bottom to top (a package may import only from its own
layer or below):

    exceptions statuses profiles published memory atomic cache packed native_output native
    runner
    robot rnn backends metrics formats reference
    control
    sim engine
    selection report jit
    harness scaling sweep
    commands cli

``jit`` warms the compiled kernels (the network's, the controller's, the
loop's) and so sits above ``sim``: the commands and the harness call it with
the backends they run before any clock starts; nothing below imports it.
``runner`` sits low because the reference solves, the isolated bench and
the closed loop's runs all take their worker processes from it: no module but
``runner/process.py`` starts one (:data:`PROCESS_OWNER`), defines the pool's
settings or has a private name imported by another.

Modules are cut by concept, not by length: no function over
:data:`MAX_FUNCTION_LINES` lines (from ``def`` to its last line, docstring
included), except the numba kernels of :data:`SIZE_EXCEPTIONS`.
"""

from __future__ import annotations

import ast
from pathlib import Path

import qpbench

ROOT = Path(qpbench.__file__).resolve().parent

LAYERS = [
    {
        "exceptions",
        "statuses",
        "profiles",
        "published",
        "memory",
        "atomic",
        "cache",
        "packed",
        "native_output",
        "native",
        "qpbench",
    },
    {"runner"},
    {
        "robot",
        "rnn",
        "backends",
        "metrics",
        "formats",
        "reference",
    },
    {"control"},
    {"sim", "engine"},
    {"selection", "report", "jit"},
    {"harness", "scaling", "sweep"},
    {"commands", "cli"},
]
#: Allowed across layers in both directions (none: every package has its layer).
BESIDE_ALL: set[str] = set()


def _modules() -> dict[str, Path]:
    out = {}
    for path in ROOT.rglob("*.py"):
        parts = path.relative_to(ROOT.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        targets = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            targets = [
                f"{module}.{a.name}" if f"{module}.{a.name}" in modules else module
                for a in node.names
            ]
        for target in targets:
            while target and target not in modules:
                target = target.rpartition(".")[0]
            if target.startswith("qpbench") and target != name:
                found.add(target)
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def _group(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "qpbench"


def _layer(group: str) -> int:
    return next(i for i, layer in enumerate(LAYERS) if group in layer)


def test_every_package_has_a_layer():
    groups = {_group(m) for m in _graph()} - BESIDE_ALL
    assert all(any(g in layer for layer in LAYERS) for g in groups), groups


def test_no_upward_import():
    upward = []
    for module, deps in _graph().items():
        a = _group(module)
        for dep in deps:
            b = _group(dep)
            if a in BESIDE_ALL or b in BESIDE_ALL:
                continue
            if _layer(b) > _layer(a):
                upward.append(f"{module} -> {dep}")
    assert upward == []


def test_no_import_cycle():
    graph = _graph()
    state: dict[str, int] = {}
    cycles = []

    def visit(node, path):
        state[node] = 1
        for dep in graph[node]:
            if state.get(dep) == 1:
                cycles.append(path[path.index(dep) :] + [dep])
            elif dep not in state:
                visit(dep, path + [dep])
        state[node] = 2

    for node in graph:
        if node not in state:
            visit(node, [node])
    assert cycles == []


def test_markdown_and_plots_do_not_import_each_other():
    graph = _graph()
    assert "qpbench.report.plots" not in graph["qpbench.report.markdown"]
    assert "qpbench.report.markdown" not in graph["qpbench.report.plots"]


#: The one module that starts, feeds, times out and reaps worker processes (docs/architecture.md,
#: "Worker processes"); the Dask executor (runner/dask_.py) hands tasks to a cluster's workers,
#: which Dask starts.
PROCESS_OWNER = "qpbench.runner.process"
#: Calls that start, connect to or stop a process, or choose how one starts.
PROCESS_CALLS = {
    "Process",
    "Pipe",
    "get_context",
    "set_start_method",
    "set_forkserver_preload",
    "ProcessPoolExecutor",
    "Popen",
    "fork",
    "kill",
    "terminate",
}
#: Modules that start processes their own way.
PROCESS_MODULES = {"multiprocessing", "subprocess", "concurrent.futures", "loky", "pebble"}
#: Modules other than the owner allowed to import :data:`PROCESS_MODULES`, with the reason.
PROCESS_EXCEPTIONS = {
    "qpbench.backends._qpoases_shim": "runs the C++ compiler once to build the native shim",
}
#: The pool's settings, each defined in :data:`PROCESS_OWNER` only.
POOL_SETTINGS = ("START_TIMEOUT_S", "DEADLINE_MARGIN_S", "MAX_ATTEMPTS", "PRELOAD_KERNELS_ENV")


def _trees() -> dict[str, ast.Module]:
    return {name: ast.parse(path.read_text()) for name, path in _modules().items()}


def _typing_only(tree: ast.Module) -> set[ast.AST]:
    """The imports under ``if TYPE_CHECKING:`` (names for annotations, nothing run)."""
    nodes = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            nodes.update(n for stmt in node.body for n in ast.walk(stmt))
    return nodes


def test_only_runner_process_starts_worker_processes():
    found = []
    for module, tree in _trees().items():
        if module == PROCESS_OWNER:
            continue
        typing_only = _typing_only(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                func = node.func
                called = getattr(func, "attr", None) or getattr(func, "id", None)
                if called in PROCESS_CALLS:
                    found.append(f"{module}: calls {called}()")
            elif isinstance(node, (ast.Import, ast.ImportFrom)) and node not in typing_only:
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
                if isinstance(node, ast.ImportFrom) and not node.level:
                    names = [node.module or ""]
                for name in names:
                    root = next(
                        (m for m in PROCESS_MODULES if f"{name}.".startswith(f"{m}.")), None
                    )
                    if root is not None and module not in PROCESS_EXCEPTIONS:
                        found.append(f"{module}: imports {name}")
    assert found == []


def test_process_exceptions_are_still_needed():
    """Each exception imports a process module, so dropping that import drops the exception."""
    sources = {name: path.read_text() for name, path in _modules().items()}
    for module in PROCESS_EXCEPTIONS:
        assert any(f"import {m}" in sources[module] for m in PROCESS_MODULES), module


def test_the_pools_settings_are_defined_once_in_runner_process():
    defined = {}
    for module, tree in _trees().items():
        for node in ast.walk(tree):
            targets = node.targets if isinstance(node, ast.Assign) else []
            if isinstance(node, ast.AnnAssign):
                targets = [node.target]
            for target in targets:
                if getattr(target, "id", None) in POOL_SETTINGS:
                    defined.setdefault(target.id, []).append(module)
    assert defined == {name: [PROCESS_OWNER] for name in POOL_SETTINGS}


MAX_FUNCTION_LINES = 80

#: The only functions allowed past the size limit: numba kernels kept whole by
#: necessity (each has the reason in a comment beside it, too). Keys: a module's path from the
#: repository root and ``path:function`` (``path:Class.method`` for a method).
SIZE_EXCEPTIONS = {
    "qpbench/rnn/kernels.py:_integrate_loops": (
        "numba kernel: the integrator's main loop, one compiled loop pinned bit for bit by its "
        "numpy twin"
    ),
    "qpbench/control/build_kernel.py:_build_kernel_py": (
        "numba kernel: the controller's tick build, compiled as one function"
    ),
}


def _sources() -> dict[str, str]:
    return {
        path.relative_to(ROOT.parent).as_posix(): path.read_text() for path in ROOT.rglob("*.py")
    }


def _function_lengths(source: str) -> dict[str, int]:
    """``{qualified name: lines from def to the last line}`` of every function of a module."""
    lengths = {}

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = prefix + child.name
                lengths[name] = child.end_lineno - child.lineno + 1
                visit(child, name + ".")
            elif isinstance(child, ast.ClassDef):
                visit(child, prefix + child.name + ".")
            else:
                visit(child, prefix)

    visit(ast.parse(source), "")
    return lengths


def _too_long() -> dict[str, int]:
    functions = {}
    for path, source in _sources().items():
        for name, length in _function_lengths(source).items():
            if length > MAX_FUNCTION_LINES:
                functions[f"{path}:{name}"] = length
    return functions


def test_size_limits_measure_what_they_say():
    source = (
        'def f():\n    """Doc."""\n    return 1\n\n\nclass C:\n    def m(self):\n        pass\n'
    )
    assert _function_lengths(source) == {"f": 3, "C.m": 2}


def test_no_function_over_80_lines():
    functions = _too_long()
    over = {name: lines for name, lines in functions.items() if name not in SIZE_EXCEPTIONS}
    assert over == {}, f"functions over {MAX_FUNCTION_LINES} lines: {over}"


def test_size_exceptions_are_still_needed():
    stale = sorted(set(SIZE_EXCEPTIONS) - set(_too_long()))
    assert stale == [], f"within the limits now, drop from SIZE_EXCEPTIONS: {stale}"


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _private_imports() -> list[str]:
    """``module: source.name`` for every private name, or private module, a module imports from
    outside its own package (a module's private names are its own; a package's private modules,
    ``backends._common``, are its package's)."""
    found = []
    for module, tree in _trees().items():
        package = module if _modules()[module].name == "__init__.py" else module.rpartition(".")[0]
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                source = node.module or ""
                if node.level:
                    parts = package.split(".")
                    base = parts[: len(parts) - node.level + 1]
                    source = ".".join(base + ([node.module] if node.module else []))
                pairs = [(source, a.name) for a in node.names]
            elif isinstance(node, ast.Import):
                pairs = [tuple(a.name.rpartition(".")[::2]) for a in node.names]
            else:
                continue
            for source, name in pairs:
                if not source.startswith("qpbench"):
                    continue
                target = f"{source}.{name}"
                if target in _modules():  # a module: private ones stay in their package
                    owner = source
                    if _private(name) and not (module + ".").startswith(owner + "."):
                        found.append(f"{module}: {target}")
                    continue
                if _private(name) and source != module:
                    found.append(f"{module}: {target}")
                hidden = [p for p in source.split(".") if _private(p)]
                if hidden:
                    owner = source[: source.index("." + hidden[0])]
                    if not (module + ".").startswith(owner + "."):
                        found.append(f"{module}: {target}")
    return sorted(found)


def test_no_module_imports_another_modules_private_names():
    assert _private_imports() == []
