"""Independent reference mechanics for tests/test_equilibria_beyond.py (issue 11).

Nothing here imports mechsys. Every model is rebuilt from its geometry with plain sympy: rotation matrices,
T = 1/2 m v_G.v_G + 1/2 w^T I_G w, V = -m g.r_G, the Lagrange equations M(q) q'' = f(q, q') with
f = -dV/dq + dT/dq - (d/dq dT/dq') q', and a linearization about a steady motion in the reduced state
(non-cyclic coordinates, all rates) with exact sympy derivatives. Roots of one-variable balance equations are found
by dense sampling and brentq. Closed forms (steady precession, sleeping-top threshold, intermediate-axis growth
rate) are given as plain formulas and cross-checked against these Lagrangians in the test file.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np
import sympy as sp
import yaml
from scipy.optimize import brentq

# ---------------------------------------------------------------------------------------------------------------
# rotations


def rot(axis: str, angle) -> sp.Matrix:
    """Rotation matrix (body -> parent) for a right-handed rotation by `angle` about the named axis."""
    c, s = sp.cos(angle), sp.sin(angle)
    if axis == "x":
        return sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return sp.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    if axis == "z":
        return sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    raise ValueError(axis)


def intrinsic(sequence: str, angles: Sequence) -> sp.Matrix:
    """Body-fixed (intrinsic) sequence: R = R_a1(q1) R_a2(q2) R_a3(q3)."""
    R = sp.eye(3)
    for axis, angle in zip(sequence, angles):
        R = R * rot(axis, angle)
    return R


def rotation_matrix(sequence: str, angles: Sequence[float]) -> np.ndarray:
    """Numeric intrinsic rotation matrix (body -> ground)."""
    R = np.eye(3)
    for axis, a in zip(sequence, angles):
        c, s = math.cos(a), math.sin(a)
        R = R @ {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
                 "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
                 "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]
    return R


def wrap(angle: float) -> float:
    """Angle in (-pi, pi]."""
    a = math.remainder(angle, 2 * math.pi)
    return math.pi if a == -math.pi else a


def circle_distance(a: float, b: float) -> float:
    return abs(wrap(a - b))


# ---------------------------------------------------------------------------------------------------------------
# a Lagrangian system of rigid bodies


@dataclass
class Body:
    R: sp.Matrix                     # body axes -> ground axes, a function of the coordinates
    w: sp.Matrix                     # angular velocity in body axes, a function of coordinates and rates
    origin: sp.Matrix                # ground position of the body's reference point
    mass: float = 0.0
    com: Sequence = (0, 0, 0)        # centre of mass, body axes, from `origin`
    inertia: Sequence = (0, 0, 0)    # central principal moments (xx, yy, zz), body axes


@dataclass
class LagrangeSystem:
    """M(q) q'' = f(q, u), u = q', built from `bodies` by Lagrange's equations (all numbers substituted; only
    potential forces: gravity)."""

    names: Sequence[str]
    bodies_of: Callable[[tuple, tuple], list]     # (q symbols, u symbols) -> bodies
    gravity: Sequence[float] = (0.0, 0.0, 0.0)
    q: tuple = field(init=False)
    u: tuple = field(init=False)

    def __post_init__(self):
        self.q = sp.symbols([f"q_{n}" for n in self.names], real=True)
        self.u = sp.symbols([f"u_{n}" for n in self.names], real=True)
        q, u = sp.Matrix(self.q), sp.Matrix(self.u)
        self.bodies = self.bodies_of(self.q, self.u)
        gvec = sp.Matrix(self.gravity)
        T, V = sp.Integer(0), sp.Integer(0)
        for b in self.bodies:
            rG = b.origin + b.R * sp.Matrix(b.com)
            vG = rG.jacobian(q) * u
            w = b.w
            T += sp.Rational(1, 2) * b.mass * (vG.T * vG)[0] + sp.Rational(1, 2) * (
                w.T * sp.diag(*b.inertia) * w)[0]
            V += -b.mass * (gvec.T * rG)[0]
        self.T, self.V = T, V
        p = sp.Matrix([T]).jacobian(u).T
        self.M = p.jacobian(u)
        self.f = -sp.Matrix([V]).jacobian(q).T + sp.Matrix([T]).jacobian(q).T - p.jacobian(q) * u
        args = (*self.q, *self.u)
        self._M = sp.lambdify(args, self.M, "numpy")
        self._f = sp.lambdify(args, self.f, "numpy")
        self._fq = sp.lambdify(args, self.f.jacobian(q), "numpy")
        self._fu = sp.lambdify(args, self.f.jacobian(u), "numpy")

    def index(self, name: str) -> int:
        return list(self.names).index(name)

    def state(self, coordinates: Mapping[str, float], rates: Mapping[str, float]) -> tuple:
        """Numeric (q, u); unnamed coordinates and rates are 0."""
        return (tuple(float(coordinates.get(n, 0.0)) for n in self.names)
                + tuple(float(rates.get(n, 0.0)) for n in self.names))

    def residual(self, coordinates, rates) -> np.ndarray:
        return np.asarray(self._f(*self.state(coordinates, rates)), dtype=float).ravel()

    def reduced_eigenvalues(self, coordinates, rates, cyclic: Sequence[str]) -> np.ndarray:
        """Eigenvalues of the linearization in the reduced state x = (non-cyclic q, all u):
        B x' = A x, A = [[0, S], [df/dq_N, df/du]], B = diag(I, M)."""
        s = self.state(coordinates, rates)
        n = len(self.names)
        keep = [i for i, name in enumerate(self.names) if name not in cyclic]
        k = len(keep)
        M = np.asarray(self._M(*s), dtype=float)
        fq = np.asarray(self._fq(*s), dtype=float)[:, keep]
        fu = np.asarray(self._fu(*s), dtype=float)
        A = np.zeros((k + n, k + n))
        for row, i in enumerate(keep):
            A[row, k + i] = 1.0
        A[k:, :k] = fq
        A[k:, k:] = fu
        B = np.eye(k + n)
        B[k:, k:] = M
        return np.linalg.eigvals(np.linalg.solve(B, A))


