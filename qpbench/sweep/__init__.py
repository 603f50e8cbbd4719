"""Randomised sweeps: many perturbed instances of a scenario, each in closed loop with each backend.

:mod:`.spec` reads a sweep file and draws its instances, :mod:`.runner` runs them on an executor
(:mod:`qpbench.runner`) into the sweep's table; :mod:`.report` is its section.
"""
