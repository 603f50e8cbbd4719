"""Executors: the Dask workers' settings (local cluster, worker plugin on an existing one), a lost
Dask worker's run retried once then recorded as crashed, the worker processes' request loop, and a
worker of the local pool that dies before its task reaches it."""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading

import faulty_backends
import pytest
from test_sweep import PLUGIN, rows_of, write_sweep

from qpbench.cli import main
from qpbench.runner.process import Worker, WorkerDied, requests, run_tasks

pytest.importorskip("distributed")

#: Two instances of the tiny sweep's base (short runs: each lost worker is restarted by its nanny).
TWO = """
[sweep]
name = "two"
base = "wall"
seed = 3
samples = 2
duration = 0.1

[parameters]
"controller.desired_force" = { dist = "uniform", low = 10.0, high = 30.0 }
"""


def _settings(dask_worker) -> dict:
    """``{callback: period in [ms]}`` of the worker's running periodic callbacks."""
    return {
        k: pc.callback_time for k, pc in dask_worker.periodic_callbacks.items() if pc.is_running()
    }


def _quiet(settings: dict) -> bool:
    return (
        "profile" not in settings and "profile-cycle" not in settings and settings["tick"] >= 1000
    )


def test_local_cluster_workers_start_quiet():
    from qpbench.runner import DaskExecutor

    ex = DaskExecutor(jobs=1)
    try:
        assert ex.address.startswith("tcp://127.0.0.1:")
        (settings,) = ex.client.run(_settings).values()
        assert _quiet(settings) and "memory_monitor" in settings and "heartbeat" in settings
        done = sorted(ex.run(abs, [("a", -2), ("b", 3)]), key=lambda d: d.key)
        assert [(d.key, d.value, d.lost, d.attempts) for d in done] == [
            ("a", 2, None, 1),
            ("b", 3, None, 1),
        ]
        assert all(d.worker.startswith("tcp://127.0.0.1:") and d.concurrent == 1 for d in done)
    finally:
        ex.close()


def test_worker_plugin_quiets_an_existing_cluster_until_close():
    from distributed import Client, LocalCluster

    from qpbench.runner import DaskExecutor

    with (
        LocalCluster(
            n_workers=1,
            threads_per_worker=1,
            processes=False,
            protocol="tcp://",
            host="127.0.0.1",
            dashboard_address=None,
        ) as cluster,
        Client(cluster) as admin,
    ):
        (before,) = admin.run(_settings).values()
        assert not _quiet(before)
        ex = DaskExecutor(cluster.scheduler_address)
        try:
            cluster.scale(2)  # a worker that joins while the plugin is registered gets it too
            admin.wait_for_workers(2)
            during = admin.run(_settings)
            assert len(during) == 2 and all(_quiet(s) for s in during.values())
            assert sorted(d.value for d in ex.run(abs, [("a", -1), ("b", -4)])) == [1, 4]
        finally:
            ex.close()
        after = admin.run(_settings)
        assert len(after) == 2
        assert all(
            s["profile"] == before["profile"] and s["tick"] == before["tick"]
            for s in after.values()
        )


def test_lost_dask_worker_is_retried_once_then_crashed_and_resume_fills_it(tmp_path, monkeypatch):
    flag = tmp_path / "die"
    flag.touch()
    monkeypatch.setenv("QPBENCH_TEST_DIE", str(flag))  # read by the workers the cluster spawns
    out = tmp_path / "out"
    args = ["sweep", str(write_sweep(tmp_path, TWO, "two.toml")), "--out", str(out)]
    args += ["--backends", "daqp,sweep:die-on-flag", "--plugin", PLUGIN]
    args += ["--executor", "dask", "--jobs", "2"]
    assert main(args) == 0  # the table is written, the crashed rows in it
    rows = rows_of(out)
    dead = [r for r in rows if r["backend"] == "sweep:die-on-flag"]
    assert len(rows) == 4 and len(dead) == 2
    assert all(r["status"] == "crashed" and r["attempts"] == "2" for r in dead), dead
    assert all("KilledWorker" in r["error"] and "attempt 2 of 2" in r["error"] for r in dead)
    assert all(r["status"] == "ok" for r in rows if r["backend"] == "daqp")
    flag.unlink()
    assert main(args + ["--resume"]) == 0
    rows = rows_of(out)
    assert len(rows) == 4 and all(r["status"] == "ok" and r["executor"] == "dask" for r in rows)


def _echo(conn) -> None:
    for request in requests(conn):
        conn.send(2 * request)


