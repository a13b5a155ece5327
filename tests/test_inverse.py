"""`mechsys inverse` (issue 14): one instant's accelerations, driving forces, multipliers and reactions, checked
against the digest (seeds001_004, E003-2) and an energy balance written here from the slider-crank's closed-form
kinematics (not from mechsys)."""
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from mechsys.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[1]
CRANK = str(ROOT / "docs/examples/slider_crank_driven.yaml")
L2O, L3A, M2_, M3_, M4_, G = 0.1, 0.25, 1.0, 2.0, 0.5, 9.81


def run(capsys, *args: str) -> tuple[int, str, str]:
    saved, sys.argv = sys.argv, ["mechsys", *args]
    try:
        cli_main()
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    finally:
        sys.argv = saved
    out, err = capsys.readouterr()
    return code, out, err


def instant(capsys, *args: str) -> dict:
    code, out, err = run(capsys, "inverse", CRANK, "-f", "json", *args)
    assert code == 0, err
    return json.loads(out)


def test_slider_crank_statics_reproduce_e003_2(capsys):
    """E003-2 (theta2 = 45 deg, F4 = +10 N, gravity): theta3 = -16.42994 deg, x_B = 0.621005 m, M2 = 3.912258 N m;
    reactions F12 = (-10, 22.56884) ground on crank, F23 = (-10, 12.75884) crank on rod (the pin's multipliers:
    the force on the rod's point A), F34 = (-10, -6.86116) rod on slider, so the rod's subtree gets -F34 from the
    slider. With F4 = 0, M2 = (m2 + m3) g l2O cos 45 deg = 2.081015 N m."""
    out = instant(capsys, "--set", "omega2=0", "--set", "F4=10")
    assert math.degrees(out["coordinates"]["theta3"]) == pytest.approx(-16.42994, abs=5e-6)
    assert out["coordinates"]["x4"] == pytest.approx(0.621005, abs=5e-7)
    assert out["driving"]["theta2"] == pytest.approx(3.912258, abs=5e-7)
    assert [out["reactions"]["crank"][k] for k in ("Fx", "Fy")] == pytest.approx([-10, 22.56884], abs=5e-6)
    assert [out["multipliers"][k] for k in ("crank_pin.x", "crank_pin.y")] == pytest.approx([-10, 12.75884], abs=5e-6)
    assert [out["reactions"]["rod"][k] for k in ("Fx", "Fy")] == pytest.approx([10, 6.86116], abs=5e-6)
    assert all(v == 0 for v in out["accelerations"].values())
    static = instant(capsys, "--set", "omega2=0")
    assert static["driving"]["theta2"] == pytest.approx((M2_ + M3_) * G * L2O * math.cos(math.pi / 4), abs=1e-9)


def _crank_energy(t: float, w: float) -> tuple[float, float, float]:
    """(T, V, x4) of the slider-crank at time t, crank at pi/4 + w t, from the loop closure alone."""
    th2 = math.pi / 4 + w * t
    th3 = -math.asin(2 * L2O * math.sin(th2) / (2 * L3A))
    x4 = 2 * L2O * math.cos(th2) + 2 * L3A * math.cos(th3)
    return th2, th3, x4


def _energies(t: float, w: float, h: float = 1e-4) -> tuple[float, float, float]:
    """dT/dt, dV/dt and der(x4) at t by 4th-order central differences of the closed-form positions."""
    def positions(s):
        th2, th3, x4 = _crank_energy(s, w)
        g2 = np.array([L2O * math.cos(th2), L2O * math.sin(th2)])
        g3 = np.array([x4 - L3A * math.cos(th3), -L3A * math.sin(th3)])
        return np.concatenate([g2, g3, [th2, th3, x4]])

    def d(f, s):
        return (f(s - 2 * h) - 8 * f(s - h) + 8 * f(s + h) - f(s + 2 * h)) / (12 * h)

    def T(s):
        v = d(positions, s)
        return (0.5 * M2_ * v[0:2] @ v[0:2] + 0.5 * M2_ * (2 * L2O) ** 2 / 12 * v[4] ** 2
                + 0.5 * M3_ * v[2:4] @ v[2:4] + 0.5 * M3_ * (2 * L3A) ** 2 / 12 * v[5] ** 2 + 0.5 * M4_ * v[6] ** 2)

    def V(s):
        p = positions(s)
        return G * (M2_ * p[1] + M3_ * p[3])

    return d(T, t), d(V, t), d(positions, t)[6]


