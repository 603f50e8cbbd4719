"""Sub-commands of the ``qpbench`` CLI, one module each (see :mod:`qpbench.cli`)."""