@pytest.mark.parametrize("end", ["none", "close"])
def test_requests_end_at_none_or_a_closed_pipe(end):
    parent, child = multiprocessing.Pipe()
    worker = threading.Thread(target=_echo, args=(child,), daemon=True)
    worker.start()
    for x in (1, "a", [3]):
        parent.send(x)
        assert parent.recv() == 2 * x
    if end == "none":
        parent.send(None)
    else:
        parent.close()
    worker.join(10)
    assert not worker.is_alive()


@pytest.mark.parametrize(("jobs", "attempts"), [(1, 1), (2, 1), (2, 2)])
def test_a_worker_that_dies_while_starting_loses_its_task_only(
    tmp_path, monkeypatch, jobs, attempts
):
    """A worker SIGKILLed while it starts is handled as one that dies mid-task: its task is a
    ``crashed`` result saying why (or runs again on a new worker, with attempts left), a new
    worker takes the next task, and every other task is answered."""
    flag = tmp_path / "die"
    flag.touch()
    monkeypatch.setenv(faulty_backends.DIE_AT_IMPORT_ENV, str(flag))
    tasks = [(k, k, 60.0) for k in range(4)]
    done = list(run_tasks(faulty_backends.double, tasks, jobs, attempts=attempts))
    assert not flag.exists()  # a worker died on it
    assert sorted(d.key for d in done) == [0, 1, 2, 3]
    lost = [d for d in done if d.lost is not None]
    if attempts == 1:
        assert len(lost) == 1 and lost[0].status == "crashed" and lost[0].value is None
        assert lost[0].lost == "worker process killed by SIGKILL during start"
    else:
        assert not lost and sorted(d.attempts for d in done) == [1, 1, 1, 2]
    assert all(d.value == 2 * d.key and d.status is None for d in done if d not in lost)


def test_a_worker_dead_before_its_request_is_worker_died():
    """A request sent to a worker that is gone is :class:`WorkerDied` (``crashed``, the signal),
    not the pipe's error, and the worker is reaped."""
    w = Worker(imports=("faulty_backends",))
    try:
        assert w.call(faulty_backends.double, 2, 60.0, "a task") == 4
        os.kill(w.proc.pid, signal.SIGKILL)
        w.proc.join(10)
        with pytest.raises(WorkerDied) as died:
            w.send(faulty_backends.double, 3, 60.0)
        assert died.value.status == "crashed"
        assert died.value.message == "worker process killed by SIGKILL before its request"
        assert not w.alive
    finally:
        w.kill()


def _server_of(pid: int) -> int:
    """The parent process of ``pid`` (``/proc``): the forkserver a worker was forked from."""
    with open(f"/proc/{pid}/stat") as f:
        return int(f.read().rsplit(")", 1)[1].split()[1])


@pytest.mark.skipif(
    "forkserver" not in multiprocessing.get_all_start_methods() or not os.path.isdir("/proc"),
    reason="needs the forkserver and /proc",
)
def test_a_forkserver_with_fewer_kernels_is_replaced_once_none_of_its_workers_lives(monkeypatch):
    """Kernels named after the forkserver started: while one of its workers lives the next worker
    comes from the same server (a live worker would seem dead if its server ended); once none
    lives, from a new one that loads them."""
    from qpbench.runner import process

    monkeypatch.setattr(process, "_KERNELS", process._KERNELS)  # restored afterwards
    first = Worker(name="qpbench-test-first")
    try:
        server = _server_of(first.proc.pid)
        process.preload_kernels((*process._KERNELS, "a-kernel-the-server-lacks"))
        second = Worker(name="qpbench-test-second")
        assert _server_of(second.proc.pid) == server
        assert first.call(faulty_backends.double, 2, 60.0, "a task") == 4  # first still answers
        second.stop()
    finally:
        first.stop()
    third = Worker(name="qpbench-test-third")
    try:
        assert _server_of(third.proc.pid) != server
        assert third.call(faulty_backends.double, 3, 60.0, "a task") == 6
    finally:
        third.stop()


def test_workers_import_the_qpbench_this_process_runs_not_a_folder_of_that_name_here(
    tmp_path, monkeypatch
):
    """A clone with qpbench installed beside it: the current folder holds ``qpbench/``; the
    forkserver's workers must run the installed package (and its compiled kernels' cache),
    as this process does."""
    import qpbench
    from qpbench.runner import process

    (tmp_path / "qpbench").mkdir()
    (tmp_path / "qpbench" / "__init__.py").write_text("")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(process, "_KERNELS", process._KERNELS)  # restored afterwards
    process.preload_kernels((*process._KERNELS, "a-kernel-for-a-new-server"))  # a new server
    worker = Worker(name="qpbench-test-path")
    try:
        assert worker.call(faulty_backends.qpbench_file, None, 60.0, "a task") == qpbench.__file__
    finally:
        worker.stop()
