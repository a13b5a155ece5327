"""The energy balance of `simulate` (issue 14): for driven, damped or impacting runs the summary reports the work of
the non-conservative forces W and E(t) - E(0) - W (+ impact losses), not a "drift"; checked against closed forms
written here (a damped oscillator's dissipated energy, a crank's energy change from its kinematics, a ball's
impact losses)."""
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

import mechsys
from mechsys.analysis.motion.simulate import simulate
from mechsys.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[1]
OSCILLATOR = """name: damped_oscillator
description: a block on a spring and a damper, released from x0
parameters: {m: 2.0, k: 50.0, c: 0.8, x0: 0.1}
coordinates:
  x: {initial: x0, rate: 0}
links:
  block:
    particle: true
    mass: m
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}
forces:
  - {type: spring, between: [block, ground], stiffness: k, free_length: 0}
  - {type: generalized_force, coordinate: x, value: -c*der(x)}
"""


def summary(capsys, *args: str) -> dict:
    saved, sys.argv = sys.argv, ["mechsys", "simulate", *args, "-f", "json"]
    try:
        cli_main()
    except SystemExit as exc:
        assert not exc.code
    finally:
        sys.argv = saved
    return json.loads(capsys.readouterr().out)["simulation summary"]


def test_a_damped_oscillator_dissipates_what_its_damper_works(tmp_path, capsys):
    """x'' + 2 z w x' + w^2 x = 0, x(0) = x0, x'(0) = 0: x' = -(w^2 x0 / wd) e^{-z w t} sin(wd t), and the damper's
    work up to t is -c * integral of x'^2 (quad of the closed form here)."""
    path = tmp_path / "osc.yaml"
    path.write_text(OSCILLATOR)
    m, k, c, x0, t_end = 2.0, 50.0, 0.8, 0.1, 4.0
    w = math.sqrt(k / m)
    z = c / (2 * m * w)
    wd = w * math.sqrt(1 - z * z)
    W, _ = quad(lambda t: -c * (w * w * x0 / wd * math.exp(-z * w * t) * math.sin(wd * t)) ** 2, 0, t_end,
                epsabs=1e-14, epsrel=1e-13, limit=200)
    out = summary(capsys, str(path), "--t-end", repr(t_end), "--dt", "0.001")
    assert out["work of non-conservative forces W(t_end)"] == pytest.approx(W, rel=1e-9)
    assert out["energy E(t_end) - E(0)"] == pytest.approx(W, rel=1e-9)
    assert out["max relative energy balance error"] < 1e-9
    assert "max relative energy drift" not in out


def test_the_work_of_a_drive_is_the_energy_change_of_the_crank(capsys):
    """The crank of docs/examples/slider_crank_driven.yaml turned at 3 rad/s with no other non-conservative force:
    W(t) of the drive equals T + V at t minus at 0, both from the closed-form loop kinematics (tests/test_inverse.py
    writes them: no mechsys)."""
    from test_inverse import _energies, _crank_energy  # noqa: F401 (the closed forms)
    model = mechsys.load(ROOT / "docs/examples/slider_crank_driven.yaml", release_prescribed=True)
    r = simulate(model, 1.5, 0.0015)
    L2O, L3A, M2, M3, M4, G = 0.1, 0.25, 1.0, 2.0, 0.5, 9.81

    def energy(t):
        th2, th3, x4 = _crank_energy(t, 3.0)
        w3 = -2 * L2O * math.cos(th2) * 3.0 / (2 * L3A * math.cos(th3))
        x4d = -2 * L2O * math.sin(th2) * 3.0 - 2 * L3A * math.sin(th3) * w3
        vg2 = np.array([-L2O * math.sin(th2), L2O * math.cos(th2)]) * 3.0
        vg3 = np.array([x4d + L3A * math.sin(th3) * w3, -L3A * math.cos(th3) * w3])
        T = (0.5 * M2 * vg2 @ vg2 + 0.5 * M2 * (2 * L2O) ** 2 / 12 * 9.0 + 0.5 * M3 * vg3 @ vg3
             + 0.5 * M3 * (2 * L3A) ** 2 / 12 * w3 ** 2 + 0.5 * M4 * x4d ** 2)
        V = G * (M2 * L2O * math.sin(th2) - M3 * L3A * math.sin(th3))
        return T + V

    for k in (333, 667, len(r.t) - 1):
        assert r.work[k] == pytest.approx(energy(r.t[k]) - energy(0.0), abs=1e-8)
    assert not r.conservative and r.energy_balance_error < 1e-8


