"""`info` ranks the constraint Jacobian at configurations the mechanism can take (near the file's initial one,
moved onto the constraints), not at configurations off them.

tests/data/beyond/parallelogram_third_bar.yaml: a parallelogram four-bar with a third parallel bar, the classic
overconstrained linkage. Grübler's count gives 0 degrees of freedom; it moves with 1, its crank angle, and one of
its four loop equations is redundant (on the parallelogram branch the third bar's loop repeats the first's
direction). Before, the rank was taken at random configurations off the constraints: rank 4, 'DOF 0, redundant
constraints 0', exit 0, while `simulate` moved it with one degree of freedom.
"""
from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from mechsys.cli import app

DATA = Path(__file__).resolve().parent / "data"


def _info(path: Path) -> dict:
    result = CliRunner().invoke(app, ["info", str(path), "-f", "json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


def test_a_parallelogram_with_a_third_bar_has_one_degree_of_freedom_and_one_redundant_row():
    data = _info(DATA / "beyond" / "parallelogram_third_bar.yaml")
    assert (data["dof"], data["constraint_rank"], data["redundant_constraints"], data["dof_formula"]) == (1, 3, 1, 0)


def test_the_four_bar_keeps_its_counts():
    data = _info(Path(__file__).resolve().parents[1] / "systems" / "four_bar.yaml")
    assert (data["dof"], data["constraint_rank"], data["redundant_constraints"]) == (1, 2, 0)


def test_a_loop_that_cannot_close_says_so(tmp_path):
    """A four-bar whose ground link (1.0) is longer than the other three together (0.5) cannot be assembled: the
    ranks are then those of configurations off the constraints, and the notes say so."""
    path = tmp_path / "open.yaml"
    path.write_text(OPEN_FOUR_BAR)
    data = _info(path)
    assert any(n.startswith("the closed-loop constraints could not be met near the initial configuration")
               for n in data["notes"]), data["notes"]


OPEN_FOUR_BAR = """name: open_four_bar
parameters: {l1: 1.0, l2: 0.1, l3: 0.2, l4: 0.2, m: 1, g: 9.81}
coordinates:
  theta2: {initial: 0.5}
  theta3: {initial: 0.2}
  theta4: {initial: 1.0}
ground:
  points: {O4: [l1, 0, 0]}
links:
  crank:
    joint: {type: revolute, parent: ground, axis: z, coordinate: theta2}
    mass: m
    center_of_mass: [l2/2, 0, 0]
  coupler:
    joint: {type: revolute, parent: crank, axis: z, coordinate: theta3, origin: [l2, 0, 0]}
    mass: m
    center_of_mass: [l3/2, 0, 0]
    points: {B: [l3, 0, 0]}
  rocker:
    joint: {type: revolute, parent: ground, axis: z, coordinate: theta4, origin: O4}
    mass: m
    center_of_mass: [l4/2, 0, 0]
    points: {B: [l4, 0, 0]}
constraints:
  - {type: point_on_point, name: loop_B, points: [coupler.B, rocker.B]}
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
"""


def test_a_locked_configuration_is_stable_not_asymptotically(tmp_path):
    """An equilibrium whose linearization has no degree of freedom (the constraints lock it) was 'asymptotically
    stable: all eigenvalues have negative real parts', true only for want of any eigenvalue."""
    import numpy as np

    import mechsys
    from mechsys.analysis.equilibrium.equilibria import Equilibrium, EquilibriumProblem
    from mechsys.analysis.equilibrium.stability import LOCKED, assess
    from mechsys.numeric.parameters import parameter_values

    path = tmp_path / "locked.yaml"  # a pendulum pinned at its tip to a ground point: no motion left
    path.write_text("name: locked\nparameters: {m: 1, l: 1, g: 9.81}\ncoordinates:\n  th: {initial: 0}\nground:\n"
                    "  points: {P: [l, 0, 0]}\nlinks:\n  rod:\n"
                    "    joint: {type: revolute, parent: ground, axis: z, coordinate: th}\n    mass: m\n"
                    "    center_of_mass: [l/2, 0, 0]\n    points: {tip: [l, 0, 0]}\n"
                    "constraints:\n  - {type: point_on_point, name: pin, points: [rod.tip, ground.P]}\n"
                    "forces:\n  - {type: gravity, acceleration: [0, -g, 0]}\n")
    model = mechsys.load(path)
    problem = EquilibriumProblem(model)
    p = parameter_values(model)
    e = Equilibrium({"th": 0.0}, {}, [0.0, 0.5 * 9.81])
    assess(problem, e, p)
    assert len(e.eigenvalues) == 0 and e.stability == "stable" and e.reason == LOCKED and not e.critical
