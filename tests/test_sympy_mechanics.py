"""The model as sympy.physics.mechanics objects: sympy's KanesMethod on them reproduces mechsys's M and f."""
from pathlib import Path

import numpy as np
import pytest
from sympy.physics import mechanics as me

import mechsys
from mechsys.mechanics.physics import physics_model, sympy_kane
from mechsys.numeric.lambdify import compile_matrix

ROOT = Path(__file__).resolve().parents[1]
UNCONSTRAINED = ["centrifuge", "gyrostabilizer", "indicator", "problem57", "motor_arm", "double_pendulum",
                 "cart_pendulum", "spring_chain", "wheel_on_axle"]


@pytest.mark.parametrize("name", UNCONSTRAINED)
def test_sympy_kanesmethod_agrees_with_mechsys(name):
    model = mechsys.load(ROOT / "systems" / f"{name}.yaml")
    M_ref, f_ref = sympy_kane(model)
    eq = model.equations("kane")
    params = model.parameter_symbols
    p = [model.parameters[s.name] for s in params]
    rng = np.random.default_rng(3)
    for _ in range(3):
        t, q, u = 0.7, rng.uniform(-2, 2, len(model.q)), rng.uniform(-2, 2, len(model.q))
        for ref, ours in ((M_ref, eq.M), (f_ref, eq.f)):
            a = compile_matrix(ref, model.t, model.q, model.u, params)(t, q, u, p)
            b = compile_matrix(ours, model.t, model.q, model.u, params)(t, q, u, p)
            assert np.allclose(a, b, rtol=1e-10, atol=1e-10 * max(1.0, np.abs(a).max()))


def test_physics_objects_are_sympy_mechanics_types():
    pm = physics_model(mechsys.load(ROOT / "systems" / "centrifuge.yaml"))
    assert isinstance(pm.N, me.ReferenceFrame) and set(pm.frames) == {"column", "arm"}
    assert all(isinstance(b, (me.RigidBody, me.Particle)) for b in pm.bodies)
    # the arm's angular velocity in the book's body axes: (beta', alpha' sin beta, alpha' cos beta)
    w = pm.frames["arm"].ang_vel_in(pm.N).to_matrix(pm.frames["arm"])
    assert w[0] == pm.u[1]
