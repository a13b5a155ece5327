"""Guards against silent wrong answers in simulate: constraints left behind, and a work budget that bounds wall time."""
import dataclasses
import inspect
import json
import math
import os
import subprocess
import sys
import time

import numpy as np
import pytest

import mechsys
from mechsys.analysis.motion.simulate import RESIDUAL_TOLERANCE, SimulationOptions, simulate
from mechsys.errors import AnalysisError
from tests.helpers import DATA_DIR, ROOT, SYSTEMS_DIR

OVERDRIVEN = DATA_DIR / "overdriven_slider_crank.yaml"


def _pin_speed_mismatch(a=0.2, b=0.5, w=2.0, th0=0.3, t=0.002) -> float:
    """Closed form of the velocity-level conflict of the two drives at time t (to first order in t): the slider
    moves at the crank's initial speed v0 while the crank's own slider speed changes at dv/dt = w^2 x''(theta)."""
    s, c = math.sin(th0), math.cos(th0)
    root = math.sqrt(b * b - a * a * s * s)
    # x(theta) = a cos + root: x'' = -a cos - a^2 (c^2 - s^2)/root - a^4 s^2 c^2 / root^3
    xpp = -a * c - a * a * (c * c - s * s) / root - a ** 4 * s * s * c * c / root ** 3
    return abs(w * w * xpp) * t


@pytest.mark.parametrize("method", ["auto", "DOP853", "Radau"])
def test_a_run_that_leaves_the_constraints_stops_with_the_residual(method):
    """Crank and slider of a slider-crank both prescribed, consistent only at t = 0: the projection cannot satisfy
    the loop closure and both drives; today's runs went on with a residual of 0.2 and exit 0. Now the run stops
    at the first output with the residual, the time, the tolerance and the reason."""
    with pytest.raises(AnalysisError) as err:
        simulate(mechsys.load(OVERDRIVEN), 2.0, method=method)
    text = str(err.value)
    assert "the constraint residual reached" in text and "at t = 0.002 s" in text
    assert "left the constraint manifold" in text and "rank deficient" in text
    reached = float(text.split("reached ")[1].split(" ")[0])
    tolerance = float(text.split("(tolerance ")[1].split(")")[0])
    assert tolerance == pytest.approx(RESIDUAL_TOLERANCE * (1 + 2.0 * 1), rel=0.5)  # 1 + max |q|, |q'| ~ 2
    # the drives' conflict in pin speed after one output interval, to first order (the residual is a pin-speed row
    # or a drive row, of the same size)
    assert 0.3 * _pin_speed_mismatch() < reached < 3 * _pin_speed_mismatch()


@pytest.mark.parametrize("method", ["native", "DOP853"])
def test_an_initial_state_that_cannot_be_assembled_is_an_error(tmp_path, method):
    """The slider held still while the crank turns: the drives conflict already at t = 0 (velocity level)."""
    path = tmp_path / "m.yaml"
    text = OVERDRIVEN.read_text()
    start = text.index(" - w*a*sin(th0)")
    path.write_text(text[:start] + "}" + text[text.index("\n", start):])
    with pytest.raises(AnalysisError, match=r"residual reached .* at t = 0 s .*cannot be assembled"):
        simulate(mechsys.load(path), 1.0, method=method)


def test_cli_reports_the_residual_in_one_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "mechsys", "simulate", str(OVERDRIVEN), "--t-end", "1",
                           "--method", "DOP853"], capture_output=True, text=True, cwd=ROOT,
                          env={**os.environ, "MECHSYS_CACHE": str(tmp_path)})
    assert proc.returncode == 1 and proc.stdout == ""
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert "constraint residual reached" in proc.stderr and "(tolerance " in proc.stderr


@pytest.mark.parametrize("name", ["four_bar", "slider_crank", "rolling_disk", "indicator"])
def test_healthy_closed_loops_are_not_stopped(name):
    r = simulate(mechsys.load(SYSTEMS_DIR / f"{name}.yaml"), 0.5)
    assert np.max(r.residual) < 1e-10


