"""Joint reactions (`mechsys simulate --reactions`): closed forms, an independent Newton-Euler computation, closed
loops (textbook slider-crank statics), and joints that by construction transmit nothing along their free motion."""
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import mechsys
from mechsys.numeric.parameters import parameter_values
from mechsys.analysis.motion.reactions import COMPONENTS, column_names, reaction_columns, reaction_notes
from mechsys.analysis.motion.simulate import simulate
from mechsys.cli import app
from tests.helpers import double_pendulum_accelerations

ROOT = Path(__file__).resolve().parents[1]
G = 9.81


@pytest.fixture(autouse=True)
def _no_cache(monkeypatch):
    monkeypatch.setenv("MECHSYS_CACHE", "off")


def run(path, t_end, dt, sets=None):
    """Simulate as the CLI does (prescribed coordinates released) and return the model, result and wrenches:
    ``w[link]`` is an (n_times, 6) array of Fx, Fy, Fz, Mx, My, Mz."""
    model = mechsys.load(path, sets or {}, release_prescribed=True)
    result = simulate(model, t_end, dt)
    cols = reaction_columns(model, result, parameter_values(model))
    assert list(cols) == column_names(model)
    w = {j.link: np.column_stack([cols[f"reaction({j.link}).{c}"] for c in COMPONENTS]) for j in model.kin.joints}
    return model, result, w


