"""Forward-mode derivatives of a CSE'd program printed straight to C: no symbolic derivative is ever formed.

lambdify.differentiate_program builds each derivative as a sympy expression (a diff per subexpression and
symbol, then a product and a sum per Jacobian column): most of the symbolic time of a rolling model's compiled
pieces (the bicycle: 2.4 of 3.2 s). Here the chain rule runs over the nodes of each subexpression's (small)
defining expression and only writes C text: the tangent of every needed subexpression ``x{k}``, column by
column (``d{k}_{j}``), each node's value held in a temporary where a rule reads it twice. The rules are the
derivatives sympy would take (Abs gives the sign; a power with a numeric exponent c gives c*b**(c - 1), so a
square differentiates at 0), for sums, products, powers, the elementary functions and atan2. A program with any
other node is refused (None): the caller differentiates it symbolically instead."""
from __future__ import annotations

from typing import Callable, Optional, Sequence

import sympy as sp

from mechsys.numeric.lambdify import ForwardProgram, needed_values
from mechsys.numeric.native import _c_printer, c_power


class Unsupported(Exception):
    """A node without a rule here (or without a C form)."""


#: d f(a) / da as C text, from the C text of the argument ``a`` and of the value ``v`` = f(a) (both names or
#: atoms, so repeating them costs nothing)
RULES: dict[type, Callable[[str, str], str]] = {
    sp.sin: lambda a, v: f"cos({a})",
    sp.cos: lambda a, v: f"(-sin({a}))",
    sp.tan: lambda a, v: f"(1.0 + {v}*{v})",
    sp.exp: lambda a, v: v,
    sp.log: lambda a, v: f"(1.0/{a})",
    sp.asin: lambda a, v: f"(1.0/sqrt(1.0 - {a}*{a}))",
    sp.acos: lambda a, v: f"(-1.0/sqrt(1.0 - {a}*{a}))",
    sp.atan: lambda a, v: f"(1.0/(1.0 + {a}*{a}))",
    sp.sinh: lambda a, v: f"cosh({a})",
    sp.cosh: lambda a, v: f"sinh({a})",
    sp.tanh: lambda a, v: f"(1.0 - {v}*{v})",
    sp.Abs: lambda a, v: f"((double)(({a} > 0) - ({a} < 0)))",  # sign(a), 0 at 0: what sympy's diff prints
}
ONE = "1.0"