@pytest.mark.slow
@pytest.mark.parametrize("method", ["RK45", "LSODA"])
def test_a_chattering_law_spends_the_budget_in_seconds_on_scipy(method):
    """sign(der(x)) friction sticks at t = 0.041, where RK45 then chatters with steps at the rounding limit. With the
    default budget (2e7 RHS evaluations, hours of Python) it used to run on; now the pace check stops it after a
    window of evaluations that did not advance the time."""
    model = mechsys.load(DATA_DIR / "native_functions.yaml")
    start = time.perf_counter()
    with pytest.raises(AnalysisError, match=r"step budget \(--max-steps\) is spent"):
        simulate(model, 3.0, method=method)
    assert time.perf_counter() - start < 30.0


@pytest.mark.slow
def test_a_stiff_scene_on_an_explicit_method_stops_early():
    """The stiff chain (decay rates to 2.9e4 1/s) on RK45 over 1000 s needs ~6e7 evaluations (stability bound
    h ~ 3/2.9e4 s, 6 evaluations a step): more than the budget, so the run stops at the first pace check."""
    start = time.perf_counter()
    with pytest.raises(AnalysisError, match=r"step budget .* at that pace the remaining"):
        simulate(mechsys.load(DATA_DIR / "stiff_chain.yaml"), 1000.0, method="RK45")
    assert time.perf_counter() - start < 30.0


@pytest.mark.parametrize("method", ["DOP853", "Radau"])
def test_a_drive_into_a_locked_configuration_says_so(method):
    """The crank of a slider-crank with a rod shorter than the crank, driven at w = 1 rad/s from th0 = 0.3 rad,
    locks at a sin(theta2) = b: t* = asin(b/a) - th0 = 0.627295 s. The failure names the singular Jacobian."""
    t_lock = math.asin(0.16 / 0.2) - 0.3
    with pytest.raises(AnalysisError) as err:
        simulate(mechsys.load(DATA_DIR / "crank_past_its_limit.yaml"), 2.0, method=method)
    text = str(err.value)
    assert text.startswith("integration failed at t = ") and "dead-centre or locked configuration" in text
    assert abs(float(text.split("t = ")[1].split(":")[0]) - t_lock) < 1e-4


@pytest.mark.parametrize("method, advice", [("Radau", "follows period by period"), ("RK45", "a stiff scene")])
def test_the_spent_budget_names_the_cause_that_fits_the_method(method, advice):
    """Two unit masses on springs of k = 1e9 (about 5 kHz, undamped): Radau must follow every period with Python
    steps (0.1 s took two minutes at the default budget, fuzz seed 20261126093811). Its spent budget names fast
    undamped oscillations and the compiled loop, not 'try Radau'; an explicit method's names a stiff scene."""
    model = mechsys.load(DATA_DIR / "two_mass_chain.yaml", {"k": "1e9"})
    with pytest.raises(AnalysisError, match=r"step budget \(--max-steps\) is spent") as caught:
        simulate(model, 0.1, method=method, max_steps=300)
    assert advice in str(caught.value)
    assert ("try --method Radau" in str(caught.value)) == (method != "Radau")


def test_simulate_takes_the_options_objects_fields_by_name():
    """simulate() is integrate() with the fields of SimulationOptions by name: the same names and defaults, so the
    keyword entry point and the options object (what the CLI, the warm plans and the re-charted windows pass)
    cannot drift apart."""
    keywords = inspect.signature(simulate).parameters
    for f in dataclasses.fields(SimulationOptions):
        default = inspect.Parameter.empty if f.default is dataclasses.MISSING else f.default
        assert keywords[f.name].default == default, f.name


STIFF_DAMPED = """name: stiff
parameters: {m1: 1, m2: 1, k1: 1, k: 1e12, c: 1e7}
coordinates:
  x1: {initial: 1}
  x2: {initial: 1}
links:
  b1: {joint: {type: prismatic, parent: ground, axis: x, coordinate: x1}, mass: m1}
  b2: {joint: {type: prismatic, parent: ground, axis: x, coordinate: x2}, mass: m2}
forces:
  - {type: torsional_spring, coordinate: x1, stiffness: k1}
  - {type: potential, value: k*(x2 - x1)^2/2}
  - {type: dissipation, value: c*(der(x2) - der(x1))^2/2}
"""


