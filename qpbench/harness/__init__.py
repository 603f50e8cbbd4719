"""The benchmark harness: timed, guarded, resumable runs of backends over problem sets
(``qpbench bench``, ``closed-loop``, ``run``); its modules: docs/architecture.md."""
