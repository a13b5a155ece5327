"""Driving forces of prescribed coordinates (inverse dynamics) as simulation outputs."""
from pathlib import Path

import numpy as np
import pytest

import mechsys
from mechsys.analysis.motion.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("F4, M2", [(0, 2.081015), (10, 3.912258)])
def test_slider_crank_driving_torque_is_the_static_M2_E003_2(F4, M2):
    model = mechsys.load(ROOT / "tests" / "data" / "slider_crank_driven.yaml", {"F4": F4},
                         release_prescribed=True)
    r = simulate(model, 0.2, 0.05)
    assert np.allclose(r.driving["theta2"], M2, atol=5e-6)  # digest value to its printed digits
    assert np.max(r.residual) < 1e-10
    assert np.max(np.abs(r.u)) < 1e-9  # the fully driven mechanism stays at rest


def test_gyrostabilizer_spin_torque_matches_krodkiewski_6_11():
    """M32z2 = I3z (-alpha'' sin(beta) - alpha' beta' cos(beta)) keeps the rotor spin constant (digest 2.6)."""
    model = mechsys.load(ROOT / "systems" / "gyrostabilizer.yaml", {"Omega": "300"}, release_prescribed=True)
    r = simulate(model, 4, 0.004)
    i, j = r.coordinates.index("alpha"), r.coordinates.index("beta")
    alpha_dd = np.gradient(r.u[:, i], r.t, edge_order=2)
    ref = model.parameters["I3z"] * (-alpha_dd * np.sin(r.q[:, j]) - r.u[:, i] * r.u[:, j] * np.cos(r.q[:, j]))
    scale = np.max(np.abs(ref))
    assert scale > 100  # a real torque, not a trivial zero
    assert np.max(np.abs(r.driving["gamma"][5:-5] - ref[5:-5])) < 1e-4 * scale


def test_released_model_has_the_same_motion():
    free = simulate(mechsys.load(ROOT / "systems" / "indicator.yaml"), 5, 0.05)
    driven = simulate(mechsys.load(ROOT / "systems" / "indicator.yaml", release_prescribed=True), 5, 0.05)
    k = driven.coordinates.index("beta")
    assert np.max(np.abs(free.q[:, 0] - driven.q[:, k])) < 1e-7
