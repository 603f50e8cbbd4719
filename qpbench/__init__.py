"""qpbench: which QP solver to trust inside a real-time controller.

Built around Zhou, Xu & Li (2019), "Collision-Free Compliance Control for
Redundant Manipulators: An Optimization Case". Importing this package has no
side effects: no logging set-up, no solver warm-up, no file writes.
"""

__version__ = "0.1.0"
