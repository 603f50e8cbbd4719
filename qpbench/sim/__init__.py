"""Scenarios (TOML files) and the closed-loop simulation of the controller with any backend."""
