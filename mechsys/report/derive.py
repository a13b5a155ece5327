"""Render derived equations (T, V, Q, M q'' = f, constraints) as text, Markdown, LaTeX or JSON."""
from __future__ import annotations

import json
import re
from typing import TYPE_CHECKING, Callable

import sympy as sp

from mechsys.mechanics.dag import FreeSymbols
from mechsys.mechanics.model import Equations
from mechsys.report.printing import (AUTO_NODES, SubexpressionNames, collecting, definition_latex, definition_text,
                                     distinct_latex, naming, shared_subexpressions, to_latex, to_text)
from mechsys.report.readable import readable, stored_readable

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel

FORMATS = ("text", "markdown", "latex", "json")
SUBEXPRESSIONS = ("auto", "inline", "named")
_NAME = re.compile(r"\w+(_\{\w+\})?")  # the text of a name (z12, or z_{12} in LaTeX)
Where = list[tuple[str, str]]  # (name, text) of each named subexpression, in the format's own notation


def simplified(eq: Equations) -> Equations:
    """A copy with every entry passed through sympy.simplify (opt-in, slow). An entry that simplify writes with a
    kind of node the derived one does not have (Piecewise(..., Eq(x, -1)) from a spring's |x + 1|) is kept as
    derived: the printed equations stay in the model language, which reads them back."""
    def s(expr: sp.Expr) -> sp.Expr:
        out = sp.simplify(expr)
        return out if _kinds(out) <= _kinds(expr) else expr

    return Equations(eq.method, eq.coordinates, eq.q, eq.u, eq.a, eq.M.applyfunc(s), eq.f.applyfunc(s),
                     eq.Q.applyfunc(s), s(eq.T), s(eq.V), eq.A.applyfunc(s), eq.b.applyfunc(s), eq.constraint_names)


def _kinds(expr: sp.Expr) -> set[type]:
    """The kinds of node in ``expr`` besides symbols, numbers, sums, products and powers."""
    plain = (sp.Symbol, sp.Number, sp.Add, sp.Mul, sp.Pow)
    return {type(x) for x in sp.preorder_traversal(expr) if not isinstance(x, plain)}


#: names of the multipliers, text and LaTeX, in order of preference
_MULTIPLIERS = (("lambda", "\\lambda"), ("mu", "\\mu"), ("multiplier", "\\Lambda"))


def _multiplier_names(eq: Equations) -> tuple[str, str]:
    """(text, LaTeX) stem of the multipliers' names, lambda1 and lambda_{1} unless a name of the model would
    print the same (a parameter called lambda1 or lambda_1 beside the multiplier lambda1)."""
    if not eq.A.shape[0]:
        return _MULTIPLIERS[0]
    from mechsys.mechanics.dag import FreeSymbols

    names = {str(x) for x in FreeSymbols().of_all([*eq.M, *eq.f, *eq.A, *eq.b, *eq.Q, eq.T, eq.V])}
    for text, latex in _MULTIPLIERS:
        if not any(re.fullmatch(f"{text}_?\\d+", n) for n in names):
            return text, latex
    return _MULTIPLIERS[-1]


def _paren(text: str, times: str) -> str:
    return f"({text})" if times != " " else f"\\left({text}\\right)"


def _bracketed(coeff: sp.Expr, text: str, times: str) -> str:
    """A coefficient's text, in brackets when it is a sum written out (a named subexpression needs none)."""
    return _paren(text, times) if coeff.is_Add and not _NAME.fullmatch(text) else text


def _lhs(eq: Equations, i: int, fmt: Callable[[sp.Expr], str], times: str, acc: Callable[[int], str],
         tidy: bool = False) -> str:
    if tidy:
        pieces = _pieces([(eq.M[i, j], acc(j)) for j in range(len(eq.q)) if eq.M[i, j] != 0], fmt, times)
        return _leading(pieces) or "0"
    terms = []
    for j in range(len(eq.q)):
        mij = eq.M[i, j]
        if mij == 0:
            continue
        coeff = _bracketed(mij, fmt(mij), times)
        terms.append(acc(j) if mij == 1 else f"{coeff}{times}{acc(j)}")
    return " + ".join(terms) if terms else "0"