def test_a_stiff_damped_pair_is_told_to_loosen_the_tolerances(tmp_path):
    """Two masses tied by k = 1e12 and c = 1e7 (overdamped: rates -2e7 and -1e5) on a soft spring k1 = 1. At the
    default --atol 1e-12 CVODE's steps shrink to 1e-9 s: the stiff force turns position round-off into rate errors
    above it. The message blamed 'fast undamped oscillations' and suggested the explicit native method. With
    looser tolerances the pair moves as one mass 2 on k1: x1(10) = cos(10/sqrt(2))."""
    from typer.testing import CliRunner

    from mechsys.cli import app

    path = tmp_path / "stiff.yaml"
    path.write_text(STIFF_DAMPED)
    failed = CliRunner().invoke(app, ["simulate", str(path)])
    assert failed.exit_code == 1
    message = " ".join(failed.stderr.split())
    assert "the fast motion here only decays" in message and "undamped" not in message
    ok = CliRunner().invoke(app, ["simulate", str(path), "--atol", "1e-9", "--rtol", "1e-8", "-f", "json"])
    assert ok.exit_code == 0, ok.output
    assert json.loads(ok.output)["simulation summary"]["x1(t_end)"] == pytest.approx(math.cos(10 / math.sqrt(2)),
                                                                                     abs=1e-5)


@pytest.mark.parametrize("options", [{"dt": 0.01}, {"dt": 0.5}, {"dt": 0.01, "method": "Radau"}, {}])
def test_a_free_parallelogram_whirled_through_its_flattened_position_stops_there(options):
    """A parallelogram four-bar (crank = rocker = 0.4, coupler = ground = 1, unit rods) whirled from theta2 = pi/2
    at 3 rad/s. On its branch theta4 = theta2 and (5/3) m a^2 theta2'' = -2 m g a cos(theta2) (integrated here);
    at theta2 = pi all four joints are collinear and the antiparallelogram branch crosses it. The index-1 equations
    went on along the other branch at a later crossing (theta2 at t = 1: 9.42, 3.14, 7.79 or -3.14 with the output
    interval and the method, where it is 7.933), exit 0. The run now stops at the first crossing, by any grid."""
    from scipy.integrate import solve_ivp

    a, g = 0.4, 9.81
    crossing = solve_ivp(lambda t, y: [y[1], -2 * g * a * math.cos(y[0]) / (5 / 3 * a * a)], (0, 1),
                         [math.pi / 2, 3.0], rtol=1e-12, atol=1e-12, events=lambda t, y: y[0] - math.pi).t_events[0][0]
    model = mechsys.load(DATA_DIR / "beyond" / "parallelogram_whirled.yaml")
    with pytest.raises(AnalysisError, match="passed a singular configuration of its closed loop near t = ") as err:
        simulate(model, t_end=1.0, **options)
    at = float(str(err.value).split("near t = ")[1].split(" s")[0])
    assert abs(at - crossing) <= max(options.get("dt", 0.01), 0.02) / 8  # within a sampled point of it


def test_a_driven_parallelogram_is_carried_through_its_flattened_position(tmp_path):
    """Driven (no degree of freedom: theta2 = 0.5 + 3 t), the crank carries the loop through theta2 = pi at
    t = 0.88 on its branch, theta4 = theta2 and theta3 = -theta2; it is not stopped."""
    text = (DATA_DIR / "beyond" / "parallelogram_whirled.yaml").read_text().replace(
        "theta2: {initial: pi/2, rate: w0}", "theta2: {prescribed: 0.5 + w0*t}").replace(
        "theta3: {initial: -pi/2, rate: -w0}", "theta3: {initial: -0.5, rate: -w0}").replace(
        "theta4: {initial: pi/2, rate: w0}", "theta4: {initial: 0.5, rate: w0}")
    path = tmp_path / "driven.yaml"
    path.write_text(text)
    r = simulate(mechsys.load(path), t_end=1.5, dt=0.01)
    names = r.coordinates
    theta2 = 0.5 + 3 * r.t
    assert np.allclose(r.q[:, names.index("theta4")], theta2, atol=1e-8)
    assert np.allclose(r.q[:, names.index("theta3")], -theta2, atol=1e-8)


