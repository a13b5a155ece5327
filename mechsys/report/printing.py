"""Print sympy expressions in the YAML expression syntax (round-trips through the parser) and in LaTeX."""
from __future__ import annotations

from contextlib import contextmanager
from typing import Iterable, Iterator

import sympy as sp
from sympy.printing.latex import LatexPrinter
from sympy.core.function import Function
from sympy.printing.precedence import PRECEDENCE, precedence
from sympy.printing.str import StrPrinter

_SHARING = [0]  # depth of shared_subexpressions() blocks
_NAMING: list["SubexpressionNames | None"] = [None]  # the names in force (naming() block), else None
_COLLECTING: list["list[sp.Basic] | None"] = [None]  # the expressions a collecting() block was asked to print
_UPRIGHT: list[frozenset] = [frozenset()]  # names printed upright in LaTeX (distinct_latex() block)


class _PrintsEachNodeOnce:
    """A printer that prints each subexpression object once: derived equations are DAGs whose shared subtrees
    sympy's printers walk again at every use (the bicycle's Kane equations: 1.6 s -> 0.05 s). A printer's text
    of a node depends only on the node and the settings (a call with keyword arguments, such as LaTeX's
    exponent of a function, is printed as usual), so the output is sympy's, character for character. Keys are
    object identities, each kept with its object (an id is never reused while remembered)."""

    def __init__(self, settings: dict | None = None) -> None:
        super().__init__(settings)
        self._memo: dict[int, tuple[sp.Basic, str]] = {}
        self._precedences: dict[int, tuple[sp.Basic, int]] = {}

    _defining = None  # the named subexpression whose definition is being printed (its own name not used)

    def _print(self, expr, **kwargs) -> str:
        if kwargs or not isinstance(expr, sp.Basic) or not expr.args:
            return super()._print(expr, **kwargs)
        naming = _NAMING[0]
        if naming is not None and expr is not self._defining:
            name = naming.names.get(expr)
            if name is not None:
                return self._name(name)
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
                self.forget()

    def forget(self) -> None:
        """Drop what is remembered (the texts and precedences of nodes)."""
        self._memo.clear()
        self._precedences.clear()

    def _precedence(self, expr) -> int:
        """sympy's precedence(expr), remembered per node: a product's asks whether its negation is simpler, which
        builds the negated product (half the time of printing a long chain's equations)."""
        hit = self._precedences.get(id(expr))
        if hit is not None and hit[0] is expr:
            return hit[1]
        value = _product_precedence(expr) if isinstance(expr, sp.Mul) else None
        if value is None:
            value = precedence(expr)
        self._precedences[id(expr)] = (expr, value)
        return value

    def _name(self, name: str) -> str:
        return name

    def definition(self, expr: sp.Basic) -> str:
        """The text of a named subexpression itself (the names of the subexpressions inside it used)."""
        self._defining = expr
        try:
            return self.doprint(expr)
        finally:
            self._defining = None

    def parenthesize(self, item, level, *args, **kwargs) -> str:
        if _named(item):
            return self._print(item)
        return super().parenthesize(item, level, *args, **kwargs)


def _named(expr) -> bool:
    """Whether the expression prints as a name in the naming() block in force (then it needs no brackets)."""
    naming = _NAMING[0]
    return naming is not None and isinstance(expr, sp.Basic) and expr in naming.names


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
            _PRINTER.forget()
            _LATEX.forget()


MIN_LENGTH = 24  # characters: a shared subexpression shorter than this is written out where it is used
AUTO_NODES = 10_000  # `auto` names the shared subexpressions when the inline form has more nodes than this


class SubexpressionNames:
    """Names z1, z2, ... for the subexpressions that the printed expressions share: equations derived for a
    3-D model or a long chain are DAGs whose inline text repeats the same subtrees (the 20-link chain's Kane
    equations: 7,600 distinct nodes, 7 MB of text; the bicycle's: 690 kB). A subexpression is named when it is
    used more than once (counted as sympy's tree_cse counts: by value, inside a repeated subexpression only once)
    and its text, with the names of its own shared parts, is at least MIN_LENGTH characters. The prefix is
    chosen so that no name of the model reads like a subexpression's name. ``definitions`` lists the named
    subexpressions in dependency order (each uses only names defined before it)."""

    def __init__(self, exprs: list[sp.Basic], min_length: int = MIN_LENGTH) -> None:
        self._counts, self._order, taken, self.inline_nodes = _census(exprs)
        self.min_length = min_length
        self.prefix = "z"
        taken = {t.replace("_", "") for t in taken}  # z_7 prints z_{7} in LaTeX, as the subexpression z7 does
        while any(t.startswith(self.prefix) and t[len(self.prefix):].isdigit() for t in taken):
            self.prefix += "z"
        self.names: dict[sp.Basic, str] = {}
        self.definitions: list[sp.Basic] = []

    def _choose(self) -> None:
        """Name the shared subexpressions, inner ones first (in force: each text uses the names chosen so far)."""
        for node in self._order:
            if self._counts[node] > 1 and len(_PRINTER._print(node)) >= self.min_length:
                self.definitions.append(node)
                self.names[node] = f"{self.prefix}{len(self.definitions)}"
        self._counts = self._order = None


