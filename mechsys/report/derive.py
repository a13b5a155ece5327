"""Render derived equations (T, V, Q, M q'' = f, constraints) as text, Markdown, LaTeX or JSON."""
from __future__ import annotations

import json
from typing import Callable

import sympy as sp

from mechsys.mechanics.model import Equations
from mechsys.report.printing import to_latex, to_text

FORMATS = ("text", "markdown", "latex", "json")


def simplified(eq: Equations) -> Equations:
    """A copy with every entry passed through sympy.simplify (opt-in, slow)."""
    s = sp.simplify
    return Equations(eq.method, eq.coordinates, eq.q, eq.u, eq.a, eq.M.applyfunc(s), eq.f.applyfunc(s),
                     eq.Q.applyfunc(s), s(eq.T), s(eq.V), eq.A.applyfunc(s), eq.b.applyfunc(s), eq.constraint_names)


def _lhs(eq: Equations, i: int, fmt: Callable[[sp.Expr], str], times: str, acc: Callable[[int], str]) -> str:
    terms = []
    for j in range(len(eq.q)):
        mij = eq.M[i, j]
        if mij == 0:
            continue
        coeff = fmt(mij)
        if mij.is_Add:
            coeff = f"({coeff})" if times != " " else f"\\left({coeff}\\right)"
        terms.append(acc(j) if mij == 1 else f"{coeff}{times}{acc(j)}")
    return " + ".join(terms) if terms else "0"


def _multiplier_terms(eq: Equations, i: int, fmt: Callable[[sp.Expr], str], lam: Callable[[int], str],
                      times: str) -> str:
    out = ""
    for k in range(eq.A.shape[0]):
        aki = eq.A[k, i]
        if aki != 0:
            out += f" + {lam(k)}{times}({fmt(aki)})"
    return out


def render_text(eq: Equations, name: str) -> str:
    lines = [f"{name}: equations of motion ({eq.method}), M q'' = f" + (" + A^T lambda" if eq.A.shape[0] else "")]
    lines.append("coordinates: " + (", ".join(eq.coordinates) or "(none)"))
    lines.append(f"T = {to_text(eq.T)}")
    lines.append(f"V = {to_text(eq.V)}")
    lines.append("generalized forces Q (not derived from V):")
    for c, qi in zip(eq.coordinates, eq.Q):
        lines.append(f"  {c}: {to_text(qi)}")
    lines.append("equations:")
    for i, c in enumerate(eq.coordinates):
        lhs = _lhs(eq, i, to_text, "*", lambda j: f"der(der({eq.coordinates[j]}))")
        lam = _multiplier_terms(eq, i, to_text, lambda k: f"lambda{k + 1}", "*")
        lines.append(f"  {c}: {lhs} = {to_text(eq.f[i])}{lam}")
    if eq.A.shape[0]:
        lines.append("constraints (acceleration level, A q'' = b):")
        for k, cname in enumerate(eq.constraint_names):
            row = " + ".join(f"({to_text(a)})*der(der({eq.coordinates[j]}))" for j, a in enumerate(eq.A.row(k))
                             if a != 0) or "0"
            lines.append(f"  lambda{k + 1} [{cname}]: {row} = {to_text(eq.b[k])}")
    return "\n".join(lines) + "\n"


def _latex_lines(eq: Equations) -> list[tuple[str, str]]:
    rows = [("T", f"T &= {to_latex(eq.T)}"), ("V", f"V &= {to_latex(eq.V)}")]
    for i, c in enumerate(eq.coordinates):
        rows.append((f"Q_{c}", f"Q_{{{to_latex(eq.q[i])}}} &= {to_latex(eq.Q[i])}"))
    return rows + latex_equations(eq)


def latex_equations(eq: Equations) -> list[tuple[str, str]]:
    """(label, ``lhs &= rhs``) of each equation of motion (label: its coordinate) and constraint row (its name),
    in LaTeX with dotted rates: the rows of ``derive -f latex`` after T, V and Q."""
    acc = {j: to_latex(a) for j, a in enumerate(eq.a)}
    rows = []
    for i, c in enumerate(eq.coordinates):
        lhs = _lhs(eq, i, to_latex, " ", lambda j: acc[j])
        lam = _multiplier_terms(eq, i, to_latex, lambda k: f"\\lambda_{{{k + 1}}}", " ")
        rows.append((c, f"{lhs} &= {to_latex(eq.f[i])}{lam}"))
    for k in range(eq.A.shape[0]):
        row = " + ".join(f"\\left({to_latex(a)}\\right) {acc[j]}" for j, a in enumerate(eq.A.row(k)) if a != 0)
        rows.append((eq.constraint_names[k], f"{row or '0'} &= {to_latex(eq.b[k])}"))
    return rows


def render_latex(eq: Equations, name: str) -> str:
    body = " \\\\\n".join(line for _, line in _latex_lines(eq))
    return f"% {name}: equations of motion ({eq.method})\n\\begin{{align*}}\n{body}\n\\end{{align*}}\n"


def render_markdown(eq: Equations, name: str) -> str:
    out = [f"# {name}: equations of motion ({eq.method})", "",
           "Coordinates: " + (", ".join(f"`{c}`" for c in eq.coordinates) or "none"), ""]
    for label, line in _latex_lines(eq):
        out += [f"**{label}**", "", "$$", line.replace("&=", "="), "$$", ""]
    return "\n".join(out)


def to_json_dict(eq: Equations, name: str) -> dict:
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
    return data


def render(eq: Equations, name: str, fmt: str, extra: dict | None = None) -> str:
    if fmt == "json":
        data = to_json_dict(eq, name)
        data.update(extra or {})
        return json.dumps(data, indent=2) + "\n"
    text = {"text": render_text, "markdown": render_markdown, "latex": render_latex}[fmt](eq, name)
    return text
