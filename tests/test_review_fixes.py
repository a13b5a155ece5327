"""Edge cases of the language: sliding force points, parameter-dependent line directions, reserved names,
forces on prescribed coordinates, --set error messages, explicit angle flags."""
from pathlib import Path

import pytest
import sympy as sp

import mechsys
from mechsys.errors import InputError

BAR = """
name: bar
parameters: {a: 0.5, L: 2}
coordinates:
  theta: {}
  s: {}
links:
  bar:
    joint: {type: revolute, parent: ground, axis: z, coordinate: theta}
    mass: 1
    inertia: {zz: 1}
    points: {slider: [s, 0, 0]}
  bead:
    particle: true
    joint: {type: prismatic, parent: bar, axis: x, coordinate: s}
    mass: 1
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "m.yaml"
    path.write_text(text)
    return path


def test_force_at_a_point_sliding_along_its_link_does_virtual_work_on_the_slide(tmp_path):
    path = write(tmp_path, BAR + "forces:\n  - {type: force, at: bar.slider, value: [1, 0, 0]}\n")
    model = mechsys.load(path)
    theta, s = model.q
    Q = model.generalized_forces
    # delta r = d/dtheta (s cos, s sin) dtheta + (cos, sin) ds; F = (1, 0)
    assert sp.simplify(Q[0] - (-s * sp.sin(theta))) == 0
    assert sp.simplify(Q[1] - sp.cos(theta)) == 0


def test_point_on_line_direction_may_depend_on_parameters(tmp_path):
    text = BAR + "constraints:\n  - {type: point_on_line, point: bead, through: ground, direction: [1, a, 0]}\n"
    model = mechsys.load(write(tmp_path, text))
    assert model.constraint_jacobian.shape == (1, 2)  # the z row vanishes for planar motion


def test_reserved_point_names_are_rejected(tmp_path):
    with pytest.raises(InputError, match="reserved point name"):
        mechsys.load(write(tmp_path, BAR.replace("slider: [s, 0, 0]", "com: [1, 0, 0]")))


def test_force_on_prescribed_coordinate_is_an_error(tmp_path):
    text = BAR.replace("theta: {}", "theta: {prescribed: 2*t}")
    text += "forces:\n  - {type: generalized_force, coordinate: theta, value: 1}\n"
    with pytest.raises(InputError, match="is prescribed"):
        mechsys.load(write(tmp_path, text))


def test_initial_value_on_prescribed_coordinate_is_an_error(tmp_path):
    with pytest.raises(InputError, match="prescribed coordinate has no free initial"):
        mechsys.load(write(tmp_path, BAR.replace("theta: {}", "theta: {prescribed: 2*t, initial: 1}")))
    with pytest.raises(InputError, match=r"^--set theta=1: "):
        mechsys.load(write(tmp_path, BAR.replace("theta: {}", "theta: {prescribed: 2*t}")), {"theta": "1"})


def test_set_expression_errors_name_the_option(tmp_path):
    with pytest.raises(InputError) as exc:
        mechsys.load(write(tmp_path, BAR), {"a": "2*nosuch"})
    assert str(exc.value).startswith("--set a=2*nosuch: unknown name 'nosuch'")


def test_set_values_are_exact(tmp_path):
    model = mechsys.load(write(tmp_path, BAR), {"a": "0.1"})
    assert model.doc.parameter_exprs["a"] == sp.Rational(1, 10)


def test_angle_flags(tmp_path):
    model = mechsys.load(write(tmp_path, BAR))
    assert model.angles == {"theta": True, "s": False}
    model = mechsys.load(write(tmp_path, BAR.replace("theta: {}", "theta: {angle: false}")))
    assert model.angles["theta"] is False
