"""Analyses never end in an internal error on valid input, and never answer silently wrong (issue 10).

- a parameter that is just another parameter (``m1: m2``, ``--set m1=m2``, ``dM: Mo``) works in every command and
  gives the values of the un-aliased model (closed forms from the files' header equations);
- a system on which no force acts at rest (the carriages) has every configuration as a steady motion: said so;
- a degenerate contact geometry (``--set r=0`` in Newton's cradle) is a clear AnalysisError naming the contact
  and the parameter;
- coordinates without mass or inertia: handled where the analysis can (static condensation, the pencil), and a
  clear verdict or AnalysisError naming them where the motion is not determined.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import mechsys
from mechsys.cli import app

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
DOUBLE = ROOT / "systems" / "double_pendulum.yaml"
CENTRIFUGE = ROOT / "systems" / "centrifuge.yaml"
CARRIAGES = ROOT / "systems" / "carriages.yaml"
CRADLE = ROOT / "systems" / "newton_cradle.yaml"

runner = CliRunner()


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("MECHSYS_DEBUG", raising=False)


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def ok_json(*args) -> dict:
    result = invoke(*args, "--format", "json")
    assert result.exit_code == 0, (result.stdout, result.stderr)
    return json.loads(result.stdout)


def analysis_error(*args) -> str:
    """Exit 1 with one clear line (an AnalysisError), not the catch-all internal error."""
    result = invoke(*args)
    err = result.stderr
    assert result.exit_code == 1, (result.exit_code, result.stdout, err)
    assert "internal error" not in err and "Traceback" not in err, err
    assert len(err.strip().splitlines()) == 1, err
    return err.strip()


# ----------------------------------------------------------------------------------------- closed forms
def double_pendulum_frequencies(m1, m2, l1, l2, g):
    """Header of systems/double_pendulum.yaml linearized about theta1 = theta2 = 0: det(K - w^2 M) = 0."""
    M = np.array([[m1 * l1**2 / 3 + m2 * (l1**2 + l2**2 / 3 + l1 * l2), m2 * (l2**2 / 3 + l1 * l2 / 2)],
                  [m2 * (l2**2 / 3 + l1 * l2 / 2), m2 * l2**2 / 3]])
    K = np.array([[(m1 / 2 + m2) * g * l1 + m2 * g * l2 / 2, m2 * g * l2 / 2],
                  [m2 * g * l2 / 2, m2 * g * l2 / 2]])
    a = np.linalg.det(M)
    b = M[0, 0] * K[1, 1] + M[1, 1] * K[0, 0] - 2 * M[0, 1] * K[0, 1]
    c = np.linalg.det(K)
    root = math.sqrt(b * b - 4 * a * c)
    return sorted([math.sqrt((b - root) / (2 * a)), math.sqrt((b + root) / (2 * a))])


def summary(data: dict) -> dict:
    return data["simulation summary"]


# ----------------------------------------------------------------------------------------- 1. aliases
def test_alias_by_set_modes_match_the_header_closed_form():
    data = ok_json("modes", DOUBLE, "--set", "m1=m2")
    freqs = sorted(m["frequency_rad_s"] for m in data["modes"])
    assert freqs == pytest.approx(double_pendulum_frequencies(0.8, 0.8, 0.6, 0.5, 9.81), rel=1e-9)


def test_alias_in_the_file_follows_its_source(tmp_path):
    path = tmp_path / "alias.yaml"
    path.write_text(DOUBLE.read_text().replace("  m1: 1.0 ", "  m1: m2 "), encoding="utf-8")
    assert "m1: m2 " in path.read_text()
    data = ok_json("modes", path, "--set", "m2=1.3")
    freqs = sorted(m["frequency_rad_s"] for m in data["modes"])
    assert freqs == pytest.approx(double_pendulum_frequencies(1.3, 1.3, 0.6, 0.5, 9.81), rel=1e-9)


def test_alias_equilibria_are_the_four_hanging_and_inverted_positions():
    data = ok_json("equilibria", DOUBLE, "--set", "m1=m2")
    found = sorted((round(abs(e["coordinates"]["theta1"]), 9), round(abs(e["coordinates"]["theta2"]), 9),
                    e["stability"]) for e in data["equilibria"])
    pi = round(math.pi, 9)
    assert [(a, b) for a, b, _ in found] == [(0.0, 0.0), (0.0, pi), (pi, 0.0), (pi, pi)]
    assert [s for _, _, s in found] == ["stable", "unstable", "unstable", "unstable"]


def test_alias_simulate_and_bench_equal_the_numeric_model():
    aliased = summary(ok_json("simulate", DOUBLE, "--t-end", "0.5", "--set", "m1=m2"))
    plain = summary(ok_json("simulate", DOUBLE, "--t-end", "0.5", "--set", "m1=0.8"))
    for key in ("theta1(t_end)", "theta2(t_end)", "der(theta1)(t_end)", "der(theta2)(t_end)"):
        assert aliased[key] == pytest.approx(plain[key], rel=1e-12, abs=1e-15), key
    assert abs(aliased["max relative energy drift"]) < 1e-8  # conservative system
    bench = ["bench", DOUBLE, "--t-end", "0.2", "--methods", "RK45", "--rtols", "1e-6"]
    rows_a = next(iter(ok_json(*bench, "--set", "m1=m2").values()))
    rows_p = next(iter(ok_json(*bench, "--set", "m1=0.8").values()))
    assert [r["final error"] for r in rows_a] == pytest.approx([r["final error"] for r in rows_p], rel=1e-9)


@pytest.mark.parametrize("command", ["derive", "info"])
def test_alias_symbolic_commands(command):
    assert invoke(command, DOUBLE, "--set", "m1=m2").exit_code == 0


def test_centrifuge_dM_equal_to_Mo_steady_speed_one_rad_per_second():
    """dM: Mo -> steady speed Mo/dM = 1 rad/s; the arm's angle solves m g l sin b = w^2 (m (a + l sin b) l cos b
    + (I2y - I2z) sin b cos b) (the effective potential V - T0 of the file's geometry, hand derived)."""
    data = ok_json("equilibria", CENTRIFUGE, "--set", "dM=Mo")
    assert data["equilibria"]
    m, g, l, a, I2y, I2z, w = 8, 9.81, 0.5, 0.3, 2.0, 0.2, 1.0
    for e in data["equilibria"]:
        assert e["rates"]["alpha"] == pytest.approx(1.0, rel=1e-12)
        b = e["coordinates"]["beta"]
        residual = m * g * l * math.sin(b) - w**2 * (m * (a + l * math.sin(b)) * l * math.cos(b)
                                                     + (I2y - I2z) * math.sin(b) * math.cos(b))
        assert abs(residual) < 1e-9
    assert any(e["stability"] == "asymptotically stable" for e in data["equilibria"])


def test_sweep_sensitivity_that_is_the_bare_swept_symbol(tmp_path):
    """d(m1)/d(m2) = m2 for m1: m2**2/2 (the derivative is the bare symbol m2): evaluated to its value 0.8."""
    from mechsys.analysis.equilibrium.bifurcation import parameter_sensitivity

    path = tmp_path / "square.yaml"
    path.write_text(DOUBLE.read_text().replace("  m1: 1.0 ", "  m1: m2**2/2 "), encoding="utf-8")
    model = mechsys.load(path)
    sens = parameter_sensitivity(model, "m2")
    names = [s.name for s in model.parameter_symbols]
    got = dict(zip(names, sens(np.array([model.parameters[n] for n in names]))))  # the parameter vector
    assert got == {"m1": pytest.approx(0.8, rel=1e-15), "m2": 1.0, "l1": 0.0, "l2": 0.0, "g": 0.0}


# ----------------------------------------------------------------------------------------- 2. no forces at rest
def test_carriages_every_configuration_is_a_steady_motion():
    data = ok_json("equilibria", CARRIAGES)
    assert len(data["equilibria"]) == 1
    e = data["equilibria"][0]
    assert e["coordinates"] == {}
    assert e["rates"] == {"x1": 2.0, "x2": 0.0, "x3": 0.0}  # v and two carriages at rest, as the file gives
    assert "every configuration is a steady motion" in data["message"]
    assert "not isolated" in data["message"]


def test_free_particles_at_rest_every_configuration_is_an_equilibrium():
    data = ok_json("equilibria", CARRIAGES, "--set", "v=0")
    assert data["equilibria"][0]["rates"] == {"x1": 0.0, "x2": 0.0, "x3": 0.0}
    assert "every configuration is an equilibrium" in data["message"]


def test_carriages_modes_are_three_rigid_body_modes():
    data = ok_json("modes", CARRIAGES)
    assert [m["rigid_body"] for m in data["modes"]] == [True, True, True]
    # mass-normalised: each shape is 1/sqrt(m) on its own carriage (m = 10000 kg)
    for k, mode in enumerate(data["modes"]):
        shape = [abs(v) for v in mode["shape"].values()]
        assert sorted(shape) == pytest.approx([0.0, 0.0, 0.01], abs=1e-12)


# ----------------------------------------------------------------------------------------- 3. degenerate contact
def test_collide_zero_radius_names_the_contact_and_the_parameter():
    err = analysis_error("collide", CRADLE, "--set", "r=0")
    assert "contact 'c23'" in err  # balls 2 and 3 hang at the same point when r = 0
    assert "r = 0" in err


@pytest.mark.parametrize("command", ["simulate", "bench"])
def test_simulate_zero_radius_names_the_contact_and_the_parameter(command):
    """The impact loop evaluates the gaps before any impact is resolved: the same clear message, not
    ZeroDivisionError."""
    err = analysis_error(command, CRADLE, "--set", "r=0", "--t-end", "0.2")
    assert "contact 'c23'" in err and "r = 0" in err


def test_collide_regular_cradle_still_resolves():
    """Equal balls on equal strings, e = 1, ball 1 arriving at rate w: it stops and ball 2 leaves with w."""
    data = ok_json("collide", CRADLE, "--set", "th1=0", "--set", "der(th1)=2")
    assert data["rates_after"]["th1"] == pytest.approx(0.0, abs=1e-12)
    assert data["rates_after"]["th2"] == pytest.approx(2.0, rel=1e-12)


# ----------------------------------------------------------------------------------------- 4. massless coordinates
def test_massless_condensed_mode_matches_sqrt_k1_over_m():
    data = ok_json("modes", DATA / "massless_sprung_slider.yaml")
    assert [m["frequency_rad_s"] for m in data["modes"]] == pytest.approx([math.sqrt(100 / 2.0)], rel=1e-12)
    assert data["condensed"] == ["s"]


def test_massless_sprung_slider_equilibrium_is_stable():
    data = ok_json("equilibria", DATA / "massless_sprung_slider.yaml")
    (e,) = data["equilibria"]
    assert e["coordinates"] == pytest.approx({"x": 0.0, "s": 0.0}, abs=1e-12)
    assert e["stability"] == "stable"
    assert sorted(abs(v[1]) for v in e["eigenvalues"]) == pytest.approx([math.sqrt(50)] * 2, rel=1e-9)


@pytest.mark.parametrize("model, coordinate", [("massless_free_slider.yaml", "s"),
                                               ("zero_mass_second_pendulum.yaml", "ph")])
def test_undetermined_massless_coordinate_equilibria_say_so(model, coordinate):
    data = ok_json("equilibria", DATA / model)
    assert data["equilibria"]
    for e in data["equilibria"]:
        assert e["stability"] == "undecided"
        assert f"{coordinate} carries no mass or inertia" in e["reason"]
        assert e["eigenvalues"] == []  # a singular pencil has no meaningful eigenvalues


@pytest.mark.parametrize("model, coordinate", [("massless_free_slider.yaml", "s"),
                                               ("zero_mass_second_pendulum.yaml", "ph")])
def test_undetermined_massless_coordinate_modes_name_it(model, coordinate):
    err = analysis_error("modes", DATA / model)
    assert f"{coordinate} carries no mass or inertia" in err


@pytest.mark.parametrize("command", [["simulate", "--t-end", "0.1", "--method", "Radau"], ["simulate", "--t-end", "0.1"],
                                     ["info"]])
def test_parameters_that_overflow_the_equations_are_one_reasoned_line(command, tmp_path):
    """Found by the rotating-seed CLI fuzz (seed 20261123195802): the ballistic pendulum with M = 1e200 and
    --set rG=M squares 1e200 in the generated code. Python's float power raises OverflowError and numpy's SVD did
    not converge: both were internal errors. Generated code now returns inf/nan like numpy, and the analyses
    say the equations are not finite."""
    text = (Path(__file__).resolve().parent / "data" / "p42_ballistic_pendulum.yaml").read_text()
    path = tmp_path / "huge.yaml"
    path.write_text(text.replace("  M: 5 ", "  M: 1.0e+200 "))  # a YAML float: --set takes exact numbers only
    err = analysis_error(command[0], path, "--set", "rG=M", *command[1:])
    assert "not finite" in err and "check the parameter values" in err


def test_generated_code_with_boolean_constants_is_accepted(tmp_path):
    """Found by the rotating-seed fuzz: native_functions with k = 1e15 makes sympy print `False` (and can print
    float('nan')) in generated source, which the arithmetic-only check refused with an internal error. `modes`
    now ends in its own reasoned message. The forcing's t is replaced by x: with t the model is non-autonomous and
    `modes` says so before any code is generated (the stiff spring had hidden that: d/dt of f, 3, was compared with
    1e-9 of the spring's 1e15)."""
    text = (Path(__file__).resolve().parent / "data" / "native_functions.yaml").read_text()
    path = tmp_path / "stiff.yaml"
    stiff = text.replace("parameters: {m: 1.5, k: 40,", "parameters: {m: 1.5, k: 1000000000000000.0,")
    path.write_text(stiff)
    assert "non-autonomous" in analysis_error("modes", path, "-f", "json")
    for old, new in (("3*sin(2*t)", "3*sin(2*x)"), ("0.5*cos(t)", "0.5*cos(x)"), ("exp(-t)", "exp(-x)")):
        stiff = stiff.replace(old, new)
    path.write_text(stiff)
    err = analysis_error("modes", path, "-f", "json")
    assert "no equilibrium found to vibrate about" in err


def test_an_implicit_method_on_overflowing_equations_is_one_reasoned_line(tmp_path):
    """Found by the rotating-seed fuzz: the bouncing ball with g = 1e201 on Radau ended in scipy's bare
    `ValueError: array must not contain infs or NaNs`."""
    text = (Path(__file__).resolve().parents[1] / "systems" / "bouncing_ball.yaml").read_text()
    path = tmp_path / "heavy.yaml"
    path.write_text("\n".join("  g: 9.999999999999999e+200" if line.startswith("  g: 9.81") else line
                              for line in text.splitlines()) + "\n")
    err = analysis_error("simulate", path, "--t-end", "0.1", "--method", "Radau", "--set", "e=0")
    assert "not finite" in err


@pytest.mark.parametrize("native", ["on", "off"])
def test_a_domain_error_in_a_closed_loop_is_one_reasoned_line(native, tmp_path, monkeypatch):
    """Found by the rotating-seed CLI fuzz (seed 20261126001918): the overdriven slider-crank with g = 1e200 drives
    the state to where sqrt and asin leave their domain. Python's math raised `ValueError: math domain error` and
    then numpy's SVD of the resulting nan matrix did not converge: both were internal errors. Generated code now
    gives nan there as C and numpy do, and the closed loop's step fails with the time it reached."""
    monkeypatch.setenv("MECHSYS_NATIVE", native)
    text = (DATA / "overdriven_slider_crank.yaml").read_text()
    path = tmp_path / "heavy.yaml"
    path.write_text(text.replace("g: 9.81", "g: 1.0e+200"))
    assert "g: 1.0e+200" in path.read_text()
    err = analysis_error("simulate", path, "--t-end", "0.1", "--rtol", "1e-12")
    assert "integration failed at t =" in err or "left the constraint manifold" in err


def test_a_released_drive_that_is_not_real_at_t0_is_an_input_error(tmp_path):
    """Found by the rotating-seed CLI fuzz (seed 20261126080703): `inverse` releases the prescribed coordinates
    and starts them at the drive's value at t = 0; a crank a billion times the rod makes that value complex, and
    float() raised a TypeError: an internal error. Now one line naming the file, line and key, exit 2."""
    text = (DATA / "overdriven_slider_crank.yaml").read_text()
    path = tmp_path / "huge.yaml"
    path.write_text(text.replace("a: 0.2", "a: 1000000000.0"))
    assert "a: 1000000000.0" in path.read_text()
    result = invoke("inverse", path, "--at", "0.3")
    err = result.stderr.strip()
    assert result.exit_code == 2 and len(err.splitlines()) == 1, (result.exit_code, err)
    assert err.startswith("huge.yaml:") or "huge.yaml:" in err
    assert "coordinates.x4.prescribed: does not evaluate to a finite real number at t = 0" in err


def test_generated_code_outside_a_math_domain_gives_nan_like_numpy():
    from mechsys.numeric.runtime import call_generated, function_from_source

    fn = function_from_source("def _f(x):\n    return [math.sqrt(x), math.asin(x)]\n")
    assert call_generated(fn, [0.25], 2) == [0.5, math.asin(0.25)]
    assert all(math.isnan(v) for v in call_generated(fn, [-2.0], 2))
