"""Whitelist expression parser: YAML expression strings to sympy, without eval or sympify."""
from __future__ import annotations

import difflib
import math
import re
import sys
from dataclasses import dataclass
from fractions import Fraction
from typing import Callable, Mapping, Protocol

import sympy as sp

__all__ = ["ExpressionError", "parse_expression", "FUNCTIONS", "CONSTANTS", "RESERVED", "names_in", "Quantities"]


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
    r"|(?P<op>\*\*|[-+*/^(),.]))"
)
_MAX_LENGTH = 4000
#: Nesting levels: parentheses, function arguments, unary signs and exponents each count one.
_MAX_DEPTH = 100
#: Exact numbers (numerators, denominators) written or built while parsing have at most this many digits
#: (a double has 17): sympy computes powers, sums and products of rationals exactly and factors the bases of
#: roots, so (10**-300)**(10**6), a sum of 1/(10**999 + k) or sqrt(3**2000 + 1) would run for seconds to hours.
_MAX_DIGITS = 100


@dataclass(frozen=True)
class _Tok:
    kind: str  # "num", "name", "op", "end"
    text: str
    pos: int


def _tokenize(text: str, dots: bool = False) -> list[_Tok]:
    """The tokens of ``text``; a '.' outside a number is a token only where ``dots`` (references to points and
    components in output quantities), an unexpected character everywhere else."""
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
        if kind == "op" and m.group(kind) == "." and not dots:
            raise ExpressionError("unexpected character '.' in expression", start)
        toks.append(_Tok(kind, m.group(kind), start))
        pos = m.end()
    toks.append(_Tok("end", "", n))
    return toks


def _number(text: str, pos: int = 0) -> sp.Expr:
    mantissa, _, exp10 = text.lower().partition("e")
    if len(mantissa.replace(".", "")) > _MAX_DIGITS:
        raise ExpressionError(f"number literal longer than {_MAX_DIGITS} digits", pos)
    # 1e999999999 (or 1e-999999999) would be an exact number of a billion digits: bound it before building it.
    # A literal beyond exact range but within a double's (1e-300, 2.5e120) is the binary float it reads as.
    if exp10 and (len(exp10) > 6 or abs(int(exp10)) > _MAX_DIGITS):
        if not any(ch in "123456789" for ch in mantissa):
            return sp.Integer(0)
        value = float(text) if len(exp10) <= 6 else math.inf
        if not sys.float_info.min <= abs(value) < math.inf:
            raise ExpressionError(f"number {text!r} out of range (an exact number has at most {_MAX_DIGITS} digits, "
                                  f"a float lies within {sys.float_info.min:.1e} to {sys.float_info.max:.1e})", pos)
        return sp.Float(text)
    if re.fullmatch(r"\d+", text):
        return sp.Integer(int(text))
    # Decimal literals become exact rationals so textbook formulas stay exact.
    return sp.Rational(text)