def _negative(coeff: sp.Expr) -> bool:
    """Whether the coefficient reads better negated: a leading minus, or (a sum) more negative terms than not."""
    terms = sp.Add.make_args(coeff)
    return 2 * sum(1 for t in terms if _number(t).is_negative) > len(terms)


def _number(term: sp.Expr) -> sp.Expr:
    """The numeric factor of a term (term.as_coeff_Mul()[0], without building the rest of the product)."""
    if term.is_Number:
        return term
    return term.args[0] if term.is_Mul and term.args[0].is_Number else sp.S.One


def _pieces(terms: list[tuple[sp.Expr, str]], fmt: Callable[[sp.Expr], str], times: str,
            symbol_first: bool = False) -> list[tuple[bool, str]]:
    """(minus, text) of each coefficient*symbol term, the sign taken out of the coefficient; a unit coefficient
    is left out, a sum is parenthesized."""
    out = []
    for coeff, symbol in terms:
        minus = _negative(coeff)
        c = -coeff if minus else coeff
        text = _bracketed(c, fmt(c), times)
        body = symbol if c == 1 else (f"{symbol}{times}{text}" if symbol_first else f"{text}{times}{symbol}")
        out.append((minus, body))
    return out


def _leading(pieces: list[tuple[bool, str]]) -> str:
    """'a - b + c' (no '+ -'): the first term with a bare minus, the others joined by their signs."""
    if not pieces:
        return ""
    first = ("-" if pieces[0][0] else "") + pieces[0][1]
    return first + _following(pieces[1:])


def _following(pieces: list[tuple[bool, str]]) -> str:
    return "".join(f" {'-' if minus else '+'} {body}" for minus, body in pieces)


def _multiplier_terms(eq: Equations, i: int, fmt: Callable[[sp.Expr], str], lam: Callable[[int], str],
                      times: str, tidy: bool = False) -> str:
    if tidy:
        terms = [(eq.A[k, i], lam(k)) for k in range(eq.A.shape[0]) if eq.A[k, i] != 0]
        return _following(_pieces(terms, fmt, times, symbol_first=True))
    out = ""
    for k in range(eq.A.shape[0]):
        aki = eq.A[k, i]
        if aki != 0:
            out += f" + {lam(k)}{times}({fmt(aki)})"
    return out


def _rhs(f: sp.Expr, fmt: Callable[[sp.Expr], str], multipliers: str) -> str:
    """f + the multiplier terms (' + lambda1*(...)...'); a zero f is left out when multipliers follow."""
    if f != 0 or not multipliers:
        return fmt(f) + multipliers
    sign, rest = multipliers[1], multipliers[3:]
    return rest if sign == "+" else f"-{rest}"


def _text_constraint_row(eq: Equations, k: int, tidy: bool) -> str:
    acc = [f"der(der({c}))" for c in eq.coordinates]
    if tidy:
        return _leading(_pieces([(a, acc[j]) for j, a in enumerate(eq.A.row(k)) if a != 0], to_text, "*")) or "0"
    return " + ".join(f"({to_text(a)})*{acc[j]}" for j, a in enumerate(eq.A.row(k)) if a != 0) or "0"


