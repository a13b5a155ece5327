"""Bounds of the expression parser and of parameter resolution (issue 10).

Every expression that would make sympy compute an astronomically long exact number, or Python recurse past its
stack, is an input error at its column (the time guards here catch hangs, not slowness); long parameter chains
resolve in linear time with the exact values and the cycle report ``a -> b -> a``.
"""
from __future__ import annotations

import time
from fractions import Fraction
from pathlib import Path

import pytest
import sympy as sp
from typer.testing import CliRunner

from mechsys.cli import app
from mechsys.errors import InputError
from mechsys.model.expressions import ExpressionError, parse_expression
from mechsys.model.load import read_document

X = sp.Symbol("x", real=True)
SYMS = {"x": X}
runner = CliRunner()


def _join(sep: str, items) -> str:
    """Items joined by sep, cut at a whole item below the 4000-character limit."""
    out = ""
    for item in items:
        nxt = item if not out else out + sep + item
        if len(nxt) > 3990:
            break
        out = nxt
    return out


BOMBS = [
    ("tiny-base-huge-power", "(10**-300)**(10**6)", "too large"),
    ("half-to-a-large-power", "(1/2)**(10**5)", "too large"),
    ("decimal-near-one", "1.0000001**(10**9)", "too large"),
    ("negative-power", "(2/3)**-1000000", "too large"),
    ("tower-9", "9**9**9", "too large"),
    ("tower-10", "10**10**10", "too large"),
    ("tower-caret", "10^10^10", "too large"),
    ("exponent-literal-huge", "1e999999999", "out of range"),
    ("exponent-literal-tiny", "1e-999999999", "out of range"),
    ("exponent-literal-long", "1e" + "9" * 3000, "out of range"),
    ("rational-literal-4000-digits", "0." + "0" * 3996 + "1", "digits"),
    ("integer-literal-3000-digits", "9" * 3000, "digits"),
    ("product-of-powers", "10**99*10**99", "too large"),
    ("sum-of-big-reciprocals", _join("+", (f"1/(9**99+{k})" for k in range(400))), "too large"),
    ("sum-of-small-reciprocals", _join("+", (f"1/(9**9+{k})" for k in range(400))), "too large"),
    ("product-of-roots", _join("*", ["sqrt(9**99+1)"] * 300), "too large"),
    ("product-of-distinct-roots", _join("*", (f"sqrt({10**9 + k})" for k in range(400))), "too large"),
    ("exp-of-large", "exp(10**6)", "too large"),
    ("pi-power", "pi**(10**7)", "too large"),
    ("unary-minus-3000", "-" * 3000 + "1", "nested too deeply"),
    ("unary-mixed-3000", "-+" * 1500 + "x", "nested too deeply"),
    ("power-chain-1000", "**".join(["x"] * 1000), "nested too deeply"),
    ("power-chain-caret-1000", "^".join(["2"] * 1000), "nested too deeply"),
    ("nested-calls-150", "sin(" * 150 + "x" + ")" * 150, "nested too deeply"),
    ("nested-parentheses-1500", "(" * 1500 + "x" + ")" * 1500, "nested too deeply"),
    ("minus-parentheses-600", "-(" * 600 + "x" + ")" * 600, "nested too deeply"),
    ("exponent-parentheses", "x**(" * 300 + "x" + ")" * 300, "nested too deeply"),
]


@pytest.mark.parametrize("text, fragment", [b[1:] for b in BOMBS], ids=[b[0] for b in BOMBS])
def test_bombs_are_refused_quickly(text, fragment):
    start = time.perf_counter()
    with pytest.raises(ExpressionError) as info:
        parse_expression(text, SYMS)
    elapsed = time.perf_counter() - start
    assert fragment in info.value.message
    assert 0 <= info.value.column < len(text)
    assert elapsed < 15.0, f"{elapsed:.2f} s"  # a hang guard (a bomb that is not refused runs for hours), not a speed test


@pytest.mark.parametrize("text, column", [
    ("-" * 3000 + "1", 99),             # the top level and 99 signs are 100 levels: the 100th sign is one too many
    ("**".join(["x"] * 1000), 298),     # the 100th '**' (0-based column 1 + 3 * 99)
    ("(" * 200 + "x" + ")" * 200, 99),  # the 100th '(' opens level 101
    ("sin(" * 150 + "x" + ")" * 150, 396),
])
def test_depth_error_points_at_the_column(text, column):
    with pytest.raises(ExpressionError) as info:
        parse_expression(text, SYMS)
    assert info.value.column == column


