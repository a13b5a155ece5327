"""Numeric parameter vectors of a model: the file's values, or some changed with the parameters defined from them."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel


def parameter_values(model: MechanicalModel, changes: dict[str, float] | None = None) -> np.ndarray:
    """Numeric parameter vector (model.parameter_symbols order) with some parameters set to new values; the
    parameters defined from them follow (dM = Mo/7 moves with Mo)."""
    doc = model.doc
    if not changes:
        return np.array([doc.parameter_values[n] for n in doc.parameters], dtype=float)
    followers = _followers(doc, frozenset(changes))
    if not followers:  # nothing is defined from them (a continuation's usual case: thousands of calls)
        out = np.array([doc.parameter_values[n] for n in doc.parameters], dtype=float)
        names = list(doc.parameters)  # the order of model.parameter_symbols
        for name, value in changes.items():
            out[names.index(name)] = float(value)
        return out
    values = {sym: doc.parameter_values[name] for name, sym in doc.parameters.items()}
    for name in changes:
        values[doc.parameters[name]] = float(changes[name])
    for name, expr in followers:  # in dependency order
        # sympy Floats, not Python floats: for an alias ``m1: m2`` the xreplace returns the value itself
        known = {s: sp.Float(values[s]) for s in expr.free_symbols if s in values}
        values[doc.parameters[name]] = float(sp.sympify(expr.xreplace(known)).evalf())
    return np.array([float(values[s]) for s in model.parameter_symbols], dtype=float)


def _followers(doc, changed: frozenset[str]) -> list[tuple[str, sp.Expr]]:
    """The parameters defined (directly or not) from the changed ones, in dependency order; remembered per set of
    names on the document (a continuation sets the same parameter thousands of times). The memo belongs to the
    document's definitions: a copy with other definitions (with_overrides) gets its own."""
    owner, memo = doc.__dict__.get("_parameter_followers", (None, {}))
    if owner is not doc.parameter_exprs:
        memo = {}
        doc.__dict__["_parameter_followers"] = (doc.parameter_exprs, memo)
    if changed not in memo:
        moved = {doc.parameters[name] for name in changed}
        out = []
        for name, expr in doc.parameter_exprs.items():
            if name not in changed and expr.free_symbols & moved:
                moved.add(doc.parameters[name])
                out.append((name, expr))
        memo[changed] = out
    return memo[changed]
