"""Differentiation that visits each subexpression once: sympy's rules, memoized over the expression DAG.

sympy's `diff` recurses through `Derivative.__new__` at every node, and each call walks the node's whole subtree
again (its free symbols, then a `replace` of nested derivatives), so differentiating a derived expression costs
the square of its size, and the entries of M, which share most of their subtrees, repeat all of it. This
module applies the same rules as sympy (sums term by term, Leibniz's rule over a product's factors, sympy's
formula for powers, the chain rule through `fdiff` for sin and cos, the same shortcut to zero for a node without
the variable) and remembers each node's derivative, so the result is sympy's expression, built once. Nodes of
other kinds are differentiated by sympy itself.

Most of the time left was sympy's constructors on the Leibniz terms and their sums: they are built directly
where flatten would only sort (mechanics/construct.py), by sympy's constructors everywhere else."""
from __future__ import annotations

import sympy as sp
from sympy.core.function import ArgumentIndexError, Function

from mechsys.mechanics.construct import Constructors
from mechsys.mechanics.dag import FreeSymbols


class Differentiator:
    """d(expr)/d(symbol), remembered per (node, symbol) for the lifetime of the object (one model)."""

    def __init__(self) -> None:
        self._memo: dict[tuple[sp.Basic, sp.Symbol], sp.Expr] = {}
        self.symbols = FreeSymbols()  # expr.free_symbols, remembered per node (sympy recomputes it every call)
        self.free = self.symbols.of
        self.build = Constructors()  # the Leibniz terms and their sums, directly where flatten would only sort

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
            return self.build.add([self._d(a, x) for a in expr.args])
        if kind is sp.Mul:
            # Mul._eval_derivative: one term per factor differentiated (Leibniz), none for a factor without x
            args = expr.args
            terms = []
            for i, a in enumerate(args):
                d = self._d(a, x)
                if d is not sp.S.Zero:
                    terms.append(self.build.mul([*args[:i], d, *args[i + 1:]]))
            return self.build.add(terms)
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
            return self.build.times(df, da)  # sympy's Add(df*da): a sum of one term is the term
        return sp.diff(expr, x)