def test_documented_depth_is_accepted():
    """Nesting depth 100 (yaml-reference 3.1): 99 parentheses inside the top-level expression, or 99 signs."""
    assert parse_expression("(" * 99 + "x" + ")" * 99, SYMS) == X
    assert parse_expression("-" * 98 + "x", SYMS) == X
    assert parse_expression("-(" * 49 + "x" + ")" * 49, SYMS) == -X


@pytest.mark.parametrize("text, expected", [
    ("2**300", sp.Integer(2) ** 300),
    ("(1/3)**60", sp.Rational(1, 3**60)),
    ("(10**-30)**3", sp.Rational(1, 10**90)),
    ("2^-1", sp.Rational(1, 2)),
    ("-x^2", -X**2),
    ("2**2**2**2", sp.Integer(65536)),
    ("(-1)**(10**12)", sp.Integer(1)),
    ("1**(10**20)", sp.Integer(1)),
    ("sqrt(2)*sqrt(2)", sp.Integer(2)),
    ("1e-100", sp.Rational(1, 10**100)),
    ("9" * 100, sp.Integer(int("9" * 100))),
    ("0.0254*12*0.45359237*9.80665*0.3048*1.609344*0.0254*12*0.45359237*9.80665",
     sp.Rational(Fraction("0.0254") * 12 * Fraction("0.45359237") * Fraction("9.80665") * Fraction("0.3048")
                 * Fraction("1.609344") * Fraction("0.0254") * 12 * Fraction("0.45359237") * Fraction("9.80665"))),
])
def test_ordinary_numbers_stay_exact(text, expected):
    assert parse_expression(text, SYMS) == expected


@pytest.fixture
def flatten_calls(monkeypatch):
    """How many times sympy flattens an Add or a Mul: a count of work that does not depend on machine load."""
    calls = {"Add": 0, "Mul": 0}
    for cls in (sp.Add, sp.Mul):
        original = cls.flatten.__func__

        def counted(klass, seq, _original=original, _name=cls.__name__):
            calls[_name] += 1
            return _original(klass, seq)

        monkeypatch.setattr(cls, "flatten", classmethod(counted))
    return calls


def test_long_ordinary_sums_and_products_are_linear(flatten_calls):
    """2000 terms or factors: one flatten, not one per operator (that was quadratic and took about a second).

    Counted, not timed: a wall-clock bound failed on a loaded CI machine (1.2 s for 0.1 s of work)."""
    parsed = parse_expression("+".join(["x"] * 1999), SYMS)
    assert flatten_calls["Add"] <= 5, flatten_calls
    assert parsed == 1999 * X
    flatten_calls.update(Add=0, Mul=0)
    parsed = parse_expression("*".join(["x"] * 1999), SYMS)
    assert flatten_calls["Mul"] <= 5, flatten_calls
    assert parsed == X**1999
    flatten_calls.update(Add=0, Mul=0)
    parsed = parse_expression(_join("+", (f"{k}/7*x" for k in range(1, 600))), SYMS)
    assert flatten_calls["Add"] <= 5, flatten_calls  # the 599 terms are one Add, built once
    assert parsed.is_Mul


# ----------------------------------------------------------------------------------------- in a file, in --set
MODEL = """\
name: bounds
parameters:
  m: 2
  k: {k}
coordinates:
  x: {{initial: 0.1, rate: 0}}
links:
  body:
    joint: {{type: prismatic, parent: ground, axis: x, coordinate: x}}
    mass: m
forces:
  - {{type: spring, between: [ground, body], stiffness: k, free_length: 0}}
"""


@pytest.mark.parametrize("bomb, fragment", [("(10**-300)**(10**6)", "too large"), ("-" * 3000 + "1", "nested"),
                                            ("**".join(["2"] * 1000), "nested"), ("1e999999999", "out of range")])
def test_bomb_in_a_file_is_a_positioned_input_error(tmp_path, bomb, fragment):
    path = tmp_path / "model.yaml"
    path.write_text(MODEL.format(k=f'"{bomb}"'), encoding="utf-8")
    start = time.perf_counter()
    result = runner.invoke(app, ["info", str(path)])
    assert time.perf_counter() - start < 30.0  # a hang guard, not a speed test
    assert result.exit_code == 2, (result.stdout, result.stderr)
    line = result.stderr.strip()
    assert line.startswith(f"{path}:4:"), line
    assert ": parameters.k: " in line and fragment in line, line
    assert "internal error" not in line and len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("bomb, fragment", [("(10**-300)**(10**6)", "too large"), ("-" * 3000 + "1", "nested"),
                                            ("10**10**10", "too large")])
