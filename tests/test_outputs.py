"""`outputs:` (issue 14): built-in quantities as result columns, checked against closed forms written here."""
import csv
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

import reference_nonholonomic as ref
from mechsys.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[1]
FLIP = """name: flip
description: Dzhanibekov flip, a torque-free body spun about its intermediate axis (y)
parameters: {Ix: 1.0, Iy: 2.0, Iz: 3.0, w: 2.0, eps: 0.01}
coordinates:
  psi: {initial: 0, rate: eps}
  theta: {initial: 0, rate: 0}
  phi: {initial: 0, rate: w}
links:
  body:
    joint: {type: spherical, parent: ground, sequence: zxy, coordinates: [psi, theta, phi]}
    mass: 1
    inertia: {xx: Ix, yy: Iy, zz: Iz}
    points: {tip: [0, 1, 0]}
outputs:
  H: angular_momentum(body)
  H_norm: norm(angular_momentum(system))
  T2: 2*kinetic_energy(body)
  tip_y: position(body.tip).y
"""


def run(*args: str) -> int:
    """`mechsys ARGS` in this process (as a user runs it): the exit code."""
    saved, sys.argv = sys.argv, ["mechsys", *args]
    try:
        cli_main()
        return 0
    except SystemExit as exc:
        return int(exc.code or 0)
    finally:
        sys.argv = saved


def table(path: Path) -> dict[str, np.ndarray]:
    rows = list(csv.reader(path.open()))
    data = np.array(rows[1:], dtype=float)
    return {name: data[:, k] for k, name in enumerate(rows[0])}


def simulate(tmp_path: Path, text: str, *options: str) -> dict[str, np.ndarray]:
    model, out = tmp_path / "model.yaml", tmp_path / "out.csv"
    model.write_text(text)
    assert run("simulate", str(model), "-o", str(out), *options) == 0
    return table(out)


def test_a_dzhanibekov_flip_conserves_the_angular_momentum_vector_and_the_energy(tmp_path):
    """Torque-free: H (ground axes) and T are constant through the flip; at t = 0 the body axes are the ground
    axes, so H = (Ix w_x, Iy w_y, Iz w_z) = (0, Iy w, Iz eps) and 2T = Iy w^2 + Iz eps^2. The spin axis (body y)
    turns over: the tip at body (0, 1, 0) goes from y = 1 to near y = -1 and back."""
    c = simulate(tmp_path, FLIP, "--t-end", "20", "--rtol", "1e-12", "--atol", "1e-14")
    H0 = np.array([0.0, 2.0 * 2.0, 3.0 * 0.01])
    for k, axis in enumerate("xyz"):
        assert np.max(np.abs(c[f"H.{axis}"] - H0[k])) < 1e-10 * np.linalg.norm(H0)
    assert np.max(np.abs(c["H_norm"] - np.linalg.norm(H0))) < 1e-10 * np.linalg.norm(H0)
    assert np.max(np.abs(c["T2"] - (2.0 * 4 + 3.0 * 1e-4))) < 1e-10 * 8
    assert np.allclose(c["T2"], 2 * c["T"], rtol=1e-13, atol=0)
    assert c["tip_y"][0] == pytest.approx(1.0) and c["tip_y"].min() < -0.99


def test_the_generalized_momenta_of_a_heavy_top_are_conserved(tmp_path):
    """Symmetric heavy top in z-x-z angles about its fixed tip (transverse moment about the tip A = A0 + m l^2,
    axial C): p_phi = C (phi' + psi' cos theta), p_psi = A psi' sin^2 theta + p_phi cos theta; both constant while
    theta nutates."""
    text = (ROOT / "tests/data/beyond/top_zxz.yaml").read_text()
    text += "outputs:\n  p_psi: momentum_of(psi)\n  p_phi: momentum_of(phi)\n"
    c = simulate(tmp_path, text, "--t-end", "3", "--rtol", "1e-12", "--atol", "1e-14")
    m, l, A0, C = 1.0, 0.1, 0.004, 0.008
    A = A0 + m * l * l
    th, psd, phd = c["theta"], c["der(psi)"], c["der(phi)"]
    p_phi = C * (phd + psd * np.cos(th))
    p_psi = A * psd * np.sin(th) ** 2 + p_phi * np.cos(th)
    assert np.allclose(c["p_phi"], p_phi, rtol=1e-12, atol=0) and np.allclose(c["p_psi"], p_psi, rtol=1e-12, atol=0)
    assert np.ptp(th) > 0.01  # it does nutate
    for name in ("p_psi", "p_phi"):
        assert np.ptp(c[name]) < 1e-10 * abs(c[name][0])


