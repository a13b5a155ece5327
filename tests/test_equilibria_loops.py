"""Equilibria of closed loops with redundant rows and at singular configurations (analysis/equilibrium/loops.py).

tests/data/beyond/parallelogram_third_bar.yaml, a parallelogram four-bar with a third parallel bar (one of its four
loop rows redundant), listed 46 'stable' rests with no eigenvalue ('locked') near its change points theta2 = 0, pi,
and said the equilibria were not isolated; `modes` vibrated about one of them. Near a change point the constraint
Jacobian loses rank and f + A^T lambda = 0 is met only as the multipliers grow without bound (1e4 to 1e15): Newton
stopped where their rounding hid F. Its rests are theta2 = -pi/2 (hanging) and +pi/2, with
omega^2 = (5/2) m g a / (2 m a^2) = 5 g / (4 a): three bars of inertia m a^2/3 about their pivots and the coupler, in
circular translation, m a^2; the weights of the three bars (centres at a/2) and the coupler (at a) lift by
(5/2) m g a (1 - cos phi).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq
from typer.testing import CliRunner

from mechsys.cli import app

BEYOND = Path(__file__).resolve().parent / "data" / "beyond"
runner = CliRunner()


def _run(*args: str) -> dict:
    result = runner.invoke(app, [*args, "-f", "json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def test_parallelogram_with_a_third_bar_has_its_two_rests_and_no_locked_ones():
    data = _run("equilibria", str(BEYOND / "parallelogram_third_bar.yaml"))
    omega = math.sqrt(5 * 9.81 / (4 * 0.5))
    rests = sorted(data["equilibria"], key=lambda e: e["coordinates"]["theta2"])
    assert [round(e["coordinates"]["theta2"], 9) for e in rests] == [round(-math.pi / 2, 9), round(math.pi / 2, 9)]
    hanging, upright = rests
    assert hanging["stability"] == "stable"
    assert sorted(abs(im) for _, im in hanging["eigenvalues"]) == pytest.approx([omega, omega], rel=1e-9)
    assert upright["stability"] == "unstable"
    assert sorted(re for re, _ in upright["eigenvalues"]) == pytest.approx([-omega, omega], rel=1e-9)
    assert "not rests" in data["message"] and "not isolated" not in data["message"]


def test_modes_of_the_parallelogram_with_a_third_bar_are_about_its_hanging_rest():
    data = _run("modes", str(BEYOND / "parallelogram_third_bar.yaml"))
    assert data["equilibrium"]["coordinates"]["theta2"] == pytest.approx(-math.pi / 2, abs=1e-9)
    assert [m["frequency_rad_s"] for m in data["modes"]] == pytest.approx([math.sqrt(5 * 9.81 / 2)], rel=1e-9)


# ----------------------------------------------------------------------------- a four-bar closed twice
L1, L2, L3, L4, M2, M3, M4, G = 0.4, 0.1, 0.35, 0.3, 0.5, 1.2, 1.0, 9.81


def _fourbar(theta2: float, branch: int) -> tuple[np.ndarray, np.ndarray]:
    """Crank tip A and coupler-rocker pin B of the four-bar on assembly branch +-1 (circle intersection)."""
    a = L2 * np.array([math.cos(theta2), math.sin(theta2)])
    o4 = np.array([L1, 0.0])
    d = o4 - a
    dist = float(np.linalg.norm(d))
    along = (L3**2 - L4**2 + dist**2) / (2 * dist)
    across = math.sqrt(L3**2 - along**2)
    return a, a + along * d / dist + branch * across * np.array([-d[1], d[0]]) / dist


def _potential(theta2: float, branch: int) -> float:
    a, b = _fourbar(theta2, branch)
    return G * (M2 * a[1] / 2 + M3 * (a[1] + b[1]) / 2 + M4 * b[1] / 2)


def _kinetic_mass(theta2: float, branch: int, h: float = 1e-6) -> float:
    """M_eff with T = M_eff theta2'^2 / 2: slender rods, crank and rocker about their pivots, coupler about its
    centre plus its centre's speed (velocities by central differences of the closed-form geometry)."""
    (a0, b0), (a1, b1) = _fourbar(theta2 - h, branch), _fourbar(theta2 + h, branch)
    da, db = (a1 - a0) / (2 * h), (b1 - b0) / (2 * h)
    a, b = _fourbar(theta2, branch)
    phi3 = lambda a_, b_: math.atan2(b_[1] - a_[1], b_[0] - a_[0])  # noqa: E731
    w3 = math.remainder(phi3(a1, b1) - phi3(a0, b0), 2 * math.pi) / (2 * h)
    w4 = math.remainder(math.atan2(b1[1], b1[0] - L1) - math.atan2(b0[1], b0[0] - L1), 2 * math.pi) / (2 * h)
    return (M2 * L2**2 / 3 + M3 * float(np.dot((da + db) / 2, (da + db) / 2)) + M3 * L3**2 / 12 * w3**2
            + M4 * L4**2 / 3 * w4**2)