def test_a_bouncing_ball_loses_what_its_impacts_take(capsys):
    """Dropped from h, restitution e: impact k (k = 1, 2, ...) leaves the speed e^k sqrt(2 g h) and takes
    (1 - e^2) of the kinetic energy before it; after N impacts the ball has lost m g h (1 - e^{2N})."""
    m, h, e, g = 0.1, 1.0, 0.5, 9.81
    out = summary(capsys, str(ROOT / "systems/bouncing_ball.yaml"), "--t-end", "1.5")
    n = out["impacts"]
    assert n >= 3 and out["events recorded"] >= n
    assert out["energy lost in impacts"] == pytest.approx(m * g * h * (1 - e ** (2 * n)), rel=1e-9)
    assert out["max relative energy balance error"] < 1e-12


def test_a_conservative_run_keeps_the_drift(capsys):
    out = summary(capsys, str(ROOT / "systems/double_pendulum.yaml"), "--t-end", "1")
    assert out["max relative energy drift"] < 1e-9
    assert "work of non-conservative forces W(t_end)" not in out and "max relative energy balance error" not in out


def test_a_warm_run_reports_the_same_balance(tmp_path, capsys, monkeypatch):
    """The second identical run starts from its stored plan (no model): the same W and balance (a cached result
    equals an uncached one)."""
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "osc.yaml"
    path.write_text(OSCILLATOR)
    first = summary(capsys, str(path), "--t-end", "2")
    second = summary(capsys, str(path), "--t-end", "2")
    assert any("warm plan" in k for k in second) and not any("warm plan" in k for k in first)
    for key in ("work of non-conservative forces W(t_end)", "max relative energy balance error",
                "energy E(t_end) - E(0)"):
        assert second[key] == first[key]


def test_a_transient_between_output_rows_is_named_not_blamed_on_the_integration():
    """The stiff chain (springs 1 to 1e8, a damper of 2e4 on the stiffest) dissipates nearly all its energy within
    the first 0.01 s: W, summed on a 0.01 s grid, missed it, and the balance error 0.99 came with a quadrature
    estimate of 5e-4, pointing at the integrator. The note now names the interval; a finer grid closes the balance."""
    from typer.testing import CliRunner

    from mechsys.cli import app

    path = Path(__file__).resolve().parent / "data" / "beyond" / "stiff_chain.yaml"
    coarse = CliRunner().invoke(app, ["simulate", str(path), "--t-end", "1", "--dt", "0.01", "--method", "native",
                                      "-f", "json"])
    assert coarse.exit_code == 0, coarse.output
    notes = json.loads(coarse.output)["notes"]
    assert any("within one output interval (t = 0 to 0.01 s)" in n for n in notes)
    fine = CliRunner().invoke(app, ["simulate", str(path), "--t-end", "0.01", "--dt", "1e-6", "--method", "native",
                                    "-f", "json"])
    data = json.loads(fine.output)
    assert data["simulation summary"]["max relative energy balance error"] < 1e-3
    assert not any("within one output interval" in n for n in data["notes"])


TURNED_ANCHOR = """name: turned anchor
description: a rotor on a torsional spring whose anchor angle is turned back and forth (t in the spring)
parameters: {I: 0.1, k: 2.0, A: 0.3, w: 3.0}
coordinates:
  q: {initial: 0, rate: 0}
links:
  rotor:
    joint: {type: revolute, parent: ground, axis: z, coordinate: q}
    inertia: {zz: I}
forces:
  - {type: torsional_spring, coordinate: q, stiffness: k, free_angle: A*sin(w*t)}
"""