_PENDULUM_UNDER = ("name: {name}\nparameters: {{m: 1, l: 0.8, g: 9.81, v: 2, t0: 0.5}}\ncoordinates:\n{coords}links:\n"
                   "{links}  bob:\n    joint: {{type: revolute, parent: {parent}, axis: z, coordinate: phi{origin}}}\n"
                   "    mass: m\n    particle: true\n    center_of_mass: [0, -l, 0]\nforces:\n"
                   "  - {{type: gravity, acceleration: [0, -g, 0]}}\n{extra}")


@pytest.mark.parametrize("kind", ["origin", "constraint"])
def test_a_velocity_jump_written_in_a_joint_origin_or_a_constraint_is_refused(tmp_path, kind):
    """A pendulum whose pivot moves as v*abs(t - t0), written in the joint's origin or as a holonomic constraint on
    a free cart. At t0 the pivot reverses from -2 to 2 m/s, which throws the pendulum to phi' = -2v/l = -5 rad/s;
    both runs kept phi = 0, exit 0 (only prescribed motions were checked). Before the jump the runs are fine."""
    if kind == "origin":
        text = _PENDULUM_UNDER.format(name="pivot", coords="  phi: {initial: 0}\n", links="", parent="ground",
                                      origin=', origin: ["v*abs(t - t0)", 0, 0]', extra="")
        match = (r"the position of 'bob' \(v\*Abs\(t - t0\)\) changes its velocity by a jump near t = 0.5 s "
                 r"\(from -2 to 2\)")
    else:
        text = _PENDULUM_UNDER.format(
            name="cart", coords="  x: {initial: 1, rate: -2}\n  phi: {initial: 0}\n", parent="cart", origin="",
            links="  cart:\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n    mass: 3\n",
            extra="constraints:\n  - {type: holonomic, name: drive_x, expression: \"x - v*abs(t - t0)\"}\n")
        match = r"the constraint 'drive_x' .* changes its velocity by a jump near t = 0.5 s \(from 2 to -2\)"
    path = tmp_path / "pivot.yaml"
    path.write_text(text)
    with pytest.raises(AnalysisError, match=match):
        simulate(mechsys.load(path), t_end=1.0)
    r = simulate(mechsys.load(path), t_end=0.4)
    assert np.max(np.abs(r.q[:, r.coordinates.index("phi")])) < 1e-9  # a pivot at constant velocity: no swing


def test_a_spin_up_whose_velocity_only_kinks_runs_and_matches_the_bead_equation(tmp_path):
    """A bead on a hoop spun up as psi = w*(min(max(t, 0), T)**2/(2T) + max(t - T, 0)): psi' = w*min(t, T)/T is
    continuous (a ramp blended into a constant rate, as the docs advise), only psi'' jumps: the jump check must let
    it run (its switching points t = 0 and t = T are kinks of the velocity, not jumps). Checked against the bead's
    own equation theta'' = sin(theta) (psi'^2 cos(theta) - g/R)."""
    from scipy.integrate import solve_ivp

    path = tmp_path / "hoop.yaml"
    path.write_text("name: hoop\nparameters: {m: 0.3, R: 0.5, g: 9.81, w: 6.0, T: 1.0}\ncoordinates:\n"
                    "  psi: {prescribed: \"w*(min(max(t, 0), T)**2/(2*T) + max(t - T, 0))\"}\n  theta: {initial: 0.5}\n"
                    "links:\n  hoop:\n    joint: {type: revolute, parent: ground, axis: y, coordinate: psi}\n"
                    "    mass: 2\n    shape: {disk: {radius: R, axis: z}}\n  arm:\n"
                    "    joint: {type: revolute, parent: hoop, axis: z, coordinate: theta}\n  bead:\n"
                    "    joint: {type: fixed, parent: arm, origin: [0, -R, 0]}\n    mass: m\n    particle: true\n"
                    "forces:\n  - {type: gravity, acceleration: [0, -g, 0]}\n")
    r = simulate(mechsys.load(path, release_prescribed=True), t_end=2.0)  # as `mechsys simulate` loads it

    def bead(t, y):
        rate = 6.0 * min(max(t, 0.0), 1.0)
        return [y[1], math.sin(y[0]) * (rate ** 2 * math.cos(y[0]) - 9.81 / 0.5)]

    ref = solve_ivp(bead, (0, 2), [0.5, 0.0], rtol=1e-12, atol=1e-12, max_step=0.01, dense_output=True)
    theta = r.q[:, r.coordinates.index("theta")]
    assert np.max(np.abs(theta - ref.sol(r.t)[0])) < 1e-8


