"""Results do not depend on the units a model is written in: the bundled models scaled to MEMS size (lengths x 1e-4,
masses x 1e-9, times kept, so g x 1e-4) and to a large machine (lengths x 1e3, masses x 1e6) give what dimensional
analysis and the closed forms say. Thresholds against 1 in the model's own units made a MEMS ball fall through its
floor, a MEMS bullet bounce off a pendulum as off a wall, and `inverse` report a MEMS four-bar at rest."""
from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from mechsys.cli import app
from tests import reference_nonholonomic as ref
from tests.helpers import SYSTEMS_DIR

SCALES = {"mems": (1e-4, 1e-9), "large": (1e3, 1e6)}


def _run(*args) -> dict:
    result = CliRunner().invoke(app, [*map(str, args), "-f", "json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def _sets(**values) -> list[str]:
    return [x for name, value in values.items() for x in ("--set", f"{name}={value!r}")]


def _four_bar(command: str, scale: str) -> tuple[dict, dict]:
    """`command` on systems/four_bar.yaml as bundled and with its bars, masses and g scaled (T kept)."""
    L, M = SCALES[scale]
    path = SYSTEMS_DIR / "four_bar.yaml"
    lengths = {k: v * L for k, v in {"l1": 0.4, "l2": 0.1, "l3": 0.35, "l4": 0.3}.items()}
    masses = {k: v * M for k, v in {"m2": 0.5, "m3": 1.2, "m4": 1.0}.items()}
    return _run(command, path), _run(command, path, *_sets(**lengths, **masses, g=9.81 * L))


@pytest.mark.parametrize("scale", SCALES)
def test_the_bullet_and_pendulum_impact_at_any_scale(scale):
    """The bullet (m2, v) strikes the pendulum (IO about the hinge) at rC with restitution e: omega = m2 v rC (1 + e)
    / (IO + m2 rC^2) = 5.351833 rad/s at every scale (T kept), the bullet leaves at rC omega - e v, and the hinge
    takes m1 rG omega - P with P = m2 (v - v2') (closed forms). At MEMS scale the pendulum turned at 3.6e-7 rad/s
    and the hinge impulse printed 0; at the large scale the bullet went through."""
    L, M = SCALES[scale]
    m1, IO, rG, m2, v, rC, e = 5.0 * M, 2.0 * M * L * L, 0.5 * L, 0.05 * M, 300 * L, 0.6 * L, 0.2
    data = _run("collide", SYSTEMS_DIR / "bullet_pendulum.yaml",
                *_sets(m1=m1, IO=IO, rG=rG, m2=m2, v=v, rC=rC, **{"der(x2)": v, "y2": -rC}))
    omega = m2 * v * rC * (1 + e) / (IO + m2 * rC ** 2)
    v2 = rC * omega - e * v
    P = m2 * (v - v2)
    assert omega == pytest.approx(5.351833498513, rel=1e-11)
    assert data["rates_after"]["phi"] == pytest.approx(omega, rel=1e-10)
    assert data["rates_after"]["x2"] == pytest.approx(v2, rel=1e-10)
    assert data["impulse"] == pytest.approx(P, rel=1e-10)
    assert data["joint_impulses"]["pendulum"][0] == pytest.approx(m1 * rG * omega - P, rel=1e-9)
    assert data["joint_impulses"]["bullet"] == [0.0, 0.0, 0.0]


def test_a_mems_ball_comes_to_rest_on_its_floor():
    """A ball dropped from h with restitution e stops bouncing at t1 (1 + e)/(1 - e), t1 = sqrt(2 h / g) (closed
    form, the same at every scale with T kept) and then rests on the floor. At 100 um and 1e-10 kg its weight on
    the floor (1e-13 N) was taken for 'not pressed' and it fell through: y(2) = -2e-4 m, still accelerating."""
    L, M = SCALES["mems"]
    data = _run("simulate", SYSTEMS_DIR / "bouncing_ball.yaml", "--t-end", "2", "--dt", "0.01",
                *_sets(m=0.1 * M, h=1.0 * L, g=9.81 * L, y=1.0 * L))["simulation summary"]
    t1 = math.sqrt(2 * 1.0 / 9.81)
    assert data["last impact at t"] == pytest.approx(t1 * 1.5 / 0.5, rel=1e-6)
    assert abs(data["y(t_end)"]) <= 1e-12 * L and abs(data["der(y)(t_end)"]) <= 1e-12 * L


@pytest.mark.parametrize("scale", SCALES)
def test_inverse_dynamics_of_the_four_bar_at_any_scale(scale):
    """The four-bar at rest released under gravity: the angular accelerations do not depend on the units (T kept),
    the loop's multipliers and the joints' reactions scale as M L (forces). At MEMS scale `inverse` reported
    q'' = 1e-27 (the constrained equations were solved by least squares in mixed units: M ~ 1e-17 beside A ~ 1e-4),
    and at the large scale -9.55 instead of -37.0."""
    L, M = SCALES[scale]
    metre, scaled = _four_bar("inverse", scale)
    assert metre["accelerations"]["theta2"] == pytest.approx(-36.997075487, rel=1e-9)
    for name, value in metre["accelerations"].items():
        assert scaled["accelerations"][name] == pytest.approx(value, rel=1e-9)
    for name, value in metre["multipliers"].items():
        assert scaled["multipliers"][name] == pytest.approx(value * M * L, rel=1e-9)
    assert scaled["reactions"]["crank"]["Fx"] == pytest.approx(metre["reactions"]["crank"]["Fx"] * M * L, rel=1e-9)


@pytest.mark.parametrize("scale", SCALES)
def test_the_four_bar_has_its_four_rests_at_any_scale(scale):
    """The four-bar's rests and their eigenvalues do not depend on the units (T kept). At MEMS scale (forces of
    1e-17 N m beside loop rows of 1e-5 m) two of the four were found and the equilibria were called 'not
    isolated': the deflated Newton stopped at its starts, and the continuum test saw no stiffness."""
    metre, scaled = _four_bar("equilibria", scale)
    assert len(metre["equilibria"]) == len(scaled["equilibria"]) == 4 and "not isolated" not in scaled["message"]
    for a, b in zip(metre["equilibria"], scaled["equilibria"]):
        assert b["coordinates"] == pytest.approx(a["coordinates"], abs=1e-9) and a["stability"] == b["stability"]
        assert sorted(abs(complex(*v)) for v in b["eigenvalues"]) == \
            pytest.approx(sorted(abs(complex(*v)) for v in a["eigenvalues"]), rel=1e-7)


def test_info_of_a_mems_rolling_disk_is_the_metre_one():
    """The rolling disk at MEMS scale: m = 2e-9 kg on its translations beside m r^2 = 2e-18 kg m^2 on its angles.
    The mass matrix is regular at every scale (a disk has mass and inertia in every coordinate), but `info`
    said 'the mass matrix is singular' at MEMS scale, its rank taken at 1e-9 of the largest entry across units."""
    L, M = SCALES["mems"]
    metre = _run("info", SYSTEMS_DIR / "rolling_disk.yaml")
    scaled = _run("info", SYSTEMS_DIR / "rolling_disk.yaml", *_sets(m=2.0 * M, r=0.3 * L, g=9.81 * L))
    assert scaled["notes"] == metre["notes"] == [] and scaled["massless_coordinates"] == []
    assert (scaled["dof"], scaled["constraint_rank"]) == (metre["dof"], metre["constraint_rank"])


@pytest.mark.parametrize("scale", SCALES)
def test_the_steady_turns_of_a_rolling_disk_at_any_scale(scale):
    """The rolling disk's steady turns at yaw rate 0.5 rad/s and spin 1/r (the file's) scaled with its speed: the
    leans solve the steady-turning condition (tests/reference_nonholonomic.py, a closed form), which depends on
    g/r only, so they and their eigenvalues are the metre disk's. At MEMS scale `equilibria` listed 50 'steady
    motions', one per start, its rows and multipliers (1e-18 kg m^2, 1e-13 N) judged against 1; at both scales the
    family's zero eigenvalue was left in ('undecided' where the metre disk is stable)."""
    L, M = SCALES[scale]
    path = SYSTEMS_DIR / "rolling_disk.yaml"
    metre = _run("equilibria", path)
    m, r, g = 2.0 * M, 0.3 * L, 9.81 * L
    scaled = _run("equilibria", path, *_sets(m=m, r=r, g=g), "--set", f"der(x)={L!r}",
                  "--set", f"der(spin)={1 / 0.3!r}")
    assert len(metre["equilibria"]) == len(scaled["equilibria"]) == 2
    for a, b in zip(metre["equilibria"], scaled["equilibria"]):
        lean = b["coordinates"]["lean"]
        residual = ref.steady_turning_residual(m, r, m * r * r / 2, m * r * r / 4, g, lean, 1 / 0.3, 0.5)
        assert abs(residual) < 1e-10 * m * r * r  # in units of m r^2 (1/s^2)
        assert lean == pytest.approx(a["coordinates"]["lean"], abs=1e-9)
        assert a["stability"] == b["stability"] == "stable"
        assert sorted(abs(complex(*v)) for v in b["eigenvalues"]) == \
            pytest.approx(sorted(abs(complex(*v)) for v in a["eigenvalues"]), rel=1e-7)
