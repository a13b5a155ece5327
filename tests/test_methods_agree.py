"""For every bundled model, Lagrange's and Kane's derivations give the same M, f (and A, b) at random states.

With the rates u = der(q) as generalized speeds the two routes must agree identically, so the comparison is
numerical at random coordinates, rates, times and parameter values (relative tolerance 1e-9).
"""
from __future__ import annotations

import numpy as np
import pytest

from helpers import SYSTEMS_DIR, assert_close, evaluate, load_data, load_system, random_point

SYSTEM_NAMES = sorted(p.stem for p in SYSTEMS_DIR.glob("*.yaml"))


def test_systems_are_bundled():
    # the glob must find the bundled library (otherwise the parametrized test below checks nothing)
    assert {"centrifuge", "gyrostabilizer", "indicator", "problem57", "motor_arm", "double_pendulum",
            "cart_pendulum", "spring_chain", "slider_crank", "four_bar", "rolling_disk",
            "wheel_on_axle"} <= set(SYSTEM_NAMES)


def _scale(*arrays) -> float:
    return max([1.0] + [float(np.max(np.abs(a))) for a in arrays if np.size(a)])


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_lagrange_and_kane_agree(name, rng):
    _check_agree(load_system(name), name, rng)


@pytest.mark.parametrize("name", ["fig8_mobility", "chain_base_excitation"])
def test_lagrange_and_kane_agree_on_test_models(name, rng):
    _check_agree(load_data(name), name, rng)


def _check_agree(model, name, rng):
    lag = model.equations("lagrange")
    kane = model.equations("kane")
    assert lag.M.shape == kane.M.shape == (len(model.q), len(model.q))
    assert lag.f.shape == kane.f.shape == (len(model.q), 1)
    assert lag.A.shape == kane.A.shape and lag.b.shape == kane.b.shape
    for k in range(4):
        # file parameters at the first point, then randomized parameters
        pt = random_point(model, rng, randomize_parameters=k > 0, length_span=0.05)
        for field in ("M", "f", "A", "b"):
            a = evaluate(getattr(lag, field), model, point=pt)
            b = evaluate(getattr(kane, field), model, point=pt)
            assert_close(a, b, rtol=1e-9, atol=1e-12 * _scale(a, b), what=f"{name}: {field} lagrange vs kane")
