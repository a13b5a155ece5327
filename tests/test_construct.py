"""mechanics/construct.py and order.py: the direct sums and products are sympy's Add and Mul (srepr and
commutativity) at every boundary of flatten's cases and on random lists, derivatives through them are sympy's, and
the canonical order is Basic.compare's."""
from __future__ import annotations

import random

import pytest
import sympy as sp

from mechsys.mechanics.construct import QUICK, Constructors
from mechsys.mechanics.differentiate import Differentiator
from mechsys.mechanics.order import OWN, VERIFIED, _stepwise, canonical_key


def _same(a, b) -> bool:
    return sp.srepr(a) == sp.srepr(b)


_x, _y, _z = sp.symbols("x y z")
_r = sp.Symbol("r", positive=True)
_A = sp.Symbol("A", commutative=False)
_S = _x + _y
_PRODUCTS = {
    "plain factors, sorted": [_y, sp.cos(_x), _x, _S],
    "a rational coefficient": [sp.Rational(1, 2), _x, _S],
    "a number derivative": [_x, sp.Integer(3), _y],
    "a number derivative, coefficient 1 again": [sp.Rational(1, 3), _x, sp.Integer(3), _y],
    "a derivative that is a product": [_y, sp.Mul(-1, _x, sp.sin(_x)), _S],
    "a product with a sum factor": [_y, sp.Mul(-2, _x, _S)],
    "a power sharing a base (x*cos(x)**2)": [_x, sp.cos(_x) ** 2, sp.cos(_x)],
    "a base and its power": [_x, _x**2, _y],
    "a product bringing in a shared base": [_x, sp.Mul(_x, _y)],
    "exponentials sharing the base E": [sp.exp(_x), sp.exp(_y)],
    "a rational times one sum": [sp.Rational(1, 2), _S],
    "a number times one sum after flattening": [sp.Integer(2), _x, sp.Pow(_x, -1), _S],
    "a rational times a coefficient times a sum (2-argument case)": [sp.Integer(2), sp.Mul(3, _S, evaluate=False)],
    "a rational times a coefficient times a sum, to one": [sp.Integer(2),
                                                            sp.Mul(sp.Rational(1, 2), _S, evaluate=False)],
    "a rational times one plain factor": [sp.Integer(2), _x],
    "a float coefficient": [sp.Float(2.5), _x, _y],
    "a float inside a factor's product": [_x, sp.Mul(sp.Float(0.5), _y)],
    "zero": [sp.Integer(0), _x, _y],
    "a zero derivative factor": [_x, sp.S.Zero],
    "one factor left": [_x, sp.S.One],
    "only ones": [sp.S.One, sp.S.One],
    "the imaginary unit": [sp.I, _x, _y],
    "complex infinity": [sp.zoo, _r, _x],
    "infinity": [sp.oo, _r, _x],
    "nan": [sp.nan, _x],
    "the imaginary unit twice": [sp.I, sp.Mul(sp.I, _x)],
    "the imaginary unit and a power of it": [sp.I, sp.sqrt(sp.I), _x],
    "a numeric base": [sp.sqrt(2), _x, _y],
    "numeric bases with one exponent": [2**_x, 3**_x, _y],
    "a non-commutative factor": [_A, _x, _y],
    "an unevaluated power of one": [_x, sp.Pow(_y, 1, evaluate=False)],
    "an unevaluated power that evaluates": [_x, sp.Pow(sp.Integer(4), sp.Rational(1, 2), evaluate=False)],
    "an unevaluated exponent that evaluates": [_y, sp.Pow(_x, sp.Mul(2, _S, evaluate=False), evaluate=False)],
    "an unevaluated unsorted product": [_z, sp.Mul(_y, _x, evaluate=False)],
    "a number symbol": [sp.pi, _x, _y],
    "an interval": [sp.AccumBounds(1, 2), sp.Integer(2), _x],
    "an order term": [sp.O(_x), _y, _z],
    "a non-commutative product": [_x, sp.Mul(_A, _y)],
    "a product marked non-commutative": [_z, sp.Mul._from_args((_x, _y), False)],
}
_SUMS = {
    "plain terms, sorted": [_y * _z, sp.cos(_x), _x, -_y],
    "like terms": [_x * _y, 2 * _x * _y, _z],
    "a term and its multiple": [_x, 2 * _x],
    "cancelling terms": [_S, -_y],
    "a nested sum": [_S, _z * _x],
    "a number term": [sp.Integer(1), _x],
    "a rational and a product": [sp.Rational(1, 2), _x * _y],
    "a float term": [sp.Float(1.5), _x],
    "a float coefficient": [sp.Float(2.0) * _x, _y],
    "zero terms": [sp.S.Zero, _x, sp.S.Zero],
    "one term left": [sp.S.Zero, _x * _y],
    "an unevaluated coefficient 1": [sp.Mul(1, _x, _y, evaluate=False), _z],
    "an unevaluated coefficient 0": [sp.Mul(0, _x, _y, evaluate=False), _z],
    "a coefficient times a sum, unevaluated (kept)": [sp.Mul(2, _S, evaluate=False), _z],
    "a coefficient times an unevaluated product": [sp.Mul(2, sp.Mul(_x, _y, evaluate=False), evaluate=False), _z],
    "a coefficient times a number": [sp.Mul(2, sp.Integer(3), evaluate=False), _z],
    "a coefficient times x**1": [sp.Mul(2, sp.Pow(_x, 1, evaluate=False), evaluate=False), _z],
    "an order term": [sp.O(_x), _x**2, _y],
    "infinity": [sp.oo, _x],
    "complex infinity": [sp.zoo, _x],
    "a non-commutative term": [_A, _x],
    "a non-commutative product term": [sp.Mul(_A, _x), _y],
    "a nan coefficient, unevaluated": [sp.Mul(sp.nan, _x, evaluate=False), _y],
    "a power of a numeric base": [sp.Pow(2, -1, evaluate=False), _x],
}


