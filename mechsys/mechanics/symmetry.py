"""Cyclic (ignorable) coordinates, decided semantically: numerically at random states, confirmed symbolically."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from mechsys.mechanics.dag import FreeSymbols

#: A coordinate is numerically cyclic when shifting it changes no entry of M, f, A, b by more than this (relative).
ROUND_OFF = 1e-9
#: Entries larger than this (operation count) are not simplified symbolically; the numerical decision stands.
SYMBOLIC_LIMIT = 4000
#: Nor are the entries of one coordinate larger than this together, in tree nodes (a bicycle's wheel angles: 33 entries
#: of 84,000 operations took 30 s to leave the decision numeric). A size, not a time: the basis reported must
#: not depend on the machine.
SYMBOLIC_BUDGET = 20000
SAMPLES = 4


@dataclass
class CyclicDecision:
    """Which coordinates are cyclic and on what basis: 'absent' (the coordinate does not occur in the equations),
    'symbolic' (it occurs, but only through combinations that are constant, e.g. cos(q)**2 + sin(q)**2, proven
    modulo sin^2 + cos^2 = 1), 'numeric' (independent to round-off at random states; not proven symbolically),
    'declared' (the file says `cyclic: true` and the equations agree at the file's values)."""

    names: list[str] = field(default_factory=list)
    basis: dict[str, str] = field(default_factory=dict)
    denied: list[str] = field(default_factory=list)  # the file says `cyclic: false`


def decide(model) -> CyclicDecision:
    """The cyclic coordinates of ``model``: the equations of motion (M, f, the constraint rows A, b and the
    holonomic constraints Phi themselves) do not depend on them. Phi matters: a slider closing a loop enters the
    velocity rows only through constant coefficients, yet shifting it alone opens the loop. Decided at the file's parameter values with every nonzero value varied randomly (a generic
    point), so the answer does not hinge on a coincidence of values; a file's `cyclic: true` is checked at the
    file's own values instead (a symmetry that holds only there, e.g. a zero eccentricity)."""
    from mechsys.mechanics.model import INTERNAL_METHOD

    eq = model.equations(INTERNAL_METHOD)
    parts = [sp.Matrix(m) for m in (eq.M, eq.f, eq.A, eq.b, model.holonomic_constraints)
             if m.shape[0] and m.shape[1]]
    declared = {name: c.cyclic for name, c in model.doc.spec.coordinates.items()
                if c.cyclic is not None and name in model.coordinates}
    symbols = FreeSymbols()  # the entries share their subtrees: each walked once, not once per entry and name
    present = symbols.of_all(e for m in parts for e in m)
    out = CyclicDecision(denied=[n for n, v in declared.items() if v is False])
    values = np.array([model.parameters[s.name] for s in model.parameter_symbols], dtype=float)
    generic = values * np.random.default_rng(17).uniform(0.7, 1.3, len(values))
    check = _Shifts(model, parts)
    for i, (name, q) in enumerate(zip(model.coordinates, model.q)):
        if declared.get(name) is False:
            continue
        if declared.get(name):
            if q in present and not check.independent(i, values):
                raise model.doc.error(("coordinates", name, "cyclic"),
                                      f"declared cyclic, but the equations of motion depend on {name} "
                                      f"(shifting {name} changes M or f at a random state)")
            out.names.append(name)
            out.basis[name] = "declared"
            continue
        if q not in present:
            out.names.append(name)
            out.basis[name] = "absent"
        elif check.independent(i, generic):
            out.names.append(name)
            out.basis[name] = "symbolic" if _proven_constant([e for m in parts for e in m if q in symbols.of(e)], q) \
                else "numeric"
    return out


def _proven_constant(exprs: list[sp.Expr], q: sp.Symbol) -> bool:
    """Every entry proven constant in q (_constant_in), the smallest first (a failure ends the proof early);
    False without trying when together they exceed SYMBOLIC_BUDGET operations."""
    sized, total = [], 0
    for k, e in enumerate(exprs):
        size = _size(e, SYMBOLIC_BUDGET - total)
        total += size
        if total > SYMBOLIC_BUDGET:
            return False
        sized.append((size, k))
    return all(_constant_in(exprs[k], q) for _, k in sorted(sized))


def _size(expr: sp.Expr, limit: int) -> int:
    """The number of nodes of the expression tree, counted up to limit + 1 only (count_ops of a bicycle's entry
    costs more than the decision it guards)."""
    count = 0
    for _ in sp.preorder_traversal(expr):
        count += 1
        if count > limit:
            break
    return count


class _Shifts:
    """M, f, A, b compiled once; compares them at random states with one coordinate shifted."""

    def __init__(self, model, parts: list[sp.Matrix]) -> None:
        from mechsys.numeric.lambdify import compile_matrix

        self.model = model
        self.fns = None
        self._compile = lambda: [compile_matrix(m, model.t, model.q, model.u, model.parameter_symbols, light=True)
                                 for m in parts]  # evaluated at a few states only

    def independent(self, i: int, p: np.ndarray) -> bool:
        if self.fns is None:
            self.fns = self._compile()
        n = len(self.model.q)
        rng = np.random.default_rng(23 + i)
        for _ in range(SAMPLES):
            t, q, u = rng.uniform(0, 5), rng.uniform(-3, 3, n), rng.uniform(-2, 2, n)
            shifted = q.copy()
            shifted[i] += rng.uniform(0.4, 2.6)
            for fn in self.fns:
                try:
                    with np.errstate(all="ignore"):
                        a = np.asarray(fn(t, q, u, p), dtype=float)
                        b = np.asarray(fn(t, shifted, u, p), dtype=float)
                except (ValueError, ArithmeticError):
                    return False  # undefined there (sqrt of a negative value): no symmetry claimed from it
                if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
                    return False  # a singular state: do not claim a symmetry from it
                scale = max(1.0, float(np.max(np.abs(a))), float(np.max(np.abs(b))))
                if np.max(np.abs(a - b)) > ROUND_OFF * scale:
                    return False
        return True


def _constant_in(expr: sp.Expr, q: sp.Symbol) -> bool:
    """``expr`` does not depend on ``q``, proven after expanding trigonometric functions of sums and multiples
    and reducing modulo sin(q)**2 + cos(q)**2 - 1 (the normal form of a polynomial function on the circle is
    unique). False when not proven (q outside sin/cos, or the entry too large to expand cheaply)."""
    if sp.count_ops(expr) > SYMBOLIC_LIMIT:
        return False
    s, c = sp.Dummy("s"), sp.Dummy("c")
    e = sp.expand_trig(expr).xreplace({sp.sin(q): s, sp.cos(q): c})
    if q in e.free_symbols:
        return False
    num, den = sp.fraction(sp.together(e))
    # d/dq along the circle (s' = c, c' = -s) of num/den has numerator (num' den - num den')
    dnum = sp.diff(num, s) * c - sp.diff(num, c) * s
    dden = sp.diff(den, s) * c - sp.diff(den, c) * s
    numerator = sp.expand(dnum * den - num * dden)
    if numerator == 0:
        return True
    try:
        _, remainder = sp.reduced(numerator, [s**2 + c**2 - 1], s, c)
    except sp.PolynomialError:
        return False
    return sp.expand(remainder) == 0