def render_text(eq: Equations, name: str, tidy: bool = False, where: Where = ()) -> str:
    """The text form; tidy: signs joined as 'a - b' (never 'a + -b'), unit coefficients left out."""
    text_name = _multiplier_names(eq)[0]
    lines = [f"{name}: equations of motion ({eq.method}), M q'' = f" + (f" + A^T {text_name}" if eq.A.shape[0] else "")]
    lines.append("coordinates: " + (", ".join(eq.coordinates) or "(none)"))
    lines.append(f"T = {to_text(eq.T)}")
    lines.append(f"V = {to_text(eq.V)}")
    lines.append("generalized forces Q (not derived from V):")
    for c, qi in zip(eq.coordinates, eq.Q):
        lines.append(f"  {c}: {to_text(qi)}")
    lines.append("equations:")
    for i, c in enumerate(eq.coordinates):
        lhs = _lhs(eq, i, to_text, "*", lambda j: f"der(der({eq.coordinates[j]}))", tidy)
        lam = _multiplier_terms(eq, i, to_text, lambda k: f"{text_name}{k + 1}", "*", tidy)
        lines.append(f"  {c}: {lhs} = {_rhs(eq.f[i], to_text, lam)}")
    if eq.A.shape[0]:
        lines.append("constraints (acceleration level, A q'' = b):")
        for k, cname in enumerate(eq.constraint_names):
            lines.append(f"  {text_name}{k + 1} [{cname}]: {_text_constraint_row(eq, k, tidy)} = {to_text(eq.b[k])}")
    if where:
        lines.append("where (subexpressions that several entries share, each printed once):")
        lines += [f"  {z} = {text}" for z, text in where]
    return "\n".join(lines) + "\n"


def _latex_lines(eq: Equations, tidy: bool = False) -> list[tuple[str, str]]:
    rows = [("T", f"T &= {to_latex(eq.T)}"), ("V", f"V &= {to_latex(eq.V)}")]
    for i, c in enumerate(eq.coordinates):
        rows.append((f"Q_{c}", f"Q_{{{to_latex(eq.q[i])}}} &= {to_latex(eq.Q[i])}"))
    return rows + latex_equations(eq, tidy)


def latex_equations(eq: Equations, tidy: bool = False) -> list[tuple[str, str]]:
    """(label, ``lhs &= rhs``) of each equation of motion (label: its coordinate) and constraint row (its name),
    in LaTeX with dotted rates: the rows of ``derive -f latex`` after T, V and Q (tidy: signs as in
    render_text)."""
    acc = {j: to_latex(a) for j, a in enumerate(eq.a)}
    stem = _multiplier_names(eq)[1]
    rows = []
    for i, c in enumerate(eq.coordinates):
        lhs = _lhs(eq, i, to_latex, " ", lambda j: acc[j], tidy)
        lam = _multiplier_terms(eq, i, to_latex, lambda k: f"{stem}_{{{k + 1}}}", " ", tidy)
        rows.append((c, f"{lhs} &= {_rhs(eq.f[i], to_latex, lam)}"))
    for k in range(eq.A.shape[0]):
        if tidy:
            row = _leading(_pieces([(a, acc[j]) for j, a in enumerate(eq.A.row(k)) if a != 0], to_latex, " "))
        else:
            row = " + ".join(f"\\left({to_latex(a)}\\right) {acc[j]}" for j, a in enumerate(eq.A.row(k)) if a != 0)
        rows.append((eq.constraint_names[k], f"{row or '0'} &= {to_latex(eq.b[k])}"))
    return rows


def render_latex(eq: Equations, name: str, tidy: bool = False, where: Where = ()) -> str:
    body = " \\\\\n".join(line for _, line in _latex_lines(eq, tidy))
    if where:
        body += " \\\\\n\\intertext{where}\n" + " \\\\\n".join(f"{z} &= {text}" for z, text in where)
    return f"% {name}: equations of motion ({eq.method})\n\\begin{{align*}}\n{body}\n\\end{{align*}}\n"


def render_markdown(eq: Equations, name: str, tidy: bool = False, where: Where = ()) -> str:
    out = [f"# {name}: equations of motion ({eq.method})", "",
           "Coordinates: " + (", ".join(f"`{c}`" for c in eq.coordinates) or "none"), ""]
    for label, line in _latex_lines(eq, tidy):
        out += [f"**{label}**", "", "$$", line.replace("&=", "="), "$$", ""]
    if where:
        out += ["**where** (subexpressions that several entries share, each printed once)", ""]
        for z, text in where:
            out += ["$$", f"{z} = {text}", "$$", ""]
    return "\n".join(out)


