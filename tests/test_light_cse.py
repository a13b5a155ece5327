"""lambdify.light_cse (shared subtrees only, for code that runs a few times: info's ranks, the cyclic test) gives
the same numbers as sympy's full cse on a model's matrices."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from mechsys.numeric.lambdify import compile_matrix, generate_source

sys.path.insert(0, str(Path(__file__).parent))
from helpers import load_system  # noqa: E402


def test_light_and_full_cse_compute_the_same_matrices():
    model = load_system("rolling_disk")
    eq = model.equations("kane")
    args = (model.t, model.q, model.u, model.parameter_symbols)
    p = [model.parameters[s.name] for s in model.parameter_symbols]
    rng = np.random.default_rng(8)
    for matrix in (eq.M, eq.f, eq.A, eq.b):
        light, full = compile_matrix(matrix, *args, light=True), compile_matrix(matrix, *args)
        assert generate_source(list(matrix), [model.t, *model.q, *model.u, *model.parameter_symbols], True) \
            != generate_source(list(matrix), [model.t, *model.q, *model.u, *model.parameter_symbols])
        for _ in range(5):
            t, q, u = rng.uniform(0, 1), rng.uniform(-2, 2, len(model.q)), rng.uniform(-2, 2, len(model.u))
            np.testing.assert_allclose(light(t, q, u, p), full(t, q, u, p), rtol=1e-12, atol=1e-12)

