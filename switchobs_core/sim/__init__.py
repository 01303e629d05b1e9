"""Simulation: the exact plant, the simulation driving the run-time observer, the paper's figures."""
