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

#: Points of the grid on which the switching functions' sign changes are sought (then refined by bisection).
GRID = 4001


@dataclass(frozen=True)
class Driven:
    """A time-dependent piece of the kinematics with a non-smooth function of t in it: what the message calls it,
    the expression as written, and whether it is a position (its velocity is its time derivative) or a velocity."""

    what: str
    written: sp.Expr
    position: bool


def driven(model: MechanicalModel) -> list[Driven]:
    """The time-dependent kinematics written with abs, sign, min, max (...) of t: prescribed motions, frame poses
    (a joint `origin` or transform step with t), holonomic constraints, and velocity constraints at rest."""
    T = model.t
    out: list[Driven] = []
    seen: set = set()
    symbols = FreeSymbols()  # shared subtrees once: a deep 3-D chain's frame poses are large

    def add(what: str, expr: sp.Expr, position: bool) -> None:
        if symbols.has(expr, T) and expr not in seen and switches([expr], T):
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


def _jump(f: Callable, tc: float) -> tuple[float, float, float]:
    """(jump, value before, value after) of f at tc, jump 0 when there is none: the difference of its one-sided
    values that does not shrink as they close in (a steep but continuous function's shrinks 1000 times over 1000
    times closer). At t = 0 the run starts from f(0) itself, so another value just after it is a jump too."""
    def gap(h: float) -> tuple[float, float, float]:
        before = tc - h if tc - h > 0 else 0.0
        with np.errstate(all="ignore"):
            pair = np.broadcast_to(np.asarray(f(np.array([before, tc + h])), dtype=float), (2,))
        return float(abs(pair[1] - pair[0])), float(pair[0]), float(pair[1])

    h = 1e-6 * max(1.0, abs(tc))
    far, _, _ = gap(h)
    near, a, b = gap(h * 1e-3)
    if not (np.isfinite(far) and np.isfinite(near)) or near <= 0.5 * far or near <= 1e-9 * (1.0 + abs(a) + abs(b)):
        return 0.0, a, b
    return near, a, b


def refuse_jumps(model: MechanicalModel, p: np.ndarray, q0: np.ndarray, t_end: float) -> None:
    """An AnalysisError at the first time in [0, t_end] where a driven position or velocity jumps (abs, sign, min,
    max of t in a prescribed motion, a joint origin or a constraint): an impulse on what it carries, which the
    integration does not apply (a pendulum on a cart prescribed as abs(t - 0.5) stayed at rest where the reversal
    throws it to -3.6 rad/s). A velocity that only kinks (a ramp blended into a constant rate) is fine."""
    pieces = driven(model)
    if not pieces:
        return
    T = model.t
    values = {s: sp.Float(float(v)) for s, v in zip(model.parameter_symbols, p)}
    values.update({q: sp.Float(float(x)) for q, x in zip(model.q, q0)})
    first: tuple | None = None
    for d in pieces:
        written = d.written.xreplace(values)
        levels = [("position", written), ("velocity", sp.diff(written, T))] if d.position else [("velocity", written)]
        for level, expr in levels:
            expr = expr.replace(sp.DiracDelta, lambda *args: sp.Integer(0))  # the jump itself is what is sought
            f = sp.lambdify(T, expr, "numpy")
            for s in switches([expr], T):
                for tc in _roots(sp.lambdify(T, s, "numpy"), t_end):
                    size, before, after = _jump(f, tc)
                    if size and (first is None or tc < first[0]):
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
