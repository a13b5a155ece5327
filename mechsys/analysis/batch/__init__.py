"""Batch runs: analyses as tasks with scalar outputs, parameter sweeps and the CI expectations of `check`."""
