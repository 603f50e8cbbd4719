"""The paper's planar redundant arm (kinematics, key points) and its environment (contact, obstacles)."""