SHAKEN = """name: shaken pendulum
parameters: {m: 1.0, L: 0.5, g: 9.81, A: 0.05, w: 8.0}
coordinates:
  th: {initial: 0.2, rate: 0}
links:
  bob:
    joint: {type: revolute, parent: ground, axis: y, coordinate: th, origin: [A*sin(w*t), 0, 0]}
    particle: true
    mass: m
    center_of_mass: [0, 0, -L]
forces:
  - {type: gravity, acceleration: [0, 0, -g]}
"""

SHAKEN_BY_A_DRIVE = """name: shaken pendulum, the pivot's motion a prescribed coordinate
parameters: {m: 1.0, L: 0.5, g: 9.81, A: 0.05, w: 8.0}
coordinates:
  x: {prescribed: A*sin(w*t)}
  th: {initial: 0.2, rate: 0}
links:
  slider:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}
  bob:
    joint: {type: revolute, parent: slider, axis: y, coordinate: th}
    particle: true
    mass: m
    center_of_mass: [0, 0, -L]
forces:
  - {type: gravity, acceleration: [0, 0, -g]}
"""


def test_a_spring_whose_setting_moves_with_time_does_work(tmp_path, capsys):
    """I q'' = -k (q - A sin wt): q = A wn^2/(wn^2 - w^2) (sin wt - (w/wn) sin wn t), and the anchor's work up to t is
    the integral of dV/dt (partial: dE/dt = dV/dt along the motion) = -k (q - A sin wt) A w cos wt (quad of the
    closed form here). The run was called conservative and its 'drift' was 1.0."""
    path = tmp_path / "anchor.yaml"
    path.write_text(TURNED_ANCHOR)
    I, k, A, w, t_end = 0.1, 2.0, 0.3, 3.0, 3.0
    wn = math.sqrt(k / I)

    def q(t):
        return A * wn**2 / (wn**2 - w**2) * (math.sin(w * t) - w / wn * math.sin(wn * t))

    W, _ = quad(lambda t: -k * (q(t) - A * math.sin(w * t)) * A * w * math.cos(w * t), 0, t_end, epsabs=1e-14,
                epsrel=1e-13, limit=200)
    out = summary(capsys, str(path), "--t-end", repr(t_end), "--dt", "0.001")
    assert "max relative energy drift" not in out
    assert out["q(t_end)"] == pytest.approx(q(t_end), rel=1e-8)
    assert out["work of non-conservative forces W(t_end)"] == pytest.approx(W, rel=1e-8)
    assert out["max relative energy balance error"] < 1e-9


def test_a_pivot_moved_in_the_joint_origin_works_as_its_drive_does(tmp_path, capsys):
    """The shaken pendulum with the pivot's motion written in the joint origin (t in T and V) and as a prescribed
    coordinate (the work of its driving force, from the multipliers): the same motion, the same work; the first was
    called conservative with a 'drift' of 0.07."""
    (tmp_path / "origin.yaml").write_text(SHAKEN)
    (tmp_path / "drive.yaml").write_text(SHAKEN_BY_A_DRIVE)
    a = summary(capsys, str(tmp_path / "origin.yaml"), "--t-end", "3", "--dt", "0.001")
    b = summary(capsys, str(tmp_path / "drive.yaml"), "--t-end", "3", "--dt", "0.001")
    assert a["th(t_end)"] == pytest.approx(b["th(t_end)"], rel=1e-8)
    W = b["work of non-conservative forces W(t_end)"]
    assert abs(W) > 1e-3
    assert a["work of non-conservative forces W(t_end)"] == pytest.approx(W, rel=1e-7)
    assert a["energy E(t_end) - E(0)"] == pytest.approx(W, rel=1e-7)
    assert a["max relative energy balance error"] < 1e-8
