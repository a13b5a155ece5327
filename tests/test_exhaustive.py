"""`mechsys equilibria --exhaustive` (mechsys/analysis/equilibrium/exhaustive.py): every isolated root of equations polynomial in
the unknowns, sin and cos of the angles, compared with root counts obtained independently (closed forms, sign
changes on a fine grid, numpy's companion-matrix roots), and the refusals (exit 2, one line)."""
from __future__ import annotations

import json
import re
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.equilibrium.equilibria import EquilibriumProblem, find_equilibria
from mechsys.numeric.parameters import parameter_values
from mechsys.analysis.equilibrium.exhaustive import NotExhaustible, exhaustive_roots
from mechsys.cli import app

ROOT = Path(__file__).resolve().parents[1]
SYSTEMS = ROOT / "systems"
DATA = ROOT / "tests" / "data"
runner = CliRunner()

PENDULUM = """
name: pendulum
parameters: {m: 2, l: 0.5, g: 9.81, tau: 0}
coordinates: {q: {initial: 0.3}}
links:
  rod:
    joint: {type: revolute, parent: ground, axis: z, coordinate: q}
    mass: m
    center_of_mass: [0, -l, 0]
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
  - {type: torque, on: rod, axis: z, value: tau}
"""


def exhaustive(*args: str) -> dict:
    result = runner.invoke(app, ["equilibria", *map(str, args), "--exhaustive", "-f", "json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def refused(*args: str) -> str:
    result = runner.invoke(app, ["equilibria", *map(str, args), "--exhaustive"])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    return lines[0]


def configurations(result) -> np.ndarray:
    """The equilibria's coordinates, sorted on rounded values (ties of equal roots do not reorder them)."""
    return np.array(sorted((list(e.coordinates.values()) for e in result.equilibria),
                           key=lambda z: [round(x, 6) for x in z]))


def sign_change_roots(g, n: int = 200_001) -> list[float]:
    """Simple roots of a 2*pi-periodic function on (-pi, pi], located by sign changes and bisection."""
    x = np.linspace(-math.pi, math.pi, n)
    y = g(x)
    out = []
    for k in np.nonzero(np.sign(y[:-1]) != np.sign(y[1:]))[0]:
        a, b = x[k], x[k + 1]
        for _ in range(60):
            c = 0.5 * (a + b)
            a, b = (a, c) if np.sign(g(np.array([a]))[0]) != np.sign(g(np.array([c]))[0]) else (c, b)
        out.append(0.5 * (a + b))
    return out


@pytest.mark.parametrize("speed, count", [(12, 4), (7, 4), (3, 2)])
def test_centrifuge_steady_motions_all_found(speed, count):
    """Krodkiewski ch. 5: omega = Mo/dM; the beta row omega^2 (I2y - I2z + m l^2) sin cos + a m l omega^2 cos
    - m g l sin = 0 has 4 roots at 7 and 12 rad/s and 2 at 3 rad/s (below the fold at 5.128). Counted
    independently by sign changes, values to 1e-9."""
    data = exhaustive(SYSTEMS / "centrifuge.yaml", "--set", "dM=50/7", "--set", f"Mo={speed}*50/7")
    I2y, I2z, m, a, l, g = 2.0, 0.2, 8.0, 0.3, 0.5, 9.81
    w = float(speed)
    roots = sign_change_roots(lambda b: w**2 * (I2y - I2z + m * l**2) * np.sin(b) * np.cos(b)
                              + a * m * l * w**2 * np.cos(b) - m * g * l * np.sin(b))
    found = sorted(e["coordinates"]["beta"] for e in data["equilibria"])
    assert len(found) == len(roots) == count
    assert np.allclose(found, sorted(roots), atol=1e-9)
    assert all(abs(e["rates"]["alpha"] - w) < 1e-9 for e in data["equilibria"])
    assert data["exhaustive"] == {"exhaustive": True, "unknowns": ["beta", "der(alpha)"], "charts": 2,
                                  "complex_roots": 4, "real_roots": count, "positive_dimension": 0}


def test_problem57_double_well_roots_are_the_cubic_roots():
    """-q^3 + pi^2 q = 0: numpy's companion-matrix roots are -pi, 0, pi, all real; pi enters as a rational
    approximation and Newton on the original equation restores it."""
    data = exhaustive(SYSTEMS / "problem57.yaml")
    expected = sorted(np.roots([-1.0, 0.0, math.pi**2, 0.0]).real)
    assert [e["coordinates"]["q"] for e in data["equilibria"]] == pytest.approx(expected, abs=1e-12)
    assert [e["stability"] for e in data["equilibria"]] == ["asymptotically stable", "unstable",
                                                            "asymptotically stable"]
    assert data["exhaustive"]["complex_roots"] == 3


@pytest.mark.parametrize("tau, expected", [
    (0.0, [0.0, math.pi]),                                   # q = pi lives in the chart at infinity (t = tan(q/2))
    (4.0, [math.asin(4 / 9.81), math.pi - math.asin(4 / 9.81)]),  # m g l sin q = tau
    (12.0, []),                                              # tau > m g l: no equilibrium at all
])
def test_pendulum_with_a_torque(tmp_path, tau, expected):
    path = tmp_path / "pendulum.yaml"
    path.write_text(PENDULUM)
    data = exhaustive(path, "--set", f"tau={tau}")
    found = sorted(e["coordinates"]["q"] for e in data["equilibria"])
    assert found == pytest.approx(sorted(expected), abs=1e-12)
    assert data["exhaustive"]["real_roots"] == len(expected)
    if not expected:
        assert "no real root" in data["message"]


def test_double_pendulum_four_configurations():
    """sin(th1) and sin(th1 + th2) terms: the four hanging/inverted combinations, two of them in charts at pi."""
    data = exhaustive(SYSTEMS / "double_pendulum.yaml")
    found = sorted((round(e["coordinates"]["theta1"], 9), round(e["coordinates"]["theta2"], 9))
                   for e in data["equilibria"])
    pi = round(math.pi, 9)
    assert found == [(0.0, 0.0), (0.0, pi), (pi, 0.0), (pi, pi)]
    assert data["exhaustive"]["charts"] == 4


def test_closed_loop_multipliers_are_eliminated_slider_crank():
    """Slider-crank (2 loop rows): the multipliers are eliminated by the minor det[f | A^T] = 0; the exhaustive
    roots are the multistart's (the book's theta3 = -16.42994 deg branch among them)."""
    model = mechsys.load(SYSTEMS / "slider_crank.yaml", {"M2": 2.081015})
    exact = find_equilibria(model, exhaustive=True)
    multi = find_equilibria(model)
    assert exact.exhaustive is not None and not exact.exhaustive.positive_dimension
    assert exact.exhaustive.unknowns == ["theta2", "theta3", "x4"]
    found = configurations(exact)
    assert np.allclose(found, configurations(multi), atol=1e-9)
    assert any(np.allclose(z, [math.pi / 4, -0.2867566, 0.621005], atol=1e-6) for z in found)


@pytest.mark.slow
def test_four_bar_exhaustive_matches_the_multistart():
    """Three angles, two loop rows: 20 complex roots over 8 charts (after saturating the spurious t = +-i
    continuum), 4 real, the multistart's 4."""
    model = mechsys.load(SYSTEMS / "four_bar.yaml")
    exact = find_equilibria(model, exhaustive=True)
    multi = find_equilibria(model)
    assert exact.exhaustive.complex_roots == 20 and exact.exhaustive.real_roots == 4
    assert np.allclose(configurations(exact), configurations(multi), atol=1e-9)


def test_positive_dimensional_solution_set_is_reported():
    """The winch (linear springs between a drum, two gears and a rope) turns freely as a whole: the solution set
    is a line. It is reported, not dropped: NOT exhaustive, dimension 1, the multistart's representative."""
    data = exhaustive(DATA / "winch_gear.yaml")
    assert data["exhaustive"]["exhaustive"] is False and data["exhaustive"]["positive_dimension"] == 1
    assert "not isolated" in data["message"]
    assert len(data["equilibria"]) == 1 and data["search"] is not None
    result = runner.invoke(app, ["equilibria", str(DATA / "winch_gear.yaml"), "--exhaustive"])
    assert "NOT exhaustive" in " ".join(result.stdout.split())


def test_refusals_are_one_line_and_exit_2():
    assert "appears both inside and outside sin/cos" in refused(SYSTEMS / "gyrostabilizer.yaml")
    assert "not polynomial" in refused(SYSTEMS / "spring_chain.yaml")
    assert "cannot be combined with --search" in refused(SYSTEMS / "problem57.yaml", "--search", "q=0:1")


def test_size_limit_andrews_squeezer():
    """Seven angles (and a spring with a square root) are beyond the stated limit of 6 unknowns."""
    line = refused(DATA / "andrews_squeezer.yaml")
    assert "7 unknowns" in line and "limit of 6" in line


def test_time_budget_refuses():
    model = mechsys.load(SYSTEMS / "four_bar.yaml")
    problem = EquilibriumProblem(model)
    with pytest.raises(NotExhaustible, match="time budget of 0.05 s"):
        exhaustive_roots(problem, parameter_values(model), budget=0.05)


def test_the_exhaustive_example_of_the_docs_is_what_the_tool_prints():
    """docs/equilibria.md §2.6 shows the centrifuge at 3 rad/s in exhaustive mode (trimmed to coordinates, rates
    and verdicts): it must stay true."""
    doc = (ROOT / "docs" / "equilibria.md").read_text()
    command = ("$ mechsys equilibria systems/centrifuge.yaml --set dM=50/7 --set Mo=3*50/7 --exhaustive -f json"
               "   (trimmed)\n")
    block = doc.split(command, 1)[1].split("```", 1)[0]  # trimmed with `...` (tests/test_docs_examples.py)
    summary = json.loads("{" + block[block.index('"exhaustive": {'):block.rindex("}")] + "}")
    shown = [{"beta": float(b), "alpha": float(a), "stability": st} for b, a, st in re.findall(
        r'"beta": (\S+?)\}, "rates": \{"alpha": (\S+?)\}.*?"stability": "([^"]+)"', block, re.S)]
    data = exhaustive(SYSTEMS / "centrifuge.yaml", "--set", "dM=50/7", "--set", "Mo=3*50/7")
    assert data["exhaustive"] == summary["exhaustive"] and data["message"] == ""
    assert len(data["equilibria"]) == len(shown) == 2
    for got, want in zip(data["equilibria"], shown):
        assert got["stability"] == want["stability"]
        assert got["coordinates"]["beta"] == pytest.approx(want["beta"], abs=1e-9)
        assert got["rates"]["alpha"] == pytest.approx(want["alpha"], abs=1e-9)
