"""Differentiation that visits each subexpression once: sympy's rules, memoized over the expression DAG.

sympy's `diff` recurses through `Derivative.__new__` at every node, and each call walks the node's whole subtree
again (its free symbols, then a `replace` of nested derivatives), so differentiating a derived expression costs
the square of its size, and the entries of M, which share most of their subtrees, repeat all of it. This
module applies the same rules as sympy (sums term by term, Leibniz's rule over a product's factors, sympy's
formula for powers, the chain rule through `fdiff` for sin and cos, the same shortcut to zero for a node without
the variable) and remembers each node's derivative, so the result is sympy's expression, built once. Nodes of
other kinds are differentiated by sympy itself.

Most of the time left is sympy's constructors (Mul.flatten and Add.flatten on the Leibniz terms and their sums),
so the products and sums are built directly where flatten provably would only multiply rational numbers and sort:
see `_quick_product` and `_quick_sum`; sympy's constructor builds every other case. Their sorting is sympy's
canonical order (mechanics/order.py). They follow sympy's private helpers and its flatten rules as of the
versions in order.VERIFIED (tests/test_differentiate.py compares them with sympy's constructors); on any other
sympy its constructors build everything, as before."""
from __future__ import annotations

from functools import cache

import sympy as sp
from sympy.core.function import ArgumentIndexError, Function
from sympy.core.parameters import global_parameters

from mechsys.mechanics.dag import FreeSymbols
from mechsys.mechanics.order import VERIFIED, canonical_key

try:
    from sympy.calculus.accumulationbounds import AccumBounds
    from sympy.core.basic import _get_postprocessors

    QUICK = ".".join(sp.__version__.split(".")[:2]) in VERIFIED  # the direct sums and products
except ImportError:  # pragma: no cover - another sympy layout: its constructors only
    QUICK = False

_ONE, _ZERO = sp.S.One, sp.S.Zero


class Differentiator:
    """d(expr)/d(symbol), remembered per (node, symbol) for the lifetime of the object (one model)."""

    def __init__(self) -> None:
        self._memo: dict[tuple[sp.Basic, sp.Symbol], sp.Expr] = {}
        self.symbols = FreeSymbols()  # expr.free_symbols, remembered per node (sympy recomputes it every call)
        self.free = self.symbols.of
        # id -> (factor, the base Mul.flatten files it under, None when flatten would not keep it as it is); by id
        # with the object kept (so an id is not reused): a dict keyed by the expression would compare big equal
        # sums node by node
        self._bases: dict[int, tuple[sp.Basic, sp.Basic | None]] = {}

    def __call__(self, expr: sp.Basic | sp.MatrixBase, x: sp.Symbol) -> sp.Basic:
        """What sympy.diff(expr, x) gives (elementwise for a matrix)."""
        if isinstance(expr, sp.MatrixBase):
            return expr.applyfunc(lambda e: self(e, x))
        return self._d(sp.sympify(expr), x)

    def _d(self, expr: sp.Basic, x: sp.Symbol) -> sp.Basic:
        """d(expr)/dx of a sympy expression, remembered (the rules' own calls: no matrix, nothing to sympify)."""
        key = (expr, x)
        hit = self._memo.get(key)
        if hit is None:
            hit = self._derivative(expr, x)
            self._memo[key] = hit
        return hit

    def _derivative(self, expr: sp.Basic, x: sp.Symbol) -> sp.Basic:
        """d(expr)/dx by sympy's rule for expr's kind (its derivatives of the arguments from the memo)."""
        if not self.symbols.has(expr, x):
            return sp.S.Zero  # Derivative.__new__'s quick exit
        kind = type(expr)
        if kind is sp.Add:
            return self._sum([self._d(a, x) for a in expr.args])
        if kind is sp.Mul:
            # Mul._eval_derivative: one term per factor differentiated (Leibniz), none for a factor without x
            args = expr.args
            terms = []
            for i, a in enumerate(args):
                d = self._d(a, x)
                if d is not sp.S.Zero:
                    terms.append(self._product([*args[:i], d, *args[i + 1:]]))
            return self._sum(terms)
        if kind is sp.Pow:
            base, exp = expr.args
            dexp = self._d(exp, x)
            log_part = dexp * sp.log(base) if dexp != 0 else sp.S.Zero
            return expr * (log_part + self._d(base, x) * exp / base)
        if kind in (sp.sin, sp.cos):
            # Function._eval_derivative: fdiff times the argument's derivative
            da = self._d(expr.args[0], x)
            if da.is_zero:
                return sp.Add()
            try:
                df = expr.fdiff(1)
            except ArgumentIndexError:
                df = Function.fdiff(expr, 1)
            return self._times(df, da)  # sympy's Add(df*da): a sum of one term is the term
        return sp.diff(expr, x)

    def _times(self, a: sp.Expr, b: sp.Expr) -> sp.Expr:
        """a * b."""
        if type(a).__mul__ is sp.Expr.__mul__ and isinstance(b, sp.Expr) and b._op_priority <= a._op_priority:
            return self._product([a, b])  # what Expr.__mul__ returns: Mul(a, b)
        return a * b

    def _product(self, factors: list[sp.Expr]) -> sp.Expr:
        """sp.Mul(*factors)."""
        if not QUICK or not global_parameters.evaluate:
            return sp.Mul(*factors)  # (inside sympy's evaluate(False): kept as given)
        seq = [f for f in factors if f is not _ONE]
        if len(seq) < 2 and all(isinstance(f, sp.Expr) for f in seq):
            return seq[0] if seq else _ONE  # AssocOp.__new__: no factor but ones is one, one is itself
        quick = self._quick_product(seq)
        return quick if quick is not None else sp.Mul(*factors)

    def _sum(self, terms: list[sp.Expr]) -> sp.Expr:
        """sp.Add(*terms)."""
        if not QUICK or not global_parameters.evaluate:
            return sp.Add(*terms)
        seq = [t for t in terms if t is not _ZERO]
        if len(seq) < 2 and all(isinstance(t, sp.Expr) for t in seq):
            return seq[0] if seq else _ZERO  # AssocOp.__new__: no term but zeros is zero, one is itself
        quick = self._quick_sum(seq)
        return quick if quick is not None else sp.Add(*terms)

    def _quick_product(self, factors: list[sp.Expr]) -> sp.Expr | None:
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

    def _quick_sum(self, terms: list[sp.Expr]) -> sp.Expr | None:
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