class _Writer:
    """C statements of the tangents of one program (in the order they must run) and the text of each tangent."""

    def __init__(self, program: ForwardProgram, wrt: Sequence[sp.Symbol]) -> None:
        names = {a: f"a[{i}]" for i, a in enumerate(program.args)}
        names.update({sym: name for name, sym in program.symbols.items()})
        self.printer = _c_printer(names)
        self.tangent: dict[sp.Basic, dict[int, str]] = {w: {j: ONE} for j, w in enumerate(wrt)}
        # a node equal to a subexpression is read from its name (computed before any tangent)
        self.temps: dict[sp.Basic, str] = {value: name for name, value in program.values}
        self.lines: list[str] = []

    def text(self, e: sp.Basic) -> str:
        """C text of ``e`` (the printer's, refused when it has no C form)."""
        try:
            text = self.printer.doprint(e)
        except (ValueError, TypeError, NotImplementedError) as exc:  # a strict printer's refusal
            raise Unsupported(str(exc)) from None
        if getattr(self.printer, "_not_supported", None):
            raise Unsupported(str(e))
        return text

    def value(self, e: sp.Basic) -> str:
        """A C name (or atom) holding the value of ``e``."""
        if e.is_Symbol or e.is_Number or e.is_NumberSymbol:
            return self.text(e)
        name = self.temps.get(e)
        if name is None:
            name = self.temps[e] = f"v{len(self.temps)}"
            self.lines.append(f"    const double {name} = {self.text(e)};")
        return name

    def power(self, base: str, c: sp.Number) -> str:
        """base**c as C text, with the numeric printer's exact products for small integers."""
        text = c_power(base, c)
        return text if text is not None else f"pow({base}, {self.text(c)})"

    def tan(self, e: sp.Basic) -> dict[int, str]:
        """The nonzero tangents of ``e`` by column, as C text."""
        if e.is_Symbol:
            return self.tangent.get(e, {})
        if e.is_Number or e.is_NumberSymbol:
            return {}
        if e.is_Add:
            return _sums([self.tan(a) for a in e.args])
        if e.is_Mul:
            parts = [(i, self.tan(a)) for i, a in enumerate(e.args)]
            parts = [(i, t) for i, t in parts if t]
            if not parts:
                return {}
            # the value of every factor another factor's term reads
            values = {k: self.value(a) for k, a in enumerate(e.args) if any(i != k for i, _ in parts)}
            return _sums([{j: _times("*".join(v for k, v in values.items() if k != i), s) for j, s in t.items()}
                          for i, t in parts])
        if e.is_Pow:
            base, exp = e.args
            tb, tx = self.tan(base), self.tan(exp)
            if not tx:
                if not tb:
                    return {}
                if exp.is_Number:
                    factor = f"{self.text(exp)}*{self.power(self.value(base), exp - 1)}"
                else:  # b**x with x constant: x*b**x/b, sympy's form
                    factor = f"{self.value(exp)}*{self.value(e)}/{self.value(base)}"
                return {j: _times(factor, s) for j, s in tb.items()}
            # b**x with both varying: b**x*(log(b)*dx + x*db/b)
            v, b, x = self.value(e), self.value(base), self.value(exp)
            inner = _sums([{j: _times(f"log({b})", s) for j, s in tx.items()},
                           {j: _times(f"{x}/{b}", s) for j, s in tb.items()}])
            return {j: f"{v}*{s}" for j, s in inner.items()}
        rule = RULES.get(type(e))
        if rule is not None and len(e.args) == 1:
            t = self.tan(e.args[0])
            if not t:
                return {}
            factor = rule(self.value(e.args[0]), self.value(e))
            return {j: _times(factor, s) for j, s in t.items()}
        if type(e) is sp.atan2:  # atan2(y, x)' = (x*dy - y*dx)/(x**2 + y**2)
            y, x = e.args
            ty, tx = self.tan(y), self.tan(x)
            if not (ty or tx):
                return {}
            yv, xv = self.value(y), self.value(x)
            r2 = f"({xv}*{xv} + {yv}*{yv})"
            num = _sums([{j: _times(xv, s) for j, s in ty.items()}, {j: _times(f"(-{yv})", s) for j, s in tx.items()}])
            return {j: f"{s}/{r2}" for j, s in num.items()}
        raise Unsupported(type(e).__name__)


def _times(factor: str, tangent: str) -> str:
    if not factor:
        return tangent
    return factor if tangent == ONE else f"{factor}*{tangent}"


def _sums(parts: list[dict[int, str]]) -> dict[int, str]:
    """Column-wise sums of tangents."""
    terms: dict[int, list[str]] = {}
    for part in parts:
        for j, s in part.items():
            terms.setdefault(j, []).append(s)
    return {j: t[0] if len(t) == 1 else "(" + " + ".join(t) + ")" for j, t in terms.items()}


def program_source(program: ForwardProgram, wrt: Sequence[sp.Symbol], rows: int,
                   functions: dict[str, tuple[int, bool]]) -> Optional[str]:
    """C translation unit of shared_program's ``program`` with the Jacobian of its first ``rows`` outputs with
    respect to ``wrt``, laid out like native.program_source's (each ``name: (count, with_jacobian)`` writes the
    first ``count`` outputs, then the Jacobian row by row); None when a node has no rule or no C form."""
    writer = _Writer(program, wrt)
    try:
        values = [f"    const double {name} = {writer.text(e)};" for name, e in program.values]
        outputs = [writer.text(sp.sympify(e)) for e in program.outputs]
        needed = needed_values(program, rows)
        for k, (name, e) in enumerate(program.values):
            if name not in needed:
                continue
            own = {}
            for j, s in writer.tan(e).items():
                writer.lines.append(f"    const double d{k}_{j} = {s};")
                own[j] = f"d{k}_{j}"
            writer.tangent[program.symbols[name]] = own
        jacobian = []
        for e in program.outputs[:rows]:
            row = writer.tan(sp.sympify(e))
            jacobian += [row.get(j, "0.0") for j in range(len(wrt))]
    except Unsupported:
        return None
    parts = ["#include <math.h>", "#ifndef M_PI", "#define M_PI 3.14159265358979323846", "#endif"]
    for fname, (count, with_jacobian) in functions.items():
        body = values + (writer.lines if with_jacobian else [])
        results = outputs[:count] + (jacobian if with_jacobian else [])
        parts.append(f"void {fname}(const double *a, double *out) {{")
        parts += body + [f"    out[{i}] = {e};" for i, e in enumerate(results)] + ["}"]
    return "\n".join(parts) + "\n"

