"""The machine a report was produced on: CPU, cores, OS, Python and package versions."""

from __future__ import annotations

import os
import platform
from pathlib import Path

#: Distributions whose versions every report lists.
PACKAGES = (
    "qpbench",
    "numpy",
    "scipy",
    "pandas",
    "numba",
    "qpsolvers",
    "qpbenchmark",
    "osqp",
    "proxsuite",
    "clarabel",
    "cvxpy",
    "daqp",
    "quadprog",
    "piqp",
    "cmeel-qpoases",
    "highspy",
    "scs",
    "qpalm",
    "ecos",
    "cvxopt",
    "gurobipy",
    "matplotlib",
)


def cpu_name() -> str:
    """Model name of the CPU (``/proc/cpuinfo``'s ``model name``), or the platform's guess."""
    cpuinfo = Path("/proc/cpuinfo")
    try:
        for line in cpuinfo.read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def machine_info() -> dict[str, str]:
    """CPU, core counts, OS and Python of the current machine, as display strings."""
    from ..runner import default_jobs

    return {
        "CPU": cpu_name(),
        "Cores (usable / logical)": f"{default_jobs()} / {os.cpu_count()}",
        "OS": platform.platform(),
        "Python": f"{platform.python_implementation()} {platform.python_version()}",
    }
