"""Where time-dependent kinematics jump in position or velocity: an impulse that simulate does not apply."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np
import sympy as sp

from mechsys.errors import AnalysisError
from mechsys.mechanics.dag import FreeSymbols, switches

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel

#: Points of the grid on which the switching functions' sign changes and other jumps are sought (then refined by
#: bisection).
GRID = 4001


@dataclass(frozen=True)
class Driven:
    """A time-dependent piece of the kinematics with a non-smooth function of t in it: what the message calls it,
    the expression as written, and whether it is a position (its velocity is its time derivative) or a velocity."""

    what: str
    written: sp.Expr
    position: bool


def driven(model: MechanicalModel) -> list[Driven]:
    """The time-dependent kinematics: prescribed motions, frame poses (a joint `origin` or transform step with t),
    holonomic constraints, and velocity constraints at rest."""
    T = model.t
    out: list[Driven] = []
    seen: set = set()
    symbols = FreeSymbols()  # shared subtrees once: a deep 3-D chain's frame poses are large

    def add(what: str, expr: sp.Expr, position: bool) -> None:
        if symbols.has(expr, T) and expr not in seen:
            seen.add(expr)
            out.append(Driven(what, expr, position))

    for name, motion in {**model.doc.prescribed, **model.doc.released}.items():
        add(f"the prescribed motion of {name}", motion, True)
    for link, frame in model.kin.frames.items():
        for part, matrix in (("position", frame.origin), ("orientation", frame.R)):
            for entry in matrix:
                add(f"the {part} of '{link}'", entry, True)
    rest = {u: 0 for u in model.u}
    for row in model.kin.constraints:
        if row.kind == "holonomic" and row.position is not None:
            add(f"the constraint '{row.name}'", row.position, True)
        else:
            add(f"the constraint '{row.name}'", row.velocity.xreplace(rest), False)
    return out


def _roots(g: Callable, t_end: float) -> list[float]:
    """The sign changes of g on [0, t_end], each refined by bisection to the rounding of t."""
    grid = np.linspace(0.0, t_end, GRID)
    with np.errstate(all="ignore"):
        values = np.broadcast_to(np.asarray(g(grid), dtype=float), grid.shape)
    roots = []
    for k in np.flatnonzero((values[:-1] * values[1:] <= 0) & np.isfinite(values[:-1]) & np.isfinite(values[1:])):
        a, b, ga = float(grid[k]), float(grid[k + 1]), float(values[k])
        if ga == 0:
            roots.append(a)
            continue
        while True:
            mid = 0.5 * (a + b)
            if mid in (a, b):
                break
            with np.errstate(all="ignore"):
                gm = float(np.asarray(g(np.array([mid])), dtype=float).ravel()[0])
            if gm == 0:
                a = b = mid
                break
            if (gm < 0) == (ga < 0):
                a, ga = mid, gm
            else:
                b = mid
        roots.append(0.5 * (a + b))
    return roots


def _suspects(f: Callable, t_end: float) -> list[float]:
    """Where f may jump on [0, t_end], whatever function makes it (asin(sin(w t)), a triangle wave, has no switching
    function): on grids of GRID points over [0, t_end] and over its first 10**-k (k = 1 .. WINDOWS - 1: a wave
    faster than the whole grid, or whose period is its spacing, a 50 Hz triangle over 80 s, is resolved near the
    start, where the first jump is), the intervals across which f changes ten times more than across either
    neighbour (beyond rounding), each narrowed by bisection to the half that changes more, and the grid points
    where f is not finite. In time order; _jump decides."""
    return sorted({t for k in range(WINDOWS) for t in _window(f, t_end * 10.0 ** -k)})


#: Grids of _suspects: over [0, t_end] and over its first tenth, hundredth, ...
WINDOWS = 7


def _window(f: Callable, t_end: float) -> list[float]:
    grid = np.linspace(0.0, t_end, GRID)
    values = _values(f, grid)
    finite = np.isfinite(values)
    if not np.any(finite):
        return []
    change = np.abs(np.diff(values))
    change[~(finite[:-1] & finite[1:])] = 0.0
    beside = np.maximum(np.concatenate([[0.0], change[:-1]]), np.concatenate([change[1:], [0.0]]))
    floor = 1e-9 * (1.0 + float(np.max(np.abs(values[finite]))))
    found = [float(t) for t in grid[~finite]]
    for k in np.flatnonzero((change > floor) & (change > 10.0 * beside))[:_SUSPECTS]:
        a, b, fa, fb = float(grid[k]), float(grid[k + 1]), float(values[k]), float(values[k + 1])
        for _ in range(64):
            mid = 0.5 * (a + b)
            fm = float(_values(f, np.array([mid]))[0])
            if mid in (a, b) or not np.isfinite(fm):
                a = b = mid
                break
            if abs(fm - fa) >= abs(fb - fm):
                b, fb = mid, fm
            else:
                a, fa = mid, fm
        found.append(0.0 if a == 0.0 else 0.5 * (a + b))
    return found


def _smooth(expr: sp.Expr) -> bool:
    """Whether expr is built only of functions smooth everywhere (sums, products, whole powers, sin, cos, exp, ...):
    nothing to scan (W*t, a sinusoid)."""
    return all(isinstance(node, _SMOOTH) or node.is_Atom or node.is_Pow and node.exp.is_Integer and node.exp >= 0
               for node in sp.preorder_traversal(expr))


_SMOOTH = (sp.Add, sp.Mul, sp.sin, sp.cos, sp.exp, sp.sinh, sp.cosh, sp.tanh, sp.atan)

#: Intervals of one function that _suspects narrows at most (a fast smooth oscillation aliased on the grid).
_SUSPECTS = 200


def _values(f: Callable, t: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        return np.array(np.broadcast_to(np.asarray(f(t), dtype=float), t.shape))


def _jump(f: Callable, tc: float) -> tuple[float, float, float]:
    """(jump, value before, value after) of f at tc, jump 0 when there is none: the difference of its one-sided
    values that does not shrink as they close in (a steep but continuous function's shrinks 1000 times over 1000
    times closer; 100 times closer where the closest values are not finite: the velocity of asin(sin(w t)) divides
    by its rounding there). The values reported are those 1e-6 (1 + |tc|) away: closer, that rounding shows in them.
    At t = 0 the run starts from f(0) itself, so another value just after it is a jump too."""
    def gap(h: float) -> tuple[float, float, float]:
        before = tc - h if tc - h > 0 else 0.0
        a, b = _values(f, np.array([before, tc + h]))
        with np.errstate(all="ignore"):
            return float(abs(b - a)), float(a), float(b)

    h = 1e-6 * max(1.0, abs(tc))
    far, a, b = gap(h)
    near, _, _ = gap(h * 1e-3)
    if not np.isfinite(near):
        near, _, _ = gap(h * 1e-2)
    if not (np.isfinite(far) and np.isfinite(near)) or near <= 0.5 * far or near <= 1e-9 * (1.0 + abs(a) + abs(b)):
        return 0.0, a, b
    return near, a, b


def refuse_jumps(model: MechanicalModel, p: np.ndarray, q0: np.ndarray, t_end: float) -> None:
    """An AnalysisError at the first time in [0, t_end] where a driven position or velocity jumps (abs, sign, min,
    max of t in a prescribed motion, a joint origin or a constraint, or any other non-smooth function: a triangle
    wave asin(sin(w t))): an impulse on what it carries, which the integration does not apply (a pendulum on a cart
    prescribed as abs(t - 0.5) stayed at rest where the reversal throws it to -3.6 rad/s). A velocity that only
    kinks (a ramp blended into a constant rate) is fine. Sought where the switching functions change sign and where
    grids of GRID points over the run and its first tenth, hundredth, ... show a jump (_suspects)."""
    pieces = driven(model)
    if not pieces:
        return
    T = model.t
    values = {s: sp.Float(float(v)) for s, v in zip(model.parameter_symbols, p)}
    values.update({q: sp.Float(float(x)) for q, x in zip(model.q, q0)})
    first: tuple | None = None
    for d in pieces:
        if _smooth(d.written):
            continue  # (W*t, a sinusoid: smooth, and so is its velocity)
        written = d.written.xreplace(values)
        levels = [("position", written), ("velocity", sp.diff(written, T))] if d.position else [("velocity", written)]
        for level, expr in levels:
            expr = expr.replace(sp.DiracDelta, lambda *args: sp.Integer(0))  # the jump itself is what is sought
            f = sp.lambdify(T, expr, "numpy")
            known = [tc for s in switches([expr], T) for tc in _roots(sp.lambdify(T, s, "numpy"), t_end)]
            for tc in sorted(known + _suspects(f, t_end)):
                if first is not None and tc >= first[0]:
                    break
                size, before, after = _jump(f, tc)
                if size:
                    first = (tc, d, level, before, after)
    if first is None:
        return
    tc, d, level, before, after = first
    where = (f"at the start (t = 0: {before:.6g} as written, {after:.6g} just after)" if tc == 0.0 else
             f"near t = {tc:.6g} s (from {before:.6g} to {after:.6g})")
    raise AnalysisError(
        f"{d.what} ({d.written}) changes its {level} by a jump {where}: an impulse on what it carries, which "
        "simulate does not apply; smooth the motion (abs(t - a) as sqrt((t - a)**2 + e**2), a ramp with a blend), "
        "or simulate up to the jump (--t-end)")