def chain(steps, parent=None) -> tuple[sp.Matrix, sp.Matrix]:
    """(R, w) of a frame reached from `parent` = (R, w) (default: ground at rest) by elementary rotations
    `steps` = [(axis, angle, rate), ...], each about an axis of the current frame: R <- R rot(axis, angle) and
    w <- rot(axis, angle)^T w + rate e_axis (w in the current frame's axes)."""
    R, w = parent if parent is not None else (sp.eye(3), sp.zeros(3, 1))
    for axis, angle, rate in steps:
        r = rot(axis, angle)
        e = sp.zeros(3, 1)
        e["xyz".index(axis)] = 1
        R, w = R * r, r.T * w + rate * e
    return R, w


def angular_velocity_body(R: sp.Matrix, q: sp.Matrix, u: sp.Matrix) -> sp.Matrix:
    """w in body axes from  [w]x = R^T R'."""
    Rdot = sp.zeros(3, 3)
    for qi, ui in zip(q, u):
        Rdot += R.diff(qi) * ui
    W = R.T * Rdot
    return sp.Matrix([W[2, 1], W[0, 2], W[1, 0]])


def roots_on_circle(func: Callable[[np.ndarray], np.ndarray], samples: int = 40001) -> list[float]:
    """Every simple root of a 2pi-periodic function on (-pi, pi]: sign changes on a dense grid (shifted so that
    roots at 0 and pi do not fall on grid points), refined by brentq, wrapped and deduplicated."""
    step = 2 * math.pi / (samples - 1)
    grid = np.linspace(-math.pi, math.pi, samples) + 0.377 * step
    values = func(grid)
    out: list[float] = []
    for i in np.nonzero(np.sign(values[:-1]) != np.sign(values[1:]))[0]:
        r = wrap(brentq(lambda x: float(func(np.array([x]))[0]), grid[i], grid[i + 1], xtol=1e-15, rtol=1e-15))
        if all(circle_distance(r, o) > 1e-9 for o in out):
            out.append(r)
    return sorted(out)


def load_parameters(path: Path | str) -> dict[str, float]:
    """The plain numeric parameters of a model file (read with PyYAML; expressions are skipped)."""
    data = yaml.safe_load(Path(path).read_text())
    out = {}
    for name, value in (data.get("parameters") or {}).items():
        try:
            out[name] = float(value)
        except (TypeError, ValueError):
            pass
    return out


# ---------------------------------------------------------------------------------------------------------------
# 1. Furuta pendulum with a rod arm


@functools.lru_cache(maxsize=None)
def furuta(ma: float, La: float, mp: float, Lp: float, g: float) -> LagrangeSystem:
    """Arm: uniform rod along its x axis, turning about ground Z (th1). Pendulum: uniform rod along its own z axis,
    hinged at the arm tip about the arm's x axis (th2); th2 = 0 hangs down. Thin rods: transverse central moment
    m L^2/12, axial 0."""
    def bodies(q, u):
        arm = chain([("z", q[0], u[0])])
        pendulum = chain([("x", q[1], u[1])], arm)
        return [Body(*arm, sp.zeros(3, 1), ma, (La / 2, 0, 0), (0, ma * La**2 / 12, ma * La**2 / 12)),
                Body(*pendulum, arm[0] * sp.Matrix([La, 0, 0]), mp, (0, 0, -Lp / 2),
                     (mp * Lp**2 / 12, mp * Lp**2 / 12, 0))]
    return LagrangeSystem(("th1", "th2"), bodies, (0.0, 0.0, -g))