def write(tmp_path, text, name="model.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


PENDULUM = """
name: pendulum
parameters: {{m: 1.5, L: 0.8, g: 9.81, tau: {tau}}}
coordinates:
  theta: {{initial: {theta0}, rate: {rate0}}}
links:
  bob:
    joint: {{type: revolute, parent: ground, axis: z, coordinate: theta}}
    mass: m
    center_of_mass: [0, -{com}, 0]
    {body}
forces:
  - {{type: gravity, acceleration: [0, -g, 0]}}
{extra}
"""


def radial_tangential(theta, F):
    """Components of the hinge force along the rod towards the pivot (-e_r) and along e_t, where
    e_r = (sin th, -cos th) points from the pivot to the body and e_t = (cos th, sin th) (theta increasing)."""
    e_r = np.column_stack([np.sin(theta), -np.cos(theta)])
    e_t = np.column_stack([np.cos(theta), np.sin(theta)])
    return -np.sum(F[:, :2] * e_r, axis=1), np.sum(F[:, :2] * e_t, axis=1)


def test_point_pendulum_rod_force_closed_form(tmp_path):
    """Particle m on a massless rod L, theta from the downward vertical, gravity -g y. r = L e_r,
    a = L th'' e_t - L th'^2 e_r and the hinge force is F = m a - m g. With g.e_r = g cos th, g.e_t = -g sin th:
    along the rod towards the pivot F = m (g cos th + L th'^2) (the rod tension), across it
    F.e_t = m (L th'' + g sin th) = 0 since th'' = -(g/L) sin th; no moment about the hinge."""
    path = write(tmp_path, PENDULUM.format(tau=0, theta0=1.2, rate0=0.5, com="L", body="particle: true", extra=""))
    model, result, w = run(path, 2.0, 0.02)
    th, dth = result.q[:, 0], result.u[:, 0]
    m, L = 1.5, 0.8
    along, across = radial_tangential(th, w["bob"])
    np.testing.assert_allclose(along, m * (G * np.cos(th) + L * dth**2), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(across, 0.0, atol=1e-9)
    np.testing.assert_allclose(w["bob"][:, 2:], 0.0, atol=1e-9)
    assert np.ptp(along) > 5  # the run swings: the check is not made at one trivial state


@pytest.mark.parametrize("actuator", ["generalized_force", "torque"])
def test_compound_pendulum_with_drive_closed_form(tmp_path, actuator):
    """Uniform rod m, L hinged at one end (G at L/2, I_O = m L^2/3) with a constant torque tau:
    th'' = (tau - m g (L/2) sin th)/(m L^2/3). Hinge force F = m a_G - m g with a_G = (L/2)(th'' e_t - th'^2 e_r):
    towards the pivot m (g cos th + (L/2) th'^2), along e_t m ((L/2) th'' + g sin th). The hinge moment is
    M_z = I_O th'' + m g (L/2) sin th - (external couples): tau when tau is a generalized force on theta (an actuator
    inside the joint), 0 when it is a `torque` load on the rod (an external couple on the subtree)."""
    extra = ("  - {type: generalized_force, coordinate: theta, value: tau}" if actuator == "generalized_force"
             else "  - {type: torque, on: bob, axis: z, value: tau}")
    body = "shape: {rod: {length: L, axis: y}}"
    path = write(tmp_path, PENDULUM.format(tau=2.0, theta0=0.4, rate0=-1.0, com="L/2", body=body, extra=extra))
    model, result, w = run(path, 1.5, 0.01)
    th, dth = result.q[:, 0], result.u[:, 0]
    m, L, tau = 1.5, 0.8, 2.0
    ddth = (tau - m * G * L / 2 * np.sin(th)) / (m * L**2 / 3)
    along, across = radial_tangential(th, w["bob"])
    np.testing.assert_allclose(along, m * (G * np.cos(th) + L / 2 * dth**2), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(across, m * (L / 2 * ddth + G * np.sin(th)), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(w["bob"][:, 5], tau if actuator == "generalized_force" else 0.0, atol=1e-9)
    np.testing.assert_allclose(w["bob"][:, 2:5], 0.0, atol=1e-9)


def test_hanging_pendulum_at_rest_carries_its_weight(tmp_path):
    """At rest in the hanging position nothing accelerates: the hinge holds the weight, F = (0, m g, 0), M = 0,
    for a point mass and for a rod alike."""
    for body, com in (("particle: true", "L"), ("shape: {rod: {length: L, axis: y}}", "L/2")):
        path = write(tmp_path, PENDULUM.format(tau=0, theta0=0, rate0=0, com=com, body=body, extra=""))
        _model, _result, w = run(path, 1.0, 0.1)
        np.testing.assert_allclose(w["bob"], np.tile([0, 1.5 * G, 0, 0, 0, 0], (len(w["bob"]), 1)), atol=1e-12)


def double_pendulum_newton_euler(q, u, m1=1.0, m2=0.8, l1=0.6, l2=0.5, g=G):
    """Independent planar Newton-Euler for systems/double_pendulum.yaml (th1 absolute, th2 relative, uniform rods
    hinged at O and at the tip B of rod 1). q'' from the file header's equations, then
    rod 2 at B: F2 = m2 (a_G2 - g), M2 = (G2 - B) x m2 (a_G2 - g) + I2 phi2'';
    rod 1 at O: F1 = m1 (a_G1 - g) + F2, M1 = G1 x m1 (a_G1 - g) + I1 phi1'' + G2 x m2 (a_G2 - g) + I2 phi2''."""
    th1, th2 = q
    w1, w2 = u
    a1, a2 = double_pendulum_accelerations(q, u, m1, m2, l1, l2, g)
    phi = [th1, th1 + th2]
    dphi = [w1, w1 + w2]
    ddphi = [a1, a1 + a2]

    def along(s, k):  # position and acceleration of the point at distance s along rod k from its hinge
        e, t = np.array([np.sin(phi[k]), -np.cos(phi[k])]), np.array([np.cos(phi[k]), np.sin(phi[k])])
        return s * e, s * ddphi[k] * t - s * dphi[k] ** 2 * e

    gv = np.array([0.0, -g])
    B, aB = along(l1, 0)
    G1, aG1 = along(l1 / 2, 0)
    r2, a2rel = along(l2 / 2, 1)
    G2, aG2 = B + r2, aB + a2rel
    I1, I2 = m1 * l1**2 / 12, m2 * l2**2 / 12
    cross = lambda r, f: r[0] * f[1] - r[1] * f[0]  # noqa: E731
    f1, f2 = m1 * (aG1 - gv), m2 * (aG2 - gv)
    M2 = cross(G2 - B, f2) + I2 * ddphi[1]
    M1 = cross(G1, f1) + I1 * ddphi[0] + cross(G2, f2) + I2 * ddphi[1]
    return np.array([*(f1 + f2), 0, 0, 0, M1]), np.array([*f2, 0, 0, 0, M2])


def test_double_pendulum_matches_independent_newton_euler():
    model, result, w = run(ROOT / "systems" / "double_pendulum.yaml", 2.0, 0.02, {"der(theta1)": 1.5})
    for i in range(len(result.t)):
        ref1, ref2 = double_pendulum_newton_euler(result.q[i], result.u[i])
        np.testing.assert_allclose(w["rod1"][i], ref1, atol=1e-9 * (1 + np.abs(ref1).max()))
        np.testing.assert_allclose(w["rod2"][i], ref2, atol=1e-9 * (1 + np.abs(ref2).max()))
    assert np.abs(w["rod1"][:, 0]).max() > 1  # horizontal hinge forces appear while it swings


SLIDER_CRANK = ROOT / "tests" / "data" / "slider_crank_driven.yaml"


@pytest.mark.parametrize("F4, M_book", [(0.0, 2.081015), (10.0, 3.912258)])
def test_slider_crank_statics_textbook(F4, M_book):
    """E003-2 (Shabana-style Fig. 5.20) held at theta2 = 45 deg. By hand, the rod (A-B, G at the middle) with the
    frictionless slider: the slider's x balance gives the rod end force R_Bx = F4 (ground cannot push along the
    guide); for F4 = 0 moments about A give R_By = m3 g/2, so the crank pin carries (0, -m3 g/2) and
      crank hinge:  F = (0, (m2 + m3/2) g), Mz = (m2 + m3) g l2O cos 45 = 2.081015 (the book's M2),
      slider guide: F = (0, (m4 + m3/2) g), M = 0,   rod pin at B: F = (0, m3 g/2), M = 0.
    With F4 = +10 N the crank torque is the book's 3.912258 N m and the crank hinge takes Fx = -F4."""
    m2, m3, m4 = 1.0, 2.0, 0.5
    model, result, w = run(SLIDER_CRANK, 0.2, 0.05, {"F4": F4})
    np.testing.assert_allclose(w["crank"][:, 5], M_book, atol=5e-7)
    np.testing.assert_allclose(w["crank"][:, 5], result.driving["theta2"], rtol=1e-10)
    np.testing.assert_allclose(w["crank"][:, 0], -F4, atol=1e-9)
    np.testing.assert_allclose(w["slider"][:, 0], 0.0, atol=1e-9)
    np.testing.assert_allclose(w["rod"][:, 0], F4, atol=1e-9)
    for link in ("crank", "slider", "rod"):
        np.testing.assert_allclose(w[link][:, 2:5], 0.0, atol=1e-9)
    np.testing.assert_allclose(w["rod"][:, 5], 0.0, atol=1e-9)
    total_y = w["crank"][:, 1] + w["slider"][:, 1]  # the loop force is internal to the whole mechanism
    np.testing.assert_allclose(total_y, (m2 + m3 + m4) * G, rtol=1e-10)
    if F4 == 0:
        np.testing.assert_allclose(w["crank"][:, 1], (m2 + m3 / 2) * G, rtol=1e-10)
        np.testing.assert_allclose(w["slider"][:, 1], (m4 + m3 / 2) * G, rtol=1e-10)
        np.testing.assert_allclose(w["rod"][:, 1], m3 * G / 2, rtol=1e-10)


def test_slider_crank_driven_dynamics_momentum_balance():
    """The crank turning at omega2 = 3 rad/s. The loop force (point_on_point) acts between rod.A and crank.A, so
    for the whole mechanism F_crank + F_slider = dP/dt - (m2 + m3 + m4) g, with the total momentum P computed here
    from closed-form positions (G2 = l2O e(th2), slider (x4, 0), G3 = (x4 - l3A cos th3, -l3A sin th3)) and dP/dt
    by central differences. The guide transmits no force along x, the rod pin no moment, and the crank hinge's
    moment is the driving torque."""
    l2O, l3A, m2, m3, m4 = 0.1, 0.25, 1.0, 2.0, 0.5
    model, result, w = run(SLIDER_CRANK, 0.6, 1e-3, {"omega2": 3})
    th2, th3, x4 = result.q.T
    w2, w3, v4 = result.u.T
    vG2 = l2O * w2[:, None] * np.column_stack([-np.sin(th2), np.cos(th2)])
    vG3 = np.column_stack([v4 + l3A * np.sin(th3) * w3, -l3A * np.cos(th3) * w3])
    P = m2 * vG2 + m3 * vG3 + m4 * np.column_stack([v4, 0 * v4])
    dP = np.gradient(P, result.t, axis=0, edge_order=2)
    total = w["crank"][:, :2] + w["slider"][:, :2]
    expected = dP - (m2 + m3 + m4) * np.array([0.0, -G])
    np.testing.assert_allclose(total[2:-2], expected[2:-2], atol=2e-5 * np.abs(expected).max())
    np.testing.assert_allclose(w["slider"][:, 0], 0.0, atol=1e-9)
    np.testing.assert_allclose(w["rod"][:, 5], 0.0, atol=1e-9)
    np.testing.assert_allclose(w["crank"][:, 5], result.driving["theta2"], rtol=1e-9, atol=1e-9)
    assert np.ptp(w["crank"][:, 0]) > 1  # the pin force really changes over the turn


def test_four_bar_hinges_transmit_no_moment_about_their_axes():
    """Free revolute joints (z axes) carry no Mz; the crank torque M2 is an external couple on the crank, so the
    crank's hinge carries none either. The loop is closed by point_on_point between coupler.B and rocker.B."""
    _model, _result, w = run(ROOT / "systems" / "four_bar.yaml", 1.0, 0.01, {"M2": 1.5})
    for link in ("crank", "coupler", "rocker"):
        np.testing.assert_allclose(w[link][:, 5], 0.0, atol=1e-9)
    assert np.abs(w["coupler"][:, :2]).max() > 1


SPRING_SLIDER = """
name: spring_slider
parameters: {m: 2.0, g: 9.81, k: 40.0, l0: 0.5, h: 0.8, c: 1.5}
coordinates:
  x: {initial: 0.9, rate: 0.3}
ground:
  points:
    A: [0, h, 0]
links:
  block:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}
    mass: m
    particle: true
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
  - {type: spring, between: [block, ground.A], stiffness: k, free_length: l0}
  - {type: damper, between: [block, ground.A], coefficient: c}
"""


def test_spring_and_damper_on_a_guided_block(tmp_path):
    """Block m on a horizontal frictionless guide at (x, 0), spring (k, l0) and damper c to A = (0, h):
    d = (x, -h), l = |d|, l' = x x'/l; the element pulls the block with F_s = -(k (l - l0) + c l') d/l. Newton:
    the guide force is F = m a - m g - F_s with a = (x'', 0): F_x = 0 (the equation of motion) and
    F_y = m g - (k (l - l0) + c l') h / l; the forces pass through the block, so M = 0."""
    m, k, l0, h, c = 2.0, 40.0, 0.5, 0.8, 1.5
    _model, result, w = run(write(tmp_path, SPRING_SLIDER), 2.0, 0.01)
    x, v = result.q[:, 0], result.u[:, 0]
    length = np.hypot(x, h)
    np.testing.assert_allclose(w["block"][:, 0], 0.0, atol=1e-9)
    np.testing.assert_allclose(w["block"][:, 1], m * G - (k * (length - l0) + c * x * v / length) * h / length,
                               rtol=1e-10)
    np.testing.assert_allclose(w["block"][:, 2:], 0.0, atol=1e-9)
    assert np.ptp(w["block"][:, 1]) > 1


BEAD_ON_ARM = """
name: bead_on_arm
parameters: {m: 0.5, M: 2.0, L: 1.0, g: 9.81}
coordinates:
  phi: {initial: 0.3, rate: 1.0}
  x: {initial: 0.4*cos(0.3), rate: 0}
  y: {initial: 0.4*sin(0.3), rate: 0}
links:
  arm:
    joint: {type: revolute, parent: ground, axis: z, coordinate: phi}
    mass: M
    center_of_mass: [L/2, 0, 0]
    shape: {rod: {length: L, axis: x}}
  carriage:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}
  bead:
    joint: {type: prismatic, parent: carriage, axis: y, coordinate: y}
    mass: m
    particle: true
constraints:
  - {type: point_on_line, name: slot, point: bead, through: arm, direction: x, frame: arm}
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
"""


def test_bead_in_a_turning_slot_point_on_line(tmp_path):
    """A bead carried by two massless prismatic joints (x on ground, y on the carriage) and held in a slot along the
    turning arm's x axis (point_on_line with the arm as frame). All the bead's support comes from the slot, so the
    carriage joint transmits no Fx, the bead joint no Fy; the slot force also loads the arm through the couple of
    its turning normal, and the free hinge still carries no Mz only if that couple is attributed correctly."""
    _model, _result, w = run(write(tmp_path, BEAD_ON_ARM), 1.5, 0.01)
    np.testing.assert_allclose(w["carriage"][:, 0], 0.0, atol=1e-9)
    np.testing.assert_allclose(w["bead"][:, 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(w["arm"][:, 5], 0.0, atol=1e-9)
    assert np.abs(w["arm"][:, :2]).max() > 1


def test_rolling_disk_needs_only_a_contact_force():
    """systems/rolling_disk.yaml: a planar joint (x, y, yaw) at the contact C, lean about the heading x axis, spin
    about the lean frame's y axis, and the rolling rows (ground x, y) at C. The real disk is held by one force at C,
    so the planar joint carries only the normal force Fz (no Fx, Fy, no moment about C), and the lean and spin
    hinges carry no moment about their axes, (cos yaw, sin yaw, 0) and Rz(yaw) (0, cos lean, sin lean)."""
    model, result, w = run(ROOT / "systems" / "rolling_disk.yaml", 2.0, 0.02)
    q = dict(zip(model.coordinates, result.q.T))
    yaw, lean = q["yaw"], q["lean"]
    heading = w["heading"]
    np.testing.assert_allclose(heading[:, [0, 1, 3, 4, 5]], 0.0, atol=1e-9)
    assert np.all(heading[:, 2] > 0)
    lean_axis = np.column_stack([np.cos(yaw), np.sin(yaw), 0 * yaw])
    spin_axis = np.column_stack([-np.sin(yaw) * np.cos(lean), np.cos(yaw) * np.cos(lean), np.sin(lean)])
    np.testing.assert_allclose(np.sum(w["lean_link"][:, 3:] * lean_axis, axis=1), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.sum(w["disk"][:, 3:] * spin_axis, axis=1), 0.0, atol=1e-9)
    assert np.abs(w["disk"][:, 3:]).max() > 0.1


def test_gyroscopic_indicator_joint_torques():
    """systems/indicator.yaml (Krodkiewski ch. 7): platform driven about z (psi), housing hinged about the platform's
    x axis (beta) with the potential MG (1 - cos beta) and a damper c, rotor spun about the housing z axis (gamma).
    Loads given only in coordinates act inside their joints, so the housing hinge's moment about its axis
    (cos psi, sin psi, 0) is -MG sin beta - c beta'; the platform's Mz and the rotor's moment about
    (sin psi sin beta, -cos psi sin beta, cos beta) are the driving torques of psi and gamma."""
    model, result, w = run(ROOT / "systems" / "indicator.yaml", 0.5, 0.005)
    q = dict(zip(model.coordinates, result.q.T))
    u = dict(zip(model.coordinates, result.u.T))
    psi, beta = q["psi"], q["beta"]
    x_p = np.column_stack([np.cos(psi), np.sin(psi), 0 * psi])
    z_h = np.column_stack([np.sin(psi) * np.sin(beta), -np.cos(psi) * np.sin(beta), np.cos(beta)])
    np.testing.assert_allclose(np.sum(w["housing"][:, 3:] * x_p, axis=1), -5 * np.sin(beta) - 0.2 * u["beta"],
                               atol=1e-9)
    np.testing.assert_allclose(w["platform"][:, 5], result.driving["psi"], atol=1e-9)
    np.testing.assert_allclose(np.sum(w["rotor"][:, 3:] * z_h, axis=1), result.driving["gamma"], atol=1e-9)
    np.testing.assert_allclose(w["housing"][:, :3], 0.0, atol=1e-12)  # massless: inertia only
    assert np.abs(w["housing"][:, 3:]).max() > 1  # the gyroscopic moment loads the hinge
    assert any("potential" in n for n in reaction_notes(model, result))


def test_compiled_reactions_are_cached_on_disk(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    first = run(SLIDER_CRANK, 0.1, 0.05, {"omega2": 2})[2]
    entries = set((tmp_path / "cache").glob("*.json"))
    assert entries
    again = run(SLIDER_CRANK, 0.1, 0.05, {"omega2": 2})[2]  # a fresh model: the reaction code comes from disk
    assert set((tmp_path / "cache").glob("*.json")) == entries
    for link in first:
        np.testing.assert_array_equal(first[link], again[link])


def test_cli_reactions_columns_in_csv_and_json(tmp_path):
    runner = CliRunner()
    out_csv, out_json = tmp_path / "r.csv", tmp_path / "r.json"
    r = runner.invoke(app, ["simulate", str(SLIDER_CRANK), "--t-end", "0.3", "--dt", "0.05", "--set", "omega2=3",
                            "--reactions", "-o", str(out_csv), "-f", "markdown"])
    assert r.exit_code == 0, r.output
    lines = out_csv.read_text().splitlines()
    header = lines[0].split(",")
    expected = [f"reaction({link}).{c}" for link in ("crank", "slider", "rod") for c in COMPONENTS]
    assert header[-18:] == expected and "driving(theta2)" in header
    data = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]])
    np.testing.assert_allclose(data[:, header.index("reaction(crank).Mz")], data[:, header.index("driving(theta2)")],
                               rtol=1e-9)
    assert "joint reactions" in r.stdout and str(out_csv) in r.stdout
    r = runner.invoke(app, ["simulate", str(SLIDER_CRANK), "--t-end", "0.3", "--dt", "0.05", "--reactions",
                            "-o", str(out_json)])
    assert r.exit_code == 0, r.output
    assert json.loads(out_json.read_text())["columns"][-18:] == expected
    r = runner.invoke(app, ["simulate", str(SLIDER_CRANK), "--t-end", "0.3", "--dt", "0.05", "-o", str(out_csv)])
    assert r.exit_code == 0 and not any("reaction(" in c for c in out_csv.read_text().splitlines()[0].split(","))


def test_cli_reactions_bad_file_is_one_line_error(tmp_path):
    bad = write(tmp_path, "name: x\nlinks: {}\nparameters: {a: }\n")
    r = CliRunner().invoke(app, ["simulate", str(bad), "--reactions"])
    assert r.exit_code == 2 and "Traceback" not in r.output
