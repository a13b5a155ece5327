"""Analyses of a MechanicalModel, grouped by the question they answer: equilibrium, motion, impact, batch."""
