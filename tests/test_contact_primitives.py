"""Named gap primitives (point_plane, sphere_plane, sphere_sphere, point_line) and joint impulses of gap contacts.

Each primitive must give the same impact as the hand-written `gap:` expression of the same geometry. The model
(tests/data/primitives_planar.yaml) has a disk `ball` (x, y, th; point P = (a, b) in its axes), a disk `ball2`
(x2, y2, th2), and a massless `paddle` hinged at the origin (psi). The hand-written gaps:
  point_plane, ball.P on the ground plane through Q = (0.1, -0.2) with normal n = (-sin alpha, cos alpha):
      gap = n . (P - Q),  P = (x + a cos th - b sin th, y + a sin th + b cos th)
  point_line, the same point and the line through Q along (cos alpha, sin alpha): n = z x d, the same gap
  sphere_plane, ball (radius r) on the paddle's x axis (normal = the paddle's y axis (-sin psi, cos psi)):
      gap = -sin(psi) x + cos(psi) y - r
  sphere_sphere, ball2 (r2) against ball (r): gap = sqrt((x2 - x)^2 + (y2 - y)^2) - r - r2
Joint impulses (gap contacts): a primitive knows where its impulse acts, so every joint is reported. For the
paddle (massless, hinged at O) the hinge must take the whole contact impulse: U_O = U n. With friction the
primitive also carries a tangential impulse, which a plain gap cannot (it is refused).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.impact.collide import resolve
from mechsys.analysis.motion.simulate import simulate
from mechsys.cli import app

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
BASE = (DATA / "primitives_planar.yaml").read_text()
P = "(x + a*cos(th) - b*sin(th))", "(y + a*sin(th) + b*cos(th))"
PAIRS = {
    "point_plane": ("point_plane: {point: ball.P, plane: {point: ground.Q, normal: [-sin(alpha), cos(alpha), 0]}}",
                    f"gap: '-sin(alpha)*({P[0]} - 0.1) + cos(alpha)*({P[1]} + 0.2)'"),
    "point_line": ("point_line: {point: ball.P, line: {point: ground.Q, direction: [cos(alpha), sin(alpha), 0]}}",
                   f"gap: '-sin(alpha)*({P[0]} - 0.1) + cos(alpha)*({P[1]} + 0.2)'"),
    "sphere_plane": ("sphere_plane: {center: ball, radius: r, plane: {point: paddle, normal: y}}",
                     "gap: '-sin(psi)*x + cos(psi)*y - r'"),
    "sphere_sphere": ("sphere_sphere: {centers: [ball2, ball], radii: [r2, r]}",
                      "gap: 'sqrt((x2 - x)^2 + (y2 - y)^2) - r - r2'"),
}


def model_with(tmp_path: Path, contact: str, name: str = "m", sets: dict | None = None, **kw):
    f = tmp_path / f"{name}.yaml"
    f.write_text(BASE + "contacts:\n  - {name: c, " + contact + ", restitution: e" + "".join(
        f", {k}: {v}" for k, v in kw.items()) + "}\n")
    return mechsys.load(f, sets, release_prescribed=True)


@pytest.mark.parametrize("kind", list(PAIRS))
@pytest.mark.parametrize("sets", [None, {"th": 1.3, "psi": -0.4, "der(x)": 0.7, "e": 0.2}])
def test_primitive_equals_hand_written_gap(tmp_path, kind, sets):
    prim, gap = PAIRS[kind]
    a = resolve(model_with(tmp_path, prim, "prim", sets))
    b = resolve(model_with(tmp_path, gap, "gap", sets))
    assert a.impulses[0] > 0
    np.testing.assert_allclose(a.rates_after, b.rates_after, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(a.impulses, b.impulses, rtol=1e-12)
    np.testing.assert_allclose(a.normal_velocity_before, b.normal_velocity_before, rtol=1e-12)
    assert a.energy_loss == pytest.approx(b.energy_loss, rel=1e-12)


def test_point_line_normal_is_left_of_direction(tmp_path):
    """Reversing the line direction flips the outside: the same point then separates (no impact)."""
    prim = PAIRS["point_line"][0].replace("[cos(alpha), sin(alpha), 0]", "[-cos(alpha), -sin(alpha), 0]")
    m = model_with(tmp_path, prim)
    vn = float(m.kin.contacts[0]["vn"].subs({**{s: v for s, v in zip(m.q, [0.5, 0.35, 0.4, 0.62, 0.09, -0.2, 0.25])},
                                             **{s: v for s, v in zip(m.u, [-0.4, -1.1, 2.0, -0.9, 0.6, 1.5, 0.8])},
                                             **{m.doc.parameters[k]: float(v) for k, v in m.parameters.items()}}))
    ref = resolve(model_with(tmp_path, PAIRS["point_line"][0], "ref"))
    assert vn == pytest.approx(-ref.normal_velocity_before[0], rel=1e-12)


def test_sphere_plane_joint_impulse_on_the_massless_paddle(tmp_path):
    r = resolve(model_with(tmp_path, PAIRS["sphere_plane"][0]))
    psi = 0.25
    n = np.array([-math.sin(psi), math.cos(psi), 0.0])
    np.testing.assert_allclose(r.joint_impulses["paddle"], r.impulses[0] * n, rtol=1e-12, atol=1e-15)
    # the free disks take no joint impulse
    np.testing.assert_allclose(r.joint_impulses["ball"], 0, atol=1e-12)
    # the plain gap knows the paddle is involved (psi appears) but not where: the paddle and ball joints are
    # left out; ball2 does not move with x, y or psi, so its joint is still reported (zero)
    g = resolve(model_with(tmp_path, PAIRS["sphere_plane"][1], "gap"))
    assert set(g.joint_impulses) == {"ball2"}


def test_sphere_plane_with_friction_at_any_spin_angle(tmp_path):
    """A rough sphere_plane contact (paddle at psi = 0, at rest): the closed form of a disk (I = m r^2/2) striking a
    plane: stick when |s| (1/m + r^2/I)^-1 <= mu U, i.e. (1/3)|s| <= mu (1 + e) v; the contact point is the lowest
    point at every th, which a body-fixed `between` point is not."""
    m, R, e = 0.8, 0.1, 0.7
    for th, mu in [(0.0, 0.2), (1.1, 0.2), (2.0, 2.0)]:
        sets = {"psi": 0, "der(psi)": 0, "th": th, "x": 0, "y": R}
        res = resolve(model_with(tmp_path, PAIRS["sphere_plane"][0], f"f{th}", sets, friction=mu))
        vx, v, w = -0.4, 1.1, 2.0
        s = vx + w * R  # sliding velocity of the lowest point
        U = m * (1 + e) * v
        if abs(s) / 3 <= mu * (1 + e) * v:
            F, mode = -m * s / 3, "stick"
        else:
            F, mode = -mu * U * math.copysign(1, s), "slip"
        after = dict(zip(res.coordinates, res.rates_after))
        assert res.modes == [mode]
        assert after["x"] == pytest.approx(vx + F / m, rel=1e-12)
        assert after["th"] == pytest.approx(w + R * F / (m * R**2 / 2), rel=1e-12)
        assert after["y"] == pytest.approx(e * v, rel=1e-12)
        # the massless paddle passes the whole contact impulse (normal + friction) to its hinge
        # (the paddle receives -(U n + F t) from the ball, so its hinge gives +(U n + F t), n = y, t = x)
        np.testing.assert_allclose(res.joint_impulses["paddle"], [F, U, 0], rtol=1e-12, atol=1e-14)


def test_cradle_of_sphere_sphere_primitives_simulates_like_the_gap_file(tmp_path):
    """systems/newton_cradle.yaml with its four gaps replaced by sphere_sphere primitives on the balls' centres:
    the same four impacts at the same instant with the same impulses, and ball 5 leaves with ball 1's speed.
    The primitive also gives the hinge impulses: ball k's string takes m (v_after - v_before) - (contact
    impulses on ball k); at the bottom of the swing the contact impulses are horizontal, so it is 0."""
    src = (ROOT / "systems" / "newton_cradle.yaml").read_text()
    head, tail = src.split("contacts:\n")
    prim = "contacts:\n" + "".join(
        f"  - {{name: c{k}{k + 1}, sphere_sphere: {{centers: [ball{k + 1}.com, ball{k}.com], radii: [r, r]}}, "
        "restitution: e}\n" for k in range(1, 5))
    f = tmp_path / "cradle.yaml"
    f.write_text(head + prim + tail[tail.index("# Expectations"):])
    a = simulate(mechsys.load(f), 0.6)
    b = simulate(mechsys.load(ROOT / "systems" / "newton_cradle.yaml"), 0.6)
    assert [i["contact"] for i in a.impacts] == [i["contact"] for i in b.impacts] == ["c12", "c23", "c34", "c45"]
    np.testing.assert_allclose([i["t"] for i in a.impacts], [i["t"] for i in b.impacts], rtol=1e-12)
    np.testing.assert_allclose([i["impulse"] for i in a.impacts], [i["impulse"] for i in b.impacts], rtol=1e-12)
    np.testing.assert_allclose(a.q[-1], b.q[-1], rtol=1e-9, atol=1e-12)
    for im in a.impacts:
        for vec in im["joint_impulses"].values():
            np.testing.assert_allclose(vec, 0, atol=1e-12)
    # the plain gaps do not locate their impulse: the joints of the two struck balls are left out
    for im in b.impacts:
        k = int(im["contact"][1])
        assert set(im["joint_impulses"]) == {f"ball{j}" for j in range(1, 6)} - {f"ball{k}", f"ball{k + 1}"}


def test_two_balls_head_on_sphere_sphere_simulation(tmp_path):
    """Two free balls on the x axis (masses m1, m2, radii r1, r2, e): one impact when x2 - x1 = r1 + r2, with
    v1' = ((m1 - e m2) v1 + (1 + e) m2 v2)/(m1 + m2) and v2' = ((m2 - e m1) v2 + (1 + e) m1 v1)/(m1 + m2)."""
    text = """name: two_balls