def to_json_dict(eq: Equations, name: str, where: Where = ()) -> dict:
    """The equations as JSON data; with ``where``, the entries use the names of its "subexpressions"."""
    data = {
        "name": name,
        "method": eq.method,
        "coordinates": list(eq.coordinates),
        "mass_matrix": [[to_text(eq.M[i, j]) for j in range(eq.M.shape[1])] for i in range(eq.M.shape[0])],
        "forcing": [to_text(x) for x in eq.f],
        "kinetic_energy": to_text(eq.T),
        "potential_energy": to_text(eq.V),
        "generalized_forces": [to_text(x) for x in eq.Q],
    }
    if eq.A.shape[0]:
        data["constraints"] = {
            "names": list(eq.constraint_names),
            "jacobian": [[to_text(eq.A[k, j]) for j in range(eq.A.shape[1])] for k in range(eq.A.shape[0])],
            "rhs": [to_text(x) for x in eq.b],
        }
    if where:
        data["subexpressions"] = dict(where)
    return data


def render(eq: Equations, name: str, fmt: str, extra: dict | None = None, raw: bool = False,
           model: MechanicalModel | None = None,
           subexpressions: str = "auto") -> str:
    """The equations in a format. Text, Markdown and LaTeX print the readable form (report/readable.py: exact
    clean-up within a time budget, a one-line note when it runs out) unless raw; JSON is always as derived.
    ``model``: the model whose own derived equations ``eq`` are (not simplified), so the clean-up is read from
    and kept in the derivation cache. ``subexpressions``: "named" prints the subexpressions that several
    entries share once, as z1, z2, ... defined at the end (report/printing.py SubexpressionNames); "inline"
    writes every entry out; "auto" names them when the inline form would have more than AUTO_NODES nodes
    (text, Markdown, LaTeX; JSON stays inline unless "named" is asked for)."""
    if subexpressions not in SUBEXPRESSIONS:
        raise ValueError(f"unknown subexpressions {subexpressions!r}; use one of {SUBEXPRESSIONS}")
    note = None
    if fmt != "json" and not raw:
        cleanup = readable(eq) if model is None else stored_readable(model, eq)
        eq, note = cleanup.equations, cleanup.note()
    return _named_or_inline(eq, name, fmt, extra, raw, subexpressions) + (_note(note, fmt) if note else "")


def _note(note: str, fmt: str) -> str:
    return {"text": f"{note}\n", "markdown": f"\n{note}\n", "latex": f"% {note}\n"}[fmt]


def _named_or_inline(eq: Equations, name: str, fmt: str, extra: dict | None, raw: bool, subexpressions: str) -> str:
    eq = eq.interned()  # the printers' memo, census and names meet each value once
    latex = fmt in ("latex", "markdown")
    symbols = FreeSymbols().of_all([*eq.M, *eq.f, *eq.Q, *eq.A, *eq.b, eq.T, eq.V, *eq.q]) if latex else ()
    with distinct_latex(s.name for s in symbols), shared_subexpressions():
        write = _writer(eq, name, fmt, extra, tidy=fmt != "json" and not raw)
        if subexpressions == "inline" or (subexpressions == "auto" and fmt == "json"):
            text = write(())
        else:
            with collecting() as printed:
                write(())
            names = SubexpressionNames(printed)
            if subexpressions == "auto" and names.inline_nodes <= AUTO_NODES:
                text = write(())
            else:
                with naming(names):
                    defined = definition_latex if latex else definition_text
                    label = to_latex if latex else to_text
                    text = write([(label(sp.Symbol(names.names[z])), defined(z)) for z in names.definitions])
    return text


def _writer(eq: Equations, name: str, fmt: str, extra: dict | None, tidy: bool) -> Callable[[Where], str]:
    """The function that writes the equations in a format, given the named subexpressions' definitions."""
    if fmt == "json":
        def write(where: Where) -> str:
            data = to_json_dict(eq, name, where)
            data.update(extra or {})
            return json.dumps(data, indent=2) + "\n"
        return write
    renderer = {"text": render_text, "markdown": render_markdown, "latex": render_latex}[fmt]
    return lambda where: renderer(eq, name, tidy, where)
