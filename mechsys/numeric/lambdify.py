"""Compile symbolic matrices to numpy callables of (t, q, u, p) with common-subexpression elimination."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import sympy as sp


@dataclass
class StateFunction:
    """``fn(t, q, u, p)`` evaluating a symbolic matrix at numeric arrays; shape is the matrix shape."""

    shape: tuple[int, int]
    _fn: Callable[..., object]

    def __call__(self, t: float, q: Sequence[float], u: Sequence[float], p: Sequence[float]) -> np.ndarray:
        if self.shape[0] == 0 or self.shape[1] == 0:
            return np.zeros(self.shape)
        out = self._fn(t, *q, *u, *p)
        return np.array(out, dtype=float).reshape(self.shape)


def compile_matrix(expr: sp.Matrix, t: sp.Symbol, q: Sequence[sp.Symbol], u: Sequence[sp.Symbol],
                   params: Sequence[sp.Symbol]) -> StateFunction:
    """A numpy function of (t, q..., u..., p...) for ``expr`` (a Matrix); CSE is shared across entries."""
    expr = sp.Matrix(expr)
    args = [t, *q, *u, *params]
    if expr.shape[0] == 0 or expr.shape[1] == 0:
        return StateFunction(expr.shape, lambda *a: None)
    fn = sp.lambdify(args, expr, modules="numpy", cse=_cse)
    return StateFunction(expr.shape, fn)


def _cse(exprs):
    """Common-subexpression elimination without canonical ordering (much faster on long expressions)."""
    return sp.cse(exprs, order="none")
