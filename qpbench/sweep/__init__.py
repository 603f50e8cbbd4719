"""Randomised sweeps: many perturbed instances of a scenario, each in closed loop with each backend.

:mod:`.spec` reads a sweep file, :mod:`.sample` draws the instances, :mod:`.runner` runs them on an
executor (:mod:`qpbench.runner`) into the table of :mod:`.rows`; :mod:`.report` is its section.
"""