@pytest.mark.parametrize("t", [0.0, 0.37, 1.2])
def test_the_driving_torque_of_a_turning_crank_balances_the_power(capsys, t):
    """Crank driven at omega2 = 3 rad/s, F4 = 4 N: M2 omega2 + F4 x4' = dT/dt + dV/dt (the only work is the
    motor's and the slider force's), with T and V from the closed-form kinematics differentiated numerically."""
    w, F4 = 3.0, 4.0
    out = instant(capsys, "--at", repr(t), "--set", f"F4={F4}")
    dT, dV, x4d = _energies(t, w)
    assert out["rates"]["x4"] == pytest.approx(x4d, abs=1e-8)
    assert out["driving"]["theta2"] == pytest.approx((dT + dV - F4 * x4d) / w, rel=1e-7)
    assert out["coordinates"]["theta2"] == pytest.approx(math.pi / 4 + w * t)


def test_inverse_equals_simulate_at_the_same_instant(capsys, tmp_path):
    """The driving torque and the reactions that `inverse --at t` gives equal the `simulate --reactions`
    columns at t (the same state, the same equations)."""
    csv_path = tmp_path / "run.csv"
    code, _, err = run(capsys, "simulate", CRANK, "--t-end", "1", "--dt", "0.25", "--reactions", "-o", str(csv_path),
                       "--rtol", "1e-12", "--atol", "1e-14")
    assert code == 0, err
    rows = [line.split(",") for line in csv_path.read_text().splitlines()]
    row = dict(zip(rows[0], map(float, rows[-1])))
    out = instant(capsys, "--at", "1")
    assert out["driving"]["theta2"] == pytest.approx(row["driving(theta2)"], rel=1e-8)
    assert out["reactions"]["rod"]["Fy"] == pytest.approx(row["reaction(rod).Fy"], rel=1e-8)


def test_bad_instant_options_are_one_line(capsys):
    code, out, err = run(capsys, "inverse", CRANK, "--at", "nan")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--at" in err


def test_an_instant_too_far_for_the_assembly_steps_is_refused(capsys):
    """At t = 1e6 s the crank (3 rad/s) has turned 3e6 rad; the assembly path was capped at 100000 steps of ~30
    rad and sampled the drive every 500 s (each sample whole turns apart: it looked still), so the rod flipped to
    the mirrored branch: x4 and the torque of another configuration, exit 0. Now refused; an instant the steps
    can reach is still the closed form's (above)."""
    code, out, err = run(capsys, "inverse", CRANK, "--at", "1e6")
    assert code == 1 and "assembly steps" in err and len(err.strip().splitlines()) == 1
    w, F4, t = 3.0, 4.0, 20.0
    reached = instant(capsys, "--at", repr(t), "--set", f"F4={F4}")
    dT, dV, x4d = _energies(t, w)
    assert reached["driving"]["theta2"] == pytest.approx((dT + dV - F4 * x4d) / w, rel=1e-6)


GEARS = """\
name: gears
description: two meshing gears, gear 1 driven, a load torque on gear 2 (the mesh as an expression)
parameters: {r1: 0.05, r2: 0.15, J1: 0.002, J2: 0.03, TL: 1.2}
coordinates:
  p1: {prescribed: 3*t + 2*t^2}
  p2: {initial: 0}
ground:
  points: {C2: [0.2, 0, 0]}
links:
  gear1:
    joint: {type: revolute, parent: ground, axis: z, coordinate: p1}
    inertia: {zz: J1}
  gear2:
    joint: {type: revolute, parent: ground, axis: z, coordinate: p2, origin: C2}
    inertia: {zz: J2}
constraints:
  - {type: holonomic, name: mesh, expression: r1*p1 + r2*p2}
forces:
  - {type: torque, on: gear2, axis: z, value: -TL}
"""


def test_a_constraint_without_a_point_is_noted_as_simulate_notes_it(capsys, tmp_path):
    """A gear mesh written as an expression has no point of application: its force is counted inside the joints
    of its coordinates, and `inverse` says so, as `simulate --reactions` does. The drive torque from the power
    balance (p2 = -k p1, k = r1/r2): J1 p1'' + J2 k^2 p1'' - TL k with p1'' = 4."""
    path = tmp_path / "gears.yaml"
    path.write_text(GEARS)
    code, out, err = run(capsys, "inverse", str(path), "-f", "json")
    assert code == 0, err
    data = json.loads(out)
    assert any("constraint mesh has no point of application" in n for n in data["notes"])
    ratio = 0.05 / 0.15
    assert math.isclose(data["driving"]["p1"], 0.002 * 4 + 0.03 * ratio**2 * 4 - 1.2 * ratio, rel_tol=1e-10)