def test_driven_slider_crank_accelerations_match_the_loop_closure(tmp_path):
    """Crank turned at constant omega2: from l2 sin th2 + l3 sin th3 = 0 (l2 = 2 l2O, l3 = 2 l3A),
    th3' = -l2 cos th2 th2' / (l3 cos th3) and th3'' = (l2 sin th2 th2'^2 + l3 sin th3 th3'^2) / (l3 cos th3);
    the crank pin A moves on the circle of radius l2 with centripetal acceleration l2 omega2^2."""
    text = (ROOT / "docs/examples/slider_crank_driven.yaml").read_text()
    text += ("outputs:\n  th3dd: der(der(theta3))\n  th2dd: der(der(theta2))\n  aA: norm(acceleration(crank.A))\n"
             "  vA: velocity(crank.A)\n")
    c = simulate(tmp_path, text, "--t-end", "2", "--rtol", "1e-12", "--atol", "1e-14")
    l2, l3, w = 0.2, 0.5, 3.0
    th2, th3 = c["theta2"], c["theta3"]
    th3d = -l2 * np.cos(th2) * w / (l3 * np.cos(th3))
    assert np.allclose(c["der(theta3)"], th3d, rtol=0, atol=1e-9)
    want = (l2 * np.sin(th2) * w**2 + l3 * np.sin(th3) * th3d**2) / (l3 * np.cos(th3))
    assert np.max(np.abs(c["th3dd"] - want)) < 1e-7
    assert np.max(np.abs(c["th2dd"])) < 1e-9
    assert np.allclose(c["aA"], l2 * w**2, rtol=1e-8)
    assert np.allclose(c["vA.x"], -l2 * w * np.sin(th2), atol=1e-9)
    assert np.allclose(c["vA.y"], l2 * w * np.cos(th2), atol=1e-9)


def test_a_rolling_disk_in_steady_turning_tracks_a_circle(tmp_path):
    """Thin disk at lean 0.3 and spin 1/r on a steady turn (yaw rate: a root of the steady-turning condition,
    tests/reference_nonholonomic.py): the contact point (the lean link's origin) runs on a circle of radius
    R = r phi' / |psi'| (its speed r phi', its heading turning at psi') and is back at the start after one
    period 2 pi / |psi'|."""
    m, r, g, lean = 2.0, 0.3, 9.81, 0.3
    spin = 1 / r
    yaw = ref.steady_turning_yaw_rates(m, r, m * r * r / 2, m * r * r / 4, g, lean, spin)[1]
    period = 2 * math.pi / abs(yaw)
    text = (ROOT / "systems/rolling_disk.yaml").read_text()
    text += "outputs:\n  contact: position(lean_link)\n"
    c = simulate(tmp_path, text, "--t-end", repr(period), "--rtol", "1e-12", "--atol", "1e-14",
                 "--set", f"lean={lean}", "--set", f"der(yaw)={yaw!r}", "--set", "der(x)=1")
    x, y = c["contact.x"], c["contact.y"]
    R = r * spin / abs(yaw)
    centre = np.array([0.0, R * math.copysign(1, yaw)])  # starting at the origin heading along +x
    assert np.allclose(np.hypot(x - centre[0], y - centre[1]), R, rtol=1e-8)
    assert abs(x[-1]) < 1e-8 and abs(y[-1]) < 1e-8
    assert np.allclose(c["lean"], lean, atol=1e-9)


