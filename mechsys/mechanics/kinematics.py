"""Frame kinematics on symbol matrices: rotations, link frames, positions and angular velocities."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import sympy as sp

from mechsys.mechanics.products import product, sums

AXES = {
    "x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1),
    "-x": (-1, 0, 0), "-y": (0, -1, 0), "-z": (0, 0, -1),
}


def unit(axis: Sequence[sp.Expr]) -> sp.Matrix:
    """Normalize an axis vector (exactly, when its entries are numbers)."""
    v = sp.Matrix(list(axis))
    norm2 = sum(e**2 for e in v)
    if norm2 == 1:
        return v
    return v / sp.sqrt(norm2)


def rotation(axis: sp.Matrix, angle: sp.Expr) -> sp.Matrix:
    """Rotation matrix about unit ``axis`` by ``angle`` (columns: rotated axes in the old axes)."""
    c, s = sp.cos(angle), sp.sin(angle)
    key = tuple(axis)
    if key == (1, 0, 0):
        return sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])
    if key == (0, 1, 0):
        return sp.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    if key == (0, 0, 1):
        return sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    if tuple(-e for e in key) in ((1, 0, 0), (0, 1, 0), (0, 0, 1)):
        return rotation(-axis, -angle)
    x, y, z = axis
    cross = sp.Matrix([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return c * sp.eye(3) + s * cross + (1 - c) * axis * axis.T


@dataclass
class FrameState:
    """Pose and motion of a frame relative to ground.

    ``R`` maps frame components to ground components. ``pure`` records that R is a single rotation of
    ``pure_angle`` about the ground-fixed unit axis ``pure_axis`` (or the identity); composing same-axis
    rotations then adds angles instead of multiplying matrices, which keeps planar chains at
    cos(q1 + q2 + ...) instead of products of sines and cosines.

    Velocities and accelerations are propagated recursively, as in the textbook (no differentiation of long
    expressions): ``omega``/``alpha`` are the angular velocity and the q''-free part of the angular
    acceleration in frame components; ``v``/``a`` the origin velocity and q''-free acceleration in *home*
    components, which are ground axes while the frame is pure and the frame's own axes otherwise. So a cyclic
    coordinate such as the centrifuge's alpha never appears in T; nothing has to be simplified away.
    """

    R: sp.Matrix
    origin: sp.Matrix
    omega: sp.Matrix
    alpha: sp.Matrix
    v: sp.Matrix
    a: sp.Matrix
    pure: bool = True
    pure_axis: tuple | None = None
    pure_angle: sp.Expr = sp.Integer(0)
    v_own: sp.Matrix | None = None  # origin velocity and acceleration in own axes, kept for pure frames
    a_own: sp.Matrix | None = None

    @staticmethod
    def ground() -> "FrameState":
        z = sp.zeros(3, 1)
        return FrameState(sp.eye(3), z, z, z, z, z, v_own=z, a_own=z)

    def rotated(self, axis: sp.Matrix, angle: sp.Expr, rate: sp.Expr, accel0: sp.Expr) -> "FrameState":
        """This frame turned by ``angle`` about its own ``axis`` (a unit vector in this frame's axes);
        ``rate`` is the angle's rate and ``accel0`` the q''-free part of its second derivative."""
        key = tuple(axis)
        R_rel = rotation(axis, angle)
        carried = product(R_rel.T, self.omega)
        omega = carried + axis * rate  # the axis is invariant under its own rotation
        alpha = product(R_rel.T, self.alpha) + axis * accel0 + carried.cross(axis * rate)
        if self.pure:
            v_own, a_own = product(R_rel.T, self.v_own), product(R_rel.T, self.a_own)
            merged = None
            if self.pure_axis is None:
                merged = (R_rel, key, angle)
            elif key == self.pure_axis:
                merged = (rotation(axis, self.pure_angle + angle), key, self.pure_angle + angle)
            elif tuple(-e for e in key) == self.pure_axis:
                total = self.pure_angle - angle
                merged = (rotation(sp.Matrix(self.pure_axis), total), self.pure_axis, total)
            if merged is not None:
                R, pure_axis, total = merged
                return FrameState(R, self.origin, omega, alpha, self.v, self.a, True, pure_axis, total, v_own, a_own)
            return FrameState(product(self.R, R_rel), self.origin, omega, alpha, v_own, a_own, False)
        return FrameState(product(self.R, R_rel), self.origin, omega, alpha, product(R_rel.T, self.v),
                          product(R_rel.T, self.a), False)

    def translated(self, offset: sp.Matrix, rate: sp.Matrix, accel0: sp.Matrix) -> "FrameState":
        """This frame moved by ``offset`` given in its own axes (``rate``, ``accel0``: its derivatives)."""
        v_own = a_own = None
        if self.pure:
            w, al = product(self.R, self.omega), product(self.R, self.alpha)
            d, dd, ddd = product(self.R, offset), product(self.R, rate), product(self.R, accel0)
            v = self.v + w.cross(d) + dd
            a = self.a + al.cross(d) + w.cross(w.cross(d)) + 2 * w.cross(dd) + ddd
            v_own, a_own = _moved(self.v_own, self.a_own, self.omega, self.alpha, offset, rate, accel0)
        else:
            v, a = _moved(self.v, self.a, self.omega, self.alpha, offset, rate, accel0)
        return FrameState(self.R, self.origin + product(self.R, offset), self.omega, self.alpha, v, a, self.pure,
                          self.pure_axis, self.pure_angle, v_own, a_own)

    def point(self, local: sp.Matrix) -> sp.Matrix:
        """Ground position of a point fixed in this frame."""
        return self.origin + product(self.R, local)

    @property
    def omega_ground(self) -> sp.Matrix:
        return product(self.R, self.omega)

    @property
    def omega_home(self) -> sp.Matrix:
        return product(self.R, self.omega) if self.pure else self.omega

    @property
    def home_R(self) -> sp.Matrix:
        """Maps home components to ground components."""
        return sp.eye(3) if self.pure else self.R

    def to_home(self, ground_vec: sp.Matrix) -> sp.Matrix:
        return ground_vec if self.pure else product(self.R.T, ground_vec)

    def point_velocity(self, local: sp.Matrix) -> sp.Matrix:
        """Velocity (home components) of a point fixed in this frame."""
        arm = product(self.R, local) if self.pure else local
        return self.v + self.omega_home.cross(arm)

    def point_acceleration(self, local: sp.Matrix) -> sp.Matrix:
        """The q''-free part of the acceleration (home components) of a point fixed in this frame."""
        if self.pure:
            w, al, arm = product(self.R, self.omega), product(self.R, self.alpha), product(self.R, local)
        else:
            w, al, arm = self.omega, self.alpha, local
        return self.a + al.cross(arm) + w.cross(w.cross(arm))


def _moved(v: sp.Matrix, a: sp.Matrix, w: sp.Matrix, al: sp.Matrix, d: sp.Matrix, dd: sp.Matrix,
           ddd: sp.Matrix) -> tuple[sp.Matrix, sp.Matrix]:
    """Velocity and acceleration of a point at offset d (moving with rate dd) from an origin, in rotating axes."""
    return v + w.cross(d) + dd, a + al.cross(d) + w.cross(w.cross(d)) + 2 * w.cross(dd) + ddd


def time_derivative(expr: sp.Expr | sp.Matrix, coords: Sequence[sp.Symbol], rates: Sequence[sp.Symbol],
                    t: sp.Symbol, accels: Sequence[sp.Symbol] | None = None,
                    diff: Callable[[Any, sp.Symbol], Any] = sp.diff) -> sp.Expr | sp.Matrix:
    """Total time derivative by the chain rule over coordinates (and rates, when ``accels`` is given); ``diff``
    takes the partial derivatives (a model's memoized Differentiator, or sympy's diff)."""
    out = diff(expr, t)
    for q, u in zip(coords, rates):
        out = out + diff(expr, q) * u
    if accels is not None:
        for u, a in zip(rates, accels):
            out = out + diff(expr, u) * a
    return out


class _Nonlinear(Exception):
    """An expression is not linear in the rates (a product of two rate-dependent factors, a rate inside a
    function or power)."""


class _RateSplit:
    """The coefficients of the rates in expressions linear in them, read in one walk of each shared subtree:
    {rate index: coefficient} per node, memoized (a chain's velocities share their long sums)."""

    def __init__(self, rates: Sequence[sp.Symbol]) -> None:
        self.index = {u: j for j, u in enumerate(rates)}
        self.memo: dict[sp.Basic, dict[int, Any]] = {}

    def coefficients(self, e: sp.Basic) -> dict[int, Any]:
        out = self.memo.get(e)
        if out is None:
            out = self.memo[e] = self._split(e)
        return out

    def _split(self, e: sp.Basic) -> dict[int, Any]:
        if e.is_Atom:
            j = self.index.get(e)
            return {} if j is None else {j: sp.S.One}
        parts = [self.coefficients(a) for a in e.args]
        if not any(parts):
            return {}
        if e.is_Add:
            terms: dict[int, list] = {}
            for part in parts:
                for j, c in part.items():
                    terms.setdefault(j, []).append(c)
            return dict(zip(terms, sums(list(terms.values()))))
        if e.is_Mul:
            moving = [k for k, part in enumerate(parts) if part]
            if len(moving) > 1:
                raise _Nonlinear
            rest = e.args[:moving[0]] + e.args[moving[0] + 1:]
            return {j: sp.Mul(*rest, c) for j, c in parts[moving[0]].items()}
        raise _Nonlinear


def rate_coefficients(expr: sp.Matrix, rates: Sequence[sp.Symbol]) -> sp.Matrix:
    """Jacobian of ``expr`` (linear in ``rates``) with respect to the rates, read off the expression's sums and
    products in one walk (no differentiation: far cheaper on the long nested sums of a chain's partial
    velocities, Kane's method). An entry that is not linear in the rates gets the secant by substitution,
    entry(u_j = 1, other rates 0) - entry(all rates 0), as before the walk."""
    expr = sp.Matrix(expr)
    rows, cols = expr.shape[0] * expr.shape[1], len(rates)
    split = _RateSplit(rates)
    out = sp.zeros(rows, cols)
    for i, e in enumerate(expr):
        try:
            for j, c in split.coefficients(sp.sympify(e)).items():
                out[i, j] = c
        except _Nonlinear:
            zero = {u: 0 for u in rates}
            base = e.xreplace(zero)
            for j, u in enumerate(rates):
                out[i, j] = e.xreplace({**zero, u: 1}) - base
    return out
