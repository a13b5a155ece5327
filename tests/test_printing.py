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
    """The same printer walking every node at every use (sympy's own traversal, nothing remembered), with
    sympy's own products, sums and brackets (YamlExprPrinter builds the common product's text directly)."""

    def _print(self, expr, **kwargs):
        return StrPrinter._print(self, expr, **kwargs)

    _print_Mul = StrPrinter._print_Mul
    _print_Add = StrPrinter._print_Add
    parenthesize = StrPrinter.parenthesize


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
                                         ("slider_crank", "lagrange"), ("bicycle", "kane"), ("centrifuge", "kane")])
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


def test_products_print_as_sympy_prints_them():
    """The products YamlExprPrinter writes itself (a rational coefficient, then symbols, sums, functions and
    positive powers) and those it leaves to sympy (floats, negative and integer powers, unevaluated products)."""
    x, y, m, l = sp.symbols("x y m l")
    rate = sp.Symbol("der(x)")
    s = x + y
    exprs = [m * l**2 / 12, -m * l * sp.cos(x) / 2, -x * s, -s * sp.sin(y), 3 * x * s**2, -sp.Rational(7, 3) * rate * s,
             sp.sqrt(x) * y, -sp.sqrt(2) * x, 2.5 * x * y, -0.5 * s * x, x / y, -x / (2 * y), x * y**-2,
             sp.Mul(2, 3, x, evaluate=False), sp.Mul(1, x, y, evaluate=False), sp.Mul(-1, s, evaluate=False),
             sp.Mul(x, sp.Pow(2, 3, evaluate=False), evaluate=False), sp.exp(x) * y, -sp.exp(x) * s / 4,
             sp.Abs(x) * y, -sp.Max(x, y) * l, x**sp.Rational(3, 2) * y, -(s**2) * sp.cos(s) * l / 7,
             sp.Mul(-1, x, evaluate=False), sp.Mul(sp.Rational(-1, 2), s, evaluate=False)]
    plain = _EveryNode({"order": "none"})
    for e in exprs:
        assert to_text(e) == plain.doprint(e), e
        assert to_text(s + e) == plain.doprint(s + e), e
        assert to_text(e * sp.cos(e)) == plain.doprint(e * sp.cos(e)), e