class _Parser:
    """Pratt parser over the token list. Grammar: sums, products, unary minus, right-assoc powers."""

    def __init__(self, text: str, symbols: Mapping[str, sp.Expr], rates: Mapping[str, sp.Expr] | None,
                 quantities: "Quantities | None" = None):
        self.text = text
        self.toks = _tokenize(text, dots=quantities is not None)
        self.i = 0
        self.symbols = symbols
        self.rates = rates
        self.quantities = quantities
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

    def enter(self, pos: int) -> None:
        """One more nesting level (parenthesis, call argument, unary sign, exponent); every recursion of the
        parser passes here, so no input can exhaust Python's stack."""
        self.depth += 1
        if self.depth > _MAX_DEPTH:
            raise ExpressionError(f"expression nested too deeply (more than {_MAX_DEPTH} levels of parentheses, "
                                  "calls, signs or powers)", pos)

    def expr(self, opened_at: int | None = None) -> sp.Expr:
        """A sum; ``opened_at`` is the column of the parenthesis or call that opens this level (for errors)."""
        start = self.peek().pos
        self.enter(start if opened_at is None else opened_at)
        terms = [self.term()]
        while self.peek().text in ("+", "-"):
            op = self.take().text
            right = self.term()
            terms.append(right if op == "+" else -right)
        self.depth -= 1
        if len(terms) == 1:
            return terms[0]
        _check_sum(terms, start)
        return sp.Add(*terms)  # one flatten for the whole sum: linear, not quadratic, in the number of terms

    def term(self) -> sp.Expr:
        start = self.peek().pos
        factors = [self.unary()]
        while self.peek().text in ("*", "/"):
            op = self.take()
            right = self.unary()
            if op.text == "/":
                if right == 0:
                    raise ExpressionError("division by zero", op.pos)
                factors.append(1 / right)
            else:
                factors.append(right)
        if len(factors) == 1:
            return factors[0]
        _check_product(factors, start)
        return sp.Mul(*factors)

    def unary(self) -> sp.Expr:
        tok = self.peek()
        if tok.text in ("-", "+"):
            self.take()
            self.enter(tok.pos)
            inner = self.unary()
            self.depth -= 1
            return -inner if tok.text == "-" else inner
        return self.power()

    def power(self) -> sp.Expr:
        base = self.atom()
        if self.peek().text in ("**", "^"):
            op = self.take()
            self.enter(op.pos)
            exponent = self.unary()  # right associative, allows 2**-1
            self.depth -= 1
            if base.is_number and exponent.is_number and _too_large(base, exponent):
                raise ExpressionError(f"number too large (an exact number has at most {_MAX_DIGITS} digits)",
                                      op.pos)
            return base**exponent
        return base

    def atom(self) -> sp.Expr:
        tok = self.take()
        if tok.kind == "num":
            return _number(tok.text, tok.pos)
        if tok.text == "(":
            inner = self.expr(tok.pos)
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
        start = self.i - 1  # the index of the function name
        self.expect("(")
        if tok.text == "der" and self.quantities is not None and self.peek().text == "der":
            return self.second_derivative(tok)
        if self.quantities is not None and (tok.text in self.quantities.functions or tok.text == "norm"):
            return self.quantity(tok, start)
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
        args = [self.expr(tok.pos)]
        while self.peek().text == ",":
            self.take()
            args.append(self.expr(tok.pos))
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
                raise ExpressionError(f"number too large: {tok.text}() of more than 700", tok.pos)
        return fn(*args)


    def second_derivative(self, tok: _Tok) -> sp.Expr:
        """der(der(NAME)): the coordinate's acceleration (output quantities only)."""
        inner = self.take()
        self.expect("(")
        arg = self.take()
        if arg.kind != "name" or arg.text not in self.quantities.accels:
            raise ExpressionError(f"der(der()) takes a coordinate name{self.hint(arg, self.quantities.accels)}",
                                  arg.pos)
        self.expect(")")
        self.expect(")")
        return self.quantities.accels[arg.text]

    @staticmethod
    def hint(arg: _Tok, options: Mapping) -> str:
        close = difflib.get_close_matches(arg.text, list(options), n=1) if arg.kind == "name" else []
        return f" (did you mean {close[0]!r}?)" if close else ""

    def quantity(self, tok: _Tok, start: int) -> sp.Expr:
        """A built-in quantity FUNCTION(REF, ...): a scalar, or a vector that must be followed by a component
        (.x, .y, .z), be the argument of norm(), or be the whole expression (one column per component)."""
        if tok.text == "norm":
            inner = self.take()
            if inner.kind != "name" or inner.text not in self.quantities.functions or self.peek().text != "(":
                raise ExpressionError("norm() takes a vector quantity, e.g. norm(angular_momentum(system))",
                                      inner.pos)
            self.take()
            value = self.quantity_value(inner)
            self.expect(")")
            if not isinstance(value, sp.MatrixBase):
                raise ExpressionError(f"norm() takes a vector quantity; {inner.text}() is a scalar", inner.pos)
            return sp.sqrt(sum(e**2 for e in value))
        value = self.quantity_value(tok)
        if not isinstance(value, sp.MatrixBase):
            return value
        if self.peek().text == ".":
            self.take()
            comp = self.take()
            names = self.quantities.components(tok.text)
            if comp.text not in names:
                raise ExpressionError(f"{tok.text}() has the components {', '.join(names)}", comp.pos)
            return value[names.index(comp.text)]
        if start == 0 and self.peek().kind == "end":
            return value  # the whole expression: one column per component
        first = self.quantities.components(tok.text)[0]
        raise ExpressionError(f"{tok.text}() is a vector: take a component ({tok.text}(...).{first}) or its norm "
                              f"(norm({tok.text}(...)))", tok.pos)

    def quantity_value(self, tok: _Tok) -> sp.Expr | sp.MatrixBase:
        """The arguments (references such as crank, crank.A, system, x4) up to the closing parenthesis."""
        refs: list[tuple[str, int]] = []
        while True:
            first = self.take()
            if first.kind != "name":
                raise ExpressionError(f"{tok.text}() takes names of links, points or coordinates", first.pos)
            text = first.text
            while True:
                nxt = self.peek()
                if nxt.kind == "num" and re.fullmatch(r"\.\d+", nxt.text) and nxt.pos == first.pos + len(text):
                    text += self.take().text  # a numbered row: floor.1 (read as the number .1)
                    continue
                if nxt.text != ".":
                    break
                self.take()
                part = self.take()
                if part.kind != "name":
                    raise ExpressionError("expected a point name after '.'", part.pos)
                text += "." + part.text
            refs.append((text, first.pos))
            if self.peek().text != ",":
                break
            self.take()
        self.expect(")")
        return self.quantities.evaluate(tok.text, refs, tok.pos)


class Quantities(Protocol):
    """What an expression of output quantities may call (mechanics/quantities.py provides it): ``functions``
    are the built-in names, ``evaluate(name, [(ref, column)], column)`` returns a scalar or a 3-vector (or raises
    ExpressionError), ``components(name)`` names a vector's components and ``accels`` maps coordinates to
    their acceleration symbols (for der(der(NAME)))."""

    functions: frozenset
    accels: Mapping[str, sp.Expr]

    def evaluate(self, name: str, refs: list[tuple[str, int]], pos: int) -> sp.Expr | sp.MatrixBase: ...

    def components(self, name: str) -> tuple[str, ...]: ...


