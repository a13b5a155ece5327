"""Sums and products as sympy's Add and Mul build them: directly where their flatten would only multiply rational
numbers and sort (the same expressions, without flatten's work), by sympy's constructors everywhere else.

Most of the time of a derivation's differentiation and of the readable clean-up was sympy's constructors on
arguments that flatten only sorts: the Leibniz terms of a product's derivative and their sums, a node rebuilt over
its cleaned arguments. The direct paths follow sympy's private helpers and its flatten rules as of the versions in
order.VERIFIED (tests/test_differentiate.py compares them with sympy's constructors case by case and on random
lists); on any other sympy its constructors build everything."""
from __future__ import annotations

from functools import cache

import sympy as sp
from sympy.core.parameters import global_parameters

from mechsys.mechanics.order import VERIFIED, canonical_key

try:
    from sympy.calculus.accumulationbounds import AccumBounds
    from sympy.core.basic import _get_postprocessors

    QUICK = ".".join(sp.__version__.split(".")[:2]) in VERIFIED
except ImportError:  # pragma: no cover - another sympy layout: its constructors only
    QUICK = False

_ONE, _ZERO = sp.S.One, sp.S.Zero


class Constructors:
    """sp.Add, sp.Mul and a * b, with what flatten decides about a factor remembered per object (one per
    derivation or clean-up: the memo keeps the objects it has seen)."""

    def __init__(self) -> None:
        # id -> (factor, the base Mul.flatten files it under, None when flatten would not keep it as it is); by id
        # with the object kept (so an id is not reused): a dict keyed by the expression would compare big equal
        # sums node by node
        self._bases: dict[int, tuple[sp.Basic, sp.Basic | None]] = {}

    def times(self, a: sp.Expr, b: sp.Expr) -> sp.Expr:
        """a * b."""
        if type(a).__mul__ is sp.Expr.__mul__ and isinstance(b, sp.Expr) and b._op_priority <= a._op_priority:
            return self.mul([a, b])  # what Expr.__mul__ returns: Mul(a, b)
        return a * b

    def mul(self, factors: list[sp.Expr]) -> sp.Expr:
        """sp.Mul(*factors)."""
        if not QUICK or not global_parameters.evaluate:
            return sp.Mul(*factors)  # (inside sympy's evaluate(False): kept as given)
        seq = [f for f in factors if f is not _ONE]
        if len(seq) < 2 and all(isinstance(f, sp.Expr) for f in seq):
            return seq[0] if seq else _ONE  # AssocOp.__new__: no factor but ones is one, one is itself
        quick = self._quick_mul(seq)
        return quick if quick is not None else sp.Mul(*factors)

    def add(self, terms: list[sp.Expr]) -> sp.Expr:
        """sp.Add(*terms)."""
        if not QUICK or not global_parameters.evaluate:
            return sp.Add(*terms)
        seq = [t for t in terms if t is not _ZERO]
        if len(seq) < 2 and all(isinstance(t, sp.Expr) for t in seq):
            return seq[0] if seq else _ZERO  # AssocOp.__new__: no term but zeros is zero, one is itself
        quick = self._quick_add(seq)
        return quick if quick is not None else sp.Add(*terms)

    def _quick_mul(self, factors: list[sp.Expr]) -> sp.Expr | None:
        """sp.Mul(*factors) (two or more, no ones) built directly where Mul.flatten would only multiply the
        rational numbers and sort the rest: commutative products flattened in, each other factor one flatten keeps
        as it is (`_plain_base`), no two on the same base (flatten would merge their powers), a nonzero coefficient
        and two factors or more left, or one that is no sum (a number times a sum is multiplied out; this also
        covers flatten's two-argument case, a rational times a sum or a number times a sum). None otherwise."""
        seq = factors
        coeff = _ONE
        rest = []
        bases = set()
        for o in seq:  # (the list grows: a product's factors are appended, as flatten does)
            if o.is_Mul:
                seq.extend(o.args)  # (flatten keeps the non-commutative ones apart: `_base` turns them down)
            elif o.is_Rational:
                coeff *= o  # exact: the order of the multiplications does not matter
            else:
                base = self._base(o)
                if base is None or base in bases:
                    return None
                bases.add(base)
                rest.append(o)
        if (coeff is _ZERO or not _quiet(type(coeff))
                or len(rest) < 2 and (coeff is _ONE or not rest or rest[0].is_Add)):
            return None
        rest.sort(key=canonical_key)  # Mul.flatten's _mulsort
        return sp.Mul._from_args(rest if coeff is _ONE else [coeff, *rest], True)

    def _quick_add(self, terms: list[sp.Expr]) -> sp.Expr | None:
        """sp.Add(*terms) (two or more, no zeros) built directly where Add.flatten would only sort the terms: sums
        flattened in, no number, each other term a commutative product whose coefficient is a rational other than 0
        and 1 or missing, or a factor `_plain_base` accepts, no two terms alike (flatten would add their
        coefficients). flatten rebuilds each term from its coefficient and the rest, which gives back the same
        product (a coefficient times a sum: kept unevaluated; times a plain factor: flatten's own product). None
        otherwise."""
        seq = terms
        out = []
        # the terms without their coefficients, as flatten compares them; a product by its tuple of factors (tuples
        # of equal factors are equal whenever the products are, so a doubt only sends the sum to sympy)
        alike = set()
        for o in seq:  # (the list grows: a sum's terms are appended, as flatten does)
            if o.is_Add:
                seq.extend(o.args)
                continue
            if o.is_Mul:
                if type(o) is not sp.Mul or o.is_commutative is not True or not _quiet(sp.Mul):
                    return None  # (a subclass may split off its coefficient otherwise)
                args = o.args
                c = args[0]
                if not c.is_Number:
                    key = args
                elif not c.is_Rational or c is _ONE or c is _ZERO:
                    return None
                elif len(args) > 2:
                    key = args[1:]
                else:
                    # flatten rebuilds c*key with Mul's constructor: the same product for a sum (kept unevaluated)
                    # or a plain factor (`_base` is None for a product too)
                    key = args[1]
                    if not _quiet(type(c)) or (not _quiet(type(key)) if key.is_Add else self._base(key) is None):
                        return None
            elif self._base(o) is None:
                return None
            else:
                key = o
            if key in alike:
                return None
            alike.add(key)
            out.append(o)
        out.sort(key=canonical_key)  # Add.flatten's _addsort
        return sp.Add._from_args(out, True)

    def _base(self, factor: sp.Expr) -> sp.Basic | None:
        """`_plain_base(factor)`, remembered per object."""
        hit = self._bases.get(id(factor))
        if hit is not None and hit[0] is factor:
            return hit[1]
        base = _plain_base(factor)
        self._bases[id(factor)] = (factor, base)
        return base


