"""Simulation drivers: the shared time loop and one model per kind of physics."""