parameters: {m1: 1.0, m2: 3.0, r1: 0.1, r2: 0.2, e: 0.8}
coordinates:
  x1: {initial: 0, rate: 2}
  x2: {initial: 1, rate: -1}
links:
  b1: {particle: true, joint: {type: prismatic, parent: ground, axis: x, coordinate: x1}, mass: m1}
  b2: {particle: true, joint: {type: prismatic, parent: ground, axis: x, coordinate: x2}, mass: m2}
contacts:
  - {name: hit, sphere_sphere: {centers: [b2, b1], radii: [r2, r1]}, restitution: e}
"""
    f = tmp_path / "balls.yaml"
    f.write_text(text)
    r = simulate(mechsys.load(f), 1.0)
    m1, m2, e, v1, v2 = 1.0, 3.0, 0.8, 2.0, -1.0
    assert len(r.impacts) == 1
    assert r.impacts[0]["t"] == pytest.approx((1 - 0.3) / 3, rel=1e-9)
    after = r.impacts[0]["rates_after"]
    assert after["x1"] == pytest.approx(((m1 - e * m2) * v1 + (1 + e) * m2 * v2) / (m1 + m2), rel=1e-12)
    assert after["x2"] == pytest.approx(((m2 - e * m1) * v2 + (1 + e) * m1 * v1) / (m1 + m2), rel=1e-12)
    # prismatic joints along x take no impulse: the contact impulse is along x
    for vec in r.impacts[0]["joint_impulses"].values():
        np.testing.assert_allclose(vec, 0, atol=1e-12)


BAD = [
    ("sphere_sphere: {centers: [ball2.nope, ball], radii: [r2, r]}", "contacts[0].sphere_sphere.centers[0]",
     "unknown point 'nope' of 'ball2'", "ball2.nope"),
    ("point_plane: {point: bal.P, plane: {point: ground.Q, normal: y}}", "contacts[0].point_plane.point",
     "unknown link 'bal' (did you mean 'ball'?)", "bal.P"),
    ("point_plane: {point: ball.P, plane: {point: ground.Q, normal: y, frame: padle}}",
     "contacts[0].point_plane.plane.frame", "unknown link 'padle'", "padle"),
    ("point_line: {point: ball.P, line: {point: ground.Q, direction: z}}", "contacts[0].point_line.line.direction",
     "must not be along the frame's z axis", "z}"),
    ("sphere_plane: {center: ball, radius: -r, plane: {point: paddle, normal: y}}",
     "contacts[0].sphere_plane.radius", "must not be negative", "-r"),
    ("sphere_plane: {center: ball, radius: r, plane: {point: paddle, normal: y}}, normal: y",
     "contacts[0].normal", "'normal' belongs to 'between' contacts", "y, restitution"),
    ("point_plane: {point: ball2, plane: {point: ball2.com, normal: y}}", "contacts[0].point_plane",
     "the gap does not depend on any free coordinate", "{point: ball2,"),
]


@pytest.mark.parametrize("contact, path, message, anchor", BAD)
def test_bad_primitive_is_a_one_line_positioned_error(tmp_path, contact, path, message, anchor):
    f = tmp_path / "bad.yaml"
    f.write_text(BASE + "contacts:\n  - {name: c, " + contact + ", restitution: e}\n")
    r = CliRunner().invoke(app, ["collide", str(f)])
    assert r.exit_code == 2, r.output
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and "Traceback" not in r.output
    last = f.read_text().splitlines()
    line = len(last)
    col = last[-1].index(anchor) + 1
    assert lines[0] == f"{f}:{line}:{col}: {path}: " + lines[0].split(f"{path}: ", 1)[1]
    assert lines[0].startswith(f"{f}:{line}:{col}: {path}: ") and message in lines[0]


def test_two_kinds_at_once_is_refused(tmp_path):
    f = tmp_path / "bad.yaml"
    f.write_text(BASE + "contacts:\n  - {name: c, gap: y, sphere_sphere: {centers: [ball2, ball], radii: [r2, r]}}\n")
    r = CliRunner().invoke(app, ["collide", str(f)])
    assert r.exit_code == 2 and "give exactly one of" in r.output and "(got gap, sphere_sphere)" in r.output
