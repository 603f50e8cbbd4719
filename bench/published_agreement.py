"""``qpbench bench`` on a published test set, against qpbenchmark's results for it.

Runs, as a user would::

    qpbench bench FOLDER --backends clarabel,osqp,proxqp,qpsolvers:osqp --profile P --out OUT.csv --force

(plus ``--reference``, ``--time-limit``, ``--jobs`` when given) in a child
process, and prints:

- the run: its wall time, the peak resident memory of the largest process
  of the run (``getrusage(RUSAGE_CHILDREN).ru_maxrss``: the bench and its
  worker processes), rows per status and success per backend;
- per ``qpsolvers:<solver>`` backend (the routes qpbenchmark itself drives),
  the agreement of our ``found`` flag with qpbenchmark's on the same problem
  and settings, and the rows where they differ (with qpbenchmark's runtime:
  a disagreement where qpbenchmark needed longer than our time limit is
  the time limit's, not the solver's).

qpbenchmark's results come from ``--published FILE`` (default
``FOLDER/qpbenchmark_results.csv`` when it exists, as in a folder of
published Maros-Meszaros problems). A folder without one (the 14 small
Maros-Meszaros problems) is compared with a run of qpbenchmark's own runner
here, on the problems as qpbench reads them (matrices as CSC, as
qpbenchmark's Maros-Meszaros loader gives them), with the same settings and
time limit: the table then says ``qpbenchmark run here``.

The settings compared: ``qpbenchmark:<settings>`` profiles compare with
``<settings>``; qpbench's own ``low_accuracy``, ``default``,
``high_accuracy`` with qpbenchmark's ``low_accuracy``, ``mid_accuracy``,
``high_accuracy`` (judged at the same thresholds); ``--settings`` overrides.

Usage::

    python bench/published_agreement.py FOLDER [--profile qpbenchmark:default]
        [--backends clarabel,osqp,proxqp,qpsolvers:osqp] [--published FILE] [--settings NAME]
        [--reference auto|none|FILE] [--time-limit S] [--jobs N] [--out OUT.csv]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import pandas as pd

from qpbench.published import import_qpbenchmark, read_published_results

DEFAULT_BACKENDS = "clarabel,osqp,proxqp,qpsolvers:osqp"
#: qpbenchmark's settings judged at the thresholds of each of qpbench's own profiles.
SETTINGS_OF_PROFILE = {
    "low_accuracy": "low_accuracy",
    "default": "mid_accuracy",
    "high_accuracy": "high_accuracy",
}
#: Target agreement of the found flags, in percent.
TARGET = 90.0


def settings_of(profile: str) -> str:
    if profile.startswith("qpbenchmark:"):
        return profile.split(":", 1)[1]
    return SETTINGS_OF_PROFILE[profile]


def run_bench_cli(args, out: Path) -> tuple[int, float, float]:
    """``(exit code, wall time [s], peak RSS [MiB])`` of ``qpbench bench`` in a child process."""
    exe = Path(sys.executable).with_name("qpbench")
    cli = [
        "bench",
        str(args.folder),
        "--backends",
        args.backends,
        "--profile",
        args.profile,
        "--out",
        str(out),
        "--force",
        "--reference",
        args.reference,
        "--jobs",
        str(args.jobs),
    ]
    if args.time_limit is not None:
        cli += ["--time-limit", str(args.time_limit)]
    print("$ qpbench " + " ".join(cli), flush=True)
    cmd = (
        [str(exe)]
        if exe.exists()
        else [sys.executable, "-c", "import sys; from qpbench.cli import main; sys.exit(main())"]
    )
    cmd += cli
    started = time.perf_counter()
    code = subprocess.call(cmd)
    wall = time.perf_counter() - started
    peak_mib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0  # kB on Linux
    return code, wall, peak_mib


def run_qpbenchmark_here(
    folder: Path, solvers: list[str], settings: str, time_limit: float | None, problems: list[str]
) -> pd.DataFrame:
    """qpbenchmark's runner on the problems of ``folder`` as qpbench reads them (CSC matrices)."""
    import scipy.sparse as spa

    from qpbench.formats import load_problems

    qpb = import_qpbenchmark()
    records = [r for r in load_problems(folder).records if r.name in problems]

    class Published(qpb.TestSet):
        title = "qpbench's reading of " + folder.name
        description = "Problems of a published folder, as qpbench reads them"
        sparse_only = True

        def define_tolerances(self) -> None:
            super().define_tolerances(**({} if time_limit is None else {"runtime": time_limit}))

        def __iter__(self):
            for r in records:
                p = r.problem
                csc = lambda M: None if M is None else spa.csc_matrix(M)
                yield qpb.Problem(
                    csc(p.P), p.q, csc(p.G), p.h, csc(p.A), p.b, p.lb, p.ub, name=r.name
                )

    test_set = Published()
    test_set.solvers = set(solvers) & set(test_set.solvers)
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        results = qpb.Results(Path(tmp) / "qpbenchmark.csv", test_set)
        with contextlib.redirect_stderr(io.StringIO()):  # its progress bar
            qpb.run(test_set, results, only_settings=settings)
    df = results.df.reset_index(drop=True)
    df["found"] = df["found"].astype(bool)
    return df


