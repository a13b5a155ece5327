"""Equations of motion of the bundled models against the textbooks' printed (or digest-corrected) equations.

Each textbook equation is written as a sympy expression "LHS = 0" in the model's own symbols and compared row by
row with the model's residual M*q'' - f, numerically at random states and random parameter values, for both the
Lagrange and the Kane derivation (and symbolically where the expressions are small).
Sources: /work/shared/reference digests (Krodkiewski 2008 ch. 1-7; seeds 001 and 003).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from helpers import (METHODS, assert_close, assert_rows_match, coords, evaluate, load_data, load_system,
                     parameter_values, random_point, simplifies_to_zero, sym)

sin, cos = sp.sin, sp.cos


def P(model, *names):
    return [sym(model, n) for n in names]


# ------------------------------------------------------------------------------------------ Krodkiewski ch. 5
def centrifuge_rows(model):
    I1, m, I2x, I2y, I2z, a, l, g, Mo, dM = P(model, "I1", "m", "I2x", "I2y", "I2z", "a", "l", "g", "Mo", "dM")
    c = coords(model)
    _, ad, add = c["alpha"]
    b, bd, bdd = c["beta"]
    # (5.16), with the digest's errata: M = Mo - dM*der(alpha) (5.1), V = -m g l cos(beta) (5.13)
    row_alpha = ((I1 + m * a**2) + (I2y + m * l**2) * sin(b)**2 + 2 * m * a * l * sin(b) + I2z * cos(b)**2) * add \
        + (2 * (I2y - I2z + m * l**2) * sin(b) * cos(b) + 2 * m * a * l * cos(b)) * ad * bd - Mo + dM * ad
    row_beta = (I2x + m * l**2) * bdd - (I2y - I2z + m * l**2) * ad**2 * sin(b) * cos(b) \
        - m * a * l * ad**2 * cos(b) + m * g * l * sin(b)
    return [row_alpha, row_beta]


@pytest.mark.parametrize("method", METHODS)
def test_centrifuge_eq_5_16_matches_krodkiewski(method, rng):
    model = load_system("centrifuge")
    assert model.coordinates == ["alpha", "beta"]
    assert_rows_match(model, method, centrifuge_rows(model), rng)


def test_centrifuge_eq_5_16_symbolic_lagrange():
    model = load_system("centrifuge")
    res = model.equations("lagrange").residual()
    for got, want in zip(res, centrifuge_rows(model)):
        assert simplifies_to_zero(got - want)


# ------------------------------------------------------------------------------------------ Krodkiewski ch. 6
def gyrostabilizer_rows(model):
    I1y, I2x, I2y, I2z, I3, I3z, Mro, S, g, k, c, Om = P(
        model, "I1y", "I2x", "I2y", "I2z", "I3", "I3z", "Mro", "S", "g", "k", "c", "Omega")
    cs = coords(model)
    al, ad, add = cs["alpha"]
    b, bd, bdd = cs["beta"]
    Mr = -Mro * sin(al)                      # (6.24)
    Mb = -k * b - c * bd                     # (6.25)
    # (6.23) with the digest's errata for (6.15)/(6.22):
    # gravity terms S g cos(beta) sin(alpha) and S g cos(alpha) sin(beta)
    row_alpha = (I1y + (I2y + I3) * cos(b)**2 + (I2z + I3z) * sin(b)**2) * add \
        + (I2z - I2y + I3z - I3) * ad * bd * sin(2 * b) - I3z * Om * bd * cos(b) + S * g * cos(b) * sin(al) - Mr
    row_beta = (I2x + I3) * bdd + sp.Rational(1, 2) * (I3 - I3z + I2y - I2z) * ad**2 * sin(2 * b) \
        + I3z * Om * ad * cos(b) + S * g * cos(al) * sin(b) - Mb
    return [row_alpha, row_beta]


@pytest.mark.parametrize("method", METHODS)
def test_gyrostabilizer_eq_6_23(method, rng):
    model = load_system("gyrostabilizer")
    assert model.coordinates == ["alpha", "beta"]
    assert set(model.prescribed) == {"gamma"}
    assert_rows_match(model, method, gyrostabilizer_rows(model), rng)


def test_gyrostabilizer_energies_match_digest_lagrangian(rng):
    """Part-2 digest §2.3: T = 1/2[I1y + (I2y+I3)cos^2 b + I2z sin^2 b] a'^2 + 1/2 (I2x+I3) b'^2
    + 1/2 I3z (Omega - a' sin b)^2 and V = S g (1 - cos a cos b)."""
    model = load_system("gyrostabilizer")
    I1y, I2x, I2y, I2z, I3, I3z, S, g, Om = P(model, "I1y", "I2x", "I2y", "I2z", "I3", "I3z", "S", "g", "Omega")
    cs = coords(model)
    al, ad, _ = cs["alpha"]
    b, bd, _ = cs["beta"]
    T_book = ((I1y + (I2y + I3) * cos(b)**2 + I2z * sin(b)**2) * ad**2 + (I2x + I3) * bd**2
              + I3z * (Om - ad * sin(b))**2) / 2
    V_book = S * g * (1 - cos(al) * cos(b))
    eq = model.equations("lagrange")
    for _ in range(5):
        pt = random_point(model, rng, randomize_parameters=True)
        assert_close(evaluate(eq.T, model, point=pt), evaluate(T_book, model, point=pt), 1e-9, what="T")
        assert_close(evaluate(eq.V, model, point=pt), evaluate(V_book, model, point=pt), 1e-9, 1e-6, what="V")


# ------------------------------------------------------------------------------------------ Krodkiewski ch. 7
def indicator_rows(model):
    Ix, Iy, Iz, I3z, Om, w1, MG, c = P(model, "Ix", "Iy", "Iz", "I3z", "Omega", "omega1", "MG", "c")
    b, bd, bdd = coords(model)["beta"]
    # (7.8)
    return [Ix * bdd + (Iz - Iy) * w1**2 * sin(b) * cos(b) + I3z * Om * w1 * sin(b) + MG * sin(b) + c * bd]


@pytest.mark.parametrize("method", METHODS)
def test_indicator_eq_7_8(method, rng):
    model = load_system("indicator")
    assert model.coordinates == ["beta"]
    assert set(model.prescribed) == {"psi", "gamma"}
    assert_rows_match(model, method, indicator_rows(model), rng)


@pytest.mark.parametrize("method", METHODS)
def test_indicator_eq_7_8_symbolic(method):
    model = load_system("indicator")
    (got,) = model.equations(method).residual()
    (want,) = indicator_rows(model)
    assert simplifies_to_zero(got - want)


# ------------------------------------------------------------------------------------------ Krodkiewski ch. 4
def problem57_rows(model):
    q, qd, qdd = coords(model)["q"]
    return [qdd + (1 + cos(q)**2) * qd - sp.pi**2 * q + q**3]      # (4.32)


@pytest.mark.parametrize("method", METHODS)
def test_problem57_eq_4_32(method, rng):
    model = load_system("problem57")
    assert_rows_match(model, method, problem57_rows(model), rng, ranges={"q": (-4.0, 4.0)})
    (got,) = model.equations(method).residual()
    assert simplifies_to_zero(got - problem57_rows(model)[0])


# ------------------------------------------------------------------------------------------ Krodkiewski ch. 1
def motor_arm_rows(model):
    m, a, l, Mo, dM, g = P(model, "m", "a", "l", "Mo", "dM", "g")
    cs = coords(model)
    _, w, wd = cs["alpha"]                     # omega = der(alpha) (1.43 reduces the order)
    b, bd, bdd = cs["beta"]
    J = m * l**2 / 12 + m * (l / 2)**2         # I + m (l/2)^2, I = m l^2/12
    row_alpha = (m * a**2 + J * sin(b)**2 + m * a * l * sin(b)) * wd \
        + (2 * J * sin(b) * cos(b) + m * l * a * cos(b)) * w * bd - (Mo - dM * w)
    row_beta = J * bdd - J * w**2 * sin(b) * cos(b) - m * a * (l / 2) * w**2 * cos(b) + m * g * (l / 2) * sin(b)
    return [row_alpha, row_beta]


@pytest.mark.parametrize("method", METHODS)
def test_problem1_motor_arm_eq_1_43(method, rng):
    model = load_system("motor_arm")
    assert_rows_match(model, method, motor_arm_rows(model), rng)
    for got, want in zip(model.equations(method).residual(), motor_arm_rows(model)):
        assert simplifies_to_zero(got - want)


def test_problem1_motor_arm_steady_state_eq_1_44():
    """Equilibrium (1.44): omega_o = Mo/dM = 5 rad/s and beta_o = 0.778899 rad (digest [computed]); the
    model's forcing must vanish there with zero accelerations and der(beta) = 0."""
    model = load_system("motor_arm")
    cs = coords(model)
    pt = parameter_values(model)
    pt.update({cs["alpha"][0]: 0.3, cs["alpha"][1]: 5.0, cs["beta"][1]: 0.0})
    beta = sp.Symbol("beta_o")
    for method in METHODS:
        f = model.equations(method).f.xreplace(pt).xreplace({cs["beta"][0]: beta})
        assert abs(float(f[0])) < 1e-12
        root = sp.nsolve(f[1], beta, 0.7)
        assert abs(float(root) - 0.778899) < 5e-7


def wheel_on_axle_rows(model):
    m, r, b_, l, g, w, Om = P(model, "m", "r", "b", "l", "g", "omega", "Omega")
    b, bd, bdd = coords(model)["beta"]
    I = m * (r**2 / 4 + b_**2 / 12 + l**2)
    Iz2 = m * r**2 / 2
    # (1.52): I b'' + (Iz2 - I) w^2 sin b cos b + Iz2 Omega w sin b = m g l sin b
    return [I * bdd + (Iz2 - I) * w**2 * sin(b) * cos(b) + Iz2 * Om * w * sin(b) - m * g * l * sin(b)]


@pytest.mark.parametrize("method", METHODS)
def test_problem2_wheel_on_axle_eq_1_52(method, rng):
    model = load_system("wheel_on_axle")
    assert model.coordinates == ["beta"]
    assert_rows_match(model, method, wheel_on_axle_rows(model), rng)
    (got,) = model.equations(method).residual()
    assert simplifies_to_zero(got - wheel_on_axle_rows(model)[0])


def test_problem2_wheel_on_axle_equilibrium_eq_1_56():
    """(1.56): cos(beta_o) = (m g l - Iz2 Omega omega)/((Iz2 - I) omega^2); digest example beta_o = 76.409 deg."""
    model = load_system("wheel_on_axle")
    b = coords(model)["beta"][0]
    v = model.parameters
    I = v["m"] * (v["r"]**2 / 4 + v["b"]**2 / 12 + v["l"]**2)
    Iz2 = v["m"] * v["r"]**2 / 2
    closed_form = math.acos((v["m"] * v["g"] * v["l"] - Iz2 * v["Omega"] * v["omega"]) / ((Iz2 - I) * v["omega"]**2))
    assert abs(math.degrees(closed_form) - 76.409) < 1e-3
    for method in METHODS:
        eq = model.equations(method)
        pt = parameter_values(model)
        pt.update({u: 0.0 for u in model.u})
        pt[model.t] = 0.7
        root = float(sp.nsolve(eq.f[0].xreplace(pt), b, 1.3))
        assert abs(root - closed_form) < 1e-9


# ------------------------------------------------------------------------------------------ seed 001
def cart_pendulum_rows(model):
    m1, m2, R, r, k, g = P(model, "m1", "m2", "R", "r", "k", "g")
    cs = coords(model)
    x, xd, xdd = cs["x"]
    ph, phd, phdd = cs["phi"]
    I = sp.Rational(2, 5) * m2 * r**2
    # (2.54)
    return [(m1 + m2) * xdd + m2 * R * phdd * cos(ph) - m2 * R * phd**2 * sin(ph) + 2 * k * x,
            (m2 * R**2 + I) * phdd + m2 * R * xdd * cos(ph) + m2 * g * R * sin(ph)]


@pytest.mark.parametrize("method", METHODS)
def test_cart_pendulum_eq_2_54_001_problem18(method, rng):
    model = load_system("cart_pendulum")
    assert_rows_match(model, method, cart_pendulum_rows(model), rng, ranges={"x": (-0.4, 0.4)})
    for got, want in zip(model.equations(method).residual(), cart_pendulum_rows(model)):
        assert simplifies_to_zero(got - want)


def test_cart_pendulum_energies_eq_2_45_2_46_001_problem18(rng):
    """T (2.45) exactly; V (2.46) = 2*(1/2)k x^2 - m2 g R cos(phi) up to a constant."""
    model = load_system("cart_pendulum")
    m1, m2, R, r, k, g = P(model, "m1", "m2", "R", "r", "k", "g")
    cs = coords(model)
    x, xd, _ = cs["x"]
    ph, phd, _ = cs["phi"]
    I = sp.Rational(2, 5) * m2 * r**2
    T_book = (m1 + m2) * xd**2 / 2 + m2 * R * xd * phd * cos(ph) + (m2 * R**2 + I) * phd**2 / 2
    V_book = 2 * k * x**2 / 2 - m2 * g * R * cos(ph)
    eq = model.equations("lagrange")
    assert simplifies_to_zero(eq.T - T_book)
    offsets = []
    for _ in range(4):
        pt = random_point(model, rng, ranges={"x": (-0.4, 0.4)})   # same (file) parameters each time
        offsets.append(evaluate(eq.V - V_book, model, point=pt))
    assert max(offsets) - min(offsets) < 1e-12, offsets


def _check_linear_chain(model, method, rng, Mb, Cb, Kb, Fb):
    """Residual rows equal M x'' + C x' + K x - F(t); M exactly; K, C, F(t) also by differentiating f."""
    x, u, a = sp.Matrix(model.q), sp.Matrix(model.u), sp.Matrix(model.a)
    small = {n: (-0.05, 0.05) for n in model.coordinates}   # springs never pass through zero length
    assert_rows_match(model, method, list(Mb * a + Cb * u + Kb * x - Fb), rng, ranges=small)
    eq = model.equations(method)
    assert sp.simplify(eq.M - Mb) == sp.zeros(*Mb.shape)
    for _ in range(3):
        pt = random_point(model, rng, randomize_parameters=True, ranges=small)
        assert_close(evaluate(-eq.f.jacobian(model.q), model, point=pt), evaluate(Kb, model, point=pt), what="K")
        assert_close(evaluate(-eq.f.jacobian(model.u), model, point=pt), evaluate(Cb, model, point=pt), what="C")
        zero = dict(pt)
        zero.update({s_: 0.0 for s_ in list(model.q) + list(model.u)})
        assert_close(evaluate(eq.f, model, point=zero).ravel(), evaluate(Fb, model, point=zero).ravel(),
                     1e-9, 1e-12, what="F(t)")


@pytest.mark.parametrize("method", METHODS)
def test_mdof_chain_matrices_E001_1(method, rng):
    """Seed 001, (2.4)/(2.16) assembly rule: 3 masses between two walls, M x'' + C x' + K x = 0."""
    model = load_system("spring_chain")
    m1, m2, m3, k1, k12, k23, k3, c1, c12, c23, c3 = P(
        model, "m1", "m2", "m3", "k1", "k12", "k23", "k3", "c1", "c12", "c23", "c3")
    Mb = sp.diag(m1, m2, m3)
    Kb = sp.Matrix([[k1 + k12, -k12, 0], [-k12, k12 + k23, -k23], [0, -k23, k23 + k3]])
    Cb = sp.Matrix([[c1 + c12, -c12, 0], [-c12, c12 + c23, -c23], [0, -c23, c23 + c3]])
    _check_linear_chain(model, method, rng, Mb, Cb, Kb, sp.zeros(3, 1))


@pytest.mark.parametrize("method", METHODS)
def test_mdof_chain_base_excitation_eq_2_4_E001_1(method, rng):
    """Seed 001, Fig. 1, (2.4): m_i x_i'' + (c_i + c_ij) x_i' - c_ij x_j' + (k_i + k_ij) x_i - k_ij x_j = k_i y_i(t);
    the damper c_i has a fixed end, so the moving base contributes only k_i y_i(t)."""
    model = load_data("chain_base_excitation")
    assert model.coordinates == ["x_i", "x_j"]
    m_i, m_j, k_i, k_ij, k_j, c_i, c_ij, Y, w = P(model, "m_i", "m_j", "k_i", "k_ij", "k_j", "c_i", "c_ij", "Y", "w")
    y = model.prescribed["y_i"]
    assert sp.simplify(y - Y * sp.sin(w * model.t)) == 0
    Mb = sp.diag(m_i, m_j)
    Kb = sp.Matrix([[k_i + k_ij, -k_ij], [-k_ij, k_ij + k_j]])
    Cb = sp.Matrix([[c_i + c_ij, -c_ij], [-c_ij, c_ij]])
    _check_linear_chain(model, method, rng, Mb, Cb, Kb, sp.Matrix([k_i * y, 0]))


# ------------------------------------------------------------------------------------------ seed 003
def _static_crank_torque(model, method, config):
    """Solve f + A^T lambda = 0 at zero rates and accelerations for the unknown M2 and the multipliers."""
    eq = model.equations(method)
    pt = parameter_values(model)
    M2 = sym(model, "M2")
    del pt[M2]
    pt.update(config)
    pt.update({u: 0.0 for u in model.u})
    pt[model.t] = 0.0
    lam = sp.symbols(f"lam0:{eq.A.rows}")
    eqs = list((eq.f + eq.A.T * sp.Matrix(lam)).xreplace(pt))
    sol = sp.solve(eqs, [M2, *lam], dict=True)
    assert len(sol) == 1, sol
    return float(sol[0][M2])


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("F4, expected", [(0.0, 2.081015), (10.0, 3.912258)])
def test_slider_crank_static_generalized_force_E003_2(method, F4, expected):
    """E003-2 (5.137-5.138): torque M2 holding the crank at 45 deg with gravity (and F4 along +x)."""
    model = load_system("slider_crank", {"F4": F4})
    cs = coords(model)
    config = {cs[n][0]: model.doc.initial[n] for n in model.coordinates}
    # the file's initial configuration is the book's: theta2 = 45 deg, theta3 = -16.42994 deg, x = 0.621005 m
    assert abs(math.degrees(model.doc.initial["theta2"]) - 45) < 1e-12
    assert abs(math.degrees(model.doc.initial["theta3"]) + 16.42994) < 5e-6
    assert abs(model.doc.initial["x4"] - 0.621005) < 5e-7
    pt = parameter_values(model)
    pt.update(config)
    assert np.abs(evaluate(model.holonomic_constraints, model, point=pt)).max() < 1e-12
    assert abs(_static_crank_torque(model, method, config) - expected) < 5e-6


@pytest.mark.parametrize("method", METHODS)
def test_slider_crank_virtual_work_eq_5_138_E003_2(method, rng):
    """Q_e = M2 - (m2+m3) g l2O cos(theta2) - 2 F4 l2O sin(theta2 - theta3)/cos(theta3) = 0 at random crank
    angles on the book's branch (theta3 from 2 l2O sin(theta2) + 2 l3A sin(theta3) = 0) and random F4."""
    model = load_system("slider_crank")
    vals = {n: model.parameters[n] for n in ("l2O", "l3A", "m2", "m3", "g")}
    cs = coords(model)
    for _ in range(4):
        th2 = rng.uniform(-math.pi, math.pi)
        F4 = rng.uniform(-20, 20)
        th3 = -math.asin(vals["l2O"] * math.sin(th2) / vals["l3A"])
        x4 = 2 * vals["l2O"] * math.cos(th2) + 2 * vals["l3A"] * math.cos(th3)
        m = load_system("slider_crank", {"F4": float(F4)})
        config = {cs["theta2"][0]: th2, cs["theta3"][0]: th3, cs["x4"][0]: x4}
        book = (vals["m2"] + vals["m3"]) * vals["g"] * vals["l2O"] * math.cos(th2) \
            + 2 * F4 * vals["l2O"] * math.sin(th2 - th3) / math.cos(th3)
        assert_close(_static_crank_torque(m, method, config), book, 1e-9, 1e-12, what="M2")


# ------------------------------------------------------------------------------------------ other bundled systems
def double_pendulum_rows(model):
    m1, m2, l1, l2, g = P(model, "m1", "m2", "l1", "l2", "g")
    cs = coords(model)
    t1, t1d, t1dd = cs["theta1"]
    t2, t2d, t2dd = cs["theta2"]
    c2, s2 = cos(t2), sin(t2)
    M11 = m1 * l1**2 / 3 + m2 * (l1**2 + l2**2 / 3 + l1 * l2 * c2)
    M12 = m2 * (l2**2 / 3 + l1 * l2 * c2 / 2)
    M22 = m2 * l2**2 / 3
    return [M11 * t1dd + M12 * t2dd - m2 * l1 * l2 * s2 * (t1d * t2d + t2d**2 / 2)
            + (m1 / 2 + m2) * g * l1 * sin(t1) + m2 * g * l2 / 2 * sin(t1 + t2),
            M12 * t1dd + M22 * t2dd + m2 * l1 * l2 * s2 * t1d**2 / 2 + m2 * g * l2 / 2 * sin(t1 + t2)]


@pytest.mark.parametrize("method", METHODS)
def test_double_pendulum_relative_angles_compound_rods(method, rng):
    model = load_system("double_pendulum")
    assert_rows_match(model, method, double_pendulum_rows(model), rng)


@pytest.mark.parametrize("method", METHODS)
def test_rolling_disk_no_slip_rows_krodkiewski_eq_1_5(method, rng):
    """Rolling without slip (Krodkiewski (1.5)-(1.6)): the disk's contact point has zero velocity, which for this
    construction reads der(x) - r der(spin) cos(yaw) = 0 and der(y) - r der(spin) sin(yaw) = 0; the
    acceleration-level rows A q'' = b are their time derivatives."""
    model = load_system("rolling_disk")
    eq = model.equations(method)
    r = sym(model, "r")
    cs = coords(model)
    yaw, yawd, _ = cs["yaw"]
    _, sd, sdd = cs["spin"]
    (_, xd, xdd), (_, yd, ydd) = cs["x"], cs["y"]
    vel = [xd - r * sd * cos(yaw), yd - r * sd * sin(yaw)]
    acc = [xdd - r * sdd * cos(yaw) + r * sd * yawd * sin(yaw), ydd - r * sdd * sin(yaw) - r * sd * yawd * cos(yaw)]
    assert eq.A.shape == (2, 5)
    a = sp.Matrix(model.a)
    u = sp.Matrix(model.u)
    for _ in range(5):
        pt = random_point(model, rng, randomize_parameters=True)
        assert_close(evaluate(eq.A * u, model, point=pt).ravel(), [evaluate(v, model, point=pt) for v in vel],
                     1e-9, 1e-12, what="A u")
        assert_close(evaluate(eq.A * a - eq.b, model, point=pt).ravel(),
                     [evaluate(v, model, point=pt) for v in acc], 1e-9, 1e-12, what="A a - b")
    # the initial state in the file satisfies the rolling constraints
    pt = parameter_values(model)
    pt.update({q: model.doc.initial[n] for n, q in zip(model.coordinates, model.q)})
    pt.update({v: model.doc.initial_rate[n] for n, v in zip(model.coordinates, model.u)})
    assert np.abs(evaluate(eq.A * u, model, point=pt)).max() < 1e-12


@pytest.mark.parametrize("method", METHODS)
def test_four_bar_static_crank_torque_by_virtual_work(method, rng):
    """Principle of virtual work (Krodkiewski (2.32)): the crank torque holding the four-bar still against gravity
    is M2 = dV/dtheta2 along the loop; V from the closed-form loop solution, derivative by central differences."""
    model = load_system("four_bar")
    p = {n: model.parameters[n] for n in ("l1", "l2", "l3", "l4", "m2", "m3", "m4", "g")}

    def loop(th2):
        d2 = p["l1"]**2 + p["l2"]**2 - 2 * p["l1"] * p["l2"] * math.cos(th2)
        d = math.sqrt(d2)
        th3abs = math.atan2(-p["l2"] * math.sin(th2), p["l1"] - p["l2"] * math.cos(th2)) \
            + math.acos((p["l3"]**2 + d2 - p["l4"]**2) / (2 * p["l3"] * d))
        bx = p["l2"] * math.cos(th2) + p["l3"] * math.cos(th3abs)
        by = p["l2"] * math.sin(th2) + p["l3"] * math.sin(th3abs)
        th4 = math.atan2(by, bx - p["l1"])
        return th3abs, th4

    def potential(th2):
        th3abs, th4 = loop(th2)
        y2 = p["l2"] / 2 * math.sin(th2)
        y3 = p["l2"] * math.sin(th2) + p["l3"] / 2 * math.sin(th3abs)
        y4 = p["l4"] / 2 * math.sin(th4)
        return p["g"] * (p["m2"] * y2 + p["m3"] * y3 + p["m4"] * y4)

    cs = coords(model)
    # the file's initial configuration closes the loop
    init = parameter_values(model)
    init.update({cs[n][0]: model.doc.initial[n] for n in model.coordinates})
    assert np.abs(evaluate(model.holonomic_constraints, model, point=init)).max() < 1e-12
    for th2 in [math.pi / 3, *rng.uniform(-math.pi, math.pi, 3)]:
        th3abs, th4 = loop(th2)
        config = {cs["theta2"][0]: th2, cs["theta3"][0]: th3abs - th2, cs["theta4"][0]: th4}
        h = 1e-5
        book = (potential(th2 + h) - potential(th2 - h)) / (2 * h)
        assert_close(_static_crank_torque(model, method, config), book, 1e-7, 1e-10, what="M2")


# ------------------------------------------------------------------------------------------ autonomy (ch. 1, 6, 7)
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", ["gyrostabilizer", "indicator", "wheel_on_axle"])
def test_constant_spin_rotors_give_autonomous_eom_krodkiewski(name, method, rng):
    """Part-2 digest §1.7 (and (1.55), (6.23), (7.8)): a prescribed CONSTANT spin Omega*t (and platform rate
    omega1*t) is rheonomic, but the EOM contain only the rates, never the angles, so they are autonomous.
    First the derivation: d(residual)/dt = 0 at random states; then the model's classification."""
    model = load_system(name)
    res = model.equations(method).residual()
    d_dt = res.diff(model.t)
    for _ in range(3):
        pt = random_point(model, rng, randomize_parameters=True)
        scale = max(1.0, float(np.max(np.abs(evaluate(res, model, point=pt)))))
        assert np.max(np.abs(evaluate(d_dt, model, point=pt))) <= 1e-9 * scale
    assert model.is_rheonomic
    assert model.is_autonomous(method), f"{name} [{method}]: EOM reported non-autonomous"


def test_derive_json_carries_the_parameter_values_of_the_load():
    """README: `mechsys derive systems/centrifuge.yaml --set Mo=60 -f json -o eom.json`. The JSON held the symbolic
    equations only, byte for byte the same with and without --set: the override was lost. It now carries the
    parameter values, dependent ones recomputed (dM = Mo/7 in the file)."""
    from typer.testing import CliRunner

    from mechsys.cli import app

    path = Path(__file__).resolve().parents[1] / "systems" / "centrifuge.yaml"
    plain = json.loads(CliRunner().invoke(app, ["derive", str(path), "-f", "json"]).output)["parameters"]
    changed = json.loads(CliRunner().invoke(app, ["derive", str(path), "--set", "Mo=60", "-f", "json"]).output)
    assert changed["parameters"]["Mo"] == 60.0 and plain["Mo"] != 60.0
    assert changed["parameters"]["dM"] == pytest.approx(60.0 / 7, rel=1e-15)
    assert {k: v for k, v in changed["parameters"].items() if k not in ("Mo", "dM")} == \
        {k: v for k, v in plain.items() if k not in ("Mo", "dM")}