def _digits(n: int) -> float:
    """Decimal digits of a (possibly huge) positive integer, without converting it to text."""
    return math.log10(n) if n > 0 else 0.0


def _rational_digits(r: sp.Rational) -> float:
    """Digits of the longer of the numerator and the denominator."""
    return max(_digits(abs(int(r.p))), _digits(int(r.q)))


def _exact_digits(expr: sp.Expr, times: sp.Expr = sp.Integer(1)) -> float:
    """Digits of the exact rational numbers sympy computes for ``expr**times`` when ``expr`` is a number: a
    product of powers b**k contributes |k*times|*digits(b) for each rational base b (sqrt(2)**2000 is the integer
    2**1000). Other factors (pi, 1 + sqrt(2), sin(1)) stay symbolic: they count the digits of their magnitude.
    Infinite when the size cannot be bounded."""
    total = 0.0
    for b, k in expr.as_powers_dict().items():
        try:
            power = abs(complex(k * times))
        except (OverflowError, TypeError, ValueError):
            return math.inf
        if b.is_Rational:
            if b.q == 1 and abs(b.p) <= 1:
                continue  # 0, 1, -1: any power is trivial
            total += power * _rational_digits(b)
            continue
        if not b.is_number:
            continue
        if power > 1e6:
            return math.inf
        try:
            magnitude = abs(complex(b.evalf(15)))
        except (OverflowError, TypeError, ValueError):
            return math.inf
        if magnitude == 0 or magnitude == math.inf or magnitude != magnitude:
            return math.inf
        total += power * abs(math.log10(magnitude))
    return total


def _too_large(base: sp.Expr, exponent: sp.Expr) -> bool:
    """Would base**exponent be an exact number of more than _MAX_DIGITS digits (slow to compute, too long to
    print)? Bounds |exponent|*digits for every base: large ones, fractions ((1/2)**(10**5)), negative exponents
    and decimals close to 1 (1.0000001**(10**9) has 7*10**9 digits exactly)."""
    try:
        if abs(complex(exponent)) > 1e9:
            return not (base.is_Rational and base.q == 1 and abs(base.p) <= 1)
    except (OverflowError, TypeError, ValueError):
        return True
    return _exact_digits(base, exponent) > _MAX_DIGITS


def _fraction_digits(value: Fraction) -> float:
    return max(_digits(abs(value.numerator)), _digits(value.denominator))


def _too_long(pos: int) -> ExpressionError:
    return ExpressionError(f"number too large (an exact number has at most {_MAX_DIGITS} digits)", pos)


def _check_sum(terms: list[sp.Expr], pos: int) -> None:
    """Refuse a sum whose exact rational coefficients would exceed _MAX_DIGITS digits. The coefficients of like
    terms are added here first, as sympy will (a sum of 1/(10**99 + k) has a denominator of thousands of digits
    and sympy's gcds on it take minutes), stopping at the first one that grows too long."""
    groups: dict[sp.Expr, Fraction] = {}
    for term in terms:
        for part in sp.Add.make_args(term):
            c, rest = part.as_coeff_Mul()
            if not c.is_Rational:
                continue
            total = groups.get(rest, Fraction(0)) + Fraction(int(c.p), int(c.q))
            if _fraction_digits(total) > _MAX_DIGITS:
                raise _too_long(pos)
            groups[rest] = total


def _check_product(factors: list[sp.Expr], pos: int) -> None:
    """Refuse a product whose exact rational part would exceed _MAX_DIGITS digits: the rational coefficients
    multiply, and sympy combines powers of rational bases (sqrt(N)*sqrt(N) = N, sqrt(2)*sqrt(3) = sqrt(6)) and
    factors the combined base, so their digits count too."""
    coefficient = Fraction(1)
    roots = 0.0
    for factor in factors:
        for g in sp.Mul.make_args(factor):
            if g.is_Rational:
                coefficient *= Fraction(int(g.p), int(g.q))
            elif g.is_Pow and g.base.is_Rational and g.exp.is_Rational:
                roots += max(1.0, abs(float(g.exp))) * _rational_digits(g.base)
            else:
                continue
            if _fraction_digits(coefficient) + roots > _MAX_DIGITS:
                raise _too_long(pos)


def parse_expression(
    text: str | int | float,
    symbols: Mapping[str, sp.Expr],
    rates: Mapping[str, sp.Expr] | None = None,
    quantities: Quantities | None = None,
) -> sp.Expr:
    """Parse ``text`` into a sympy expression.

    ``symbols`` maps each name the context allows (parameters, coordinates, ``t``) to its sympy value;
    ``rates`` maps coordinate names to their rate symbols and enables ``der(name)``. Anything else is an
    :class:`ExpressionError`; nothing in the string is ever executed. ``quantities`` enables the built-in
    quantity functions of the file's `outputs:` (position(crank.A), norm(angular_momentum(system)), ...); only
    then may the result be a 3-vector (a bare vector quantity as the whole expression).
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
    return _Parser(text, symbols, rates, quantities).parse()


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
