"""mechanics/differentiate.py: the memoized differentiation gives sympy's diff, expression for expression (srepr),
on derived kinetic energies and constraint rows and on expressions with every rule and the fallback."""
from __future__ import annotations

import random

import pytest
import sympy as sp

import mechsys
from helpers import SYSTEMS_DIR
from mechsys.mechanics.differentiate import Differentiator


def _same(a, b) -> bool:
    return sp.srepr(a) == sp.srepr(b)


@pytest.mark.parametrize("name", ["rolling_disk", "gyrostabilizer", "slider_crank", "double_pendulum"])
def test_first_and_second_derivatives_of_derived_expressions_are_sympys(name):
    model = mechsys.load(SYSTEMS_DIR / f"{name}.yaml")
    d = Differentiator()
    T, V = model.kinetic_energy, model.potential_energy
    for u in model.u:
        p = sp.diff(T, u)
        assert _same(d(T, u), p)
        for v in model.u:
            assert _same(d(d(T, u), v), sp.diff(p, v))
    for x in [*model.q, model.t]:
        assert _same(d(T, x), sp.diff(T, x)) and _same(d(V, x), sp.diff(V, x))
        if model.kin.constraints:
            assert d(model.constraint_velocity, x) == sp.diff(model.constraint_velocity, x)


def test_every_rule_and_the_fallback_on_random_expressions():
    x, y, a = sp.symbols("x y a")
    rng = random.Random(7)
    leaves = [x, y, a, sp.Integer(2), sp.Rational(1, 3), sp.Float(0.25), sp.pi]

    def grow(depth: int) -> sp.Expr:
        if depth == 0:
            return rng.choice(leaves)
        kind = rng.randrange(9)
        u, v = grow(depth - 1), grow(depth - 1)
        return [u + v, u * v, u - 3 * v, u**2, u**v, sp.sin(u), sp.cos(u) * v, sp.Abs(u) + sp.exp(v),
                sp.atan2(u, v + 1) + sp.sqrt(u**2 + 1)][kind]

    d = Differentiator()
    for _ in range(150):
        e = grow(rng.randrange(1, 5))
        for s in (x, y):
            assert _same(d(e, s), sp.diff(e, s)), e


def test_the_memo_keeps_variables_apart():
    x, y = sp.symbols("x y")
    e = sp.sin(x * y) ** 2 + sp.cos(x)
    d = Differentiator()
    assert _same(d(e, x), sp.diff(e, x)) and _same(d(e, y), sp.diff(e, y)) and d(e, sp.Symbol("z")) == 0
