"""Impacts on a body whose motion is prescribed and which carries no mass (collide.py: held drives).

A ball (e = 0.8) bouncing on a massless table driven at A sin(w t), written as a user would. Released for the
impact (as a driven hammer is, M = MO), the table took any impulse without changing it: the impulse was 1e-17 and
the ball fell through the table, exit 0, with only a 'mass matrix badly conditioned (cond = inf)' warning. The
table now moves as prescribed through the impact: v+ = (1 + e) v_table - e v_ball, the vibrating-table model.
"""
from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from scipy.optimize import brentq
from typer.testing import CliRunner

from mechsys.cli import app

TABLE = """name: vib_table
parameters: {m: 0.1, A: 0.01, w: 2*pi*5, e: 0.8, g: 9.81, h: 0.05}
coordinates:
  s: {prescribed: A*sin(w*t)}
  y: {initial: h, rate: 0}
links:
  table:
    joint: {type: prismatic, parent: ground, axis: y, coordinate: s}
    mass: 0
  ball:
    particle: true
    joint: {type: prismatic, parent: ground, axis: y, coordinate: y}
    mass: m
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
contacts:
  - {name: hit, gap: y - s, restitution: e}
"""
A, W, E, G, H = 0.01, 2 * math.pi * 5, 0.8, 9.81, 0.05


def _reference(count: int) -> list[tuple[float, float]]:
    """(time, ball speed after) of the first impacts: free flight between them, each impact's time the first root
    of y(t) - A sin(w t) after the last (a fine scan, then Brent), v+ = (1 + e) A w cos(w t) - e v-."""
    t0, y0, v0, out = 0.0, H, 0.0, []
    for _ in range(count):
        def gap(t, t0=t0, y0=y0, v0=v0):
            return y0 + v0 * (t - t0) - G * (t - t0) ** 2 / 2 - A * math.sin(W * t)
        ts = np.linspace(t0 + 1e-9, t0 + 3, 300001)
        i = int(np.argmax(np.array([gap(x) for x in ts]) < 0))
        t = brentq(gap, ts[i - 1], ts[i], xtol=1e-15)
        v = (1 + E) * A * W * math.cos(W * t) - E * (v0 - G * (t - t0))
        out.append((t, v))
        t0, y0, v0 = t, A * math.sin(W * t), v
    return out


def test_collide_keeps_the_massless_table_on_its_prescribed_motion(tmp_path):
    model = tmp_path / "table.yaml"
    model.write_text(TABLE)
    result = CliRunner().invoke(app, ["collide", str(model), "--set", "y=0", "--set", "der(y)=-1", "-f", "json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["held"] == ["s"]
    assert data["rates_after"]["y"] == pytest.approx((1 + E) * A * W - E * (-1.0), rel=1e-12)
    assert data["rates_after"]["s"] == pytest.approx(A * W, rel=1e-12)


def test_a_ball_on_a_massless_vibrating_table_bounces_as_the_closed_form(tmp_path):
    model = tmp_path / "table.yaml"
    model.write_text(TABLE)
    hits = tmp_path / "impacts.csv"
    result = CliRunner().invoke(app, ["simulate", str(model), "--t-end", "0.35", "--impacts", str(hits), "-f", "json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    assert not any("badly conditioned" in note for note in out["notes"])
    assert out["simulation summary"]["max relative energy balance error"] < 1e-9
    table = list(csv.DictReader(hits.open()))
    reference = _reference(4)
    assert len(table) == 4 and reference[-1][0] < 0.35
    for row, (t, v) in zip(table, reference):
        assert float(row["t"]) == pytest.approx(t, rel=1e-9)
        assert float(row["after.der(y)"]) == pytest.approx(v, rel=1e-7)


def test_collide_notes_a_contact_whose_points_are_apart():
    """The bullet set 0.3 m below the pendulum's point C is resolved as striking C (the contact's points): the
    output says the points are apart. At the file's state they touch, and there is no note."""
    from pathlib import Path

    bullet = str(Path(__file__).resolve().parents[1] / "systems" / "bullet_pendulum.yaml")
    apart = json.loads(CliRunner().invoke(app, ["collide", bullet, "--set", "y2=-0.3", "-f", "json"]).output)
    assert apart["apart"] == {"bullet_hits_pendulum": "its points bullet and pendulum.C are 0.3 apart"}
    touching = json.loads(CliRunner().invoke(app, ["collide", bullet, "-f", "json"]).output)
    assert touching["apart"] == {}
    text = CliRunner().invoke(app, ["collide", bullet, "--set", "y2=-0.3"]).output
    assert "does not touch at this state" in " ".join(text.split())


def test_the_drive_carries_the_ball_while_it_rests_on_the_table(tmp_path):
    """Once the ball is captured it rides the table, and the massless table's drive carries its weight and
    acceleration: driving(s) = m (g + s''), s'' = -A w^2 sin(w t). The drive's force (and its work in the energy
    balance) was computed without the resting contact: 0, and the balance error read 0.4."""
    model = tmp_path / "table.yaml"
    model.write_text(TABLE)
    rows = tmp_path / "run.csv"
    result = CliRunner().invoke(app, ["simulate", str(model), "--t-end", "2", "-o", str(rows), "-f", "json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["simulation summary"]["max relative energy balance error"] < 1e-4
    riding = [r for r in csv.DictReader(rows.open()) if float(r["driving(s)"]) != 0.0]
    assert len(riding) > 100
    for r in riding:
        t = float(r["t"])
        assert float(r["y"]) == pytest.approx(A * math.sin(W * t), abs=1e-9)
        assert float(r["driving(s)"]) == pytest.approx(0.1 * (G - A * W**2 * math.sin(W * t)), rel=1e-6, abs=1e-9)
