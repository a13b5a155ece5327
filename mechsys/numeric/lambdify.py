"""Compile symbolic expressions to Python callables: common-subexpression elimination, then plain source code.

sympy.lambdify walks the whole (unshared) expression tree several times to find symbols and functions, which
dominates for the long expressions of a chain; here CSE runs once and only its small results are printed."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import sympy as sp
from sympy.printing.pycode import PythonCodePrinter


class _Printer(PythonCodePrinter):
    """Python source with positional argument names a0, a1, ... for the input symbols."""

    def __init__(self, names: dict[sp.Symbol, str]) -> None:
        super().__init__({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": False})
        self._names = names

    def _print_Symbol(self, expr: sp.Symbol) -> str:
        return self._names.get(expr) or super()._print_Symbol(expr)

    _print_Dummy = _print_Symbol

    def _print_DiracDelta(self, expr: sp.Expr) -> str:
        # derivative of sign(x) in |x| (e.g. a 1-D spring length): zero except at the singular point itself
        return "0.0"


def generate_source(exprs: Sequence[sp.Expr], args: Sequence[sp.Symbol]) -> str:
    """Python source of ``_f(a0, a1, ...)`` returning ``exprs`` (shared subexpressions computed once)."""
    names = {a: f"a{i}" for i, a in enumerate(args)}
    exprs = [sp.sympify(e) for e in exprs]
    replacements, reduced = sp.cse(exprs, order="none")
    for k, (sym, _) in enumerate(replacements):
        names[sym] = f"x{k}"
    printer = _Printer(names)
    lines = [f"def _f({', '.join(names[a] for a in args)}):"]
    lines += [f"    {names[sym]} = {printer.doprint(value)}" for sym, value in replacements]
    lines.append("    return [" + ", ".join(printer.doprint(e) for e in reduced) + "]")
    return "\n".join(lines)


def function_from_source(source: str) -> Callable[..., list[float]]:
    """The function defined by generated source (printed by sympy from parsed expressions, or read back from
    mechsys's own cache): no user text reaches it."""
    namespace: dict = {"math": math}
    exec(compile(source, "<mechsys-generated>", "exec"), namespace)  # noqa: S102
    return namespace["_f"]


def compile_exprs(exprs: Sequence[sp.Expr], args: Sequence[sp.Symbol]) -> Callable[..., list[float]]:
    """A function of ``args`` returning the list of ``exprs`` as floats (shared subexpressions computed once)."""
    return function_from_source(generate_source(exprs, args))


@dataclass
class StateFunction:
    """``fn(t, q, u, p)`` evaluating a symbolic matrix at numeric arrays; shape is the matrix shape."""

    shape: tuple[int, int]
    _fn: Callable[..., list[float]]

    def __call__(self, t: float, q: Sequence[float], u: Sequence[float], p: Sequence[float]) -> np.ndarray:
        if self.shape[0] == 0 or self.shape[1] == 0:
            return np.zeros(self.shape)
        out = self._fn(t, *q, *u, *p)
        return np.array(out, dtype=float).reshape(self.shape)


def matrix_source(expr: sp.Matrix, t: sp.Symbol, q: Sequence[sp.Symbol], u: Sequence[sp.Symbol],
                  params: Sequence[sp.Symbol]) -> dict:
    """Cacheable description of a compiled matrix: shape and generated source."""
    expr = sp.Matrix(expr)
    empty = expr.shape[0] == 0 or expr.shape[1] == 0
    return {"shape": list(expr.shape), "source": None if empty else generate_source(list(expr), [t, *q, *u, *params])}


def matrix_from_source(desc: dict) -> StateFunction:
    shape = tuple(desc["shape"])
    if desc["source"] is None:
        return StateFunction(shape, lambda *a: [])
    return StateFunction(shape, function_from_source(desc["source"]))


def compile_matrix(expr: sp.Matrix, t: sp.Symbol, q: Sequence[sp.Symbol], u: Sequence[sp.Symbol],
                   params: Sequence[sp.Symbol]) -> StateFunction:
    """A function of (t, q..., u..., p...) for ``expr`` (a Matrix), entries row by row."""
    return matrix_from_source(matrix_source(expr, t, q, u, params))
