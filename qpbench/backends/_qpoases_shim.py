"""The qpOASES shim of the ``qpoases`` backend: ``qpOASES::SQProblem`` in a few ``extern "C"``
functions (``data/qpoases_shim.cpp``), compiled against the ``cmeel-qpoases`` wheel on first
use and loaded once per process, and the :class:`Workspace` of buffers it reads and writes.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from ..exceptions import BackendError

#: qpOASES options the ``qpoases`` backend accepts as settings (set as numbers), by the C
#: type the shim stores them as: ``bool`` (given as 0/1), ``int`` or ``real``.
_OPTION_TYPES = {
    "bool": """enableRamping enableFarBounds enableFlippingBounds enableRegularisation
        enableFullLITests enableNZCTests enableEqualities enableInertiaCorrection""",
    "int": """enableDriftCorrection enableCholeskyRefactorisation numRegularisationSteps
        numRefinementSteps""",
    "real": """terminationTolerance boundTolerance boundRelaxation epsNum epsDen maxPrimalJump
        maxDualJump initialRamping finalRamping initialFarBounds growFarBounds epsFlipping
        epsRegularisation epsIterRef epsLITests epsNZCTests rcondSMin""",
}
_OPTION_KINDS = {name: kind for kind, names in _OPTION_TYPES.items() for name in names.split()}
#: qpOASES option names the ``qpoases`` backend accepts as settings.
OPTION_NAMES = tuple(_OPTION_KINDS)
#: qpOASES' option sets (``Options::setTo...()``) by name.
PRESETS = {"default": 0, "mpc": 1, "reliable": 2, "fast": 3}
_SETTERS = {"bool": "(v != 0.0 ? BT_TRUE : BT_FALSE)", "int": "(int_t) v", "real": "(real_t) v"}


def _option_setters() -> str:
    return "\n".join(
        f'    if (!strcmp(name, "{name}")) {{ o.{name} = {_SETTERS[kind]}; return 0; }}'
        for name, kind in _OPTION_KINDS.items()
    )


#: The shim's C++ source. Buffer ``d`` (float64, row-major): ``H (n*n), g, A (m*n), lb, ub,
#: lbA, ubA, x, -y (n+m), obj, time limit, solve time, qpOASES cputime [s]``; ``iv`` (int):
#: ``nWSR limit, -, nWSR done, return value, status``.
SHIM_SOURCE = (
    (Path(__file__).parents[1] / "data" / "qpoases_shim.cpp")
    .read_text()
    .replace("@SETTERS@", _option_setters())
)

LOADED: list = []  # the loaded shim (one per process)


def qpoases_prefix() -> Path | None:
    """The ``cmeel.prefix`` folder of the installed cmeel-qpoases wheel, or None."""
    from importlib.metadata import PackageNotFoundError, distribution

    try:
        dist = distribution("cmeel-qpoases")
    except PackageNotFoundError:
        return None
    header = Path(str(dist.locate_file("cmeel.prefix/include/qpOASES.hpp")))
    return header.parents[1] if header.is_file() else None


def compiler() -> str | None:
    """The C++ compiler: ``$CXX``, else ``g++``, else ``c++`` (None when there is none)."""
    for name in (os.environ.get("CXX"), "g++", "c++"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def shim_path(prefix: Path) -> Path:
    """Where the shim for this source and this qpOASES lives (the name hashes both)."""
    from ..cache import cache_root

    digest = hashlib.sha256((SHIM_SOURCE + "\0" + str(prefix.resolve())).encode()).hexdigest()[:16]
    return cache_root() / "qpoases" / f"qpbench_qpoases_{digest}.so"


def compile_shim(prefix: Path, target: Path) -> None:
    """Compile the shim into ``target`` atomically (temporary file, then rename)."""
    cxx = compiler()
    if cxx is None:
        raise BackendError(
            "qpoases: no C++ compiler (set $CXX or install g++) to build the qpOASES shim"
        )
    include, lib = prefix / "include", prefix / "lib"
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        src, tmp_so = Path(tmp, "shim.cpp"), Path(tmp, "shim.so")
        src.write_text(SHIM_SOURCE)
        flags = ["-O2", "-shared", "-fPIC", "-std=c++11", "-lqpOASES", f"-Wl,-rpath,{lib}"]
        cmd = [cxx, str(src), f"-I{include}", f"-L{lib}", *flags, "-o", str(tmp_so)]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            raise BackendError(
                f"qpoases: compiling the qpOASES shim failed: {' '.join(cmd)}\n{done.stderr[-2000:]}"
            )
        os.replace(tmp_so, target)


def load() -> ctypes.CDLL:
    """The shim library, compiled first if needed (see :meth:`QpoasesBackend.prepare`)."""
    if LOADED:
        return LOADED[0]
    prefix = qpoases_prefix()
    if prefix is None:
        raise BackendError("qpoases: cmeel-qpoases is not installed (pip install cmeel-qpoases)")
    path = shim_path(prefix)
    if not path.is_file():
        compile_shim(prefix, path)
    lib = ctypes.CDLL(str(path))
    vp, ip = ctypes.c_void_p, ctypes.c_int
    for function, argtypes, restype in (
        (lib.qpb_new, [ip, ip, vp, vp, ip], vp),
        (lib.qpb_set_option, [vp, ctypes.c_char_p, ctypes.c_double], ip),
        (lib.qpb_free, [vp], None),
        (lib.qpb_renew, [vp], None),
        (lib.qpb_message, [ip], ctypes.c_char_p),
        (lib.qpb_solve, [vp], ip),
    ):
        function.argtypes, function.restype = argtypes, restype
    LOADED.append(lib)
    return lib


def layout(n: int, m: int) -> np.ndarray:
    """Where ``H, g, A, lb, ub, lbA, ubA, [x, -y]`` and the four scalars start in ``d`` for
    ``n`` variables and ``m`` rows, then ``d``'s length."""
    return np.cumsum([0, n * n, n, m * n, n, n, m, m, 2 * n + m, 4])