def _plain_base(o: sp.Expr) -> sp.Basic | None:
    """The base under which Mul.flatten files the factor o, if flatten keeps o as it is (and Add.flatten keeps it
    as a term as it is): a commutative expression that is no number, product, complex infinity or interval,
    whose type has no constructor postprocessors, and that flatten's rebuild from its base and exponent gives
    back (x**1 unevaluated would come back as x, numeric bases are combined). None otherwise. (The imaginary unit
    may pass: flatten keeps a lone I as it is, and a second one shares its base; an order term's commutativity
    is unknown, so it is turned down with the non-commutative.)"""
    if (not isinstance(o, sp.Expr) or o.is_Number or o.is_Mul or o is sp.S.ComplexInfinity
            or isinstance(o, AccumBounds) or o.is_commutative is not True or not _quiet(type(o))):
        return None
    b, e = o.as_base_exp()
    if e is _ONE:
        return b if b is o else None
    if o.is_Pow and b.is_Number:
        return None
    c, t = e.as_coeff_Mul()
    e = c * t  # flatten's _gather rebuilds the exponent so
    if e is _ONE or e.is_zero:
        return None
    return b if sp.Pow(b, e) == o else None


@cache
def _quiet(kind: type) -> bool:
    """No constructor postprocessor of Mul or Add runs for an argument of this type (sympy keeps them per type,
    cached the same way; matrix and tensor expressions have some)."""
    return not _get_postprocessors("Mul", kind) and not _get_postprocessors("Add", kind)