def _census(exprs: list[sp.Basic]) -> tuple[dict, list, set[str], int]:
    """(uses of each compound subexpression by value, the compound ones in post-order, the symbol names, the
    number of nodes of the inline form). Iterative: the trees of long chains are deeper than Python's stack."""
    counts: dict[sp.Basic, int] = {}
    sizes: dict[sp.Basic, int] = {}
    order: list[sp.Basic] = []
    taken: set[str] = set()
    roots = [sp.sympify(r) for r in exprs]
    for root in roots:
        stack: list[tuple[sp.Basic, bool]] = [(root, False)]
        while stack:
            node, done = stack.pop()
            if done:
                order.append(node)
                sizes[node] = 1 + sum(sizes.get(a, 1) for a in node.args)
            elif not node.args:
                if node.is_Symbol:
                    taken.add(node.name)
            elif node in counts:
                counts[node] += 1
            else:
                counts[node] = 1
                stack.append((node, True))
                stack.extend((a, False) for a in reversed(node.args))
    return counts, order, taken, sum(sizes.get(r, 1) for r in roots)


@contextmanager
def _block(naming: "SubexpressionNames | None") -> Iterator[None]:
    previous = _NAMING[0]
    _NAMING[0] = naming
    _PRINTER.forget()
    _LATEX.forget()
    try:
        with shared_subexpressions():
            yield
    finally:
        _NAMING[0] = previous
        _PRINTER.forget()
        _LATEX.forget()


@contextmanager
def naming(names: SubexpressionNames) -> Iterator[SubexpressionNames]:
    """Within the block, to_text and to_latex print the named subexpressions by name (chosen on entry)."""
    with _block(names):
        if names._counts is not None:
            names._choose()
        yield names


@contextmanager
def collecting() -> Iterator[list[sp.Basic]]:
    """Within the block, to_text and to_latex only record their expressions (and return a placeholder): a dry
    run of a renderer lists exactly what it prints, the input of SubexpressionNames."""
    previous = _COLLECTING[0]
    _COLLECTING[0] = seen = []
    try:
        yield seen
    finally:
        _COLLECTING[0] = previous


def _product_precedence(expr: sp.Mul) -> int | None:
    """sympy's precedence of a product whose numbers are finite and whose functions bind tighter than '*': Add's
    when its coefficient is negative, else Mul's (precedence_Mul decides the same by negating the whole product
    to ask Mul.could_extract_minus_sign whether -x == x). None for any other product."""
    for a in expr.args:
        if a.is_Number and not (a.is_Rational or a.is_Float):
            return None
        if isinstance(a, Function) and getattr(a, "precedence", PRECEDENCE["Func"]) < PRECEDENCE["Mul"]:
            return None
    first = expr.args[0]
    return PRECEDENCE["Add"] if first.is_Number and first.is_extended_negative else PRECEDENCE["Mul"]


def _plain_factor(a: sp.Expr) -> bool:
    """A factor that StrPrinter._print_Mul puts in the numerator as it is, in a product it does not treat as
    unevaluated: a symbol, a sum, a function, or a power with a positive rational exponent (not of integers)."""
    if not a.is_commutative or a.is_Number:
        return False
    if a.is_Pow:
        return a.exp.is_Rational and a.exp.is_positive and not all(x.is_Integer for x in a.args)
    return a.is_Symbol or a.is_Add or isinstance(a, Function)


