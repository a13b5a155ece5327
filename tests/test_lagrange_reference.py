"""mechsys's Lagrange and Kane equations against an independent derivation (tests/reference_mechanics.py: plain
sympy, T and V written from each body's geometry, f = -dV/dq + dT/dq - (d/dq dT/dq') q') on models written as a
user would (tests/data/beyond/): a Furuta pendulum with a massive arm and a heavy top in four charts, one of them
with massless gimbal frames. M and f at random states, with every coordinate and rate nonzero."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import mechsys
import reference_mechanics as ref
from mechsys.numeric.lambdify import compile_matrix
from mechsys.numeric.parameters import parameter_values

BEYOND = Path(__file__).resolve().parent / "data" / "beyond"


def _reference(case: str) -> tuple[Path, ref.LagrangeSystem]:
    if case == "furuta":
        path = BEYOND / "furuta_rod_arm.yaml"
        p = ref.load_parameters(path)
        return path, ref.furuta(p["ma"], p["La"], p["mp"], p["Lp"], p["g"])
    path = BEYOND / {"zxz": "top_zxz.yaml", "cardan": "top_cardan.yaml", "resal": "top_resal_rotor.yaml",
                     "xyz": "top_xyz.yaml"}[case]
    p = ref.load_parameters(path)
    return path, ref.heavy_top(case, p["m"], p["l"], p["g"], p["A0"], p["C"])


@pytest.mark.parametrize("method", ["lagrange", "kane"])
@pytest.mark.parametrize("case", ["furuta", "zxz", "cardan", "resal", "xyz"])
def test_mass_matrix_and_forcing_equal_the_reference(case, method):
    path, system = _reference(case)
    model = mechsys.load(path)
    assert sorted(model.coordinates) == sorted(system.names)
    order = [model.coordinates.index(name) for name in system.names]
    eq = model.equations(method)
    args = (model.t, model.q, model.u, model.parameter_symbols)
    M_fn, f_fn = compile_matrix(eq.M, *args), compile_matrix(eq.f, *args)
    p = parameter_values(model)
    rng = np.random.default_rng(19)
    for _ in range(5):
        q, u = rng.uniform(-2, 2, len(order)), rng.uniform(-3, 3, len(order))
        state = (*q[order], *u[order])
        M_ref = np.asarray(system._M(*state), dtype=float)
        f_ref = np.asarray(system._f(*state), dtype=float).ravel()
        M, f = M_fn(0.0, q, u, p), f_fn(0.0, q, u, p).ravel()
        scale = max(1.0, np.abs(M_ref).max(), np.abs(f_ref).max())
        np.testing.assert_allclose(M[np.ix_(order, order)], M_ref, rtol=0, atol=1e-10 * scale)
        np.testing.assert_allclose(f[order], f_ref, rtol=0, atol=1e-10 * scale)
