"""Cyclic (ignorable) coordinates, decided semantically: numerically at random states, confirmed symbolically."""
from __future__ import annotations

from dataclasses import dataclass, field
from itertools import islice
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from mechsys.mechanics.dag import Evaluation, FreeSymbols, Points

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel

#: A coordinate is numerically cyclic when shifting it changes no entry of M, f, A, b by more than this (relative).
ROUND_OFF = 1e-9
#: Entries larger than this (operation count) are not simplified symbolically; the numerical decision stands.
SYMBOLIC_LIMIT = 4000
#: Nor are the entries of one coordinate larger than this together, in tree nodes (a bicycle's wheel angles: 33 entries
#: of 84,000 operations took 30 s to leave the decision numeric). A size, not a time: the basis reported must
#: not depend on the machine.
SYMBOLIC_BUDGET = 20000
SAMPLES = 4
#: Entries of each of M, f, A, b, Phi containing a coordinate that the first, uncompiled test evaluates
#: (_Entries) before they are compiled for the full one (a chain's first angle changes f only).
TRIES = 8


@dataclass
class CyclicDecision:
    """Which coordinates are cyclic and on what basis: 'absent' (the coordinate does not occur in the equations),
    'symbolic' (it occurs, but only through combinations that are constant, e.g. cos(q)**2 + sin(q)**2, proven
    modulo sin^2 + cos^2 = 1), 'numeric' (independent to round-off at random states; not proven symbolically),
    'declared' (the file says `cyclic: true` and the equations agree at the file's values)."""

    names: list[str] = field(default_factory=list)
    basis: dict[str, str] = field(default_factory=dict)
    denied: list[str] = field(default_factory=list)  # the file says `cyclic: false`


def decide(model: MechanicalModel) -> CyclicDecision:
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
    quick = _Entries(model, parts, symbols, generic)
    sizes: dict = {}  # _size's memo: the entries share their subtrees
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
        elif not quick.dependent(q) and check.independent(i, generic):
            out.names.append(name)
            entries = [e for m in parts for e in m if symbols.has(e, q)]
            out.basis[name] = "symbolic" if _proven_constant(entries, q, sizes) else "numeric"
    return out


def _proven_constant(exprs: list[sp.Expr], q: sp.Symbol, sizes: dict | None = None) -> bool:
    """Every entry proven constant in q (_constant_in), the smallest first (a failure ends the proof early);
    False without trying when together they exceed SYMBOLIC_BUDGET operations. ``sizes``: _size's memo."""
    sized, total = [], 0
    for k, e in enumerate(exprs):
        size = _size(e, SYMBOLIC_BUDGET - total, sizes)
        total += size
        if total > SYMBOLIC_BUDGET:
            return False
        sized.append((size, k))
    return all(_constant_in(exprs[k], q) for _, k in sorted(sized))


def _size(expr: sp.Expr, limit: int, sizes: dict | None = None) -> int:
    """The number of nodes of the expression tree (every path counted, as preorder_traversal visits them), up
    to limit + 1 (count_ops of a bicycle's entry costs more than the decision it guards). Computed over the DAG,
    each shared node once: ``sizes`` remembers them by object, across calls."""
    sizes = {} if sizes is None else sizes
    stack = [expr]
    while stack:  # iterative post-order: deep trees never reach the recursion limit
        node = stack[-1]
        if id(node) in sizes:
            stack.pop()
            continue
        waiting = [a for a in node.args if id(a) not in sizes]
        if waiting:
            stack.extend(waiting)
            continue
        sizes[id(node)] = (node, 1 + sum(sizes[id(a)][1] for a in node.args))
        stack.pop()
    return min(sizes[id(expr)][1], limit + 1)


class _Entries:
    """The first test, before anything is compiled: shifting a coordinate changes one of the first TRIES entries
    of M, f, A, b or Phi that contain it, evaluated in floating point at one generic state (dag.Evaluation: only
    the nodes that contain the coordinate computed again), by more than ROUND_OFF times the largest value on the
    way. It only ever proves a dependence; the rest is _Shifts' decision. An 80-link chain's `info`: its compiled
    M and f took 29 s to show that no angle is cyclic."""

    def __init__(self, model, parts: list[sp.Matrix], symbols: FreeSymbols, p: np.ndarray) -> None:
        rng = np.random.default_rng(29)
        n = len(model.q)
        q = rng.uniform(-3, 3, n)
        self.shift = dict(zip(model.q, q + rng.uniform(0.4, 2.6, n)))
        self.values = {model.t: rng.uniform(0, 5), **dict(zip(model.q, q)),
                       **dict(zip(model.u, rng.uniform(-2, 2, n))), **dict(zip(model.parameter_symbols, p))}
        self.symbols = symbols
        self.base = Evaluation(self.values, free=symbols)
        self.parts = [[e for e in m if e.args] for m in parts]

    def dependent(self, q: sp.Symbol) -> bool:
        shifted = Evaluation({**self.values, q: self.shift[q]}, base=self.base, changed=frozenset({q}))
        for entries in self.parts:
            for e in islice((e for e in entries if self.symbols.has(e, q)), TRIES):
                a, b = self.base.of(e), shifted.of(e)
                if a is not None and b is not None and abs(a[0] - b[0]) > ROUND_OFF * max(1.0, a[1], b[1]):
                    return True
        return False