@pytest.mark.parametrize("expression, message", [
    ("position(body.nose).x", "nose"),
    ("2*angular_momentum(body)", "angular_momentum() is a vector"),
    ("norm(kinetic_energy(body))", "kinetic_energy() is a scalar"),
    ("momentum_of(omega)", "momentum_of() takes a free coordinate"),
    ("position(body.tip).w", "components x, y, z"),
    ("velocity(body.tip, body)", "takes 1 argument"),
    ("der(der(chi))", "der(der()) takes a coordinate name"),
])
def test_a_bad_output_is_one_line_naming_file_line_and_key(tmp_path, capsys, expression, message):
    model = tmp_path / "bad.yaml"
    model.write_text(FLIP.replace("tip_y: position(body.tip).y", f"bad: {expression}"))
    assert run("info", str(model)) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert f"{model}:" in err and "outputs.bad" in err and message in err


def test_outputs_feed_check_expectations(tmp_path, capsys):
    """`expect:` reads final/max/min of an output: the flip's |H| at the end equals its initial value."""
    text = FLIP + """expect:
  - name: "|H| conserved"
    analysis: simulate
    options: {t_end: 5}
    output: final.H_norm
    value: 4.00011249841801
    tolerance: 1.0e-8
  - name: "the tip turns over"
    analysis: simulate
    options: {t_end: 20}
    output: min.tip_y
    max: -0.99
"""
    model = tmp_path / "flip.yaml"
    model.write_text(text)
    assert run("check", str(model), "-f", "json") == 0
    report = json.loads(capsys.readouterr().out)
    assert (report["passed"], report["failed"], report["errors"]) == (2, 0, 0), report


PIN_IN_TREE = """name: slider_crank_pin_in_tree
description: the driven slider-crank with the crank pin A as a joint (rod on crank) and the loop closed at the slider
parameters: {l2O: 0.1, l3A: 0.25, m2: 1.0, m3: 2.0, m4: 0.5, g: 9.81, M2: 0, F4: 4, omega2: 3}
coordinates:
  theta2: {prescribed: pi/4 + omega2*t}
  phi: {initial: -asin(l2O*sin(pi/4)/l3A) - pi/4, rate: 0}   # rod angle relative to the crank
  x4: {initial: 2*l2O*cos(pi/4) + 2*l3A*cos(asin(l2O*sin(pi/4)/l3A)), rate: 0}
links:
  crank:
    joint: {type: revolute, parent: ground, axis: z, coordinate: theta2}
    mass: m2
    center_of_mass: [l2O, 0, 0]
    shape: {rod: {length: 2*l2O, axis: x}}
  rod:
    joint: {type: revolute, parent: crank, axis: z, coordinate: phi, origin: [2*l2O, 0, 0]}
    mass: m3
    center_of_mass: [l3A, 0, 0]
    shape: {rod: {length: 2*l3A, axis: x}}
    points: {B: [2*l3A, 0, 0]}
  slider:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x4}
    mass: m4
constraints:
  - {type: point_on_point, name: gudgeon, points: [rod.B, slider]}
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
  - {type: torque, on: crank, axis: z, value: M2}
  - {type: force, at: slider, value: [F4, 0, 0]}
outputs:
  pin: reaction(rod)
"""


