"""Simulated rigs with known clocks: the per-pixel simulator, the density-level one, simulated bags."""
