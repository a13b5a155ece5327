"""The printers of report/printing.py print each subexpression object once (derived equations share most of their
subtrees): the text and LaTeX must be sympy's own printers' output, character for character, inside and outside
a shared block, and what they remember is dropped when the block (or the call) ends."""
from __future__ import annotations

import pytest
import sympy as sp
from sympy.printing.str import StrPrinter

import mechsys
from helpers import SYSTEMS_DIR
from mechsys.report import printing
from mechsys.report.printing import YamlExprPrinter, shared_subexpressions, to_latex, to_text


class _EveryNode(YamlExprPrinter):
    """The same printer walking every node at every use (sympy's own traversal, nothing remembered)."""

    def _print(self, expr, **kwargs):
        return StrPrinter._print(self, expr, **kwargs)


def _sympy_latex(expr: sp.Expr) -> str:
    """sympy.latex with rates dotted through its symbol_names setting (how mechsys printed LaTeX before)."""
    names = {}
    for s in expr.free_symbols:
        if s.name.startswith("der(der("):
            names[s] = f"\\ddot{{{sp.latex(sp.Symbol(s.name[8:-2]))}}}"
        elif s.name.startswith("der("):
            names[s] = f"\\dot{{{sp.latex(sp.Symbol(s.name[4:-1]))}}}"
    return sp.latex(expr, symbol_names=names)


def _entries(name: str, method: str) -> list[sp.Expr]:
    eq = mechsys.load(SYSTEMS_DIR / f"{name}.yaml").equations(method)
    return [eq.T, eq.V, *eq.Q, *eq.M, *eq.f, *eq.A, *eq.b]


@pytest.mark.parametrize("name,method", [("rolling_disk", "kane"), ("gyrostabilizer", "lagrange"),
                                         ("slider_crank", "lagrange")])
def test_shared_printing_is_sympys_printing(name, method):
    exprs = _entries(name, method)
    plain = _EveryNode({"order": "none"})
    text = [plain.doprint(e) for e in exprs]
    latex = [_sympy_latex(e) for e in exprs]
    assert [to_text(e) for e in exprs] == text
    assert [to_latex(e) for e in exprs] == latex
    with shared_subexpressions():
        assert [to_text(e) for e in exprs] == text
        assert [to_latex(e) for e in exprs] == latex
        assert printing._PRINTER._memo  # remembered across the calls of the block


def test_a_subtree_in_different_places_prints_the_same():
    x, y, a, b = sp.symbols("x y a b")
    rate = sp.Symbol("der(x)")
    s = sp.sin(x) * rate + a * sp.cos(y)  # one object, used as a term, a factor, a base, a negated sum
    exprs = [s, s**2 - 3 * s, -s, a / s, sp.sqrt(s) * sp.sin(x) ** 2, sp.Abs(s) + sp.Max(s, b), s ** sp.Rational(-1, 2)]
    plain = _EveryNode({"order": "none"})
    with shared_subexpressions():
        assert [to_text(e) for e in exprs] == [plain.doprint(e) for e in exprs]
        assert [to_latex(e) for e in exprs] == [_sympy_latex(e) for e in exprs]
    assert "\\dot{x}" in to_latex(s) and "abs(" in to_text(exprs[5])


def test_nothing_is_remembered_after_a_call_or_a_block():
    x = sp.Symbol("x")
    expr = sp.sin(x) ** 2 + sp.cos(x) * x
    to_text(expr)
    to_latex(expr)
    assert not printing._PRINTER._memo and not printing._LATEX._memo
    with shared_subexpressions():
        with shared_subexpressions():
            to_text(expr)
        assert printing._PRINTER._memo  # the outer block still shares
    assert not printing._PRINTER._memo and not printing._LATEX._memo