@pytest.mark.parametrize("t", ["0", "0.4"])
def test_the_loop_closure_pin_force_equals_the_joint_reaction_of_the_same_pin(tmp_path, capsys, t):
    """The crank pin A as a loop-closure constraint (docs/examples/slider_crank_driven.yaml: constraint_force of
    crank_pin, the force on the rod at A) and as a revolute joint of the rod on the crank (reaction(rod): what the
    crank transmits to the rod at A), the loop closed at the slider instead: the same force at the same instant."""
    loop = tmp_path / "loop.yaml"
    loop.write_text((ROOT / "docs/examples/slider_crank_driven.yaml").read_text().replace("F4: 0 ", "F4: 4 ")
                    + "outputs:\n  pin: constraint_force(crank_pin)\n  pin_x: multiplier(crank_pin.x)\n"
                    + "  pin_rod: constraint_force(crank_pin, rod)\n  th3: theta3\n")
    tree = tmp_path / "tree.yaml"
    tree.write_text(PIN_IN_TREE)
    got = {}
    for name, path in (("loop", loop), ("tree", tree)):
        assert run("inverse", str(path), "--at", t, "-f", "json") == 0
        got[name] = json.loads(capsys.readouterr().out)["outputs"]
    for axis, comp in (("x", "Fx"), ("y", "Fy")):
        assert got["loop"][f"pin.{axis}"] == pytest.approx(got["tree"][f"pin.{comp}"], rel=1e-8, abs=1e-9)
    assert got["loop"]["pin_x"] == got["loop"]["pin.x"]
    c, s_ = math.cos(got["loop"]["th3"]), math.sin(got["loop"]["th3"])  # the rod's axes: turned by theta3 about z
    fx, fy = got["loop"]["pin.x"], got["loop"]["pin.y"]
    assert got["loop"]["pin_rod.x"] == pytest.approx(c * fx + s_ * fy, rel=1e-12, abs=1e-12)
    assert got["loop"]["pin_rod.y"] == pytest.approx(-s_ * fx + c * fy, rel=1e-12, abs=1e-12)
    assert abs(got["tree"]["pin.Mz"]) < 1e-9  # a hinge carries no moment about its axis
    assert abs(got["loop"]["pin.y"]) > 1  # a real load, not a trivial agreement


@pytest.mark.parametrize("expression, message", [
    ("constraint_force(crank_pin.x)", "unknown constraint"),
    ("multiplier(crank_pin.z)", "takes a constraint row"),
    ("reaction(ground)", "takes a link with a joint"),
    ("2*reaction(rod)", "reaction(...).Fx"),
])
def test_bad_constraint_quantities_are_one_line(tmp_path, capsys, expression, message):
    model = tmp_path / "bad.yaml"
    model.write_text((ROOT / "docs/examples/slider_crank_driven.yaml").read_text() + f"outputs:\n  bad: {expression}\n")
    assert run("info", str(model)) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "outputs.bad" in err and message in err, err


def test_plot_draws_readable_panels_for_outputs_and_reactions(tmp_path, monkeypatch):
    """A result with outputs, a driving force and reactions: one panel per vector (a reaction's forces apart from
    its moments), the scalars together, at most MAX_EXTRA_PANELS of them (the rest named in the title)."""
    from mechsys.report import simulation as report

    names = ["t", "x", "der(x)", "T", "V", "E", "residual", "driving(th)", "H.x", "H.y", "H.z", "Hn",
             *[f"reaction(rod).{c}" for c in ("Fx", "Fy", "Fz", "Mx", "My", "Mz")], "p_phi"]
    groups = report.other_column_groups(names)
    assert groups == [("driving forces", ["driving(th)"]), ("H", ["H.x", "H.y", "H.z"]), ("outputs", ["Hn", "p_phi"]),
                      ("reaction(rod) (force)", ["reaction(rod).Fx", "reaction(rod).Fy", "reaction(rod).Fz"]),
                      ("reaction(rod) (moment)", ["reaction(rod).Mx", "reaction(rod).My", "reaction(rod).Mz"])]
    drawn = {}
    monkeypatch.setattr("mechsys.report.files.write_figure",
                        lambda path, draw, option="--plot": drawn.setdefault("fig", draw.__self__))
    text = (ROOT / "docs/examples/slider_crank_driven.yaml").read_text() + "outputs:\n  pin: constraint_force(crank_pin)\n"
    model = tmp_path / "sc.yaml"
    model.write_text(text)
    assert run("simulate", str(model), "--t-end", "0.5", "--reactions", "--plot", str(tmp_path / "p.png"),
               "-o", str(tmp_path / "sc.csv")) == 0
    titles = [ax.get_title() for ax in drawn.pop("fig").axes if ax.get_visible()]
    assert titles[4:] == ["driving forces", "pin"]  # the run's own columns (reactions go to the file only)
    assert run("plot", str(tmp_path / "sc.csv"), "-o", str(tmp_path / "q.png")) == 0  # the file: reactions too
    titles = [ax.get_title() for ax in drawn["fig"].axes if ax.get_visible()]
    assert titles[:2] == ["coordinates", "rates"] and "pin" in titles and "driving forces" in titles
    assert "reaction(crank) (force)" in titles and len(titles) == 4 + report.MAX_EXTRA_PANELS
    assert "more groups of columns are in the file" in drawn["fig"]._suptitle.get_text()


