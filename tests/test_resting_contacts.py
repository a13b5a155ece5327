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


# ----------------------------------------------------------------------------- impacts on bodies that rest
STACK = """name: stack
parameters: {m1: 1.0, m2: 1.0, h: 1.0, e: 1, g: 9.81}
coordinates:
  y1: {initial: 0, rate: 0}
  y2: {initial: h, rate: 0}
links:
  A: {particle: true, joint: {type: prismatic, parent: ground, axis: y, coordinate: y1}, mass: m1}
  B: {particle: true, joint: {type: prismatic, parent: ground, axis: y, coordinate: y2}, mass: m2}
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
contacts:
  - {name: floor, gap: y1, restitution: e}
  - {name: ab, gap: y2 - y1, restitution: e}
"""


def _run_with_impacts(tmp_path, text: str, t_end: str):
    """simulate the model ``text`` to t_end with its rows and its impact table written: (result, rows, impacts)."""
    model = tmp_path / "model.yaml"
    model.write_text(text)
    rows, hits = tmp_path / "run.csv", tmp_path / "impacts.csv"
    result = CliRunner().invoke(app, ["simulate", str(model), "--t-end", t_end, "-o", str(rows), "--impacts",
                                      str(hits), "-f", "json"])
    assert result.exit_code == 0, result.output
    return result, rows, hits


def test_a_ball_struck_while_it_rests_on_the_floor_stays_on_it(tmp_path):
    """Ball B (e = 1) dropped from h onto ball A resting on the floor: A carries B's impulse into the floor, which
    returns it; B leaves at +sqrt(2 g h) and A stays at rest. Before, the resting contact was left out of the
    impact: A went on at -4.43 m/s and ended 3.3 m below the floor, exit 0."""
    result, rows, hits = _run_with_impacts(tmp_path, STACK, "1.2")
    g, h = 9.81, 1.0
    t1, v = math.sqrt(2 * h / g), math.sqrt(2 * g * h)
    table = list(csv.DictReader(hits.open()))
    assert all(float(r["t"]) == pytest.approx(t1, rel=1e-9) for r in table)
    assert float(table[-1]["after.der(y2)"]) == pytest.approx(v, rel=1e-9)
    assert float(table[-1]["after.der(y1)"]) == pytest.approx(0.0, abs=1e-9)
    run = list(csv.DictReader(rows.open()))
    assert min(float(r["y1"]) for r in run) > -1e-9
    t = float(run[-1]["t"])
    assert float(run[-1]["y2"]) == pytest.approx(v * (t - t1) - g * (t - t1) ** 2 / 2, rel=1e-7)


ROCKING = """name: rocking_block
parameters: {m: 2.0, b: 0.2, h: 0.6, g: 9.81, th0: -0.1}
coordinates:
  x: {initial: b - b*cos(th0) - h*sin(th0), rate: 0}
  y: {initial: h*cos(th0) - b*sin(th0), rate: 0}
  th: {initial: th0, rate: 0}
ground:
  points:
    O: [0, 0, 0]
links:
  block:
    joint: {type: planar, parent: ground, normal: z, coordinates: [x, y, th]}
    mass: m
    shape: {box: {size: [2*b, 2*h, 0.1]}}
    points:
      L: [-b, -h, 0]
      R: [b, -h, 0]
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
contacts:
  - {name: left, point_plane: {point: block.L, plane: {point: ground.O, normal: y}}, restitution: 0}
  - {name: right, point_plane: {point: block.R, plane: {point: ground.O, normal: y}}, restitution: 0}
"""