def test_bomb_in_set_is_an_input_error(tmp_path, bomb, fragment):
    path = tmp_path / "model.yaml"
    path.write_text(MODEL.format(k=100), encoding="utf-8")
    result = runner.invoke(app, ["info", str(path), "--set", f"k={bomb}"])
    assert result.exit_code == 2, (result.stdout, result.stderr)
    line = result.stderr.strip()
    assert line.startswith("mechsys: --set k=") and fragment in line, line[:200]
    assert len(line) < 250  # the 3000-character item is shortened in the message


@pytest.mark.parametrize("text, value", [("1e-300", 1e-300), ("2.5e120", 2.5e120), ("-1.5E-200", -1.5e-200),
                                         ("0e-500", 0.0)])
def test_literals_beyond_exact_range_are_floats(text, value):
    parsed = parse_expression(text, SYMS)
    assert float(parsed) == value
    assert parsed.is_Float or parsed == 0


@pytest.mark.parametrize("text", ["1e400", "1e-320"])
def test_literals_beyond_a_double_are_refused(text):
    with pytest.raises(ExpressionError, match="out of range"):
        parse_expression(text, SYMS)


def test_set_reads_values_as_expressions(tmp_path):
    """--set a=0.1 is the exact 1/10, like "0.1" in the file; 1e-300 is the float (yaml-reference 3.1, 14)."""
    path = tmp_path / "model.yaml"
    path.write_text(MODEL.format(k=100), encoding="utf-8")
    assert read_document(path, overrides={"k": "0.1"}).parameter_exprs["k"] == sp.Rational(1, 10)
    assert read_document(path, overrides={"k": "1e-300"}).parameter_values["k"] == 1e-300
    result = runner.invoke(app, ["info", str(path), "--set", "k=1e-300"])
    assert result.exit_code == 0, result.stderr


# ----------------------------------------------------------------------------------------- parameter chains
def chain_file(tmp_path: Path, n: int, ring: bool = False) -> Path:
    lines = ["name: chain", "parameters:", f"  p0: {f'p{n - 1}+1' if ring else 1}"]
    lines += [f"  p{i}: p{i - 1}+1" for i in range(1, n)]
    lines += ["  m: 2", "coordinates:", "  x: {initial: 0.1, rate: 0}", "links:", "  b:",
              "    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}", "    mass: m"]
    path = tmp_path / f"chain{n}.yaml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_chain_of_1000_parameters_exact_values(tmp_path):
    doc = read_document(chain_file(tmp_path, 1000))
    assert doc.parameter_values["p999"] == 1000.0
    assert all(doc.parameter_values[f"p{i}"] == i + 1 for i in range(1000))
    assert list(doc.parameter_exprs)[:2] == ["p0", "p1"]  # dependency order


def test_chain_of_2000_parameters_loads_in_linear_time(tmp_path):
    """Was quadratic (1000 parameters: 41 s) and recursive (2000: RecursionError)."""
    import mechsys

    path = chain_file(tmp_path, 2000)
    start = time.perf_counter()
    model = mechsys.load(path)
    elapsed = time.perf_counter() - start
    assert model.parameters["p1999"] == 2000.0
    assert elapsed < 30.0, f"{elapsed:.1f} s"  # a hang guard: the quadratic resolution took minutes here


def test_long_ring_is_reported_as_a_cycle(tmp_path):
    with pytest.raises(InputError) as info:
        read_document(chain_file(tmp_path, 1500, ring=True))
    message = str(info.value)
    assert "parameters form a cycle: " in message
    names = message.split("parameters form a cycle: ")[1].split(" -> ")
    assert len(names) == 1501 and names[0] == names[-1]


def test_short_cycle_report_unchanged(tmp_path):
    path = tmp_path / "cycle.yaml"
    path.write_text(MODEL.format(k="a").replace("  m: 2\n", "  m: 2\n  a: b + 1\n  b: a\n"), encoding="utf-8")
    with pytest.raises(InputError) as info:
        read_document(path)
    assert "parameters form a cycle: a -> b -> a" in str(info.value)