class _Shifts:
    """M, f, A, b and Phi at random states with one coordinate shifted, compared (the first that changes decides).
    Evaluated by one walk of their shared nodes over all the states at once (dag.Points); a matrix with a node the
    walk does not know is compiled instead (numeric/lambdify.py), as a whole."""

    def __init__(self, model, parts: list[sp.Matrix]) -> None:
        from mechsys.numeric.lambdify import compile_matrix

        self.model = model
        self.parts = parts
        self.fns: list = [None] * len(parts)
        self._compile = lambda k: compile_matrix(parts[k], model.t, model.q, model.u, model.parameter_symbols,
                                                 light=True)  # evaluated at a few states only

    def _fn(self, k: int):
        if self.fns[k] is None:
            self.fns[k] = self._compile(k)
        return self.fns[k]

    def independent(self, i: int, p: np.ndarray) -> bool:
        n = len(self.model.q)
        rng = np.random.default_rng(23 + i)
        samples = []
        for _ in range(SAMPLES):
            t, q, u = rng.uniform(0, 5), rng.uniform(-3, 3, n), rng.uniform(-2, 2, n)
            shifted = q.copy()
            shifted[i] += rng.uniform(0.4, 2.6)
            samples.append((t, q, shifted, u))
        walk = self._points(samples, p)
        for k in range(len(self.parts)):
            pairs = self._walked(k, walk, len(samples))
            if pairs is None:
                pairs = self._called(k, samples, p)
            if pairs is None:
                return False  # undefined there (sqrt of a negative value): no symmetry claimed from it
            for a, b in pairs:
                if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
                    return False  # a singular state: do not claim a symmetry from it
                # relative to the part's own values: a floor of 1 let a linkage in nanometres (entries of 1e-13)
                # pass any shift, and called its rocker angle cyclic
                scale = max(float(np.max(np.abs(a), initial=0.0)), float(np.max(np.abs(b), initial=0.0)))
                if np.max(np.abs(a - b), initial=0.0) > ROUND_OFF * scale:
                    return False
        return True

    def _points(self, samples: list, p: np.ndarray) -> Points:
        """The walk over the states: sample s at point 2s, its shifted twin at 2s + 1."""
        model = self.model
        ts = np.repeat([t for t, _, _, _ in samples], 2)
        qs = np.array([q for _, base, shifted, _ in samples for q in (base, shifted)])
        us = np.repeat([u for _, _, _, u in samples], 2, axis=0)
        values = {model.t: ts, **{s: qs[:, j] for j, s in enumerate(model.q)},
                  **{s: us[:, j] for j, s in enumerate(model.u)},
                  **{s: np.full(len(ts), v) for s, v in zip(model.parameter_symbols, p)}}
        return Points(values)

    def _walked(self, k: int, walk: Points, count: int) -> list[tuple[np.ndarray, np.ndarray]] | None:
        """(values at the state, values shifted) of part k per sample, from the walk; None if it cannot."""
        columns = []
        for e in self.parts[k]:
            v = walk.of(e)
            if v is None:
                return None
            columns.append(np.broadcast_to(np.asarray(v, dtype=float), (2 * count,)))
        table = np.array(columns)
        return [(table[:, 2 * s], table[:, 2 * s + 1]) for s in range(count)]

    def _called(self, k: int, samples: list, p: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]] | None:
        """The same from part k compiled; None where it raises (outside its domain)."""
        fn = self._fn(k)
        out = []
        for t, q, shifted, u in samples:
            try:
                with np.errstate(all="ignore"):
                    out.append((np.asarray(fn(t, q, u, p), dtype=float).ravel(),
                                np.asarray(fn(t, shifted, u, p), dtype=float).ravel()))
            except (ValueError, ArithmeticError):
                return None
        return out


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
