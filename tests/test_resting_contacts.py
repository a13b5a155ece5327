"""Resting contacts in simulate (impacts.py): a plastic impact where the contact force is zero at the instant of
the impact, and the friction a resting contact does not carry.

Cart 1 (m1 = 2, at 4 m/s) hits cart 2 (m2 = 3), which rests at the free length of a wall spring (k = 30); e = 0.
Written as a user would. Closed form: both leave the impact at m1 v/(m1 + m2) = 1.6; the spring then decelerates
them as one mass (w = sqrt(k/(m1 + m2))) and the contact force, m1 k x2/(m1 + m2), stays compressive until x2 is
back at 0, half a period later, when cart 1 leaves at -1.6 and cart 2 swings alone (w2 = sqrt(k/m2)). Before, the
contact force was exactly 0 at the impact (the spring at its free length), so the contact was judged 'not pressed',
watched only for opening, and cart 1 passed through cart 2 (the gap reached -6.4 m), exit 0.
"""
from __future__ import annotations

import csv
import json
import math

import pytest
from typer.testing import CliRunner

from mechsys.cli import app

CARTS = """name: carts_spring
parameters: {m1: 2.0, m2: 3.0, k: 30.0, e: 0.0, v: 4.0}
coordinates:
  x1: {initial: -0.5, rate: v}
  x2: {initial: 0, rate: 0}
links:
  cart1:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x1}
    mass: m1
  cart2:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x2}
    mass: m2
forces:
  - {type: spring, between: [cart2, ground], stiffness: k}
contacts:
  - {name: c12, gap: x2 - x1, restitution: e}
"""


def test_carts_stay_in_contact_while_pressed_and_part_at_the_spring_free_length(tmp_path):
    model = tmp_path / "carts.yaml"
    model.write_text(CARTS)
    rows = tmp_path / "run.csv"
    result = CliRunner().invoke(app, ["simulate", str(model), "--t-end", "4", "--dt", "0.001", "-o", str(rows),
                                      "-f", "json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)["simulation summary"]
    m1, m2, k, v, t_end = 2.0, 3.0, 30.0, 4.0, 4.0
    v1 = m1 * v / (m1 + m2)
    t_part = 0.5 / v + math.pi / math.sqrt(k / (m1 + m2))  # the impact at x1 = 0, then half a period together
    w2 = math.sqrt(k / m2)
    assert summary["der(x1)(t_end)"] == pytest.approx(-v1, rel=1e-7)
    assert summary["x1(t_end)"] == pytest.approx(-v1 * (t_end - t_part), rel=1e-6)
    assert summary["x2(t_end)"] == pytest.approx(-(v1 / w2) * math.sin(w2 * (t_end - t_part)), rel=1e-5)
    gaps = [float(r["x2"]) - float(r["x1"]) for r in csv.DictReader(rows.open())]
    assert min(gaps) > -1e-9  # never through each other
    assert not any("friction" in note for note in json.loads(result.output)["notes"])


INCLINE = """name: block_on_rough_incline
parameters: {m: 1.0, g: 9.81, alpha: 20*pi/180, mu: 0.5}
ground:
  points: {O: [0, 0, 0]}
coordinates:
  x: {initial: 1.0*cos(alpha), rate: 0}
  y: {initial: 1.0*sin(alpha), rate: 0}
links:
  sx:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}
  block:
    joint: {type: prismatic, parent: sx, axis: y, coordinate: y}
    particle: true
    mass: m
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
contacts:
  - {name: slope, point_line: {point: block, line: {point: ground.O, direction: [cos(alpha), sin(alpha), 0]}},
     restitution: 0, friction: mu}
"""


def test_a_rough_resting_contact_says_it_carries_no_friction(tmp_path):
    """A block at rest on a 20 degree incline with mu = 0.5 > tan(20 deg) would stick; simulate's resting contact
    carries no friction (docs/collide.md), so it slides at g sin(alpha): 3.355 m/s after 1 s. That is now said."""
    model = tmp_path / "incline.yaml"
    model.write_text(INCLINE)
    result = CliRunner().invoke(app, ["simulate", str(model), "--t-end", "1", "-f", "json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    speed = math.hypot(data["simulation summary"]["der(x)(t_end)"], data["simulation summary"]["der(y)(t_end)"])
    assert speed == pytest.approx(9.81 * math.sin(math.radians(20)), rel=1e-6)
    assert any(note.startswith("contact 'slope' (friction 0.5) came to rest: a resting contact carries no friction")
               for note in data["notes"])