class Workspace:
    """Buffers of one shape and the ``SQProblem`` that reads them (freed with this object unless
    :meth:`detach`-ed); ``d`` and ``iv`` may be the caller's (zeros, C-contiguous)."""

    def __init__(
        self,
        key: tuple[int, int, int, bool],
        lib: ctypes.CDLL,
        preset: int,
        options: dict[str, float],
        nwsr: int,
        time_limit: float,
        d: np.ndarray | None = None,
        iv: np.ndarray | None = None,
    ) -> None:
        n, me, mi, box = self.key = key
        m = me + mi
        ends = self.ends = layout(n, m)
        d = self.d = np.zeros(ends[-1]) if d is None else d
        self.iv = np.zeros(5, dtype=np.intc) if iv is None else iv
        # Views of d in the order of SHIM_SOURCE's layout.
        H, self.g, A, self.lb, self.ub, lbA, ubA, self.xy, self.s = (
            d[a:b] for a, b in zip(ends[:-1], ends[1:])
        )
        self.H = H.reshape(n, n)
        A = A.reshape(m, n)
        self.A_eq, self.A_in = A[:me], A[me:]
        self.lbA_eq, self.ubA_eq, self.ubA_in = lbA[:me], ubA[:me], ubA[me:]
        lbA[me:] = -np.inf
        if not box:
            self.lb[:] = -np.inf
            self.ub[:] = np.inf
        # Where x, y, z and z_box lie in a copy of ``xy`` (no bounds: an empty z_box).
        self.parts = (
            slice(0, n),
            slice(2 * n, 2 * n + me),
            slice(2 * n + me, None),
            slice(n, 2 * n if box else n),
        )
        self.sizes = None  # sizes of the arrays last written (checked then)
        self.s[1] = time_limit
        self.iv[0] = nwsr
        self._free = lib.qpb_free
        handle = lib.qpb_new(n, m, d.ctypes.data, self.iv.ctypes.data, preset)
        if not handle:
            raise MemoryError("qpoases: cannot allocate the SQProblem")
        self.handle = handle
        for name, value in options.items():
            lib.qpb_set_option(handle, name.encode(), float(value))

    def detach(self) -> int:
        """The ``SQProblem``'s address, now the caller's to free (``qpb_free``) before ``d`` and
        ``iv`` go."""
        handle, self.handle = self.handle, None
        return handle

    def __del__(self) -> None:
        handle = getattr(self, "handle", None)
        if handle:
            self.handle = None
            self._free(handle)
