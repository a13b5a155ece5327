"""Rest equations that jump: a 1-D spring at zero length is not an equilibrium (equilibria.md §2.7).

A block on a rail tied to a ground point by a spring of free length L stores V = k (|x - w| - L)^2 / 2, so its
rests are x = w +- L, both minima with w^2 = k/m; at x = w the force is +-k L on either side, its direction
undefined. sympy's sign(0) = 0 made F vanish there: the search listed it ("undecided", and a note that the
equilibria were not isolated), the energy test's higher derivatives crashed on it (internal error), and a sweep
failed every task.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mechsys.cli import app

JUMP = "the forces at rest jump (a spring of zero length, a sign() law) (e.g. x = {w:g})"


def _block(tmp_path: Path, wall: float, initial: float) -> Path:
    """The block of the module docstring, written as a user would (m = 1, k = 100, L = 0.5)."""
    path = tmp_path / "block.yaml"
    path.write_text("name: block_on_spring\nparameters: {m: 1.0, k: 100, L: 0.5}\n"
                    f"ground:\n  points: {{w: [{wall}, 0, 0]}}\ncoordinates:\n  x: {{initial: {initial}, rate: 0}}\n"
                    "links:\n  block:\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n"
                    "    mass: m\nforces:\n  - {type: spring, between: [ground.w, block], stiffness: k, free_length: L}\n")
    return path


def _json(*args: str) -> dict:
    result = CliRunner().invoke(app, [*args, "-f", "json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


@pytest.mark.parametrize("wall, extra", [(0.0, ()), (0.0, ("--search", "x=-2:2")), (-1.0, ("-s", "x=-1"))])
def test_a_spring_at_zero_length_is_not_listed(tmp_path, wall, extra):
    """The rests are x = w - L and w + L, stable, and the note names the point dropped; nothing says the
    equilibria are not isolated. (-s x=-1 starts the search at the zero-length point itself.)"""
    data = _json("equilibria", str(_block(tmp_path, wall, 0.6)), *extra)
    xs = sorted(e["coordinates"]["x"] for e in data["equilibria"])
    assert xs == pytest.approx([wall - 0.5, wall + 0.5], abs=1e-12)
    assert all(e["stability"] == "stable" for e in data["equilibria"])
    assert JUMP.format(w=wall) in data["message"] and "not isolated" not in data["message"]
    assert "points where the equations of motion are not smooth" in data["message"]


def test_modes_of_the_block_settle_at_its_rest(tmp_path):
    """From x = 0.6 the block settles at x = L = 0.5: w^2 = k/m = 100."""
    data = _json("modes", str(_block(tmp_path, 0.0, 0.6)))
    assert data["equilibrium"]["coordinates"]["x"] == pytest.approx(0.5, abs=1e-12)
    assert data["modes"][0]["frequency_rad_s"] == pytest.approx(math.sqrt(100.0), rel=1e-12)


def test_a_sweep_of_equilibria_through_the_zero_length_point_runs(tmp_path):
    """Every task of `sweep --run equilibria` failed with the internal error; now each finds the two rests."""
    out = tmp_path / "map.csv"
    result = CliRunner().invoke(app, ["sweep", str(_block(tmp_path, 0.0, 0.6)), "--param", "k=50:100:2",
                                      "--run", "equilibria", "-o", str(out)])
    assert result.exit_code == 0, result.output
    text = out.read_text()
    assert "failed" not in text and text.count("stable") >= 4


def test_the_energy_test_does_not_crash_at_a_switch(tmp_path):
    """Assessed at the zero-length point directly (as a caller might), the verdict is undecided, not a crash: the
    higher derivatives of |x| there are not numbers."""
    import numpy as np

    import mechsys
    from mechsys.analysis.equilibrium.equilibria import EquilibriumProblem
    from mechsys.analysis.equilibrium.stability import assess
    from mechsys.numeric.parameters import parameter_values

    model = mechsys.load(_block(tmp_path, 0.0, 0.6))
    problem = EquilibriumProblem(model)
    p = parameter_values(model)
    e = problem.equilibrium(np.array([0.0]))
    assess(problem, e, p)
    assert e.stability == "undecided"
    assert problem.discontinuity(np.array([0.0]), p) is not None
    assert problem.discontinuity(np.array([0.5]), p) is None


ABSORBER = """name: absorber
parameters: {M1: 10.0, K1: 4000, mu: 0.1, c2: 3.0, L: 0.5}
coordinates:
  x1: {initial: 0, rate: 0}
  x2: {initial: 0, rate: 0}
ground:
  points:
    wall: [0, 0, 0]
links:
  main:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x1, origin: [L, 0, 0]}
    mass: M1
  tmd:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x2, origin: [2*L, 0, 0]}
    mass: mu*M1
forces:
  - {type: spring, between: [ground.wall, main], stiffness: K1, free_length: L}
  - {type: spring, between: [main, tmd], stiffness: mu*K1/(1+mu)**2, free_length: L}
  - {type: damper, between: [main, tmd], coefficient: c2}
"""


def test_the_symbolic_linearization_prints_springs_without_their_kinks(tmp_path):
    """--linearize printed K+N with DiracDelta(L + x1) and sign(L + x1)**2 (the derivatives of a spring's |d|):
    0 and 1 wherever no spring has zero length, where a linearization is about. A Den Hartog absorber: K+N is
    [[K1 + k2, -k2], [-k2, k2]], C+G the damper's c2."""
    path = tmp_path / "absorber.yaml"
    path.write_text(ABSORBER)
    result = CliRunner().invoke(app, ["equilibria", str(path), "--linearize"])
    assert result.exit_code == 0, result.output
    text = result.output
    assert "DiracDelta" not in text and "sign(" not in text
    squeezed = " ".join(text.split())
    assert "K1 + K1*mu/(1 + mu)**2" in squeezed and "-c2" in squeezed


@pytest.mark.parametrize("free_length", [0.05, 0.1, 1.0])
def test_a_block_on_a_spring_to_its_own_line_rests_at_both_ends_of_the_free_length(tmp_path, free_length):
    """A block on a spring to the ground point on its line, free length L: rests at x = -L and x = L (closed form;
    x = 0 is where the spring force jumps). For L = 0.1 and 0.05 only one was found: the first start, x = 0, ended
    on the jump, and deflating it repelled Newton from the rest at -L."""
    path = tmp_path / "block.yaml"
    path.write_text("name: block\nparameters: {m: 1, k: 100, L: 0.1}\ncoordinates:\n  x: {initial: 0, rate: 0}\n"
                    "links:\n  b:\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n"
                    "    mass: m\nforces:\n  - {type: spring, between: [b, ground], stiffness: k, free_length: L}\n")
    result = CliRunner().invoke(app, ["equilibria", str(path), "--set", f"L={free_length!r}", "-f", "json"])
    assert result.exit_code == 0, result.output
    rests = sorted(e["coordinates"]["x"] for e in json.loads(result.stdout)["equilibria"])
    assert rests == pytest.approx([-free_length, free_length], abs=1e-12)