def test_a_velocity_that_jumps_at_the_start_is_refused_with_both_values(tmp_path):
    """x = v*max(t, 0) from t = 0: as written the velocity at t = 0 is v/2 (Heaviside(0) = 1/2) and v just after,
    a jump the run would start with."""
    path = tmp_path / "cart.yaml"
    path.write_text(_PENDULUM_UNDER.format(
        name="cart", coords="  x: {prescribed: \"v*max(t, 0)\"}\n  phi: {initial: 0}\n", parent="cart", origin="",
        links="  cart:\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n", extra=""))
    with pytest.raises(AnalysisError, match=r"velocity by a jump at the start \(t = 0: 1 as written, 2 just after\)"):
        simulate(mechsys.load(path, release_prescribed=True), t_end=1.0)

def test_a_triangle_wave_written_without_a_switching_function_is_refused_at_its_first_corner(tmp_path):
    """A cart driven as the triangle wave x = A*asin(sin(w t)) (no abs, sign, min or max to find): at t = pi/(2w)
    its velocity reverses from A w = 0.6 to -0.6 m/s, an impulse that throws the pendulum to phi' = -1.2/l. The run
    kept phi = 1e-8 through every corner, exit 0 at rtol 1e-6 (at rtol 1e-10 it stopped on a step too small,
    naming nothing). The grid scan finds the corner; the run before it is fine (a cart at constant speed)."""
    path = tmp_path / "triangle.yaml"
    path.write_text(_PENDULUM_UNDER.format(
        name="cart", coords="  x: {prescribed: \"0.2*asin(sin(3*t))\"}\n  phi: {initial: 0}\n", parent="cart",
        origin="", links="  cart:\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n", extra=""))
    corner = math.pi / 6
    for rtol in (1e-6, 1e-10):
        # (one-sided values read 1e-6 s from the corner: closer, the velocity's 1 - sin^2 is rounding)
        with pytest.raises(AnalysisError, match=r"the prescribed motion of x \(asin\(sin\(3\*t\)\)/5\) changes its "
                                                r"velocity by a jump near t = 0.523599 s \(from 0.6000\d* to "
                                                r"-0.59999\d*\)"):
            simulate(mechsys.load(path, release_prescribed=True), t_end=1.0, rtol=rtol, atol=rtol)
    r = simulate(mechsys.load(path, release_prescribed=True), t_end=0.95 * corner)
    assert np.max(np.abs(r.q[:, r.coordinates.index("phi")])) < 1e-9


def test_a_triangle_wave_whose_period_is_the_grid_spacing_is_refused_at_its_first_corner(tmp_path):
    """A 50 Hz triangle wave 0.001*asin(sin(100 pi t)) over 80 s: its period is the scan grid's spacing (80/4000),
    every sample saw the same phase and the run went on, the pendulum unforced, exit 0 (audit). The grids over the
    first tenth, hundredth, ... of the run resolve it: refused at its first corner, t = 1/200 s."""
    path = tmp_path / "fast.yaml"
    path.write_text(_PENDULUM_UNDER.format(
        name="cart", coords="  x: {prescribed: \"0.001*asin(sin(100*pi*t))\"}\n  phi: {initial: 0}\n",
        parent="cart", origin="",
        links="  cart:\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n", extra=""))
    with pytest.raises(AnalysisError, match=r"changes its velocity by a jump near t = 0.005 s \(from 0.314159 to "
                                            r"-0.314159\)"):
        simulate(mechsys.load(path, release_prescribed=True), t_end=80.0)


