"""The whitelist expression parser: grammar, exactness, names, and that nothing is ever executed."""
import os

import pytest
import sympy as sp

from mechsys.model.expressions import ExpressionError, names_in, parse_expression
from mechsys.report.printing import to_text

x, y = sp.symbols("x y", real=True)
u = sp.Symbol("der(x)", real=True)
SYMS = {"x": x, "y": y}


@pytest.mark.parametrize("text, expected", [
    ("1 + 2*3", sp.Integer(7)),
    ("2^3^2", sp.Integer(512)),            # right-associative powers
    ("2**-1", sp.Rational(1, 2)),
    ("-x**2", -x**2),                       # unary minus binds looser than the power
    ("0.1 + 0.2", sp.Rational(3, 10)),      # decimals are exact
    ("1e-3*x", x / 1000),
    ("sin(x)**2 + cos(x)**2", sp.sin(x)**2 + sp.cos(x)**2),
    ("atan2(y, x)", sp.atan2(y, x)),
    ("abs(x) + sign(y)", sp.Abs(x) + sp.sign(y)),
    ("min(x, y, 1)", sp.Min(x, y, 1)),
    ("pi/2", sp.pi / 2),
    ("sqrt(x)*exp(-y)", sp.sqrt(x) * sp.exp(-y)),
])
def test_grammar(text, expected):
    assert parse_expression(text, SYMS) == expected


def test_numbers_pass_through_exactly():
    assert parse_expression(3, SYMS) == 3
    assert parse_expression(0.2, SYMS) == sp.Rational(1, 5)


def test_der_only_where_allowed():
    assert parse_expression("x*der(x)", SYMS, {"x": u}) == x * u
    with pytest.raises(ExpressionError, match="not allowed"):
        parse_expression("der(x)", SYMS)
    with pytest.raises(ExpressionError, match="unknown coordinate 'z'"):
        parse_expression("der(z)", SYMS, {"x": u})


@pytest.mark.parametrize("text, fragment, column", [
    ("x + gg", "unknown name 'gg'", 4),
    ("xx*2", "did you mean 'x'", 0),
    ("sinn(x)", "did you mean 'sin'", 0),
    ("x*", "expected a number", 2),
    ("(x + y", "expected ')'", 6),
    ("x y", "unexpected 'y'", 2),
    ("x $ y", "unexpected character '$'", 2),
    ("1/0", "division by zero", 1),
    ("atan2(x)", "takes 2 argument", 0),
    ("sin", "needs arguments", 0),
    ("x(1)", "not a function", 0),
    ("", "empty expression", 0),
])
def test_errors_name_the_problem_and_column(text, fragment, column):
    with pytest.raises(ExpressionError) as exc:
        parse_expression(text, SYMS)
    assert fragment in exc.value.message
    assert exc.value.column == column


@pytest.mark.parametrize("attack", [
    "__import__('os').system('touch {marker}')",
    "().__class__.__bases__[0]",
    "lambda: 1",
    "open('{marker}', 'w')",
    "x.__class__",
    "eval('1')",
])
def test_code_is_never_executed(tmp_path, attack):
    marker = tmp_path / "pwned"
    with pytest.raises(ExpressionError):
        parse_expression(attack.format(marker=marker), SYMS)
    assert not marker.exists()
    assert not os.path.exists("pwned")


def test_names_in_skips_functions_and_constants():
    assert names_in("a*sin(b) + pi*der(c)") == {"a", "b", "c"}


@pytest.mark.parametrize("expr", [
    x**2 * sp.sin(y) - sp.Rational(3, 7) * sp.cos(x + y),
    sp.Abs(x) + sp.Min(x, y) + sp.exp(1) * sp.atan2(y, x),
    sp.sqrt(x) / (1 + y**2) + u * x,
])
def test_printer_round_trips_through_the_parser(expr):
    assert parse_expression(to_text(expr), SYMS, {"x": u}) == expr