def furuta_steady_motions(system: LagrangeSystem, arm_rate: float) -> list[float]:
    """Pendulum angles th2 of the steady motions th1' = arm_rate, th2' = 0: roots of the th2 row of f."""
    i = system.index("th2")
    func = np.vectorize(lambda x: system.residual({"th2": x}, {"th1": arm_rate})[i])
    return roots_on_circle(func, samples=4001)


# ---------------------------------------------------------------------------------------------------------------
# 2, 3. Heavy symmetric top: the same body in four charts

#  chart name -> (sequence, axis of symmetry in body axes, coordinate names, middle angle of nutation nu)
TOP_CHARTS = {
    "zxz": ("zxz", 2, ("psi", "theta", "phi"), lambda nu: nu),
    "cardan": ("zyx", 0, ("psi", "theta", "phi"), lambda nu: nu - math.pi / 2),
    "resal": ("zxz", 2, ("psi", "theta", "phi"), lambda nu: nu),       # built as a chain of frames below
    "xyz": ("xyz", 2, ("a", "b", "c"), None),
}


@functools.lru_cache(maxsize=None)
def heavy_top(chart: str, m: float, l: float, g: float, A0: float, C: float) -> LagrangeSystem:
    """Symmetric top with its fixed point at the ground origin; centre of mass at distance l along the symmetry
    axis; central moments A0 (transverse) and C (axial)."""
    sequence, axis, names, _ = TOP_CHARTS[chart]
    com = [0, 0, 0]
    com[axis] = l
    moments = [A0, A0, A0]
    moments[axis] = C

    def bodies(q, u):
        zero = sp.zeros(3, 1)
        if chart == "resal":     # massless outer and inner frames, the rotor carries the top
            outer = chain([("z", q[0], u[0])])
            inner = chain([("x", q[1], u[1])], outer)
            rotor = chain([("z", q[2], u[2])], inner)
            return [Body(*outer, zero), Body(*inner, zero), Body(*rotor, zero, m, tuple(com), tuple(moments))]
        return [Body(*chain(zip(sequence, q, u)), zero, m, tuple(com), tuple(moments))]
    return LagrangeSystem(names, bodies, (0.0, 0.0, -g))


@functools.lru_cache(maxsize=None)
def _body_rates(sequence: str) -> Callable:
    q = sp.symbols("a1:4", real=True)
    u = sp.symbols("b1:4", real=True)
    return sp.lambdify((*q, *u), chain(zip(sequence, q, u))[1], "numpy")


def body_angular_velocity(sequence: str, angles: Sequence[float], rates: Sequence[float]) -> np.ndarray:
    """Angular velocity in body axes of an intrinsic sequence, from [w]x = R^T R'."""
    return np.asarray(_body_rates(sequence)(*angles, *rates), dtype=float).ravel()


def top_spin_rate(chart: str, nu: float, precession: float, n: float) -> float:
    """The rate of the chart's last angle that makes the total spin (symmetry-axis component of w) equal n, with
    the first angle turning at `precession`, the middle angle at the chart value of nutation nu, and at rest."""
    sequence, axis, _, middle = TOP_CHARTS[chart]
    angles = (0.0, middle(nu), 0.0)
    w0 = body_angular_velocity(sequence, angles, (precession, 0.0, 0.0))[axis]
    w1 = body_angular_velocity(sequence, angles, (0.0, 0.0, 1.0))[axis]
    return (n - w0) / w1


def precession_rates(A: float, C: float, mgl: float, nu: float, n: float) -> list[float]:
    """Steady precession rates W of a heavy symmetric top at nutation nu (from the upward vertical) with total spin
    n: the nutation equation  sin(nu) (A W^2 cos(nu) - C n W + m g l) = 0  (A: transverse moment about the pivot),
    i.e. the roots of the quadratic A cos(nu) W^2 - C n W + m g l = 0."""
    a, b, c = A * math.cos(nu), -C * n, mgl
    disc = b * b - 4 * a * c
    if disc < 0:
        return []
    s = math.sqrt(disc)
    q = -0.5 * (b + math.copysign(s, b))           # stable form of the two roots
    return sorted([q / a, c / q])


def sleeping_top_threshold(A: float, C: float, mgl: float) -> float:
    """Spin rate above which the upright top is (linearly, gyroscopically) stable: C^2 w^2 = 4 A m g l."""
    return 2 * math.sqrt(A * mgl) / C


