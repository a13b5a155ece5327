"""Equilibrium and stability: steady motions, linearization, modes, continuation and bifurcations."""
