"""Whitelist expression parser: YAML expression strings to sympy, without eval or sympify."""
from __future__ import annotations

import difflib
import re
from dataclasses import dataclass
from typing import Callable, Mapping

import sympy as sp

__all__ = ["ExpressionError", "parse_expression", "FUNCTIONS", "CONSTANTS", "RESERVED", "names_in"]


class ExpressionError(ValueError):
    """A malformed or unsafe expression; ``column`` is the 0-based offset in the string."""

    def __init__(self, message: str, column: int = 0) -> None:
        super().__init__(message)
        self.message = message
        self.column = column


def _atan2(y: sp.Expr, x: sp.Expr) -> sp.Expr:
    return sp.atan2(y, x)


def _min(*args: sp.Expr) -> sp.Expr:
    return sp.Min(*args)


def _max(*args: sp.Expr) -> sp.Expr:
    return sp.Max(*args)


# name -> (sympy callable, number of arguments; None = variadic >= 2)
FUNCTIONS: dict[str, tuple[Callable[..., sp.Expr], int | None]] = {
    "sin": (sp.sin, 1), "cos": (sp.cos, 1), "tan": (sp.tan, 1),
    "asin": (sp.asin, 1), "acos": (sp.acos, 1), "atan": (sp.atan, 1), "atan2": (_atan2, 2),
    "sinh": (sp.sinh, 1), "cosh": (sp.cosh, 1), "tanh": (sp.tanh, 1),
    "exp": (sp.exp, 1), "log": (sp.log, 1), "sqrt": (sp.sqrt, 1),
    "abs": (sp.Abs, 1), "sign": (sp.sign, 1), "min": (_min, None), "max": (_max, None),
}
CONSTANTS: dict[str, sp.Expr] = {"pi": sp.pi}
#: Names a YAML file may not declare: functions, constants, time and the rate operator.
RESERVED = frozenset(FUNCTIONS) | frozenset(CONSTANTS) | {"t", "der"}

_TOKEN = re.compile(
    r"\s*(?:(?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)|(?P<name>[A-Za-z_][A-Za-z_0-9]*)"
    r"|(?P<op>\*\*|[-+*/^(),]))"
)
_MAX_LENGTH = 4000
_MAX_DEPTH = 100


@dataclass(frozen=True)
class _Tok:
    kind: str  # "num", "name", "op", "end"
    text: str
    pos: int


def _tokenize(text: str) -> list[_Tok]:
    toks: list[_Tok] = []
    pos = 0
    n = len(text)
    while pos < n:
        if text[pos:].strip() == "":
            break
        m = _TOKEN.match(text, pos)
        if not m or m.end() == pos:
            bad = pos + (len(text[pos:]) - len(text[pos:].lstrip()))
            raise ExpressionError(f"unexpected character {text[bad]!r} in expression", bad)
        kind = m.lastgroup or "op"
        start = m.start(kind)
        toks.append(_Tok(kind, m.group(kind), start))
        pos = m.end()
    toks.append(_Tok("end", "", n))
    return toks


def _number(text: str) -> sp.Expr:
    if len(text.split("e")[0].split("E")[0]) > 300:
        raise ExpressionError("number too large")
    if re.fullmatch(r"\d+", text):
        return sp.Integer(int(text))
    # Decimal literals become exact rationals so textbook formulas stay exact.
    return sp.Rational(text)


