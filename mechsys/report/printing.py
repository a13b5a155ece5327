"""Print sympy expressions in the YAML expression syntax (round-trips through the parser) and in LaTeX."""
from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

import sympy as sp
from sympy.printing.latex import LatexPrinter
from sympy.printing.str import StrPrinter

_SHARING = [0]  # depth of shared_subexpressions() blocks


class _PrintsEachNodeOnce:
    """A printer that prints each subexpression object once: derived equations are DAGs whose shared subtrees
    sympy's printers walk again at every use (the bicycle's Kane equations: 1.6 s -> 0.05 s). A printer's text
    of a node depends only on the node and the settings (a call with keyword arguments, such as LaTeX's
    exponent of a function, is printed as usual), so the output is sympy's, character for character. Keys are
    object identities, each kept with its object (an id is never reused while remembered)."""

    def __init__(self, settings: dict | None = None) -> None:
        super().__init__(settings)
        self._memo: dict[int, tuple[sp.Basic, str]] = {}

    def _print(self, expr, **kwargs) -> str:
        if kwargs or not isinstance(expr, sp.Basic) or not expr.args:
            return super()._print(expr, **kwargs)
        hit = self._memo.get(id(expr))
        if hit is not None and hit[0] is expr:
            return hit[1]
        text = super()._print(expr)
        self._memo[id(expr)] = (expr, text)
        return text

    def doprint(self, expr) -> str:
        try:
            return super().doprint(expr)
        finally:
            if not _SHARING[0]:
                self._memo.clear()


@contextmanager
def shared_subexpressions() -> Iterator[None]:
    """Within the block, to_text and to_latex remember the text of every subexpression across calls (the entries
    of one set of equations share most of their subtrees); outside, only within one call."""
    _SHARING[0] += 1
    try:
        yield
    finally:
        _SHARING[0] -= 1
        if not _SHARING[0]:
            _PRINTER._memo.clear()
            _LATEX._memo.clear()


class YamlExprPrinter(_PrintsEachNodeOnce, StrPrinter):
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


class _DottedLatexPrinter(_PrintsEachNodeOnce, LatexPrinter):
    """sympy's LaTeX with der(x) printed as a dotted x and der(der(x)) double-dotted."""

    def _print_Symbol(self, expr: sp.Symbol, style: str = "plain") -> str:
        dotted = _dotted(expr.name)
        return dotted if dotted is not None else super()._print_Symbol(expr, style)


_PRINTER = YamlExprPrinter({"order": "none"})
_LATEX = _DottedLatexPrinter()


def to_text(expr: sp.Expr) -> str:
    """The expression as a string the YAML expression parser reads back to the same value."""
    return _PRINTER.doprint(sp.sympify(expr))


def _latex_name(name: str) -> str:
    return sp.latex(sp.Symbol(name))


def _dotted(name: str) -> str | None:
    """LaTeX of der(x) as a dotted x, der(der(x)) double-dotted; None for other names."""
    if name.startswith("der(der(") and name.endswith("))"):
        return f"\\ddot{{{_latex_name(name[8:-2])}}}"
    if name.startswith("der(") and name.endswith(")"):
        return f"\\dot{{{_latex_name(name[4:-1])}}}"
    return None


def to_latex(expr: sp.Expr) -> str:
    """The expression in LaTeX, rates dotted."""
    return _LATEX.doprint(sp.sympify(expr))
