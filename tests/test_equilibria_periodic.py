"""Angles that are not periodic in the rest equations (EquilibriumProblem._periodic_angles).

A hanging pendulum (m g l = 1) on a torsional spring (k = 1) under a constant torque tau: its rests satisfy
theta + sin(theta) = tau, one root for every tau (theta + sin theta increases), stable with omega^2 = k + m g l cos
theta. The revolute angle was wrapped to (-pi, pi]: at tau = 5 the rest theta = 5.617555 was 'no equilibrium found'
even with --search th=0:7, and a sweep's branch came out 2 pi below the root for tau above about 4.6, exit 0.
"""
from __future__ import annotations

import csv
import io
import json
import math

import pytest
from scipy.optimize import brentq
from typer.testing import CliRunner

from mechsys.cli import app

MODEL = """name: torsion_pendulum
parameters: {m: 1, l: 1, g: 1, k: 1, tau: 5}
coordinates:
  th: {initial: 0, rate: 0}
links:
  arm:
    joint: {type: revolute, parent: ground, axis: z, coordinate: th}
    mass: m
    center_of_mass: [0, -l, 0]
    particle: true
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
  - {type: torsional_spring, coordinate: th, stiffness: k}
  - {type: torque, on: arm, axis: z, value: tau}
"""
runner = CliRunner()


def _rest(tau: float) -> float:
    return brentq(lambda th: th + math.sin(th) - tau, tau - 1.5, tau + 1.5, xtol=1e-14)


def test_a_spring_loaded_angle_is_not_wrapped(tmp_path):
    path = tmp_path / "tpend.yaml"
    path.write_text(MODEL)
    for extra in ([], ["--search", "th=0:7"]):
        result = runner.invoke(app, ["equilibria", str(path), *extra, "-f", "json"])
        assert result.exit_code == 0, result.output
        (rest,) = json.loads(result.output)["equilibria"]
        theta = _rest(5.0)
        assert rest["coordinates"]["th"] == pytest.approx(theta, abs=1e-10)
        assert rest["stability"] == "stable"
        assert max(abs(im) for _, im in rest["eigenvalues"]) == pytest.approx(math.sqrt(1 + math.cos(theta)), rel=1e-9)


def test_its_sweep_follows_the_root(tmp_path):
    path = tmp_path / "tpend.yaml"
    path.write_text(MODEL)
    result = runner.invoke(app, ["equilibria", str(path), "--sweep", "tau=0:8:17", "-f", "csv"])
    assert result.exit_code == 0, result.output
    rows = [r for r in csv.DictReader(io.StringIO(result.output)) if r["th"]]
    assert {r["branch"] for r in rows} == {"1"} and float(rows[-1]["tau"]) == 8.0
    for r in rows:
        assert float(r["th"]) == pytest.approx(_rest(float(r["tau"])), abs=1e-8)


def test_problem_57_marked_angular_keeps_its_three_rests(tmp_path):
    """docs/equilibria.md §2.4: problem 57 with `angle: true` in a copy of the file. Its rest equation
    pi^2 q - q^3 = 0 is not 2 pi-periodic, so q stays a plain coordinate: q = -pi, 0, pi remain three rests (the
    docs said two, with -pi and pi one point)."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "systems" / "problem57.yaml").read_text()
    path = tmp_path / "p57.yaml"
    path.write_text(text.replace("q: {initial: 0.1, rate: 0}", "q: {initial: 0.1, rate: 0, angle: true}"))
    result = runner.invoke(app, ["equilibria", str(path), "-f", "json"])
    assert result.exit_code == 0, result.output
    rests = sorted(round(e["coordinates"]["q"], 9) for e in json.loads(result.output)["equilibria"])
    assert rests == [round(-math.pi, 9), 0.0, round(math.pi, 9)]