class YamlExprPrinter(_PrintsEachNodeOnce, StrPrinter):
    """str() with the function names of the YAML language: abs, min, max, exp(1) instead of E."""

    def _print_Mul(self, expr: sp.Mul) -> str:
        """StrPrinter._print_Mul's text, built directly for the common product (a rational coefficient, then
        symbols, sums, functions and positive powers): sympy's builds the product's negation twice and the
        product without its coefficient for it. Any other product is sympy's own."""
        args = expr.args
        coeff = args[0] if args[0].is_Number else None
        rest = args[1:] if coeff is not None else args
        if coeff is sp.S.One or coeff is not None and not coeff.is_Rational or not all(map(_plain_factor, rest)):
            return super()._print_Mul(expr)
        prec = _product_precedence(expr)
        if prec is None:
            return super()._print_Mul(expr)
        negative = coeff is not None and coeff.is_negative
        c = -coeff if negative else coeff
        top: list[sp.Expr] = []
        bottom = ""
        if c is not None and c is not sp.S.One:
            if c.p != 1:
                top.append(sp.Integer(c.p))
            if c.q != 1:
                bottom = "/" + self.parenthesize(sp.Integer(c.q), prec, strict=False)
        top.extend(rest)
        return ("-" if negative else "") + "*".join(self.parenthesize(x, prec, strict=False) for x in top) + bottom

    def _print_Add(self, expr: sp.Add, order=None) -> str:
        """StrPrinter._print_Add's text, each term's precedence asked once (remembered with the term)."""
        if order is not None:
            return super()._print_Add(expr, order)
        prec = self._precedence(expr)
        out = []
        for term in self._as_ordered_terms(expr):
            t = self._print(term)
            if t.startswith("-") and not term.is_Add:
                sign, t = "-", t[1:]
            else:
                sign = "+"
            out += [sign, f"({t})" if self._precedence(term) < prec or term.is_Add else t]
        sign = out.pop(0)
        return ("" if sign == "+" else sign) + " ".join(out)

    def parenthesize(self, item: sp.Basic, level: int, strict: bool = False) -> str:
        """StrPrinter.parenthesize (the same text) with the precedence asked once and remembered."""
        if _named(item):
            return self._print(item)
        p = self._precedence(item)
        return f"({self._print(item)})" if p < level or (not strict and p <= level) else self._print(item)

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
        if dotted is not None:
            return dotted
        if expr.name in _UPRIGHT[0]:
            return _upright(expr.name)
        return _undotted(expr.name, super()._print_Symbol(expr, style))

    def _name(self, name: str) -> str:
        return _latex_name(name)

    def _print_Add(self, expr: sp.Add, order=None) -> str:
        """LaTeX's sum (a term's minus sign taken out, ' - ' before it); in a naming() block a named term keeps
        its sign inside its name (' + z_{7}'), where sympy would negate it and write the negation out."""
        naming = _NAMING[0]
        if naming is None:
            return super()._print_Add(expr, order)
        tex = ""
        for i, term in enumerate(self._as_ordered_terms(expr, order=order)):
            if i and term not in naming.names and term.could_extract_minus_sign():
                tex += " - "
                term = -term
            elif i:
                tex += " + "
            text = self._print(term)
            tex += rf"\left({text}\right)" if self._needs_add_brackets(term) else text
        return tex

    def _needs_brackets(self, expr) -> bool:
        return not _named(expr) and super()._needs_brackets(expr)

    def _needs_function_brackets(self, expr) -> bool:
        return not _named(expr) and super()._needs_function_brackets(expr)

    def _needs_mul_brackets(self, expr, first: bool = False, last: bool = False) -> bool:
        return not _named(expr) and super()._needs_mul_brackets(expr, first, last)

    def _needs_add_brackets(self, expr) -> bool:
        return not _named(expr) and super()._needs_add_brackets(expr)


_PRINTER = YamlExprPrinter({"order": "none"})
_LATEX = _DottedLatexPrinter()


def to_text(expr: sp.Expr) -> str:
    """The expression as a string the YAML expression parser reads back to the same value."""
    if _COLLECTING[0] is not None:
        _COLLECTING[0].append(sp.sympify(expr))
        return "x"
    return _PRINTER.doprint(sp.sympify(expr))


def definition_text(expr: sp.Basic) -> str:
    """The text of a named subexpression (naming() block)."""
    return _PRINTER.definition(expr)


def definition_latex(expr: sp.Basic) -> str:
    """The LaTeX of a named subexpression (naming() block)."""
    return _LATEX.definition(expr)


def _latex_name(name: str) -> str:
    if name in _UPRIGHT[0]:
        return _upright(name)
    return _undotted(name, sp.latex(sp.Symbol(name)))


def _upright(name: str) -> str:
    return "\\mathrm{" + name.replace("_", "\\_") + "}"


@contextmanager
def distinct_latex(names: Iterable[str]) -> Iterator[None]:
    """Within the block, LaTeX prints upright, as written, every one of ``names`` (a model's symbol names; rates
    der(x) follow x) whose sympy LaTeX another of them shares: l2 and l_2 are both l_{2}, alpha1 and alpha_1 both
    \\alpha_{1}, and an equation with both would read as if one symbol were meant."""
    by_tex: dict[str, set[str]] = {}
    for name in set(names):
        while name.startswith("der(") and name.endswith(")"):
            name = name[4:-1]
        by_tex.setdefault(sp.latex(sp.Symbol(name)), set()).add(name)
    previous = _UPRIGHT[0]
    _UPRIGHT[0] = frozenset(n for group in by_tex.values() if len(group) > 1 for n in group)
    _LATEX.forget()
    try:
        yield
    finally:
        _UPRIGHT[0] = previous
        _LATEX.forget()


def _undotted(name: str, tex: str) -> str:
    """``tex``, sympy's LaTeX of a model name, unless sympy turned a suffix into a dot (thetadot, xddot): then the
    name upright as written, since \\dot{\\theta} is der(theta)'s (thetadot*der(theta) read as a square)."""
    return _upright(name) if "\\dot{" in tex or "\\ddot{" in tex else tex


def _dotted(name: str) -> str | None:
    """LaTeX of der(x) as a dotted x, der(der(x)) double-dotted; None for other names."""
    if name.startswith("der(der(") and name.endswith("))"):
        return f"\\ddot{{{_latex_name(name[8:-2])}}}"
    if name.startswith("der(") and name.endswith(")"):
        return f"\\dot{{{_latex_name(name[4:-1])}}}"
    return None


def to_latex(expr: sp.Expr) -> str:
    """The expression in LaTeX, rates dotted."""
    if _COLLECTING[0] is not None:
        _COLLECTING[0].append(sp.sympify(expr))
        return "x"
    return _LATEX.doprint(sp.sympify(expr))