def steady_motion_torque_residual(sequence: str, angles, rates, com, moments, mass, gravity) -> float:
    """Is q(t) = q0 + rates*t a motion of a rigid body with a fixed point at the ground origin? The residual
    |dL/dt - tau| (ground axes) of the angular-momentum balance about the fixed point, differentiated along that
    curve. It needs no regular chart: it is valid at gimbal lock too."""
    key = (sequence, tuple(com), tuple(moments), float(mass), tuple(gravity))
    fn = _torque_balance(key)
    return float(np.linalg.norm(np.asarray(fn(*angles, *rates), dtype=float)))


@functools.lru_cache(maxsize=None)
def _torque_balance(key):
    sequence, com, moments, mass, gravity = key
    q = sp.symbols("a1:4", real=True)
    u = sp.symbols("b1:4", real=True)
    R, w = chain(zip(sequence, q, u))
    c = sp.Matrix(com)
    I_pivot = sp.diag(*moments) + mass * ((c.T * c)[0] * sp.eye(3) - c * c.T)
    L = R * I_pivot * w
    Ldot = L.jacobian(sp.Matrix(q)) * sp.Matrix(u)     # u constant along the curve
    tau = (R * c).cross(mass * sp.Matrix(gravity))
    return sp.lambdify((*q, *u), Ldot - tau, "numpy")


# ---------------------------------------------------------------------------------------------------------------
# 4. Torque-free rigid body


@functools.lru_cache(maxsize=None)
def free_body(sequence: str, Ix: float, Iy: float, Iz: float) -> LagrangeSystem:
    def bodies(q, u):
        return [Body(*chain(zip(sequence, q, u)), sp.zeros(3, 1), 1.0, (0, 0, 0), (Ix, Iy, Iz))]
    return LagrangeSystem(("psi", "theta", "phi"), bodies)


def vertical_body_axis(sequence: str, angles: Sequence[float]) -> tuple[int, float]:
    """(index of the body axis closest to ground z, |misalignment|): ground z in body axes is R^T e_z; a spin about
    ground z is a steady motion of a torque-free body with distinct principal moments iff R^T e_z is a principal
    (here: coordinate) axis, i.e. iff the misalignment is 0."""
    ez_body = rotation_matrix(sequence, angles).T @ np.array([0.0, 0.0, 1.0])
    k = int(np.argmax(np.abs(ez_body)))
    return k, float(np.linalg.norm(np.delete(ez_body, k)))


def intermediate_axis_growth(w: float, I1: float, I2: float, I3: float) -> float:
    """Growth rate of a spin w about the intermediate principal axis (I1 < I2 < I3): w sqrt((I2-I1)(I3-I2)/(I1 I3))."""
    return w * math.sqrt((I2 - I1) * (I3 - I2) / (I1 * I3))


def free_body_invariants(sequence: str, moments: Sequence[float], angles, rates) -> tuple[float, float]:
    """(kinetic energy, |angular momentum|) of a torque-free body from its chart angles and rates."""
    w = body_angular_velocity(sequence, angles, rates)
    Iw = np.asarray(moments, dtype=float) * w
    return 0.5 * float(w @ Iw), float(np.linalg.norm(Iw))


# ---------------------------------------------------------------------------------------------------------------
# 5. Centrifuge (Krodkiewski ch. 5)


@functools.lru_cache(maxsize=None)
def centrifuge(I1: float, m: float, I2x: float, I2y: float, I2z: float, a: float, l: float,
               g: float) -> LagrangeSystem:
    """Column about Z (alpha) with inertia I1 about Z; arm hinged at A = a j1 about x1 (beta), centre of mass at
    distance l below A (arm axes: -l z2), central inertias I2x, I2y, I2z; gravity -g Z. The motor torque acts on
    alpha only, so it does not enter the beta row and is omitted (the steady rate is given)."""
    def bodies(q, u):
        column = chain([("z", q[0], u[0])])
        arm = chain([("x", q[1], u[1])], column)
        return [Body(*column, sp.zeros(3, 1), 0.0, (0, 0, 0), (0, 0, I1)),
                Body(*arm, column[0] * sp.Matrix([0, a, 0]), m, (0, 0, -l), (I2x, I2y, I2z))]
    return LagrangeSystem(("alpha", "beta"), bodies, (0.0, 0.0, -g))


def centrifuge_steady_angles(system: LagrangeSystem, w: float) -> list[float]:
    """Arm angles beta of the steady motions alpha' = w, beta' = 0: roots of the beta row on (-pi, pi]."""
    i = system.index("beta")
    func = np.vectorize(lambda b: system.residual({"beta": b}, {"alpha": w})[i])
    return roots_on_circle(func, samples=4001)
