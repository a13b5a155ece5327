"""Walks of expression DAGs that visit each shared subexpression once: the free symbols of derived equations.

sympy's ``free_symbols`` unions the free symbols of every argument again at every use of a shared subtree (derived
equations are DAGs: a bicycle's M and f share most of theirs), so asking it for each entry of M, f, A and b, and
again per coordinate, walked the trees dozens of times (the cyclic-coordinate decision of a cold `info`)."""
from __future__ import annotations

from typing import Iterable

import sympy as sp

#: node types whose free symbols are exactly the union of their arguments' (no bound variables)
_PLAIN = (sp.Add, sp.Mul, sp.Pow, sp.Function, sp.Tuple)


class FreeSymbols:
    """``of(expr)``: the free symbols of expr, each subexpression object's computed once (kept with its object,
    so an id is never reused while remembered); equal to ``expr.free_symbols``."""

    def __init__(self) -> None:
        self._memo: dict[int, tuple[sp.Basic, frozenset]] = {}

    def _known(self, node: sp.Basic) -> frozenset | None:
        hit = self._memo.get(id(node))
        return hit[1] if hit is not None and hit[0] is node else None

    def of(self, expr: sp.Basic) -> frozenset:
        hit = self._known(expr)
        if hit is not None:
            return hit
        expr = sp.sympify(expr)
        stack = [(expr, False)]
        while stack:  # iterative post-order: deep sums and products never reach the recursion limit
            node, ready = stack.pop()
            if self._known(node) is not None:
                continue
            if not node.args or not isinstance(node, _PLAIN):
                self._memo[id(node)] = (node, frozenset(node.free_symbols))
            elif ready:
                self._memo[id(node)] = (node, frozenset().union(*(self._known(a) for a in node.args)))
            else:
                stack.append((node, True))
                stack.extend((a, False) for a in node.args if self._known(a) is None)
        return self._known(expr)

    def of_all(self, exprs: Iterable[sp.Basic]) -> frozenset:
        """The union over ``exprs`` (the entries of matrices, say)."""
        return frozenset().union(*(self.of(e) for e in exprs))