def _closed_form_rests() -> list[tuple[float, float]]:
    """(theta2, lambda^2 = -V''/M_eff) of every rest on both branches: roots of dV/dtheta2 on a fine grid."""
    rests = []
    for branch in (1, -1):
        dV = lambda t: (_potential(t + 1e-6, branch) - _potential(t - 1e-6, branch)) / 2e-6  # noqa: E731
        grid = np.linspace(-math.pi, math.pi, 721)
        for lo, hi in zip(grid[:-1], grid[1:]):
            if dV(lo) * dV(hi) < 0:
                t = brentq(dV, lo, hi, xtol=1e-13)
                curvature = (_potential(t + 1e-4, branch) - 2 * _potential(t, branch) + _potential(t - 1e-4, branch)) / 1e-8
                rests.append((t, -curvature / _kinetic_mass(t, branch)))
    return sorted(rests)


def test_a_four_bar_closed_twice_has_the_rests_of_its_closed_form():
    """Before, the loop closed twice found only its unstable rest; now both branches' rests, as closed once."""
    twice = _run("equilibria", str(BEYOND / "fourbar_closed_twice.yaml"))
    expected = _closed_form_rests()
    found = sorted(twice["equilibria"], key=lambda e: e["coordinates"]["theta2"])
    assert [e["coordinates"]["theta2"] for e in found] == pytest.approx([t for t, _ in expected], abs=1e-6)
    for e, (_, lam2) in zip(found, expected):
        assert e["stability"] == ("stable" if lam2 < 0 else "unstable")
        square = max(abs(complex(re, im) ** 2) for re, im in e["eigenvalues"])
        assert square == pytest.approx(abs(lam2), rel=1e-4)


# ----------------------------------------------------------------------------- rests at a change point
SIDEWAYS = """\
name: parallelogram_sideways
parameters: {L: 1.0, a: 0.5, m: 1, g: 9.81}
coordinates:
  theta2: {initial: -pi/2 + 0.3}
  theta3: {initial: pi/2 - 0.3}
  theta4: {initial: -pi/2 + 0.3}
ground:
  points:
    O4: [L, 0, 0]
links:
  crank:
    joint: {type: revolute, parent: ground, axis: z, coordinate: theta2}
    mass: m
    center_of_mass: [a/2, 0, 0]
  coupler:
    joint: {type: revolute, parent: crank, axis: z, coordinate: theta3, origin: [a, 0, 0]}
    mass: m
    center_of_mass: [L/2, 0, 0]
    points:
      B: [L, 0, 0]
  rocker:
    joint: {type: revolute, parent: ground, axis: z, coordinate: theta4, origin: O4}
    mass: m
    center_of_mass: [a/2, 0, 0]
    points:
      B: [a, 0, 0]
constraints:
  - {type: point_on_point, name: loopB, points: [coupler.B, rocker.B]}
forces:
  - {type: gravity, acceleration: [-g, 0, 0]}
"""


def test_rests_at_a_change_point_are_undecided_and_modes_refuses_them(tmp_path):
    """Gravity along the ground line: a parallelogram's rests are its collinear configurations theta2 = 0, pi, the
    change points where its antiparallelogram branch crosses (the loop's rows have rank 1 there, 2 elsewhere).
    The linearization there sees two branches at once: no verdict, and `modes` says why."""
    path = tmp_path / "sideways.yaml"
    path.write_text(SIDEWAYS, encoding="utf-8")
    data = _run("equilibria", str(path))
    found = sorted(abs(e["coordinates"]["theta2"]) for e in data["equilibria"])
    assert found == pytest.approx([0.0, math.pi], abs=1e-6)
    for e in data["equilibria"]:
        assert e["stability"] == "undecided" and "rank 1 here, 2 elsewhere" in e["reason"]
    result = runner.invoke(app, ["modes", str(path)])
    assert result.exit_code != 0
    assert "singular configuration of the closed loops" in result.stderr and "Traceback" not in result.output


@pytest.mark.parametrize("units", ["mems", "picometre"])
def test_the_parallelogram_has_the_same_two_rests_at_any_scale(units):
    """The same parallelogram with a third bar at MEMS scale (bars of 50 um, 1e-9 kg) listed a 'locked' rest at
    theta2 = -0.84, held by multipliers of 3e5 N on the rounding of its redundant loop row, and called the
    equilibria 'not isolated'; at picometre scale (1e-12 m) it listed 12 'locked' rests and refused the loop's
    rows as identically satisfied before that. Thresholds were absolute (a floor of 1 under N m and m). Its rests
    are the same two at every scale, with omega^2 = 5 g / (4 a)."""
    a, sets = {"mems": (0.5e-4, ["--set", "a=0.5e-4", "--set", "L=1e-4", "--set", "m=1e-9"]),
               "picometre": (0.5e-12, ["--set", "a=0.5e-12", "--set", "L=1e-12"])}[units]
    data = _run("equilibria", str(BEYOND / "parallelogram_third_bar.yaml"), *sets)
    omega = math.sqrt(5 * 9.81 / (4 * a))
    rests = sorted(data["equilibria"], key=lambda e: e["coordinates"]["theta2"])
    assert [round(e["coordinates"]["theta2"], 9) for e in rests] == [round(-math.pi / 2, 9), round(math.pi / 2, 9)]
    hanging, upright = rests
    assert hanging["stability"] == "stable" and upright["stability"] == "unstable"
    assert sorted(abs(im) for _, im in hanging["eigenvalues"]) == pytest.approx([omega, omega], rel=1e-9)
    assert sorted(re for re, _ in upright["eigenvalues"]) == pytest.approx([-omega, omega], rel=1e-9)
    assert "not isolated" not in data["message"]