def _rocking_reference(count: int) -> list[tuple[float, float]]:
    """(time, impulse) of the first impacts of a block (half sizes b, h) rocking on a frictionless floor, e = 0: on
    corner s its centre stays at x_G, y_G = h cos th - s b sin th, one degree of freedom th; at th = 0 the other
    corner lands plastically and takes the impulse P = 2 s b w / (1/m + b^2/I), and w+ = w (h^2 - 2 b^2) / (h^2 + 4 b^2)
    (angular momentum about the landing corner, the centre's horizontal velocity kept)."""
    from scipy.integrate import solve_ivp

    m, b, h, g = 2.0, 0.2, 0.6, 9.81
    inertia = m * (4 * b * b + 4 * h * h) / 12

    def rhs(_t, z, s):
        th, w = z
        yp, ypp = -h * math.sin(th) - s * b * math.cos(th), -h * math.cos(th) + s * b * math.sin(th)
        return [w, -(m * yp * ypp * w * w + m * g * yp) / (m * yp * yp + inertia)]

    def level(_t, z, _s):
        return z[0]
    level.terminal = True
    th, w, s, t, out = -0.1, 0.0, 1, 0.0, []
    for k in range(count):
        level.direction = 1.0 if k == 0 else -math.copysign(1.0, w)  # back through th = 0, not the start itself
        sol = solve_ivp(rhs, (t, t + 10), [th, w], args=(s,), events=level, rtol=1e-12, atol=1e-14)
        t, (th, w) = sol.t[-1], sol.y[:, -1]
        out.append((t, abs(2 * s * b * w / (1 / m + b * b / inertia))))
        w, s, th = w * (h * h - 2 * b * b) / (4 * b * b + h * h), -s, 0.0
    return out


def test_a_rocking_block_releases_its_old_pivot_when_the_other_corner_lands(tmp_path):
    """Before, the old pivot corner stayed a constraint row after the other corner landed: the block tipped over,
    sank 0.52 m through the floor and gained 75 J, exit 0."""
    result, rows, hits = _run_with_impacts(tmp_path, ROCKING, "1")
    table = list(csv.DictReader(hits.open()))
    for row, (t, impulse) in zip(table, _rocking_reference(5)):
        assert float(row["t"]) == pytest.approx(t, rel=1e-7)
        assert float(row["impulse"]) == pytest.approx(impulse, rel=1e-6)
    summary = json.loads(result.output)["simulation summary"]
    assert summary["max relative energy balance error"] < 1e-8
    final = list(csv.DictReader(rows.open()))[-1]
    assert float(final["y"]) == pytest.approx(0.6, abs=1e-9) and abs(float(final["th"])) < 1e-9


def test_collide_says_when_a_touching_contact_approaches_after_the_impact(tmp_path):
    """`collide` resolves binary impacts: B striking A, which rests on the floor, leaves A at -4.43 m/s into it.
    That is the first impact of the chain simulate resolves, and the output now says the floor's follows."""
    model = tmp_path / "stack.yaml"
    model.write_text(STACK)
    v = math.sqrt(2 * 9.81)
    args = ["collide", str(model), "--set", "y2=0", "--set", f"der(y2)={-v!r}"]
    data = json.loads(CliRunner().invoke(app, args + ["-f", "json"]).output)
    assert data["further_impacts"] == ["floor"]
    assert data["rates_after"]["y1"] == pytest.approx(-v, rel=1e-12)
    text = CliRunner().invoke(app, args).output
    assert "after this impact floor touches and approaches" in " ".join(text.split())
    alone = json.loads(CliRunner().invoke(app, ["collide", str(model), "--set", "y1=0.5", "--set", "y2=0.5", "--set",
                                                f"der(y2)={-v!r}", "-f", "json"]).output)
    assert alone["further_impacts"] == []


