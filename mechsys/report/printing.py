"""Print sympy expressions in the YAML expression syntax (round-trips through the parser) and in LaTeX."""
from __future__ import annotations

import sympy as sp
from sympy.printing.str import StrPrinter


class YamlExprPrinter(StrPrinter):
    """str() with the function names of the YAML language: abs, min, max, exp(1) instead of E."""

    def _print_Abs(self, expr: sp.Abs) -> str:
        return f"abs({self._print(expr.args[0])})"

    def _print_Min(self, expr: sp.Min) -> str:
        return "min(" + ", ".join(self._print(a) for a in expr.args) + ")"

    def _print_Max(self, expr: sp.Max) -> str:
        return "max(" + ", ".join(self._print(a) for a in expr.args) + ")"

    def _print_Exp1(self, expr: sp.Expr) -> str:
        return "exp(1)"

    def _print_ImaginaryUnit(self, expr: sp.Expr) -> str:  # never valid in a model; make it visible
        return "sqrt(-1)"


_PRINTER = YamlExprPrinter({"order": "none"})


def to_text(expr: sp.Expr) -> str:
    """The expression as a string the YAML expression parser reads back to the same value."""
    return _PRINTER.doprint(sp.sympify(expr))


def _latex_name(name: str) -> str:
    return sp.latex(sp.Symbol(name))


def latex_symbol_names(symbols: set[sp.Symbol]) -> dict[sp.Symbol, str]:
    """LaTeX names: der(x) as a dotted symbol, der(der(x)) double-dotted; others as sympy names them."""
    out = {}
    for s in symbols:
        name = s.name
        if name.startswith("der(der(") and name.endswith("))"):
            out[s] = f"\\ddot{{{_latex_name(name[8:-2])}}}"
        elif name.startswith("der(") and name.endswith(")"):
            out[s] = f"\\dot{{{_latex_name(name[4:-1])}}}"
    return out


def to_latex(expr: sp.Expr) -> str:
    expr = sp.sympify(expr)
    return sp.latex(expr, symbol_names=latex_symbol_names(expr.free_symbols))
