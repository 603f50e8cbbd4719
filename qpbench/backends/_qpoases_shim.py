"""The qpOASES shim of the ``qpoases`` backend: its C++ source, its build and load, its buffers.

The shim wraps ``qpOASES::SQProblem`` in a few ``extern "C"`` functions, compiled by the
system's C++ compiler against the ``cmeel-qpoases`` wheel on first use (once per machine and
version, into ``qpbench.cache.shim_dir("qpoases")``) and loaded once per process. A
:class:`Workspace` holds the buffers one ``SQProblem`` reads and writes.
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


#: The shim's C++ source. Data layout of the buffer ``d`` (float64), all
#: row-major: ``H (n*n), g (n), A (m*n), lb (n), ub (n), lbA (m), ubA (m),
#: x (n), -y (n+m: qpOASES' multipliers with qpsolvers' sign), obj,
#: time limit [s], solve time [s], qpOASES cputime [s]``;
#: of ``iv`` (int): ``nWSR limit, -, nWSR done, return value, status``.
SHIM_SOURCE = r"""
#include <qpOASES.hpp>
#include <string.h>
#include <time.h>
#include <new>

using namespace qpOASES;

namespace {
struct Handle {
    SQProblem qp;
    Options options;
    int nV, nC;
    double* d;
    int* iv;
    bool initialised;
    Handle(int nV_, int nC_, double* d_, int* iv_)
        : qp(nV_, nC_), nV(nV_), nC(nC_), d(d_), iv(iv_), initialised(false) {}
};
inline double now() { timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
int set_option(Options& o, const char* name, double v) {
@SETTERS@
    return -1;
}
}

extern "C" {
void* qpb_new(int nV, int nC, double* d, int* iv, int preset) {
    Handle* h = new (std::nothrow) Handle(nV, nC, d, iv);
    if (!h) return 0;
    if (preset == 1) h->options.setToMPC();
    else if (preset == 2) h->options.setToReliable();
    else if (preset == 3) h->options.setToFast();
    else h->options.setToDefault();
    h->options.printLevel = PL_NONE;
    h->qp.setOptions(h->options);
    return h;
}
int qpb_set_option(void* p, const char* name, double v) {
    Handle* h = static_cast<Handle*>(p);
    if (set_option(h->options, name, v)) return -1;
    h->options.printLevel = PL_NONE;
    h->options.ensureConsistency();
    h->qp.setOptions(h->options);
    return 0;
}
int qpb_known_option(const char* name) { Options o; return set_option(o, name, 0.0) == 0; }
void qpb_free(void* p) { delete static_cast<Handle*>(p); }
const char* qpb_message(int rv) {
    return MessageHandling::getErrorCodeMessage((returnValue) rv);
}
int qpb_solve(void* p) {
    Handle* h = static_cast<Handle*>(p);
    const int n = h->nV, m = h->nC;
    double* d = h->d;
    int* iv = h->iv;
    double* H = d;
    double* g = H + n * n;
    double* A = g + n;
    double* lb = A + m * n;
    double* ub = lb + n;
    double* lbA = ub + n;
    double* ubA = lbA + m;
    double* x = ubA + m;
    double* y = x + n;
    double* s = y + n + m;
    for (int j = 0; j < 2 * n + 2 * m; ++j) {
        if (lb[j] < -INFTY) lb[j] = -INFTY;
        else if (lb[j] > INFTY) lb[j] = INFTY;
    }
    int nWSR = iv[0];
    double cpu = s[1];
    double t0 = now();
    returnValue rv = h->initialised
        ? h->qp.hotstart(H, g, A, lb, ub, m ? lbA : 0, m ? ubA : 0, nWSR, &cpu)
        : h->qp.init(H, g, A, lb, ub, m ? lbA : 0, m ? ubA : 0, nWSR, &cpu);
    s[2] = now() - t0;
    s[3] = cpu;
    iv[2] = nWSR;
    iv[3] = (int) rv;
    int st;
    if (rv == SUCCESSFUL_RETURN) st = 0;
    else if (h->qp.isInfeasible() || rv == RET_INIT_FAILED_INFEASIBILITY
             || rv == RET_HOTSTART_STOPPED_INFEASIBILITY) st = -2;
    else if (h->qp.isUnbounded() || rv == RET_INIT_FAILED_UNBOUNDEDNESS
             || rv == RET_HOTSTART_STOPPED_UNBOUNDEDNESS) st = -3;
    else if (rv == RET_MAX_NWSR_REACHED) st = (nWSR < iv[0]) ? 2 : 1;
    else st = -1;
    iv[4] = st;
    if (st == 0) {
        h->qp.getPrimalSolution(x);
        h->qp.getDualSolution(y);
        for (int j = 0; j < n + m; ++j) y[j] = -y[j];  /* qpsolvers' sign */
        s[0] = h->qp.getObjVal();
        h->initialised = true;
    } else {
        h->initialised = false;
    }
    return st;
}
}
""".replace("@SETTERS@", _option_setters())

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
    from ..cache import shim_dir

    cxx = compiler()
    if cxx is None:
        raise BackendError(
            "qpoases: no C++ compiler (set $CXX or install g++) to build the qpOASES shim"
        )
    include, lib = prefix / "include", prefix / "lib"
    with tempfile.TemporaryDirectory(dir=shim_dir("qpoases")) as tmp:
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
    lib.qpb_new.argtypes, lib.qpb_new.restype = [ip, ip, vp, vp, ip], vp
    lib.qpb_set_option.argtypes, lib.qpb_set_option.restype = (
        [vp, ctypes.c_char_p, ctypes.c_double],
        ip,
    )
    lib.qpb_free.argtypes, lib.qpb_free.restype = [vp], None
    lib.qpb_message.argtypes, lib.qpb_message.restype = [ip], ctypes.c_char_p
    lib.qpb_solve.argtypes, lib.qpb_solve.restype = [vp], ip
    LOADED.append(lib)
    return lib


class Workspace:
    """Buffers of one shape and the ``SQProblem`` that reads them (freed with this object)."""

    def __init__(
        self,
        key: tuple[int, int, int, bool],
        lib: ctypes.CDLL,
        preset: int,
        options: dict[str, float],
        nwsr: int,
        time_limit: float,
    ) -> None:
        n, me, mi, box = self.key = key
        m = me + mi
        d = self.d = np.zeros(n * n + n + m * n + 2 * n + 2 * m + n + n + m + 4)
        self.iv = np.zeros(5, dtype=np.intc)
        # Views of d in the order of SHIM_SOURCE's layout.
        ends = np.cumsum([0, n * n, n, m * n, n, n, m, m, 2 * n + m])
        H, self.g, A, self.lb, self.ub, lbA, ubA, self.xy = (
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
        # Where x, z_box, y and z lie in a copy of ``xy`` (no bounds: an empty z_box).
        self.parts = (
            slice(0, n),
            slice(n, 2 * n if box else n),
            slice(2 * n, 2 * n + me),
            slice(2 * n + me, None),
        )
        self.sizes = None  # sizes of the arrays last written (their shapes checked then)
        self.s = d[ends[-1] :]
        self.s[1] = time_limit
        self.iv[0] = nwsr
        self._free = lib.qpb_free
        handle = lib.qpb_new(n, m, d.ctypes.data, self.iv.ctypes.data, preset)
        if not handle:
            raise MemoryError("qpoases: cannot allocate the SQProblem")
        self.handle = handle
        for name, value in options.items():
            lib.qpb_set_option(handle, name.encode(), float(value))

    def __del__(self) -> None:
        handle = getattr(self, "handle", None)
        if handle:
            self.handle = None
            self._free(handle)