def test_fast_smooth_or_steep_prescribed_motions_are_not_taken_for_jumps(tmp_path):
    """The grid scan looks closer where a function changes ten times more than beside: a fast smooth oscillation
    (over 100 s, aliased on the grid) and the docs' smoothed reversal sqrt((t - a)**2 + e**2), whose velocity turns
    over 1e-5 s (a jump on the grid, not closer), are no jumps."""
    from mechsys.analysis.motion.jumps import refuse_jumps
    from mechsys.numeric.parameters import parameter_values

    for motion, t_end in (("0.01*sqrt(1 + 0.5*sin(500*t))", 100.0), ("sqrt((t - 0.30011)**2 + 1e-10)", 1.0)):
        path = tmp_path / "smooth.yaml"
        path.write_text(_PENDULUM_UNDER.format(
            name="cart", coords=f"  x: {{prescribed: \"{motion}\"}}\n  phi: {{initial: 0}}\n", parent="cart",
            origin="", links="  cart:\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n",
            extra=""))
        model = mechsys.load(path, release_prescribed=True)
        refuse_jumps(model, parameter_values(model), np.zeros(len(model.q)), t_end)


def test_a_torque_on_a_massless_hub_that_the_constraints_let_turn_is_refused(tmp_path):
    """A massless hub with a 1 N m torque carries a wheel (I = 1) whose absolute angle a + b is locked: the hub may
    turn (the wheel counter-rotating relative to it), nothing has inertia along that motion, and a force drives it.
    The saddle-point system is regular, and the run 'stayed at rest' (0/0). Without the lock the same model is
    refused ('the mass matrix is singular')."""
    path = tmp_path / "hub.yaml"
    path.write_text("name: hub\ncoordinates:\n  a: {initial: 0.2}\n  b: {initial: 0.3}\nlinks:\n  hub:\n"
                    "    joint: {type: revolute, parent: ground, axis: z, coordinate: a}\n  wheel:\n"
                    "    joint: {type: revolute, parent: hub, axis: z, coordinate: b}\n    mass: 1\n"
                    "    inertia: {zz: 1}\nconstraints:\n  - {type: holonomic, name: lock, expression: a + b - 0.5}\n"
                    "forces:\n  - {type: torque, on: hub, axis: z, value: 1}\n")
    with pytest.raises(AnalysisError, match="a force drives one that carries no mass or inertia"):
        simulate(mechsys.load(path), t_end=1.0)


def test_a_prescribed_motion_whose_velocity_jumps_is_refused_where_the_run_meets_the_jump(tmp_path):
    """A pendulum on a cart prescribed as s = abs(t - 0.5): at t = 0.5 the cart's velocity jumps from -1 to 1 m/s,
    an impulse that throws the pendulum (to -3.6 rad/s by t = 0.6 with the jump smoothed over 1e-4 s). The run kept
    th = 0 and th' = 0 (sympy's DiracDelta evaluates to 0), exit 0. Before the jump the run is fine."""
    path = tmp_path / "cart.yaml"
    path.write_text("name: presc\nparameters: {m: 1, l: 0.5, g: 9.81}\ncoordinates:\n"
                    "  s: {prescribed: \"abs(t - 0.5)\"}\n  th: {initial: 0}\nlinks:\n  cart:\n"
                    "    joint: {type: prismatic, parent: ground, axis: x, coordinate: s}\n  rod:\n"
                    "    joint: {type: revolute, parent: cart, axis: z, coordinate: th}\n    mass: m\n"
                    "    center_of_mass: [0, -l, 0]\nforces:\n  - {type: gravity, acceleration: [0, -g, 0]}\n")
    with pytest.raises(AnalysisError, match=r"prescribed motion of s .* jump near t = 0.5 s \(from -1 to 1\)"):
        simulate(mechsys.load(path, release_prescribed=True), t_end=1.0)
    r = simulate(mechsys.load(path, release_prescribed=True), t_end=0.4)
    assert np.max(np.abs(r.q[:, r.coordinates.index("th")])) < 1e-12  # constant cart velocity: no swing
