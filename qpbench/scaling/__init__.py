"""The scaling study: generated arms of many links facing point clouds, and how solve cost grows.

- :mod:`.arms`: arms of n links (lengths summing to the paper arm's reach),
  key points, a start in contact;
- :mod:`.obstacles`: point clouds beside an arm, approaching it; how a cloud
  gives rows;
- :mod:`.sizes`: the grid of sizes, the QP shape of each, each as a scenario file;
- :mod:`.runner`: dump the closed loop's ticks, bench them, summarise (``scaling.csv``);
- :mod:`.fit`: power laws on log-log axes with standard errors, crossings.

The command is ``qpbench scaling``; the report is :mod:`qpbench.scaling.report`.
"""
