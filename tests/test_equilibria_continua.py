"""Roots that are not isolated: one representative of each continuum (equilibria.continua).

A pendulum (m = 1, l = 0.5) beside a free flywheel whose angle the user keeps non-cyclic (`cyclic: false`): it rests
hanging and upright at every flywheel angle, two continua. Only one representative of all non-isolated roots was
listed, so the upright pendulum (eigenvalues +-sqrt(g/l) = +-4.4294) disappeared, exit 0.
"""
from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from mechsys.cli import app

MODEL = """name: two_continua
parameters: {m: 1, l: 0.5, g: 9.81, J: 0.1}
coordinates:
  b: {initial: 0.1, rate: 0}
  w: {initial: 0, rate: 0, cyclic: false}
links:
  rod:
    joint: {type: revolute, parent: ground, axis: x, coordinate: b}
    mass: m
    center_of_mass: [0, 0, -l]
  wheel:
    joint: {type: revolute, parent: ground, axis: z, coordinate: w, origin: [1, 0, 0]}
    inertia: {zz: J}
forces:
  - {type: gravity, acceleration: [0, 0, -g]}
"""


def test_each_continuum_has_its_representative(tmp_path):
    path = tmp_path / "two.yaml"
    path.write_text(MODEL)
    result = CliRunner().invoke(app, ["equilibria", str(path), "-f", "json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    rests = sorted(data["equilibria"], key=lambda e: abs(e["coordinates"]["b"]))
    assert [abs(e["coordinates"]["b"]) for e in rests] == pytest.approx([0.0, math.pi], abs=1e-9)
    rate = math.sqrt(9.81 / 0.5)
    hanging, upright = rests
    assert sorted(abs(im) for _, im in hanging["eigenvalues"]) == pytest.approx([0, 0, rate, rate], abs=1e-9)
    assert upright["stability"] == "unstable"
    assert sorted(re for re, _ in upright["eigenvalues"]) == pytest.approx([-rate, 0, 0, rate], abs=1e-9)
    assert "one representative of each of 2 continua" in data["message"]


def test_roots_one_rounding_apart_are_ordered_by_their_next_coordinate():
    """A sweep's eq1 and eq2 swapped between rows where their first coordinate differed by one ulp (0.3038 and
    0.30379999999999996): the listing order rounds each value to 9 digits before comparing."""
    from mechsys.analysis.equilibrium.equilibria import Equilibrium, _order

    a = Equilibrium({"y1": 0.30379999999999996, "y2": 0.7057}, {}, [])
    b = Equilibrium({"y1": 0.3038, "y2": -0.2943}, {}, [])
    assert sorted([a, b], key=_order) == [b, a]
    assert sorted([Equilibrium({"y1": -1.0, "y2": 5.0}, {}, []), b], key=_order)[0].coordinates["y1"] == -1.0


_ONE_MASS = """name: one_mass
coordinates:
  x: {{initial: 0.5, rate: 0}}
links:
  mass:
    particle: true
    joint: {{type: prismatic, parent: ground, axis: x, coordinate: x}}
    mass: 1
forces:
{forces}
"""


def _rests(tmp_path, forces: str, *options: str) -> dict:
    path = tmp_path / "one.yaml"
    path.write_text(_ONE_MASS.format(forces=forces))
    result = CliRunner().invoke(app, ["equilibria", str(path), "-f", "json", *options])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


@pytest.mark.parametrize("exhaustive", [False, True])
def test_an_isolated_double_root_is_no_continuum(tmp_path, exhaustive):
    """V = (x - 1)**3/3 + (x - 1)**4/4, V' = x (x - 1)**2: two isolated rests, x = 0 (V'' = 1, stable) and the double
    root x = 1 (V'' = 0, V''' = 2: an inflection, no minimum). Its Jacobian is singular, and the listing said 'the
    equilibria are not isolated ... one representative of the continuum is shown' (with --exhaustive too, beside
    its own count of isolated roots): no root goes on from x = 1."""
    data = _rests(tmp_path, "  - {type: potential, value: (x-1)**3/3 + (x-1)**4/4}", *(["--exhaustive"] * exhaustive))
    assert "not isolated" not in data["message"]
    rows = [(e["coordinates"]["x"], e["stability"]) for e in data["equilibria"]]
    assert [round(x, 6) for x, _ in rows] == [0.0, 1.0]
    assert rows[0][1] == "stable" and rows[1][1] == "undecided"


@pytest.mark.parametrize("forces", [
    "  - {type: potential, value: (x**2-9/4)**2/4}\n"
    "  - {type: generalized_force, coordinate: x, value: x*(x**2-9/4)*(1 - (x**2-4)**2)}",
    "  - {type: potential, value: x**2*(3*x**6 - 41*x**4 + 204*x**2 - 432)/24}"], ids=["force", "potential"])
def test_a_double_root_where_the_force_keeps_its_sign_is_not_called_stable(tmp_path, forces):
    """F = -x (x**2 - b**2) (x**2 - 4)**2 with b = 1.5, written as a potential plus a generalized force, or as the
    potential V = x**2 (3 x**6 - 41 x**4 + 204 x**2 - 432)/24 whose V' is -F (integrated by hand, checked below).
    Rests: x = 0 (unstable), +-1.5 (stable) and the double roots +-2, where F has one sign on both sides (at x = 2
    it pushes towards -x from either side: Lyapunov unstable). Newton finds x = 2 only to ~1e-9, on whichever side
    it lands, and the stiffness there (1.7e-7) made x = +-2 'stable (strict minimum ... Lagrange-Dirichlet)', or
    'stable' by the purely oscillatory spectrum (+-1.6e-6 i). A degenerate root is now recognised: never 'stable'
    at +-2, with or without --exhaustive."""
    for exhaustive in (False, True):
        data = _rests(tmp_path, forces, *(["--exhaustive"] * exhaustive))
        rows = {round(e["coordinates"]["x"], 6): e["stability"] for e in data["equilibria"]}
        assert sorted(rows) == [-2.0, -1.5, 0.0, 1.5, 2.0]
        assert rows[0.0] == "unstable" and rows[1.5] == rows[-1.5] == "stable"
        assert rows[2.0] in ("undecided", "unstable") and rows[-2.0] in ("undecided", "unstable"), rows

    def force(x: float) -> float:
        return -x * (x * x - 2.25) * (x * x - 4) ** 2

    def potential(x: float) -> float:
        return x ** 2 * (3 * x ** 6 - 41 * x ** 4 + 204 * x ** 2 - 432) / 24

    assert all(force(x) < 0 for x in (2 - 1e-3, 2 + 1e-3)) and all(force(x) > 0 for x in (-2 - 1e-3, -2 + 1e-3))
    for x in (0.3, 1.7, 2.4):  # V' = -F (central difference)
        assert (potential(x + 1e-6) - potential(x - 1e-6)) / 2e-6 == pytest.approx(-force(x), rel=1e-7)


def test_a_soft_strict_minimum_stays_stable_at_any_size_of_its_stiffness(tmp_path):
    """V = k x**2/2 + x**3/3 with k = 3e-7: x = 0 is an exact rest and a strict minimum (V'' = k, omega = sqrt(k)),
    x = -k a maximum. The first degenerate-root test (a floor of 1e-13 on the residual where the stiffness would
    vanish, F = -k**2/4 = -2.25e-14 there) called x = 0 'undecided' in SI units and 'stable' in grams and mm."""
    data = _rests(tmp_path, "  - {type: potential, value: 3e-7*x**2/2 + x**3/3}")
    rows = {round(e["coordinates"]["x"], 12): e for e in data["equilibria"]}
    assert rows[0.0]["stability"] == "stable" and rows[-3e-7]["stability"] == "unstable"
    assert max(abs(im) for _, im in rows[0.0]["eigenvalues"]) == pytest.approx(math.sqrt(3e-7), rel=1e-9)


def test_a_soft_spring_beside_a_stiff_one_is_stable(tmp_path):
    """Two masses (m = 1) on springs k1 = 1e10 (to ground) and k2 = 1 (between them), a conservative chain: its rest
    is stable, omega = 1e5 and 0.99999999995 rad/s (closed form of the 2 x 2 problem). The soft direction is flat
    against ZERO_H (1e-9 of 1e10), and only the purely oscillatory spectrum decides; the degenerate-root guard had
    taken that away ('undecided')."""
    import numpy as np

    text = ("name: chain\nparameters: {k1: 1e10, k2: 1}\ncoordinates:\n  x1: {initial: 0.01, rate: 0}\n"
            "  x2: {initial: 0.02, rate: 0}\nlinks:\n  a:\n    particle: true\n"
            "    joint: {type: prismatic, parent: ground, axis: x, coordinate: x1}\n    mass: 1\n  b:\n"
            "    particle: true\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x2}\n    mass: 1\n"
            "forces:\n  - {type: potential, value: k1*x1**2/2 + k2*(x2-x1)**2/2}\n")
    path = tmp_path / "chain.yaml"
    path.write_text(text)
    result = CliRunner().invoke(app, ["equilibria", str(path), "-f", "json"])
    assert result.exit_code == 0, result.output
    (rest,) = json.loads(result.output)["equilibria"]
    assert rest["stability"] == "stable"
    K = np.array([[1e10 + 1, -1], [-1, 1]])
    want = np.sqrt(np.linalg.eigvalsh(K))
    got = sorted(abs(im) for _, im in rest["eigenvalues"] if im > 0)
    assert got == pytest.approx(sorted(want), rel=1e-6)


def test_a_cubic_term_decides_however_large_the_sextic_beside_it(tmp_path):
    """V = x**3/3 + 1e7 x**6: x = 0 is a rest with V'' = 0 and a cubic term, no minimum (V < 0 for small negative x);
    the other rest x = -(1/6e7)**(1/3) is a strict minimum (V'' = 2x + 3e8 x**4 > 0 there). The higher-order test
    dropped coefficients below 1e-6 of the largest and called x = 0 'stable (order-6 term positive)'. A
    coefficient now vanishes only within what the root's inaccuracy makes of the higher ones."""
    data = _rests(tmp_path, "  - {type: potential, value: x**3/3 + 1e7*x**6}")
    rows = {round(e["coordinates"]["x"], 9): e["stability"] for e in data["equilibria"]}
    x_min = round(-(1 / 6e7) ** (1 / 3), 9)
    assert rows[0.0] in ("undecided", "unstable") and rows[x_min] == "stable", rows