class _Parser:
    """Pratt parser over the token list. Grammar: sums, products, unary minus, right-assoc powers."""

    def __init__(self, text: str, symbols: Mapping[str, sp.Expr], rates: Mapping[str, sp.Expr] | None):
        self.text = text
        self.toks = _tokenize(text)
        self.i = 0
        self.symbols = symbols
        self.rates = rates
        self.depth = 0

    def peek(self) -> _Tok:
        return self.toks[self.i]

    def take(self) -> _Tok:
        tok = self.toks[self.i]
        self.i += 1
        return tok

    def expect(self, text: str) -> _Tok:
        tok = self.take()
        if tok.text != text:
            found = "end of expression" if tok.kind == "end" else repr(tok.text)
            raise ExpressionError(f"expected {text!r} but found {found}", tok.pos)
        return tok

    def parse(self) -> sp.Expr:
        if self.peek().kind == "end":
            raise ExpressionError("empty expression", 0)
        expr = self.expr()
        tok = self.peek()
        if tok.kind != "end":
            raise ExpressionError(f"unexpected {tok.text!r}", tok.pos)
        return expr

    def expr(self) -> sp.Expr:
        self.depth += 1
        if self.depth > _MAX_DEPTH:
            raise ExpressionError("expression nested too deeply", self.peek().pos)
        left = self.term()
        while self.peek().text in ("+", "-"):
            op = self.take().text
            right = self.term()
            left = left + right if op == "+" else left - right
        self.depth -= 1
        return left

    def term(self) -> sp.Expr:
        left = self.unary()
        while self.peek().text in ("*", "/"):
            op = self.take()
            right = self.unary()
            if op.text == "/":
                if right == 0:
                    raise ExpressionError("division by zero", op.pos)
                left = left / right
            else:
                left = left * right
        return left

    def unary(self) -> sp.Expr:
        if self.peek().text == "-":
            self.take()
            return -self.unary()
        if self.peek().text == "+":
            self.take()
            return self.unary()
        return self.power()

    def power(self) -> sp.Expr:
        base = self.atom()
        if self.peek().text in ("**", "^"):
            op = self.take()
            exponent = self.unary()  # right associative, allows 2**-1
            if base.is_number and exponent.is_number and _too_large(base, exponent):
                raise ExpressionError("number too large", op.pos)
            return base**exponent
        return base

    def atom(self) -> sp.Expr:
        tok = self.take()
        if tok.kind == "num":
            return _number(tok.text)
        if tok.text == "(":
            inner = self.expr()
            self.expect(")")
            return inner
        if tok.kind == "name":
            if self.peek().text == "(":
                return self.call(tok)
            return self.name(tok)
        found = "end of expression" if tok.kind == "end" else repr(tok.text)
        raise ExpressionError(f"expected a number, name or '(' but found {found}", tok.pos)

    def name(self, tok: _Tok) -> sp.Expr:
        if tok.text in self.symbols:
            return self.symbols[tok.text]
        if tok.text in CONSTANTS:
            return CONSTANTS[tok.text]
        if tok.text in FUNCTIONS or tok.text == "der":
            raise ExpressionError(f"{tok.text!r} is a function and needs arguments", tok.pos)
        raise ExpressionError(self.unknown(tok.text), tok.pos)

    def unknown(self, name: str) -> str:
        known = list(self.symbols) + list(CONSTANTS)
        close = difflib.get_close_matches(name, known, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        return f"unknown name {name!r}{hint}"

    def call(self, tok: _Tok) -> sp.Expr:
        self.expect("(")
        if tok.text == "der":
            arg = self.take()
            if self.rates is None:
                raise ExpressionError("der() is not allowed here", tok.pos)
            if arg.kind != "name":
                raise ExpressionError("der() takes a coordinate name", arg.pos)
            if arg.text not in self.rates:
                close = difflib.get_close_matches(arg.text, list(self.rates), n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise ExpressionError(f"der() of unknown coordinate {arg.text!r}{hint}", arg.pos)
            self.expect(")")
            return self.rates[arg.text]
        if tok.text not in FUNCTIONS:
            if tok.text in self.symbols:
                raise ExpressionError(f"{tok.text!r} is not a function", tok.pos)
            close = difflib.get_close_matches(tok.text, list(FUNCTIONS), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ExpressionError(f"unknown function {tok.text!r}{hint}", tok.pos)
        fn, arity = FUNCTIONS[tok.text]
        args = [self.expr()]
        while self.peek().text == ",":
            self.take()
            args.append(self.expr())
        self.expect(")")
        if arity is None and len(args) < 2:
            raise ExpressionError(f"{tok.text}() takes at least 2 arguments", tok.pos)
        if arity is not None and len(args) != arity:
            raise ExpressionError(f"{tok.text}() takes {arity} argument(s), got {len(args)}", tok.pos)
        if tok.text in ("exp", "sinh", "cosh") and args[0].is_number:
            try:
                big = abs(float(sp.re(args[0]))) > 700
            except (OverflowError, TypeError, ValueError):
                big = True
            if big:
                raise ExpressionError("number too large", tok.pos)
        return fn(*args)


def _too_large(base: sp.Expr, exponent: sp.Expr) -> bool:
    """Would base**exponent be an astronomically large (slow to compute) number?"""
    import math

    try:
        b, e = abs(complex(base)), abs(complex(exponent))
    except (OverflowError, TypeError, ValueError):
        return True
    if e > 1e6 or b > 1e300:
        return True
    return b > 1 and e * math.log10(b) > 1000


def parse_expression(
    text: str | int | float,
    symbols: Mapping[str, sp.Expr],
    rates: Mapping[str, sp.Expr] | None = None,
) -> sp.Expr:
    """Parse ``text`` into a sympy expression.

    ``symbols`` maps each name the context allows (parameters, coordinates, ``t``) to its sympy value;
    ``rates`` maps coordinate names to their rate symbols and enables ``der(name)``. Anything else is an
    :class:`ExpressionError`; nothing in the string is ever executed.
    """
    if isinstance(text, bool):
        raise ExpressionError("expected a number or an expression, got a boolean")
    if isinstance(text, int):
        if abs(text) > 10**300:
            raise ExpressionError("number too large")
        return sp.Integer(text)
    if isinstance(text, float):
        if text != text or text in (float("inf"), float("-inf")):
            raise ExpressionError("number must be finite")
        return sp.Rational(repr(text))  # the decimal as written (0.2 -> 1/5), exact
    if not isinstance(text, str):
        raise ExpressionError(f"expected a number or an expression, got {type(text).__name__}")
    if len(text) > _MAX_LENGTH:
        raise ExpressionError(f"expression longer than {_MAX_LENGTH} characters")
    return _Parser(text, symbols, rates).parse()


def names_in(text: str | int | float) -> set[str]:
    """The bare names (not function names) an expression string mentions; for dependency graphs."""
    if not isinstance(text, str):
        return set()
    try:
        toks = _tokenize(text)
    except ExpressionError:
        return set()
    out = set()
    for k, tok in enumerate(toks):
        if tok.kind == "name" and toks[k + 1].text != "(" and tok.text not in CONSTANTS:
            out.add(tok.text)
    return out
