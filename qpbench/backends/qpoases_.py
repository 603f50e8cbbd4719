"""Backend ``qpoases``: qpOASES (online active set) with hotstart, through a small compiled shim.

Route. qpOASES' C++ library and headers come from the ``cmeel-qpoases`` wheel
(LGPL, a dependency of qpbench). A C shim of about 100 lines
(``extern "C"`` around ``qpOASES::SQProblem``, source in :data:`SHIM_SOURCE`)
is compiled by the system's C++ compiler (``$CXX``, else ``g++``, else
``c++``) on first use, once per machine and version, into
``qpbench.cache.shim_dir("qpoases")``: written to a temporary file and
renamed, so a second process never loads a half-written library. Call
:meth:`QpoasesBackend.prepare` (constructing the backend does too) before any
timed or time-limited call; ``qpbench backends`` shows the backend as
unavailable, with the reason, when neither the wheel nor (without a compiled
shim) a compiler is there. The other route that installs from PyPI, casadi's
``conic('qpoases')``, is not offered: on the robot's n = 4 ticks its hotstart
costs over ten times a call of this backend, and it prints a banner.

Formulation. ``SQProblem(n, me + mi)`` solves
``min 1/2 x'Hx + g'x  s.t.  lb <= x <= ub,  lbA <= A x <= ubA`` with::

    H = P,  g = q,  A = [A_eq; G],  lbA = [b; -inf],  ubA = [b; h]

(equalities as ``lbA = ubA``; infinite bounds are passed as qpOASES'
``INFTY = 1e20``). qpOASES' multipliers ``y`` (``n`` for the bounds, then one
per row of ``A``) satisfy ``H x + g = y_box + A' y_rows``: positive at an
active *lower* bound. qpsolvers' convention is the opposite sign, so
``z_box = -y[:n]``, ``y = -y[n:n+me]``, ``z = -y[n+me:]`` (negated in the shim).

Per-call cost. The tick's arrays are copied into one buffer the shim reads
(no stacking, no allocation), the shim is one ctypes call with one
argument, the shapes are checked in full only when the sizes differ from the
previous tick's (a copy into a buffer raises on another shape, so equal
sizes are enough per tick), and ``x`` and the multipliers come out of one copy.

Persistence. The first tick of a shape ``(n, me, mi, with box)`` calls
``init()``; the next ones call ``hotstart()`` with the whole new data (H, g,
A, bounds), which starts from the previous tick's working set (qpOASES'
homotopy from the last solution). A status other than optimal leaves qpOASES
mid-homotopy, so the next tick calls ``init()`` again. ``warm_start`` is
ignored (qpOASES' warm start is the working set, which it keeps itself).
:meth:`QpoasesBackend.reset` drops the object. ``get_state``/``set_state``
copy the whole ``SQProblem`` (qpOASES' deep copy), so ``--repeat`` restarts
each repeat from the same working set.

Settings. ``max_iter`` -> ``nWSR`` (working-set recalculations),
``time_limit`` -> qpOASES' CPU-time limit [s] (measured by qpOASES with
``gettimeofday``, 1 us resolution). ``eps_abs``/``eps_rel`` are not used: an
active-set method ends on the exact solution of its final working set, and
qpOASES' own tolerances (``terminationTolerance`` 1.1e-9 relative, ...)
keep their defaults. Other settings: ``preset`` (``"default"``, ``"mpc"``,
``"reliable"``, ``"fast"``: qpOASES' ``setTo...()`` option sets; default
``"default"``) and qpOASES' options by name (:data:`OPTION_NAMES`, e.g.
``terminationTolerance=1e-12``, ``enableRegularisation=1``); an unknown name
is a :class:`~qpbench.exceptions.ParamError`. Output is off (``PL_NONE``).

Time. ``solver_time_s`` is the time of the ``init()``/``hotstart()`` call
measured in the shim with ``clock_gettime(CLOCK_MONOTONIC)``: qpOASES' own
CPU-time output (in ``extras["qpoases_cputime_s"]``) comes from
``gettimeofday`` and is too coarse for a hotstart of microseconds.

Statuses. ``SUCCESSFUL_RETURN`` -> optimal; ``isInfeasible()`` or
``RET_*_INFEASIBILITY`` -> primal_infeasible; ``isUnbounded()`` or
``RET_*_UNBOUNDEDNESS`` -> dual_infeasible; ``RET_MAX_NWSR_REACHED`` ->
max_iter, or time_limit when fewer than ``nWSR`` recalculations were done
(the CPU-time limit stopped it); any other return value -> error with
qpOASES' message. ``extras["raw_status"]`` holds qpOASES' return value. Only
an optimal solve carries ``x`` and duals (an interrupted homotopy's iterate
is not a solution of the problem asked).
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

from ..exceptions import BackendError, ParamError
from . import register
from ._common import dense_parts, generic_settings
from ._shapes import check_shapes
from .base import Backend, BackendSolution

#: qpOASES option names the ``qpoases`` backend accepts as settings (set as numbers;
#: the ``enable...`` flags take 0/1).
OPTION_NAMES = (
    "enableRamping", "enableFarBounds", "enableFlippingBounds", "enableRegularisation",
    "enableFullLITests", "enableNZCTests", "enableDriftCorrection", "enableCholeskyRefactorisation",
    "enableEqualities", "terminationTolerance", "boundTolerance", "boundRelaxation", "epsNum", "epsDen",
    "maxPrimalJump", "maxDualJump", "initialRamping", "finalRamping", "initialFarBounds", "growFarBounds",
    "epsFlipping", "numRegularisationSteps", "epsRegularisation", "numRefinementSteps", "epsIterRef",
    "epsLITests", "epsNZCTests", "rcondSMin", "enableInertiaCorrection",
)
_BOOL_OPTIONS = frozenset(
    {"enableRamping", "enableFarBounds", "enableFlippingBounds", "enableRegularisation", "enableFullLITests",
     "enableNZCTests", "enableEqualities", "enableInertiaCorrection"}
)
_INT_OPTIONS = frozenset(
    {"enableDriftCorrection", "enableCholeskyRefactorisation", "numRegularisationSteps", "numRefinementSteps"}
)
PRESETS = {"default": 0, "mpc": 1, "reliable": 2, "fast": 3}


def _option_setters() -> str:
    lines = []
    for name in OPTION_NAMES:
        if name in _BOOL_OPTIONS:
            value = "(v != 0.0 ? BT_TRUE : BT_FALSE)"
        elif name in _INT_OPTIONS:
            value = "(int_t) v"
        else:
            value = "(real_t) v"
        lines.append(f'    if (!strcmp(name, "{name}")) {{ o.{name} = {value}; return 0; }}')
    return "\n".join(lines)


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
    Handle(int nV_, int nC_, double* d_, int* iv_) : qp(nV_, nC_), nV(nV_), nC(nC_), d(d_), iv(iv_), initialised(false) {}
    Handle(const Handle& o, double* d_, int* iv_) : qp(o.qp), options(o.options), nV(o.nV), nC(o.nC), d(d_), iv(iv_), initialised(o.initialised) {}
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
void* qpb_clone(const void* p, double* d, int* iv) {
    return new (std::nothrow) Handle(*static_cast<const Handle*>(p), d, iv);
}
void qpb_assign(void* dst, const void* src) {
    Handle* a = static_cast<Handle*>(dst);
    const Handle* b = static_cast<const Handle*>(src);
    a->qp = b->qp;
    a->options = b->options;
    a->initialised = b->initialised;
}
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
    else if (h->qp.isInfeasible() || rv == RET_INIT_FAILED_INFEASIBILITY || rv == RET_HOTSTART_STOPPED_INFEASIBILITY) st = -2;
    else if (h->qp.isUnbounded() || rv == RET_INIT_FAILED_UNBOUNDEDNESS || rv == RET_HOTSTART_STOPPED_UNBOUNDEDNESS) st = -3;
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

#: Shim status -> our status.
_STATUSES = {0: "optimal", 1: "max_iter", 2: "time_limit", -2: "primal_infeasible", -3: "dual_infeasible", -1: "error"}

_LIB: list = []  # the loaded shim (one per process)


def _qpoases_prefix() -> Path | None:
    """The ``cmeel.prefix`` folder of the installed cmeel-qpoases wheel, or None."""
    from importlib.metadata import PackageNotFoundError, distribution

    try:
        dist = distribution("cmeel-qpoases")
    except PackageNotFoundError:
        return None
    header = Path(str(dist.locate_file("cmeel.prefix/include/qpOASES.hpp")))
    return header.parents[1] if header.is_file() else None


def _compiler() -> str | None:
    """The C++ compiler: ``$CXX``, else ``g++``, else ``c++`` (None when there is none)."""
    for name in (os.environ.get("CXX"), "g++", "c++"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def _shim_path(prefix: Path) -> Path:
    """Where the shim for this source and this qpOASES lives (the name hashes both)."""
    from ..cache import cache_root

    digest = hashlib.sha256((SHIM_SOURCE + "\0" + str(prefix.resolve())).encode()).hexdigest()[:16]
    return cache_root() / "qpoases" / f"qpbench_qpoases_{digest}.so"


def _compile(prefix: Path, target: Path) -> None:
    """Compile the shim into ``target`` atomically (temporary file, then rename)."""
    from ..cache import shim_dir

    cxx = _compiler()
    if cxx is None:
        raise BackendError("qpoases: no C++ compiler (set $CXX or install g++) to build the qpOASES shim")
    folder = shim_dir("qpoases")
    include, lib = prefix / "include", prefix / "lib"
    fd, tmp_so = tempfile.mkstemp(suffix=".so.tmp", dir=folder)
    os.close(fd)
    fd, src = tempfile.mkstemp(suffix=".cpp", dir=folder)
    try:
        with os.fdopen(fd, "w") as handle:
            handle.write(SHIM_SOURCE)
        cmd = [cxx, "-O2", "-shared", "-fPIC", "-std=c++11", src, f"-I{include}", f"-L{lib}",
               "-lqpOASES", f"-Wl,-rpath,{lib}", "-o", tmp_so]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            raise BackendError(f"qpoases: compiling the qpOASES shim failed: {' '.join(cmd)}\n{done.stderr[-2000:]}")
        os.replace(tmp_so, target)
    finally:
        for path in (src, tmp_so):
            if os.path.exists(path):
                os.unlink(path)


def _load() -> ctypes.CDLL:
    """The shim library, compiled first if needed (see :meth:`QpoasesBackend.prepare`)."""
    if _LIB:
        return _LIB[0]
    prefix = _qpoases_prefix()
    if prefix is None:
        raise BackendError("qpoases: cmeel-qpoases is not installed (pip install cmeel-qpoases)")
    path = _shim_path(prefix)
    if not path.is_file():
        _compile(prefix, path)
    lib = ctypes.CDLL(str(path))
    vp, ip = ctypes.c_void_p, ctypes.c_int
    lib.qpb_new.argtypes, lib.qpb_new.restype = [ip, ip, vp, vp, ip], vp
    lib.qpb_set_option.argtypes, lib.qpb_set_option.restype = [vp, ctypes.c_char_p, ctypes.c_double], ip
    lib.qpb_known_option.argtypes, lib.qpb_known_option.restype = [ctypes.c_char_p], ip
    lib.qpb_free.argtypes, lib.qpb_free.restype = [vp], None
    lib.qpb_clone.argtypes, lib.qpb_clone.restype = [vp, vp, vp], vp
    lib.qpb_assign.argtypes, lib.qpb_assign.restype = [vp, vp], None
    lib.qpb_message.argtypes, lib.qpb_message.restype = [ip], ctypes.c_char_p
    lib.qpb_solve.argtypes, lib.qpb_solve.restype = [vp], ip
    _LIB.append(lib)
    return lib


class _Workspace:
    """Buffers of one shape and the ``SQProblem`` that reads them (freed with this object)."""

    __slots__ = ("key", "d", "iv", "handle", "H", "g", "A_eq", "A_in", "lb", "ub", "lbA_eq", "ubA_eq", "ubA_in",
                 "x", "y", "xy", "s", "n", "me", "mi", "sizes", "_free")

    def __init__(self, key, lib, preset, options, nwsr, time_limit, clone_of=None):
        n, me, mi, box = key
        m = me + mi
        self.key, self.n, self.me, self.mi = key, n, me, mi
        d = self.d = np.zeros(n * n + n + m * n + 2 * n + 2 * m + n + n + m + 4)
        self.iv = np.zeros(5, dtype=np.intc)
        o = 0
        self.H = d[o : o + n * n].reshape(n, n); o += n * n
        self.g = d[o : o + n]; o += n
        A = d[o : o + m * n].reshape(m, n); o += m * n
        self.A_eq, self.A_in = A[:me], A[me:]
        self.lb = d[o : o + n]; o += n
        self.ub = d[o : o + n]; o += n
        lbA = d[o : o + m]; o += m
        ubA = d[o : o + m]; o += m
        self.lbA_eq, self.ubA_eq, self.ubA_in = lbA[:me], ubA[:me], ubA[me:]
        lbA[me:] = -np.inf
        if not box:
            self.lb[:] = -np.inf
            self.ub[:] = np.inf
        self.xy = d[o : o + 2 * n + m]
        self.x = d[o : o + n]; o += n
        self.y = d[o : o + n + m]; o += n + m
        self.sizes = None  # sizes of the arrays last written (their shapes checked then)
        self.s = d[o:]
        self.s[1] = time_limit
        self.iv[0] = nwsr
        self._free = lib.qpb_free
        if clone_of is None:
            handle = lib.qpb_new(n, m, d.ctypes.data, self.iv.ctypes.data, preset)
        else:
            handle = lib.qpb_clone(clone_of, d.ctypes.data, self.iv.ctypes.data)
        if not handle:
            raise MemoryError("qpoases: cannot allocate the SQProblem")
        self.handle = handle
        if clone_of is None:
            for name, value in options.items():
                lib.qpb_set_option(handle, name.encode(), float(value))

    def __del__(self):
        handle = getattr(self, "handle", None)
        if handle:
            self.handle = None
            self._free(handle)


@register
class QpoasesBackend(Backend):
    """qpOASES ``SQProblem``: ``init()`` on the first tick of a shape, ``hotstart()`` on the next ones."""

    name = "qpoases"
    certifies_infeasibility = True
    family = "active set (online, parametric)"
    package = "cmeel-qpoases"
    module = None

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self._ws: _Workspace | None = None
        generic, native = generic_settings(self)
        preset = native.pop("preset", "default")
        if preset not in PRESETS:
            raise ParamError(
                f"unknown preset '{preset}' for backend 'qpoases' (one of: {', '.join(PRESETS)})", key="preset"
            )
        self._preset = PRESETS[preset]
        for key in native:
            if key not in OPTION_NAMES:
                raise ParamError(
                    f"unknown setting '{key}' for backend 'qpoases' (qpOASES options: {', '.join(OPTION_NAMES)}; "
                    "also preset; generic: eps_abs, eps_rel, max_iter, time_limit)",
                    key=key,
                )
        self._native = native
        self._nwsr = int(min(generic["max_iter"], 2**31 - 1))
        limit = generic["time_limit"]
        self._time_limit = float(limit) if limit is not None and np.isfinite(limit) else 0.0
        self._lib = self.prepare()

    # -- the compiled shim ----------------------------------------------------
    @classmethod
    def prepare(cls) -> ctypes.CDLL:
        """Compile the shim if needed and load it (idempotent; call it before timing anything)."""
        return _load()

    @classmethod
    def unavailable_reason(cls) -> str | None:
        prefix = _qpoases_prefix()
        if prefix is None:
            return "cmeel-qpoases is not installed (pip install cmeel-qpoases)"
        if _LIB or _shim_path(prefix).is_file():
            return None
        if _compiler() is None:
            return "no C++ compiler ($CXX, g++ or c++) to build the qpOASES shim"
        return None

    # -- state ----------------------------------------------------------------
    def reset(self) -> None:
        self._ws = None

    def get_state(self):
        """A deep copy of the ``SQProblem`` (working set, factorisations), or None before the first tick."""
        ws = self._ws
        if ws is None:
            return None
        return _Workspace(ws.key, self._lib, self._preset, {}, self._nwsr, self._time_limit, clone_of=ws.handle)

    def set_state(self, state) -> None:
        if state is None:
            self._ws = None
        elif self._ws is not None and self._ws.key == state.key:
            self._lib.qpb_assign(self._ws.handle, state.handle)
        else:
            self._ws = _Workspace(state.key, self._lib, self._preset, {}, self._nwsr, self._time_limit,
                                  clone_of=state.handle)

    def __deepcopy__(self, memo):
        other = type(self)(self.profile, **self.settings)
        other.set_state(self.get_state())
        return other

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_ws"] = None  # native object: a pickled backend starts afresh
        state["_lib"] = None
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._lib = self.prepare()

    # -- solving --------------------------------------------------------------
    def _solve(self, problem, warm_start):
        P, q, A, b, G, h, lb, ub = (
            problem.P, problem.q, problem.A, problem.b, problem.G, problem.h, problem.lb, problem.ub
        )
        if not (
            type(P) is _ndarray and type(q) is _ndarray and q.ndim == 1
            and (A is None or (type(A) is _ndarray and type(b) is _ndarray))
            and (G is None or (type(G) is _ndarray and type(h) is _ndarray))
            and (lb is None or type(lb) is _ndarray) and (ub is None or type(ub) is _ndarray)
        ):
            P, q, A, b, G, h, lb, ub = _dense(problem)
        # The sizes decide: a copy into a buffer of another shape raises, and one of the same size
        # cannot broadcast; check_shapes names the array when the sizes changed or a copy raised.
        sizes = (P.size, q.size, None if A is None else A.size, None if b is None else b.size,
                 None if G is None else G.size, None if h is None else h.size,
                 None if lb is None else lb.size, None if ub is None else ub.size)
        ws = self._ws
        if ws is None or sizes != ws.sizes:
            ws = self._workspace(P, q, A, b, G, h, lb, ub)
            ws.sizes = sizes
        n, me, mi, box = ws.key
        try:
            ws.H[:] = P
            ws.g[:] = q
            if me:
                ws.A_eq[:] = A
                ws.lbA_eq[:] = b
                ws.ubA_eq[:] = b
            if mi:
                ws.A_in[:] = G
                ws.ubA_in[:] = h
            if box:
                ws.lb[:] = -_INF if lb is None else lb
                ws.ub[:] = _INF if ub is None else ub
        except ValueError:
            ws.sizes = None
            check_shapes(self.name, q.shape[0], P, A, b, G, h, lb, ub)
            raise
        st = self._lib.qpb_solve(ws.handle)
        obj, _, solve_time, cputime = ws.s.tolist()
        _, _, iterations, raw = ws.iv.tolist()[:4]
        # Without __init__ (BackendSolution's defaults are class attributes): a microsecond less per call.
        sol = _new(BackendSolution)
        sol.problem = problem
        sol.status = _STATUSES[st]
        sol.extras = {"raw_status": raw, "qpoases_cputime_s": cputime}
        sol.iterations = iterations
        sol.solver_time_s = solve_time
        if st == 0:
            xy = ws.xy.copy()  # x, then the multipliers (already with qpsolvers' sign): one copy, then views
            sol.x = xy[:n]
            sol.z_box = xy[n : n + n] if box else _EMPTY
            sol.y = xy[n + n : n + n + me]
            sol.z = xy[n + n + me :]
            sol._obj = obj
        elif st == -1:
            message = self._lib.qpb_message(raw)
            sol.error = f"qpOASES return value {raw}: {message.decode(errors='replace') if message else ''}"
        return sol

    def _workspace(self, P, q, A, b, G, h, lb, ub) -> _Workspace:
        """The workspace of this problem's shape (checked here), the current one when the shape holds."""
        n = q.shape[0]
        me, mi = check_shapes(self.name, n, P, A, b, G, h, lb, ub)
        key = (n, me, mi, lb is not None or ub is not None)
        ws = self._ws
        if ws is None or ws.key != key:
            self._ws = None
            ws = self._ws = _Workspace(key, self._lib, self._preset, self._native, self._nwsr, self._time_limit)
        return ws


_ndarray = np.ndarray
_new = object.__new__
_INF = np.inf
_EMPTY = np.zeros(0)
_EMPTY.flags.writeable = False


_dense = dense_parts
