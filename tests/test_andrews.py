"""Andrews' squeezing mechanism (tests/data/andrews_squeezer.yaml; Hairer & Wanner, Solving ODEs II, VII.7, and
the `andrews` problem of the IVP test set, Mazzia & Magherini): the model reproduces the test set (consistent
initial values, reference solution at t = 0.03), and `mechsys equilibria` finds every one of its 8 equilibrium
configurations without hints, compared with an independent geometric computation."""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.equilibrium.equilibria import EquilibriumProblem, find_equilibria
from mechsys.numeric.parameters import parameter_values
from mechsys.analysis.motion.simulate import simulate
from mechsys.cli import app

ANDREWS = Path(__file__).resolve().parent / "data" / "andrews_squeezer.yaml"
NAMES = ["beta", "theta", "gamma", "phi", "delta", "Omega", "epsilon"]

# IVP test set, problem andrews: y(1:14) at t = 0.03 (PSIDE, rtol = atol = 1e-14)
REFERENCE_Q = [0.1581077119629904e2, -0.1575637105984298e2, 0.4082224013073101e-1, -0.5347301163226948,
               0.5244099658805304, 0.5347301163226948, 0.1048080741042263e1]
REFERENCE_V = [0.1139920302151208e4, -0.1424379294994111e4, 0.1103291221937134e2, 0.1929337464421385e2,
               0.5735699284790808, -0.1929337464421385e2, 0.3231791658026955]

# Hairer-Wanner geometry (the positions only: masses do not enter the statics)
XA, YA, XB, YB, XC, YC = -0.06934, -0.00227, -0.03635, 0.03273, 0.014, 0.072
D, E, RR, SS, SC, SD, U, ZF, ZT = 28e-3, 2e-2, 7e-3, 35e-3, 18e-3, 2e-2, 4e-2, 2e-2, 4e-2
MOM, C0, L0 = 0.033, 4530.0, 0.07785


def wrap(a: float) -> float:
    return math.remainder(a, 2 * math.pi)


def independent_configurations() -> tuple[list[list[float]], list[float]]:
    """The equilibria by hand. Only the spring (on the triangle, gamma) and the torque (on the crank, beta) do work,
    so an equilibrium is a critical point of W = -mom*beta + V(gamma) on the four-bar loop O-F-E-B, which
    closes in two assembly branches (E on either side of the line F-B). For each branch, gamma(beta) is
    explicit and the roots of dW/dbeta are bracketed by sign changes. The two dyads from A (A-G-E of lengths
    zt, e; A-H-E of lengths u, zf) then close in 2 x 2 ways when zt - e <= |E - A| <= zt + e: their bodies carry
    no force at rest. Returns the configurations and the beta of the minima of W (stable)."""
    def gamma_of(beta: float, side: int) -> float | None:
        F = np.array([RR * math.cos(beta), RR * math.sin(beta)])
        B = np.array([XB, YB])
        r = np.linalg.norm(F - B)
        a = (SS**2 - D**2 + r**2) / (2 * r)
        if a * a > SS**2:
            return None
        Epos = B + a * (F - B) / r + side * math.sqrt(SS**2 - a * a) * np.array([-(F - B)[1], (F - B)[0]]) / r
        return math.atan2(Epos[0] - XB, -(Epos[1] - YB))  # E = B + ss*(sin, -cos)(gamma)

    def W(beta: float, side: int) -> float:
        g = gamma_of(beta, side)
        xd, yd = SD * math.cos(g) + SC * math.sin(g) + XB, SD * math.sin(g) - SC * math.cos(g) + YB
        return -MOM * beta + 0.5 * C0 * (math.hypot(xd - XC, yd - YC) - L0) ** 2

    def dW(beta: float, side: int, h: float = 1e-5) -> float:
        return (W(beta + h, side) - W(beta - h, side)) / (2 * h)

    configurations, minima = [], []
    grid = np.linspace(-math.pi, math.pi, 2001)
    for side in (1, -1):
        values = [dW(b, side) for b in grid]
        for k in range(len(grid) - 1):
            if np.sign(values[k]) == np.sign(values[k + 1]):
                continue
            beta = brentq(dW, grid[k], grid[k + 1], args=(side,), xtol=1e-14)
            gamma = gamma_of(beta, side)
            F = np.array([RR * math.cos(beta), RR * math.sin(beta)])
            Epos = np.array([XB + SS * math.sin(gamma), YB - SS * math.cos(gamma)])
            theta = math.atan2(*(F - Epos)[::-1]) - beta  # E = F - d*(cos, sin)(beta + theta)
            rel = Epos - np.array([XA, YA])
            r, base = np.linalg.norm(rel), math.atan2(rel[1], rel[0])
            if not (abs(ZT - E) <= r <= ZT + E and abs(U - ZF) <= r <= U + ZF):
                continue  # this branch cannot be assembled with the dyads from A
            if W(beta + 1e-4, side) + W(beta - 1e-4, side) > 2 * W(beta, side):
                minima.append(beta)
            for s1 in (1, -1):
                delta = base + s1 * math.acos((ZT**2 + r**2 - E**2) / (2 * ZT * r))  # G = A + zt*(cos, sin)(delta)
                w = (rel - ZT * np.array([math.cos(delta), math.sin(delta)])) / E  # (sin, -cos)(phi + delta)
                phi = math.atan2(w[0], -w[1]) - delta
                for s2 in (1, -1):
                    a = base + s2 * math.acos((U**2 + r**2 - ZF**2) / (2 * U * r))  # H = A + u*(cos, sin)(a)
                    eps = a + math.pi / 2  # H = A + u*(sin, -cos)(epsilon)
                    v = (rel - U * np.array([math.cos(a), math.sin(a)])) / ZF  # (cos, sin)(Omega + epsilon)
                    omega = math.atan2(v[1], v[0]) - eps
                    configurations.append([wrap(x) for x in (beta, theta, gamma, phi, delta, omega, eps)])
    return configurations, minima


