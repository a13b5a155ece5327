"""The Chaplygin sleigh, a model written from the docs (tests/data/chaplygin_sleigh.yaml: a planar body with a
knife edge at its frame's origin, the centre of mass a ahead of it), against the closed form.

Body axes at the blade P, forward speed u of P, yaw rate w. The blade allows no lateral velocity, so
v_G = (u, a w) and a_G = (u' - a w^2, a w' + u w). With the blade's lateral force F:
    m (u' - a w^2) = 0,    m (a w' + u w) = F,    I_G w' = -a F.
So (I_G + m a^2) w' = -m a u w: about straight motion at u = v the yaw rate has the eigenvalue
    lambda = -m a v / (I_G + m a^2),
stable for a v > 0 (the centre of mass ahead of the blade), unstable for a v < 0; u' = a w^2 gives the zero
eigenvalue of the family along the speed. Every heading is a steady motion as well (the constraint is written in
ground axes, so the heading is not ignorable): the steady motions are a continuum and a sweep cannot follow
them as branches."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mechsys.cli import app

sys.path.insert(0, str(Path(__file__).parent))
from helpers import DATA_DIR  # noqa: E402

SLEIGH = DATA_DIR / "chaplygin_sleigh.yaml"
runner = CliRunner()
M, IZ = 3.0, 0.2


def closed_form(a: float, v: float) -> float:
    return -M * a * v / (IZ + M * a * a)


@pytest.mark.parametrize("a, v, verdict", [(0.4, 1.5, "undecided"), (-0.4, 1.5, "unstable"),
                                           (0.25, -2.0, "unstable")])
def test_the_yaw_eigenvalue_of_straight_motion_is_the_closed_form(a, v, verdict):
    result = runner.invoke(app, ["equilibria", str(SLEIGH), "--set", f"a={a}", "--set", f"v={v}", "-f", "json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    (e,) = out["equilibria"]
    values = sorted(complex(*x).real for x in e["eigenvalues"])
    assert all(abs(complex(*x).imag) < 1e-12 for x in e["eigenvalues"])
    # the yaw rate's eigenvalue, and the heading's zero (a continuum of steady motions)
    assert values == pytest.approx(sorted([closed_form(a, v), 0.0]), abs=1e-9)
    # a v > 0: the yaw rate decays, but the heading's zero eigenvalue leaves the verdict open (not "stable")
    assert e["stability"].startswith(verdict)
    assert "not isolated" in out["message"]


def test_a_sweep_does_not_continue_a_continuum_of_steady_motions():
    """The sweep over v followed the heading's continuum as branches with a singular Jacobian and reported 359
    branch points and folds, all noise. Roots that are not isolated are now not continued, with a note."""
    result = runner.invoke(app, ["equilibria", str(SLEIGH), "--sweep", "v=-2:2:41", "-f", "json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["bifurcations"] == []
    (note,) = [n for n in out["sweep_notes"] if "not isolated" in n]
    assert "v = -2, -1, 0, 1, 2 are not isolated (singular Jacobian: a continuum" in note and "not continued" in note


@pytest.mark.parametrize("a, v, verdict", [(0.4, 1.5, "asymptotically stable"), (-0.4, 1.5, "unstable")])
def test_holding_the_heading_decides_the_verdict(a, v, verdict):
    """--given psi: every shape coordinate given (it was refused: "nothing is left to solve for"), the dependent
    rate and the multiplier still solved; the heading's family is set apart like the speed's, which leaves the
    yaw eigenvalue alone and decides the verdict."""
    result = runner.invoke(app, ["equilibria", str(SLEIGH), "--given", "psi", "--set", f"a={a}", "--set", f"v={v}",
                                 "-f", "json"])
    assert result.exit_code == 0, result.output
    (e,) = json.loads(result.stdout)["equilibria"]
    assert [complex(*x) for x in e["eigenvalues"]] == [pytest.approx(closed_form(a, v), abs=1e-9)]
    assert e["stability"] == verdict and "along der(x), psi apart" in e["reason"]


def test_with_the_heading_held_the_sweep_finds_the_one_crossing_at_rest():
    """lambda = -m a v / (I_G + m a^2) changes sign at v = 0 and nowhere else: one zero_eigenvalue event there."""
    result = runner.invoke(app, ["equilibria", str(SLEIGH), "--given", "psi", "--sweep", "v=-2:2:41", "-f", "json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    (event,) = out["bifurcations"]
    assert event["kind"] == "zero_eigenvalue" and event["value"] == pytest.approx(0.0, abs=1e-9)
    assert out["sweep_notes"] == []