def _identical(a, b) -> bool:
    """The same srepr and the same commutativity flag (Mul and Add carry theirs)."""
    return _same(a, b) and a.is_commutative == b.is_commutative


def test_the_direct_paths_run_on_a_verified_sympy():
    """On a sympy whose rules the direct paths follow (VERIFIED) they build the plain cases themselves, so the
    comparisons below test them and not sympy against itself; on another sympy its constructors build all."""
    if not QUICK:
        pytest.skip(f"sympy {sp.__version__} is not among {VERIFIED}: its constructors build every sum and product")
    d = Constructors()
    assert d._quick_mul(list(_PRODUCTS["plain factors, sorted"])) is not None
    assert d._quick_add(list(_SUMS["plain terms, sorted"])) is not None


@pytest.mark.parametrize("kind, name", [("mul", n) for n in _PRODUCTS] + [("add", n) for n in _SUMS])
def test_direct_products_and_sums_are_sympys(kind, name):
    """Each boundary case of flatten's: the direct path's result is sympy's Mul or Add, also inside evaluate(False)."""
    args, sympys = (_PRODUCTS[name], sp.Mul) if kind == "mul" else (_SUMS[name], sp.Add)
    for evaluate in (True, False):
        with sp.evaluate(evaluate):
            assert _identical(getattr(Constructors(), kind)(list(args)), sympys(*args)), name


class _Marked(sp.Symbol):
    """A symbol whose products and sums a constructor postprocessor replaces (sympy's hook for matrix and tensor
    expressions)."""


def test_direct_products_and_sums_run_the_constructor_postprocessors():
    w = _Marked("w")
    sp.Basic._constructor_postprocessor_mapping[_Marked] = {"Mul": [lambda e: sp.Symbol("product")],
                                                            "Add": [lambda e: sp.Symbol("sum")]}
    try:
        for args in ([w, _x], [sp.Integer(2), w, _x], [w, _x * _y]):
            assert _identical(Constructors().mul(list(args)), sp.Mul(*args)) and sp.Mul(*args).is_Symbol
            assert _identical(Constructors().add(list(args)), sp.Add(*args)) and sp.Add(*args).is_Symbol
    finally:
        del sp.Basic._constructor_postprocessor_mapping[_Marked]


