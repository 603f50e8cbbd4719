"""Randomised sweeps: many perturbed instances of a scenario, each in closed loop with each backend.

:mod:`.spec` reads a sweep file (a base scenario and distributions over its
keys), :mod:`.sample` draws the instances (full scenario files),
:mod:`.task` runs one (instance, backend) through the closed loop,
:mod:`.rows` makes its row and :mod:`.runner` runs them all on an executor
(:mod:`qpbench.runner`) into a crash-safe, resumable table. The report's
section is :mod:`qpbench.sweep.report`.
"""