def agreement(
    ours: pd.DataFrame, theirs: pd.DataFrame, settings: str, time_limit: float
) -> pd.DataFrame:
    """Per ``qpsolvers:`` backend: rows compared, found flags equal, and the rows that differ."""
    routes = ours[ours["backend"].str.startswith("qpsolvers:")].copy()
    routes["solver"] = routes["backend"].str.split(":", n=1).str[1]
    routes["found"] = routes["found"].astype(str).str.lower() == "true"
    theirs = theirs[theirs["settings"] == settings]
    m = routes.merge(
        theirs[["problem", "solver", "found", "runtime"]],
        on=["problem", "solver"],
        suffixes=("", "_qpb"),
        how="left",
        validate="1:1",
    )
    rows, differ = [], []
    for solver, g in m.groupby("solver", sort=True):
        known = g[g["found_qpb"].notna()]
        same = known["found"] == known["found_qpb"].astype(bool)
        rows.append(
            {
                "solver": f"qpsolvers:{solver}",
                "rows": len(g),
                "published": len(known),
                "found (ours)": int(known["found"].sum()),
                "found (qpbenchmark)": int(known["found_qpb"].astype(bool).sum()),
                "agree": int(same.sum()),
                "agreement %": 100.0 * same.mean() if len(known) else float("nan"),
                "differ, qpbenchmark over our time limit": int(
                    (~same & (known["runtime"] > time_limit)).sum()
                ),
            }
        )
        for _, r in known[~same].iterrows():
            differ.append(
                f"  {r['backend']} {r['problem']}: ours {r['status']} (found {r['found']}, "
                f"{r['wall_time_min_s'] if pd.notna(r['wall_time_min_s']) else float('nan'):.3g} s), "
                f"qpbenchmark found {bool(r['found_qpb'])} in {r['runtime']:.3g} s"
            )
    table = pd.DataFrame(rows)
    table.attrs["differ"] = differ
    return table


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="folder of published problems (.mat)")
    parser.add_argument("--backends", default=DEFAULT_BACKENDS)
    parser.add_argument("--profile", default="qpbenchmark:default")
    parser.add_argument(
        "--settings", default=None, help="qpbenchmark settings to compare with (default: see above)"
    )
    parser.add_argument("--published", type=Path, default=None, help="qpbenchmark results file")
    parser.add_argument("--reference", default="auto")
    parser.add_argument(
        "--time-limit",
        type=float,
        default=None,
        help="per-solve limit in s (default: the profile's)",
    )
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--out", type=Path, default=None, help="keep the bench CSV here")
    args = parser.parse_args(argv)

    from qpbench.profiles import get_profile

    settings = args.settings or settings_of(args.profile)
    profile = get_profile(args.profile)
    time_limit = args.time_limit if args.time_limit is not None else profile.time_limit
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "bench.csv"
        code, wall, peak = run_bench_cli(args, out)
        if code not in (0, 1):
            print(f"qpbench bench exited {code}", file=sys.stderr)
            return code
        ours = pd.read_csv(out)
    print(
        f"\nrun: {wall:.1f} s wall, peak memory {peak:.0f} MiB (largest process), exit {code}, "
        f"{len(ours)} rows, {ours['problem'].nunique()} problems, profile {args.profile}, time limit "
        f"{time_limit:g} s"
    )
    print(ours.groupby(["backend", "status"]).size().unstack(fill_value=0).to_markdown())
    print()
    print(ours.groupby("backend")[["found", "success"]].mean().mul(100).round(1).to_markdown())

    published = args.published or (args.folder / "qpbenchmark_results.csv")
    if published.exists():
        theirs, source = read_published_results(published), f"published ({published})"
    else:
        solvers = sorted(
            {b.split(":", 1)[1] for b in args.backends.split(",") if b.startswith("qpsolvers:")}
        )
        theirs = run_qpbenchmark_here(
            args.folder, solvers, settings, args.time_limit, list(ours["problem"].unique())
        )
        source = "qpbenchmark run here (no published results in the folder)"
    table = agreement(ours, theirs, settings, time_limit)
    print(
        f"\nfound flags of the qpsolvers: routes vs qpbenchmark's, settings {settings}; {source}; "
        f"target >= {TARGET:g} %\n"
    )
    print(
        table.to_markdown(index=False, floatfmt=".1f")
        if len(table)
        else "(no qpsolvers: backend in the run)"
    )
    for line in table.attrs.get("differ", []):
        print(line)
    below = [r["solver"] for _, r in table.iterrows() if not r["agreement %"] >= TARGET]
    print(
        f"\nagreement >= {TARGET:g} %: "
        + ("yes" if len(table) and not below else f"no ({', '.join(below)})")
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
