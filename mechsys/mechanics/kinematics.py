"""Frame kinematics on symbol matrices: rotations, link frames, positions and angular velocities."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import sympy as sp

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

    Velocities are propagated recursively, as in the textbook: ``omega`` is the angular velocity in frame
    components, and ``v`` the origin velocity in *home* components, which are ground axes while the frame is
    pure and the frame's own axes otherwise. So a cyclic coordinate such as the centrifuge's alpha never
    appears in T; nothing has to be simplified away.
    """

    R: sp.Matrix
    origin: sp.Matrix
    omega: sp.Matrix
    v: sp.Matrix
    pure: bool = True
    pure_axis: tuple | None = None
    pure_angle: sp.Expr = sp.Integer(0)
    v_own: sp.Matrix | None = None  # origin velocity in own axes, kept for pure frames

    @staticmethod
    def ground() -> "FrameState":
        return FrameState(sp.eye(3), sp.zeros(3, 1), sp.zeros(3, 1), sp.zeros(3, 1), v_own=sp.zeros(3, 1))

    def rotated(self, axis: sp.Matrix, angle: sp.Expr, angle_rate: sp.Expr) -> "FrameState":
        """This frame turned by ``angle`` about its own ``axis`` (a unit vector in this frame's axes)."""
        key = tuple(axis)
        R_rel = rotation(axis, angle)
        omega = R_rel.T * self.omega + axis * angle_rate  # the axis is invariant under its own rotation
        if self.pure:
            v_own = R_rel.T * self.v_own
            if self.pure_axis is None:
                return FrameState(R_rel, self.origin, omega, self.v, True, key, angle, v_own)
            if key == self.pure_axis:
                total = self.pure_angle + angle
                return FrameState(rotation(axis, total), self.origin, omega, self.v, True, key, total, v_own)
            if tuple(-e for e in key) == self.pure_axis:
                total = self.pure_angle - angle
                return FrameState(rotation(sp.Matrix(self.pure_axis), total), self.origin, omega, self.v, True,
                                  self.pure_axis, total, v_own)
            return FrameState(self.R * R_rel, self.origin, omega, v_own, False)
        return FrameState(self.R * R_rel, self.origin, omega, R_rel.T * self.v, False)

    def translated(self, offset: sp.Matrix, offset_rate: sp.Matrix) -> "FrameState":
        """This frame moved by ``offset`` given in its own axes (``offset_rate``: its time derivative)."""
        v_own = None
        if self.pure:
            v = self.v + self.omega_home.cross(self.R * offset) + self.R * offset_rate
            v_own = self.v_own + self.omega.cross(offset) + offset_rate
        else:
            v = self.v + self.omega.cross(offset) + offset_rate
        return FrameState(self.R, self.origin + self.R * offset, self.omega, v, self.pure, self.pure_axis,
                          self.pure_angle, v_own)

    def point(self, local: sp.Matrix) -> sp.Matrix:
        """Ground position of a point fixed in this frame."""
        return self.origin + self.R * local

    @property
    def omega_ground(self) -> sp.Matrix:
        return self.R * self.omega

    @property
    def omega_home(self) -> sp.Matrix:
        return self.R * self.omega if self.pure else self.omega

    @property
    def home_R(self) -> sp.Matrix:
        """Maps home components to ground components."""
        return sp.eye(3) if self.pure else self.R

    def to_home(self, ground_vec: sp.Matrix) -> sp.Matrix:
        return ground_vec if self.pure else self.R.T * ground_vec

    def point_velocity(self, local: sp.Matrix) -> sp.Matrix:
        """Velocity (home components) of a point fixed in this frame."""
        arm = self.R * local if self.pure else local
        return self.v + self.omega_home.cross(arm)


def time_derivative(expr: sp.Expr | sp.Matrix, coords: Sequence[sp.Symbol], rates: Sequence[sp.Symbol],
                    t: sp.Symbol, accels: Sequence[sp.Symbol] | None = None) -> sp.Expr | sp.Matrix:
    """Total time derivative by the chain rule over coordinates (and rates, when ``accels`` is given)."""
    out = sp.diff(expr, t)
    for q, u in zip(coords, rates):
        out = out + sp.diff(expr, q) * u
    if accels is not None:
        for u, a in zip(rates, accels):
            out = out + sp.diff(expr, u) * a
    return out
