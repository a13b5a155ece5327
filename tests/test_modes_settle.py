"""`mechsys modes` without --at: the stable rest the model settles at from its initial configuration
(equilibria.settle, pseudo-transient continuation), else the stable equilibrium of the search nearest the start
(docs/modes.md §2).

The frequencies of the chains are checked against a closed form written here, not against mechsys: a chain of n
identical links hanging straight down, small swings in one plane, absolute angles theta_j. The centre of mass of
link i moves l*theta_j' sideways for every link j above it and l/2*theta_i' for its own, so
M_jj = m l^2 (n - j) + m l^2/4 + I, M_jk = m l^2 (n - k + 1/2) (j < k), K_jj = m g l (n - j + 1/2), with I the
link's central moment about the swing axis. Relative angles only change coordinates, not the frequencies.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.equilibrium.equilibria import EquilibriumProblem, settle
from mechsys.cli import app
from mechsys.numeric.parameters import parameter_values

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
sys.path.insert(0, str(ROOT / "benchmarks"))
from derive_chain import PARAMS, chain_yaml  # noqa: E402  (the chain of benchmarks/derive_chain.py, as a user writes it)


def _modes_json(path: Path, *extra: str) -> dict:
    result = CliRunner().invoke(app, ["modes", str(path), "-f", "json", *extra])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


def hanging_chain_frequencies(n: int, m: float, l: float, g: float, inertia: float) -> np.ndarray:
    """The closed form of the module docstring: sqrt of the generalized eigenvalues of (K, M), ascending."""
    M = np.empty((n, n))
    for j in range(1, n + 1):
        for k in range(1, n + 1):
            M[j - 1, k - 1] = (m * l**2 * (n - j) + m * l**2 / 4 + inertia if j == k
                               else m * l**2 * (n - max(j, k) + 0.5))
    K = np.diag([m * g * l * (n - j + 0.5) for j in range(1, n + 1)])
    return np.sqrt(sla.eigh(K, M, eigvals_only=True))


def test_3d_chain_of_boxes_vibrates_about_its_hanging_rest():
    """Four boxes (a x 2a x l) on universal joints, started away from rest: the modes are about p = r = 0 with no
    note, and the eight frequencies are those of two planar chains, swinging about x (I_xx = m((2a)^2 + l^2)/12)
    and about y (I_yy = m(a^2 + l^2)/12). Before, the default was the first stable one of 406 equilibria the
    multistart found (the same point, in 2.5 times the time)."""
    data = _modes_json(DATA / "beyond" / "chain3d_boxes.yaml")
    assert "note" not in data and data["unstable_modes"] == 0
    assert all(v == 0.0 for v in data["equilibrium"]["coordinates"].values())  # not 1e-34: settle's snapping
    m, l, a, g = 0.5, 0.4, 0.05, 9.81
    expected = np.sort(np.concatenate([hanging_chain_frequencies(4, m, l, g, m * ((2 * a) ** 2 + l**2) / 12),
                                       hanging_chain_frequencies(4, m, l, g, m * (a**2 + l**2) / 12)]))
    got = [mode["frequency_rad_s"] for mode in data["modes"]]
    assert got == pytest.approx(expected, rel=1e-9)


def test_planar_chain_held_horizontal_vibrates_about_its_hanging_rest(tmp_path):
    """The benchmark's chain of uniform rods starts horizontal (all angles 0), where the Jacobian of the rest
    equations vanishes. It settles hanging down (q1 = -pi/2, the others 0) and its frequencies are the closed
    form's with I = m l^2/12. Before, the multistart of a long chain found none of its one stable rest among 2^n
    equilibria (504 unstable ones found), and modes were about an unstable configuration (with a note)."""
    n = 20
    path = tmp_path / "chain20.yaml"
    path.write_text(chain_yaml(n))
    data = _modes_json(path)
    assert "note" not in data and data["unstable_modes"] == 0
    coords = data["equilibrium"]["coordinates"]
    assert coords["q1"] == pytest.approx(-math.pi / 2, abs=1e-12)
    assert all(coords[f"q{k}"] == 0.0 for k in range(2, n + 1))
    m, l, g = PARAMS["m"], PARAMS["l"], PARAMS["g"]
    expected = hanging_chain_frequencies(n, m, l, g, m * l**2 / 12)
    assert [mode["frequency_rad_s"] for mode in data["modes"]] == pytest.approx(expected, rel=1e-9)


def test_spring_chain_default_is_the_rest_it_starts_near():
    """The spring chain starts 1 cm from its unstretched rest: that is the default now (docs/modes.md §2), not the
    configuration with springs passed through zero length that sorted first (x1 = -0.512195, ...). The
    frequencies are those of M = diag(m), K tridiagonal (the file's header), here from the parameters."""
    data = _modes_json(ROOT / "systems" / "spring_chain.yaml")
    assert all(v == 0.0 for v in data["equilibrium"]["coordinates"].values())
    m1, m2, m3, k1, k12, k23, k3 = 2.0, 1.5, 1.0, 2000.0, 1500.0, 1000.0, 800.0
    K = np.array([[k1 + k12, -k12, 0], [-k12, k12 + k23, -k23], [0, -k23, k23 + k3]])
    expected = np.sqrt(sla.eigh(K, np.diag([m1, m2, m3]), eigvals_only=True))
    assert [mode["frequency_rad_s"] for mode in data["modes"]] == pytest.approx(expected, rel=1e-9)


def _pendulum(tmp_path, theta0: float) -> mechsys.MechanicalModel:
    path = tmp_path / "pendulum.yaml"
    path.write_text("name: pendulum\nparameters: {m: 1.0, l: 0.5, g: 9.81}\ncoordinates:\n"
                    f"  th: {{initial: {theta0}}}\nlinks:\n  rod:\n"
                    "    joint: {type: revolute, parent: ground, axis: z, coordinate: th}\n"
                    "    mass: m\n    center_of_mass: [l, 0, 0]\n"
                    "forces:\n  - {type: gravity, acceleration: [0, -g, 0]}\n")
    return mechsys.load(path)


@pytest.mark.parametrize("theta0, rest", [(1.0, -math.pi / 2), (math.pi / 2 - 0.1, -math.pi / 2),
                                          (-math.pi / 2, -math.pi / 2), (math.pi / 2, math.pi / 2)])
def test_settle_follows_the_flow_to_the_rest(tmp_path, theta0, rest):
    """A point pendulum (theta from the x axis, gravity along -y): from 1 rad and from just below the top the flow
    comes down to the bottom (-pi/2); started on a rest, at the bottom or exactly at the top, it stays there (the
    top is unstable: modes then falls back to the search, test_equilibria_cli's hilltop)."""
    model = _pendulum(tmp_path, theta0)
    problem = EquilibriumProblem(model)
    z = settle(problem, np.array([theta0]), parameter_values(model))
    assert z is not None and z[0] == pytest.approx(rest, abs=1e-12)


def test_modes_of_a_pendulum_started_at_its_top_are_about_the_bottom(tmp_path):
    """Settled at the unstable top, the default falls back to the search's first stable equilibrium: the bottom,
    w^2 = g/l."""
    model_path = tmp_path / "pendulum.yaml"
    _pendulum(tmp_path, math.pi / 2)
    data = _modes_json(model_path)
    assert data["equilibrium"]["coordinates"]["th"] == pytest.approx(-math.pi / 2, abs=1e-9)
    assert data["modes"][0]["frequency_rad_s"] ** 2 == pytest.approx(9.81 / 0.5, rel=1e-9)


def test_winch_default_is_a_member_of_its_rigid_line():
    """A continuum of equilibria (the winch's drive train turns freely as a whole) is not isolated: the settling is
    not used and the search's representative is a point of the rigid line x = R phi1, phi2 = i phi1, alpha1 = phi1
    (docs/modes.md §2), with one rigid-body mode."""
    data = _modes_json(DATA / "winch_gear.yaml")
    c = data["equilibrium"]["coordinates"]
    R, i = 0.3, 3.0
    wrap = lambda a: math.remainder(a, 2 * math.pi)  # noqa: E731
    assert c["x"] == pytest.approx(R * c["phi1"], abs=1e-9)
    assert wrap(c["phi2"] - i * c["phi1"]) == pytest.approx(0.0, abs=1e-9)
    assert wrap(c["alpha1"] - c["phi1"]) == pytest.approx(0.0, abs=1e-9)
    assert [mode["rigid_body"] for mode in data["modes"]].count(True) == 1


def test_eight_mode_shapes_print_in_blocks_with_every_number_whole(monkeypatch):
    """The 3-D chain's mode shapes (8 x 8, numbers like -1.173315e-14) are wider than 80 columns: they print in
    blocks of columns, each number whole on its line (rich folded them onto up to three lines before)."""
    from mechsys.report.tables import fmt_number

    monkeypatch.setenv("COLUMNS", "80")
    path = DATA / "beyond" / "chain3d_boxes.yaml"
    result = CliRunner().invoke(app, ["modes", str(path)])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert max(len(line) for line in lines) <= 80
    cells = {c.strip() for line in lines if line.startswith("│") for c in line.split("│")[1:-1]}
    data = _modes_json(path)
    for mode in data["modes"]:
        for value in mode["shape"].values():
            assert fmt_number(value) in cells, fmt_number(value)
    assert sum(line.startswith("┃ coordinate") for line in lines) == 2


def test_a_steady_motion_says_its_frequencies_are_the_eigenvalues():
    """A conical pendulum turning at W = 4 rad/s (tests/data/beyond/conical_pendulum.yaml): the cone has
    cos(pol) = g/(W^2 l) and the small oscillations about it, gyroscopically coupled to the azimuth, have
    frequency W sqrt(1 + 3 cos^2(pol)) = 5.834747 rad/s (a closed form: linearize m l^2 (pol'' - W^2 sin cos)
    + m g l sin = 0 with the azimuth's momentum conserved). The table's 3.159944 rad/s is (K, M) without G: the
    output now says so and names 5.834747."""
    W, g, l = 4.0, 9.81, 1.0
    c = g / (W**2 * l)
    data = _modes_json(DATA / "beyond" / "conical_pendulum.yaml")
    assert data["equilibrium"]["coordinates"]["pol"] == pytest.approx(math.acos(c), abs=1e-12)
    true = W * math.sqrt(1 + 3 * c**2)
    assert max(abs(v[1]) for v in data["eigenvalues"]) == pytest.approx(true, rel=1e-9)
    assert data["coupling"].startswith("gyroscopic terms couple the coordinates")
    assert f"|Im λ| = {true:.7g} rad/s" in data["coupling"]
    assert "coupling" not in _modes_json(ROOT / "systems" / "spring_chain.yaml")
    arm = _modes_json(ROOT / "systems" / "motor_arm.yaml")  # docs/modes.md §5: 6.24724 in the table, 9.247141 in fact
    assert [round(mode["frequency_rad_s"], 5) for mode in arm["modes"]] == [0.0, 6.24724]
    assert "|Im λ| = 9.247141 rad/s" in arm["coupling"]


LEVER = """name: lever
parameters: {m1: 2.0, m2: 0.5, k1: 300, k2: 100, c1: 1.0, L: 1.0}
coordinates:
  x1: {initial: 0.01, rate: 0}
  x2: {initial: 0.02005, rate: 0}
ground:
  points: {a: [0, 0, 0], b: [0, 1, 0]}
links:
  b1:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x1, origin: [L, 0, 0]}
    mass: m1
  b2:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x2, origin: [L, 1, 0]}
    mass: m2
constraints:
  - {type: holonomic, name: lever, expression: x2 - 2*x1 - 0.5*x1**2}
forces:
  - {type: spring, between: [ground.a, b1], stiffness: k1, free_length: L}
  - {type: spring, between: [ground.b, b2], stiffness: k2, free_length: L}
  - {type: damper, between: [ground.a, b1], coefficient: c1}
"""


def test_a_constrained_model_vibrates_about_the_stable_rest_nearest_its_start(tmp_path):
    """Two masses tied by x2 = 2 x1 + x1^2/2 (a closed-loop row: no settling), started 1 cm from the springs' rest.
    Its stable rests include x1 = x2 = -2, reached only through the springs' anchors, which sorts first; the modes
    were about it (12.247449 rad/s). About x = 0, dx2/dx1 = 2: omega^2 = (k1 + 4 k2)/(m1 + 4 m2), and the damper
    gives zeta = c1 / (2 omega (m1 + 4 m2))."""
    path = tmp_path / "lever.yaml"
    path.write_text(LEVER)
    result = CliRunner().invoke(app, ["modes", str(path), "-f", "json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["equilibrium"]["coordinates"] == pytest.approx({"x1": 0.0, "x2": 0.0}, abs=1e-12)
    omega, mass = math.sqrt((300 + 4 * 100) / (2.0 + 4 * 0.5)), 2.0 + 4 * 0.5
    assert data["modes"][0]["frequency_rad_s"] == pytest.approx(omega, rel=1e-9)
    assert data["modes"][0]["damping_ratio"] == pytest.approx(1.0 / (2 * omega * mass), rel=1e-9)


def test_at_takes_constant_expressions_and_says_why_a_cyclic_coordinate_is_refused(tmp_path):
    """`--at theta1=pi` was 'expected NAME=VALUE with a number'; a cyclic coordinate whose rate is not an unknown
    (nothing acts on it at rest) was 'not a free coordinate', although `info` lists it as one."""
    dp = str(ROOT / "systems" / "double_pendulum.yaml")
    by_name = CliRunner().invoke(app, ["modes", dp, "--at", "theta1=pi", "--at", "theta2=-pi/2*2", "-f", "json"])
    by_number = CliRunner().invoke(app, ["modes", dp, "--at", f"theta1={math.pi!r}", "--at", f"theta2={-math.pi!r}",
                                         "-f", "json"])
    assert by_name.exit_code == 0, by_name.output
    assert json.loads(by_name.output)["modes"] == json.loads(by_number.output)["modes"]
    cart = tmp_path / "cart.yaml"
    cart.write_text("""name: cart
parameters: {M: 1, m: 0.2, l: 0.5, g: 9.81}
coordinates:
  x: {initial: 0, rate: 0}
  theta: {initial: 0.1, rate: 0}
links:
  cart: {joint: {type: prismatic, parent: ground, axis: x, coordinate: x}, mass: M}
  pole:
    joint: {type: revolute, parent: cart, axis: z, coordinate: theta}
    mass: m
    center_of_mass: [0, -l, 0]
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
""")
    result = CliRunner().invoke(app, ["modes", str(cart), "--at", "theta=0", "--at", "x=0"])
    assert result.exit_code == 2 and "x is cyclic, and nothing acts on it at rest" in result.stderr