def test_consistent_initial_values_satisfy_the_loop_constraints():
    model = mechsys.load(ANDREWS)
    problem = EquilibriumProblem(model)
    q0 = [model.doc.initial[c] for c in problem.free]
    assert problem.free == NAMES and problem.m == 6
    phi = problem.F(np.array(q0 + [0.0] * 6), parameter_values(model))[-6:]
    assert np.max(np.abs(phi)) < 1e-15  # lengths are ~0.03 m


def test_simulation_reproduces_the_test_set_reference_solution(tmp_path):
    """From the consistent initial values at rest to t = 0.03 (the crank turns 2.5 times): positions agree with
    the reference to 2e-9 rad, velocities to 2e-7 relative."""
    out = tmp_path / "andrews.csv"
    result = CliRunner().invoke(app, ["simulate", str(ANDREWS), "--t-end", "0.03", "--dt", "0.003", "-o", str(out)])
    assert result.exit_code == 0, result.output
    last = list(csv.DictReader(out.open()))[-1]
    assert float(last["t"]) == 0.03
    q = np.array([float(last[n]) for n in NAMES])
    v = np.array([float(last[f"der({n})"]) for n in NAMES])
    assert np.max(np.abs(q - REFERENCE_Q)) < 2e-9
    assert np.max(np.abs(v - REFERENCE_V) / np.maximum(1.0, np.abs(REFERENCE_V))) < 2e-7


def test_every_equilibrium_configuration_found():
    """8 configurations: 2 critical points of W on the assemblable loop branch (beta = -2.998977, a minimum, and
    beta = -0.124564, a maximum) times the 2 x 2 closures of the dyads from A. The multistart finds all 8 (it
    used to find 7: random starts far from the constraint manifold; now every start is first projected onto it)."""
    expected, minima = independent_configurations()
    assert len(expected) == 8 and len(minima) == 1
    assert math.isclose(minima[0], -2.998976651, abs_tol=1e-7)
    result = find_equilibria(mechsys.load(ANDREWS))
    assert len(result.equilibria) == 8
    found = [[e.coordinates[n] for n in NAMES] for e in result.equilibria]
    for want in expected:
        distances = [max(abs(wrap(a - b)) for a, b in zip(got, want)) for got in found]
        assert min(distances) < 1e-6, want
    for e in result.equilibria:
        stable = abs(wrap(e.coordinates["beta"] - minima[0])) < 1e-6
        assert e.stability == ("stable" if stable else "unstable"), (e.coordinates, e.stability)


@pytest.mark.parametrize("method", ["native", "DOP853"])
def test_work_precision_follows_rtol_on_the_default_output_grid(method):
    """Issue 13: closed loops on scipy restarted at every output point, so `bench` made 13,037 evaluations at every
    rtol and its table was flat. On the default grid (t_end/1000) the evaluations now follow rtol, the error of
    beta(0.03) against the test-set reference falls with it, and an error of 1e-8 costs under 2,500 evaluations
    (at rtol 1e-8 or 1e-9: the global error at a given rtol moves by a factor of a few with the step sequence,
    which round-off in the libraries shifts; scipy's DOP853 gave 3.2e-8 at rtol 1e-8 with numpy 2.4.6, 3.0e-9 at
    1e-9 in 1,911 evaluations)."""
    model = mechsys.load(ANDREWS)
    k = model.coordinates.index(NAMES[0])
    runs = {rtol: simulate(model, 0.03, method=method, rtol=rtol, atol=rtol * 1e-3) for rtol in (1e-6, 1e-8, 1e-9)}
    error = {rtol: abs(r.q[-1, k] - REFERENCE_Q[0]) for rtol, r in runs.items()}
    work = {rtol: r.rhs_evaluations for rtol, r in runs.items()}
    assert all(r.method == method for r in runs.values())
    assert error[1e-6] > error[1e-8] > error[1e-9] and work[1e-6] < work[1e-8] < work[1e-9], (error, work)
    assert error[1e-6] > 30 * error[1e-9]
    assert min([work[r] for r in (1e-8, 1e-9) if error[r] <= 1e-8], default=math.inf) < 2500, (error, work)
    assert max(np.max(r.residual) for r in runs.values()) <= 1e-12  # every output row projected
