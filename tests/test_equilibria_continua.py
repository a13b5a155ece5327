"""Roots that are not isolated: one representative of each continuum (equilibria.continua).

A pendulum (m = 1, l = 0.5) beside a free flywheel whose angle the user keeps non-cyclic (`cyclic: false`): it rests
hanging and upright at every flywheel angle, two continua. Only one representative of all non-isolated roots was
listed, so the upright pendulum (eigenvalues +-sqrt(g/l) = +-4.4294) disappeared, exit 0.
"""
from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from mechsys.cli import app

MODEL = """name: two_continua
parameters: {m: 1, l: 0.5, g: 9.81, J: 0.1}
coordinates:
  b: {initial: 0.1, rate: 0}
  w: {initial: 0, rate: 0, cyclic: false}
links:
  rod:
    joint: {type: revolute, parent: ground, axis: x, coordinate: b}
    mass: m
    center_of_mass: [0, 0, -l]
  wheel:
    joint: {type: revolute, parent: ground, axis: z, coordinate: w, origin: [1, 0, 0]}
    inertia: {zz: J}
forces:
  - {type: gravity, acceleration: [0, 0, -g]}
"""


def test_each_continuum_has_its_representative(tmp_path):
    path = tmp_path / "two.yaml"
    path.write_text(MODEL)
    result = CliRunner().invoke(app, ["equilibria", str(path), "-f", "json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    rests = sorted(data["equilibria"], key=lambda e: abs(e["coordinates"]["b"]))
    assert [abs(e["coordinates"]["b"]) for e in rests] == pytest.approx([0.0, math.pi], abs=1e-9)
    rate = math.sqrt(9.81 / 0.5)
    hanging, upright = rests
    assert sorted(abs(im) for _, im in hanging["eigenvalues"]) == pytest.approx([0, 0, rate, rate], abs=1e-9)
    assert upright["stability"] == "unstable"
    assert sorted(re for re, _ in upright["eigenvalues"]) == pytest.approx([-rate, 0, 0, rate], abs=1e-9)
    assert "one representative of each of 2 continua" in data["message"]


def test_roots_one_rounding_apart_are_ordered_by_their_next_coordinate():
    """A sweep's eq1 and eq2 swapped between rows where their first coordinate differed by one ulp (0.3038 and
    0.30379999999999996): the listing order rounds each value to 9 digits before comparing."""
    from mechsys.analysis.equilibrium.equilibria import Equilibrium, _order

    a = Equilibrium({"y1": 0.30379999999999996, "y2": 0.7057}, {}, [])
    b = Equilibrium({"y1": 0.3038, "y2": -0.2943}, {}, [])
    assert sorted([a, b], key=_order) == [b, a]
    assert sorted([Equilibrium({"y1": -1.0, "y2": 5.0}, {}, []), b], key=_order)[0].coordinates["y1"] == -1.0