BEAD_ON_A_SLOPED_WIRE = """name: bead on a wire
parameters: {m: 0.5, g: 9.81, alpha: 0.4}
coordinates:
  x: {initial: 0}
  y: {initial: 0}
  z: {initial: 0}
links:
  bead:
    joint: {type: transform, parent: ground, steps: [{translate: [x, y, z]}]}
    mass: m
    particle: true
constraints:
  - {type: point_on_line, name: wire, point: bead, through: ground, direction: [cos(alpha), 0, sin(alpha)]}
  - {type: point_on_plane, name: floor, point: bead, through: ground, normal: y}
forces:
  - {type: gravity, acceleration: [0, 0, -g]}
outputs:
  l1: multiplier(wire.1)
  l2: multiplier(wire.2)
  lf: multiplier(floor.1)
"""


def test_the_numbered_rows_of_point_on_line_and_plane_can_be_named(tmp_path):
    """multiplier(wire.1) was a parse error ('.1' read as a number) although the error message suggested that
    very name. A bead sliding down a wire at alpha to the horizontal: the wire's normal force has magnitude
    m g cos(alpha) (here the wire's two rows and the redundant floor row share it; their least-squares
    multipliers' combined force is the physical one)."""
    data = simulate(tmp_path, BEAD_ON_A_SLOPED_WIRE, "--t-end", "1", "--dt", "0.5")
    m, g, alpha = 0.5, 9.81, 0.4
    assert np.all(np.isfinite(data["l1"])) and np.all(np.isfinite(data["l2"])) and np.all(np.isfinite(data["lf"]))
    total = np.hypot(np.hypot(data["l1"], data["l2"]), data["lf"])
    assert total == pytest.approx(np.full(3, m * g * math.cos(alpha)), rel=1e-9)


BALL_ON_AN_INCLINE = ROOT / "tests" / "data" / "beyond" / "ball_on_incline.yaml"


def test_rolling_rows_along_the_inclines_axes_give_the_friction_and_the_normal_force(tmp_path):
    """Rolling down an incline: a = 5/7 g sin(alpha), friction 2/7 m g sin(alpha) up the slope, normal force
    m g cos(alpha). With components [x, y] in ground axes the rows' force pointed along ground x, and the slide's
    reaction took the rest (normal 19.26 instead of 18.74): right in sum, not the physical split. `axes: incline`
    puts the rows along the incline's tangents."""
    data = simulate(tmp_path, BALL_ON_AN_INCLINE.read_text(encoding="utf-8"), "--t-end", "0.3", "--dt", "0.1")
    m, g, alpha = 2.0, 9.81, 0.3
    assert data["x"][-1] == pytest.approx(5 / 14 * g * math.sin(alpha) * 0.3**2, rel=1e-9)
    assert data["F.x"] == pytest.approx(np.full(4, -2 / 7 * m * g * math.sin(alpha)), rel=1e-9)
    assert np.max(np.abs(data["F.y"])) < 1e-12 and np.max(np.abs(data["F.z"])) < 1e-12
    assert data["N.Fz"] == pytest.approx(np.full(4, m * g * math.cos(alpha)), rel=1e-9)
    assert np.max(np.abs(data["N.Fx"])) < 1e-9
