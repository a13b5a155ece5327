"""mechanics/dag.value: an expression DAG in machine floating point, each shared node once. Checked against
sympy's evalf on random expressions, and through the builder's value-dependent decisions (dag.identically_zero),
which must come out as with sympy's evalf on every bundled model; dag.precise at 30 digits against evalf."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import mechsys
from mechsys.mechanics import dag
from mechsys.mechanics.dag import Evaluation, identically_zero, precise, value

ROOT = Path(__file__).resolve().parents[1]
x, y, z = sp.symbols("x y z", real=True)


def _draw(rng, depth):
    atoms = [x, y, z, sp.Integer(3), sp.Rational(-2, 7), sp.Float(0.3), sp.pi, sp.E]
    unary = [sp.sin, sp.cos, sp.tan, sp.atan, sp.exp, sp.Abs, sp.tanh, sp.sinh, sp.cosh, sp.sign,
             lambda e: sp.sqrt(e ** 2 + 1), lambda e: sp.log(e ** 2 + 2), lambda e: sp.asin(sp.tanh(e) / 2),
             lambda e: sp.acos(sp.tanh(e) / 3)]
    if depth == 0 or rng.random() < 0.15:
        return atoms[rng.integers(len(atoms))]
    a, b = _draw(rng, depth - 1), _draw(rng, depth - 1)
    return [a + b, a * b * x - y, a / (b ** 2 + 1), a ** int(rng.integers(-3, 5)),
            unary[rng.integers(len(unary))](a) + b, sp.atan2(a, b ** 2 + 1) * y,
            (a ** 2 + 1) ** (sp.sin(b) / 2)][rng.integers(7)]


def test_value_equals_evalf_on_random_expressions():
    rng = np.random.default_rng(12)
    compared = 0
    for _ in range(60):  # (evalf is the slow side: 60 expressions of depth 4 take a few seconds)
        e = _draw(rng, 4)
        e = e * e + e  # a shared subtree
        point = dict(zip((x, y, z), rng.uniform(-1.5, 1.5, 3)))
        want = complex(e.evalf(subs=point))
        got = value(e, point)
        if got is None:
            assert not (np.isfinite(want.real) and abs(want.imag) < 1e-12 * max(1, abs(want)))
            continue
        assert got == pytest.approx(want.real, rel=1e-9, abs=1e-9) and abs(want.imag) <= 1e-9 * max(1, abs(want))
        compared += 1
    assert compared > 45


def test_an_evaluation_with_a_symbol_moved_equals_a_fresh_one():
    """Evaluation(base=..., changed={x}) takes base's value of every node free of x and computes the rest: the
    same floats as a fresh evaluation at the moved point, and a magnitude at least every node's absolute value."""
    rng = np.random.default_rng(5)
    compared = 0
    for _ in range(40):
        exprs = [_draw(rng, 4) for _ in range(3)]
        exprs.append(exprs[0] * exprs[1] + exprs[2])  # shared subtrees across the expressions
        point = dict(zip((x, y, z), rng.uniform(-1.5, 1.5, 3)))
        moved = {**point, x: point[x] + 0.7}
        base = Evaluation(point)
        shifted = Evaluation(moved, base=base, changed=frozenset({x}))
        fresh = Evaluation(moved)
        for e in exprs:
            assert base.of(e) == Evaluation(point).of(e)
            assert shifted.of(e) == fresh.of(e)
            got = fresh.of(e)
            assert (got is None) == (value(e, moved) is None)
            if got is not None:
                compared += 1
                assert got[0] == value(e, moved)
                nodes = [n for n in sp.preorder_traversal(e) if n.args]
                assert got[1] >= max([abs(v) for n in nodes if (v := value(n, moved)) is not None] + [abs(got[0])])
    assert compared > 75


@pytest.mark.parametrize("expr", [sp.sqrt(-1 - x ** 2), sp.log(-1 - x ** 2), 1 / (x - x.subs(x, 0.25)),
                                  sp.Function("g")(x), sp.Piecewise((x, x > 0), (0, True)), x + sp.I])
def test_what_leaves_the_reals_or_the_rules_is_none(expr):
    assert value(expr, {x: 0.25}) is None


def test_a_symbol_without_a_value_is_none():
    assert value(x + y, {x: 1.0}) is None


@pytest.mark.parametrize("name", sorted(p.stem for p in (ROOT / "systems").glob("*.yaml")))
def test_the_builders_decisions_are_sympys(name, monkeypatch):
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    path = ROOT / "systems" / f"{name}.yaml"
    fast = [d[3] for d in mechsys.load(path).kin.decisions]
    monkeypatch.setattr(dag, "precise", lambda expr, values, digits: None)  # sympy's evalf only
    assert [d[3] for d in mechsys.load(path).kin.decisions] == fast


def test_precise_equals_evalf_at_its_digits():
    """dag.precise at 30 digits: |evalf(30)| of random expressions to 25 digits (or None where evalf leaves the
    reals or the rules)."""
    rng = np.random.default_rng(31)
    compared = 0
    for _ in range(40):
        e = _draw(rng, 4)
        e = e * e + e
        point = dict(zip((x, y, z), rng.uniform(-1.5, 1.5, 3)))
        got = precise(e, point, 30)
        if got is None:
            continue
        want = abs(complex(e.evalf(30, subs={s: sp.Float(v, 30) for s, v in point.items()})))
        assert got == pytest.approx(want, rel=1e-13, abs=1e-25)
        compared += 1
    assert compared > 30


@pytest.mark.parametrize("scale", [1e-12, 1.0, 1e12])
def test_identically_zero_is_scale_free(scale):
    """Round-off is zero and a value is not, at any scale: L (cos^2 + sin^2 - 1) vanishes identically and L sin(x)
    does not, for L from 1e-12 to 1e12 (absolute thresholds called a 1e-12 m linkage's rows zero, and the
    identity's round-off at 1e12 a value)."""
    L = sp.Symbol("L", positive=True)
    values = {L: scale}
    assert identically_zero(L * (sp.cos(x) ** 2 + sp.sin(x) ** 2 - 1), values)
    assert identically_zero(L * (sp.cos(x + y) - sp.cos(x) * sp.cos(y) + sp.sin(x) * sp.sin(y)), values)
    assert not identically_zero(L * sp.sin(x), values)
    assert not identically_zero(L * (sp.cos(x) ** 2 + sp.sin(x) ** 2 - 1) + L * 1e-9 * x, values)
