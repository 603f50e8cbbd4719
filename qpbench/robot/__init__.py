"""The arm as a serial chain (planar, the presets, a URDF), its key points, and its environment
(contact, obstacles)."""