def test_direct_products_and_sums_on_random_lists():
    pool = [_x, _y, _z, _S, _x - _y, sp.cos(_x), sp.sin(_x) ** 2, sp.cos(_x) ** -1, _x**2, sp.exp(_x), sp.sqrt(2),
            sp.pi, sp.Integer(2), sp.Integer(-1), sp.Rational(1, 2), sp.Float(0.5), sp.S.Zero, sp.S.One,
            -2 * _x * _y, _x * sp.cos(_x), 3 * _S * _y, sp.Mul(2, _S, evaluate=False), _y / 2, -_S]
    rng = random.Random(11)
    d = Constructors()
    for _ in range(3000):
        args = [rng.choice(pool) for _ in range(rng.randrange(1, 5))]
        assert _identical(d.mul(list(args)), sp.Mul(*args)), args
        assert _identical(d.add(list(args)), sp.Add(*args)), args


@pytest.mark.parametrize("expr", [_x * sp.cos(_x) ** 2, _x * sp.exp(_x) * sp.exp(_y), (_x + _y) * (_x - _y) / 2,
                                  sp.Rational(1, 2) * _x * (_x + 1), sp.Float(0.5) * _x * sp.sin(_x) * _y,
                                  sp.cos(_x * _y) * sp.sin(_x) ** 3 * _x**-2, _x * _y * (2 * _x + _y) ** 2])
def test_derivatives_through_the_direct_paths_are_sympys(expr):
    d = Differentiator()
    for s in (_x, _y):
        assert _same(d(expr, s), sp.diff(expr, s)) and _same(d(d(expr, s), _x), sp.diff(sp.diff(expr, s), _x)), expr


class _Bag(sp.Basic):
    """A node whose hashable content holds a frozenset (Basic.compare compares those as nodes)."""

    def _hashable_content(self):
        return (frozenset(self.args),)


def test_the_canonical_order_is_sympys_compare():
    """Step for step Basic.compare's, on a pool with assumptions, dummies, floats of two precisions, a class with its
    own compare (FiniteSet) and frozenset contents; only used on a verified sympy (order.VERIFIED)."""
    if not OWN:
        pytest.skip(f"sympy {sp.__version__} is not among {VERIFIED}: its own Basic.compare orders the arguments")
    f = sp.Function("f")
    pos, neg = sp.Symbol("x", positive=True), sp.Symbol("x", negative=True)
    pool = [_x, _y, pos, neg, sp.Dummy("x"), sp.Integer(2), sp.Rational(1, 3), sp.Float(0.5), sp.Float(0.5, 30), sp.pi,
            sp.I, sp.cos(_x), sp.sin(_x), f(_x), f(_y), sp.exp(_x), _x**2, _x**_y, 2 * _x * _y, -_x * sp.cos(_y),
            _x + _y, _x + 2 * _y, _S**2, sp.Abs(_x), sp.Tuple(sp.FiniteSet(1, 2), _x), sp.Tuple(sp.FiniteSet(1, 3), _x),
            sp.Tuple(_x, _y), sp.Tuple(_x, _y, _z), sp.Derivative(f(_x), _x), _Bag(_x, _y), _Bag(_x, _z), _Bag(_y)]
    for a in pool:
        for b in pool:
            assert _stepwise(a, b) == sp.Basic.compare(a, b), (a, b)
    rng = random.Random(5)
    for _ in range(300):
        terms = [rng.choice(pool[:-8]) * rng.choice(pool[:-8]) + rng.choice(pool[:-8]) for _ in range(6)]
        assert sorted(terms, key=canonical_key) == sorted(terms, key=sp.core.basic._args_sortkey)
        assert [sp.srepr(t) for t in sorted(terms, key=canonical_key)] == [
            sp.srepr(t) for t in sorted(terms, key=sp.core.basic._args_sortkey)]
