"""Scenarios (TOML files) and the closed-loop simulation of the controller with any backend.

- :mod:`.scenario`: a scenario file -> a typed :class:`~.scenario.Scenario`;
- :mod:`.loop`: :func:`~.loop.simulate`, the closed loop, tick by tick;
- :mod:`.tick_kernel`: the compiled per-tick step (log row, sensing, plant);
- :mod:`.log`: the tick log's columns; :mod:`.summary`: a run's figures;
  :mod:`.verdict`: its verdict.
"""