def test_an_impact_at_the_start_is_in_the_energy_balance():
    """A ball started on the floor moving down (y = 0, y' = -3, e = 0.5) is struck at t = 0: the state before the
    impact is the first row, and the balance counted the impact's loss on it too (error 0.75 for a balance that
    closes to round-off)."""
    from pathlib import Path

    ball = Path(__file__).resolve().parents[1] / "systems" / "bouncing_ball.yaml"
    result = CliRunner().invoke(app, ["simulate", str(ball), "--set", "y=0", "--set", "der(y)=-3", "--t-end", "0.2",
                                      "-f", "json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)["simulation summary"]
    assert summary["energy lost in impacts"] == pytest.approx(0.5 * 0.1 * (3.0**2 - 1.5**2), rel=1e-12)  # m = 0.1
    assert summary["max relative energy balance error"] < 1e-12


def test_a_contact_simulate_does_not_watch_is_named_and_a_negative_restitution_refused(tmp_path):
    """simulate watches gap contacts only: the bullet of bullet_pendulum (a `between` contact) passed through the
    pendulum without a word. A constant restitution below 0 (which sends the bodies on into each other) was
    accepted."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "systems"
    result = CliRunner().invoke(app, ["simulate", str(root / "bullet_pendulum.yaml"), "--t-end", "0.01", "-f", "json"])
    assert result.exit_code == 0, result.output
    assert any("'bullet_hits_pendulum'" in n and "not watched in simulate" in n
               for n in json.loads(result.output)["notes"])
    bad = CliRunner().invoke(app, ["simulate", str(root / "bouncing_ball.yaml"), "--set", "e=-0.5"])
    assert bad.exit_code == 2 and "contacts[0].restitution: must not be negative" in bad.stderr


INCLINE_BALL = """\
name: incline_ball
parameters: {m: 0.2, g: 9.81, a: 0.3, e: 0.7, d: 1.0}
coordinates:
  x: {initial: -d*sin(a), rate: 0}
  y: {initial: d*cos(a), rate: 0}
links:
  sx:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}
  ball:
    particle: true
    joint: {type: prismatic, parent: sx, axis: y, coordinate: y}
    mass: m
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
contacts:
  - {name: slope, point_plane: {point: ball, plane: {point: ground, normal: [-sin(a), cos(a), 0]}}, restitution: e}
"""


def test_a_ball_bouncing_down_a_frictionless_incline_comes_to_rest_on_it_and_slides(tmp_path):
    """A particle dropped a distance d (normal to a frictionless incline of angle a) bounces with restitution e:
    the normal bounces end at t1 (1 + e)/(1 - e), t1 = sqrt(2 d / (g cos a)), and along the slope it accelerates at
    g sin a from rest all the while: x(t) = -(g sin a t^2 / 2) cos a once on the plane (closed form). After the
    last bounce the closing met at that instant had nothing to resolve and the loop restarted on it 100,000 times
    (2.5 min) before failing; now the ball rests on the plane and slides down it."""
    path = tmp_path / "incline_ball.yaml"
    path.write_text(INCLINE_BALL)
    result = CliRunner().invoke(app, ["simulate", str(path), "--t-end", "4", "--dt", "0.01", "-f", "json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)["simulation summary"]
    g, a, e, d = 9.81, 0.3, 0.7, 1.0
    t1 = math.sqrt(2 * d / (g * math.cos(a)))
    assert summary["last impact at t"] == pytest.approx(t1 * (1 + e) / (1 - e), rel=1e-6)
    assert summary["x(t_end)"] == pytest.approx(-(g * math.sin(a) * 16 / 2) * math.cos(a), rel=1e-7)
    assert summary["y(t_end)"] == pytest.approx(-(g * math.sin(a) * 16 / 2) * math.sin(a), rel=1e-7)


@pytest.mark.parametrize("method", ["BDF", "LSODA"])
def test_a_bouncing_ball_at_rest_stays_on_the_floor_with_the_implicit_methods(tmp_path, method):
    """The bundled ball (h = 1, e = 1/2) bounces until t1 (1 + e) / (1 - e) = 3 sqrt(2 h / g) = 1.354571 s and
    rests at y = 0 (closed form). With BDF and LSODA its last, grazing rebound (1.5e-6 m/s) was held as a resting
    contact that kept the speed: y rose at 1.5e-6 m/s forever (y(100) = 1.5e-4, exit 0)."""
    from pathlib import Path

    out = tmp_path / "ball.csv"
    path = Path(__file__).resolve().parents[1] / "systems" / "bouncing_ball.yaml"
    r = CliRunner().invoke(app, ["simulate", str(path), "--t-end", "5", "--dt", "0.5", "--method", method,
                                 "-o", str(out)])
    assert r.exit_code == 0, r.output
    with out.open() as fh:
        rows = [row for row in csv.DictReader(fh) if float(row["t"]) >= 1.5]
    assert rows and all(abs(float(row["y"])) < 1e-12 and abs(float(row["der(y)"])) < 1e-12 for row in rows)
