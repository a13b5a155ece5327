"""Linear vibration modes, linearized matrices and principal inertias against the textbook digests.

Sources (under /work/shared/reference/): seeds001_004_digest.md — E001-3 (beam on two springs), E001-4 (cart
pendulum), E001-8 (beads on a taut string), E001-10 (winch with a massless gear: static condensation), E001-6 and
§001.3 (free-free systems: rigid-body mode), E004-8 (two-mass chain), E002-1 (principal moments of inertia);
seed000_part2_digest.md §2.4 (indicator small oscillations: Delta beta'' + B Delta beta' + C Delta beta = 0).

API under test: vibration_modes(model, at=None) -> .coordinates, .frequencies (rad/s, ascending, K phi = w^2 M phi,
massless coordinates condensed), .frequencies_hz, .shapes (n_coordinates, n_modes), mass-normalised on the
retained coordinates with the condensed ones recovered, .rigid_body, .damping_ratios; linearize(model, eq) -> M, C,
G, K, N, A, B over all free coordinates; principal_inertia(I) -> ascending moments, orthonormal axes as columns.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla

import mechsys

ROOT = Path(__file__).resolve().parents[1]
SYSTEMS = ROOT / "systems"
DATA = ROOT / "tests" / "data"


def vibration_modes(model, at=None):
    from mechsys.analysis.equilibrium.modes import vibration_modes as _modes

    return _modes(model, at=at)


def linearize_at(model, coordinates, tol=1e-8):
    """linearize() about the equilibrium found nearest to ``coordinates`` (searched in a small box). ``tol`` > 1e-8
    only for the linear models whose rest points form a continuum (winch: the free drive train), where any rest point
    gives the same matrices."""
    from mechsys.analysis.equilibrium.equilibria import find_equilibria
    from mechsys.analysis.equilibrium.linearize import linearize

    box = {n: (v - 1e-3, v + 1e-3) for n, v in coordinates.items() if not model.angles.get(n, False)}
    res = find_equilibria(model, search=box)
    assert res.equilibria, res.message

    def dist(e):
        return max(abs(e.coordinates[n] - v) for n, v in coordinates.items() if n in e.coordinates)

    best = min(res.equilibria, key=dist)
    assert dist(best) <= tol, ([e.coordinates for e in res.equilibria], res.message)
    return linearize(model, best)


def load(path, **overrides):
    return mechsys.load(path, {k: str(v) for k, v in overrides.items()} or None)


def assert_parallel(vector, reference, tol=1e-9):
    """vector = c * reference for some scalar c != 0 (mode shapes are defined up to sign and scale)."""
    v = np.asarray(vector, dtype=float)
    r = np.asarray(reference, dtype=float)
    cos = abs(v @ r) / (np.linalg.norm(v) * np.linalg.norm(r))
    assert cos == pytest.approx(1.0, abs=tol), f"{v} is not parallel to {r}"


def assert_mass_normalised(shapes, M):
    Phi = np.asarray(shapes, dtype=float)
    assert Phi.T @ M @ Phi == pytest.approx(np.eye(Phi.shape[1]), abs=1e-9)


# ================================================================================ E001-3 beam on two springs
BEAM = DATA / "beam_two_springs.yaml"


def test_beam_two_springs_stiffness_matrix_2_40():
    """E001-3 (2.40): M = diag(m, I), K = [[k1+k2, k2 l2 - k1 l1], [k2 l2 - k1 l1, k1 l1^2 + k2 l2^2]] (file data:
    m = 10, I = 2, k1 = 2000, k2 = 3000, l1 = 0.6, l2 = 0.5 -> K = [[5000, 300], [300, 1470]])."""
    model = mechsys.load(BEAM)
    lin = linearize_at(model, {"y": 0.0, "phi": 0.0})
    m, I, k1, k2, l1, l2 = 10, 2, 2000, 3000, 0.6, 0.5
    assert lin.M == pytest.approx(np.diag([m, I]), rel=1e-12)
    K = np.array([[k1 + k2, k2 * l2 - k1 * l1], [k2 * l2 - k1 * l1, k1 * l1**2 + k2 * l2**2]])
    assert lin.K == pytest.approx(K, rel=1e-9)
    assert lin.C == pytest.approx(np.zeros((2, 2)), abs=1e-9)
    assert lin.G == pytest.approx(np.zeros((2, 2)), abs=1e-9)
    assert lin.N == pytest.approx(np.zeros((2, 2)), abs=1e-9)
    modes = vibration_modes(model, at={"y": 0.0, "phi": 0.0})
    w2 = sla.eigh(K, np.diag([m, I]), eigvals_only=True)
    assert modes.frequencies == pytest.approx(np.sqrt(w2), rel=1e-9)


def test_beam_two_springs_decouples_when_k1l1_equals_k2l2():
    """E001-3: if k1 l1 = k2 l2 (l2 = 0.4: 2000*0.6 = 3000*0.4) then w1^2 = (k1+k2)/m = 500 (pure bounce y) and
    w2^2 = (k1 l1^2 + k2 l2^2)/I = 600 (pure pitch phi)."""
    model = load(BEAM, l2=0.4)
    modes = vibration_modes(model, at={"y": 0.0, "phi": 0.0})
    assert modes.coordinates == ["y", "phi"]
    assert modes.frequencies == pytest.approx([math.sqrt(500.0), math.sqrt(600.0)], rel=1e-9)
    assert modes.frequencies_hz == pytest.approx(np.array([math.sqrt(500.0), math.sqrt(600.0)]) / (2 * math.pi),
                                                 rel=1e-9)
    shapes = np.asarray(modes.shapes)
    assert shapes.shape == (2, 2)
    assert abs(shapes[0, 0]) == pytest.approx(1 / math.sqrt(10), rel=1e-9) and abs(shapes[1, 0]) <= 1e-9
    assert abs(shapes[1, 1]) == pytest.approx(1 / math.sqrt(2), rel=1e-9) and abs(shapes[0, 1]) <= 1e-9
    assert list(modes.rigid_body) == [False, False]


# ================================================================================ E001-4 cart pendulum
def test_cart_pendulum_frequencies_and_mode_ratios():
    """E001-4 (2.55) with m1 = m2 = 1, R = 1, r = 0.1, k = 10, g = 9.81: M = [[m1+m2, m2 R], [m2 R, m2 R^2 + I]],
    K = diag(2k, m2 g R), I = 2/5 m2 r^2; w = 2.40720, 5.79571 rad/s; mode ratios phi/x = 1.45148 (in phase),
    -1.40459 (anti-phase) [DERIVED]. Default 'at': the stable rest it settles at, (x, phi) = (0, 0)."""
    model = load(SYSTEMS / "cart_pendulum.yaml", m1=1, m2=1, R=1, r=0.1, k=10, g=9.81)
    modes = vibration_modes(model)
    assert modes.coordinates == ["x", "phi"]
    assert modes.frequencies == pytest.approx([2.40720, 5.79571], abs=1e-5)
    shapes = np.asarray(modes.shapes)
    assert shapes[1, 0] / shapes[0, 0] == pytest.approx(1.45148, abs=1e-5)
    assert shapes[1, 1] / shapes[0, 1] == pytest.approx(-1.40459, abs=1e-5)
    I = 0.4 * 0.1**2
    M = np.array([[2.0, 1.0], [1.0, 1.0 + I]])
    assert_mass_normalised(shapes, M)
    lin = linearize_at(model, {"x": 0.0, "phi": 0.0})
    assert lin.M == pytest.approx(M, rel=1e-12)
    assert lin.K == pytest.approx(np.diag([20.0, 9.81]), rel=1e-9)


# ================================================================================ E001-8 beads on a string
def test_beads_on_taut_string():
    """E001-8: K = (4T/l)[[2,-1,0],[-1,2,-1],[0,-1,2]], M = m I; w^2 = (4T/(m l)){2 - sqrt2, 2, 2 + sqrt2};
    modes [1, sqrt2, 1], [1, 0, -1], [1, -sqrt2, 1]. Data m = 0.1, T = 100, l = 1 -> 4T/(m l) = 4000."""
    model = mechsys.load(DATA / "beads_string.yaml")
    at = {"y1": 0.0, "y2": 0.0, "y3": 0.0}
    lin = linearize_at(model, at)
    assert lin.K == pytest.approx(400.0 * np.array([[2, -1, 0], [-1, 2, -1], [0, -1, 2]]), rel=1e-9, abs=1e-9)
    assert lin.M == pytest.approx(0.1 * np.eye(3), rel=1e-12)
    modes = vibration_modes(model, at=at)
    s2 = math.sqrt(2)
    assert modes.frequencies**2 == pytest.approx(4000.0 * np.array([2 - s2, 2, 2 + s2]), rel=1e-9)
    assert modes.frequencies**2 / 4000.0 == pytest.approx([0.585786, 2.0, 3.414214], abs=1e-6)
    shapes = np.asarray(modes.shapes)
    for k, ref in enumerate([[1, s2, 1], [1, 0, -1], [1, -s2, 1]]):
        assert_parallel(shapes[:, k], ref)
    assert_mass_normalised(shapes, 0.1 * np.eye(3))
    assert list(modes.rigid_body) == [False, False, False]


# ================================================================================ E001-10 winch, condensation
WINCH = DATA / "winch_gear.yaml"
WP = dict(m=100.0, k=2.0e5, R=0.3, I1=5.0, c=50.0, ks1=1.0e5, ks2=4.0e4, i=3.0, I2=0.5)


def winch_condensed():
    """The digest's condensed E001-10 model on (x, phi1, phi2) [DERIVED, sympy-verified]."""
    p = WP
    ke = p["ks1"] * p["ks2"] / (p["ks1"] + p["i"] ** 2 * p["ks2"])
    k, R, i = p["k"], p["R"], p["i"]
    K = np.array([[k, -k * R, 0.0], [-k * R, k * R**2 + i**2 * ke, -i * ke], [0.0, -i * ke, ke]])
    M = np.diag([p["m"], p["I1"], p["I2"]])
    C = np.diag([0.0, p["c"] * R**2, 0.0])
    return M, C, K


def alpha1_of(phi1, phi2):
    """(2.66): alpha1 = (ks1 phi1 + i ks2 phi2)/(ks1 + ks2 i^2)."""
    p = WP
    return (p["ks1"] * phi1 + p["i"] * p["ks2"] * phi2) / (p["ks1"] + p["ks2"] * p["i"] ** 2)


AT_REST = {"x": 0.0, "phi1": 0.0, "phi2": 0.0, "alpha1": 0.0}


def test_winch_linearization_keeps_the_massless_gear_and_condenses_to_the_digest_K():
    """E001-10: over all four free coordinates (x, phi1, phi2, alpha1) the mass matrix has a zero row/column for the
    massless gear; statically condensing alpha1 out of K gives exactly the digest's 3x3 K, and C = diag(0, c R^2, 0)."""
    model = mechsys.load(WINCH)
    lin = linearize_at(model, AT_REST, tol=2e-2)
    M3, C3, K3 = winch_condensed()
    assert np.asarray(lin.M).shape == (4, 4)
    assert lin.M[:3, :3] == pytest.approx(M3, rel=1e-12)
    assert np.abs(np.asarray(lin.M)[3, :]).max() == 0 and np.abs(np.asarray(lin.M)[:, 3]).max() == 0
    assert lin.C[:3, :3] == pytest.approx(C3, abs=1e-9)
    K = np.asarray(lin.K, dtype=float)
    condensed = K[:3, :3] - K[:3, 3:] @ np.linalg.solve(K[3:, 3:], K[3:, :3])
    assert condensed == pytest.approx(K3, rel=1e-9, abs=1e-9 * np.abs(K3).max())


def test_winch_modes_condense_the_massless_gear():
    """E001-10: modes of the model with the gear kept at mass 0 equal those of the condensed model; the drive train
    turns freely as a whole (x = R phi1, phi2 = i phi1: K3 is singular), so the lowest mode is rigid. Shapes cover all
    four coordinates, with the gear row recovered from (2.66); phi^T M phi = I on the retained coordinates."""
    model = mechsys.load(WINCH)
    modes = vibration_modes(model, at=AT_REST)
    M3, C3, K3 = winch_condensed()
    w2 = sla.eigh(K3, M3, eigvals_only=True)
    expected = np.sqrt(np.clip(w2, 0.0, None))
    assert modes.coordinates == ["x", "phi1", "phi2", "alpha1"]
    assert len(modes.frequencies) == 3
    assert abs(modes.frequencies[0]) <= 1e-6 * expected[-1]
    assert modes.frequencies[1:] == pytest.approx(expected[1:], rel=1e-9)
    assert list(modes.rigid_body) == [True, False, False]
    shapes = np.asarray(modes.shapes)
    assert shapes.shape == (4, 3)
    assert_parallel(shapes[:3, 0], [WP["R"], 1.0, WP["i"]])      # rigid rotation of the whole train
    for k in range(3):
        assert shapes[3, k] == pytest.approx(alpha1_of(shapes[1, k], shapes[2, k]), rel=1e-9,
                                             abs=1e-12 * np.abs(shapes[:, k]).max())
        assert K3 @ shapes[:3, k] == pytest.approx(modes.frequencies[k] ** 2 * (M3 @ shapes[:3, k]), rel=1e-7,
                                                   abs=1e-7 * np.abs(K3).max() * np.abs(shapes[:3, k]).max())
    assert_mass_normalised(shapes[:3], M3)


# ================================================================================ E004-8 two-mass chain
def test_two_mass_chain_modes_about_the_gravity_equilibrium():
    """E004-8: m1 = m2 = m, k1 = k2 = k: w^2 = (k/m)(3 -+ sqrt5)/2 = 0.381966 k/m and 2.618034 k/m, modes
    [1, 1.618034] (in phase) and [1, -0.618034] (anti-phase); E004-4: about the static equilibrium under gravity
    the deflection cancels. Default 'at' = the stable rest it settles at (x1 = -2mg/k, x2 = -3mg/k)."""
    model = mechsys.load(DATA / "two_mass_chain.yaml")
    m, k = 1.0, 100.0
    for at in (None, {"x1": -2 * 9.81 / 100, "x2": -3 * 9.81 / 100}):
        modes = vibration_modes(model, at=at)
        assert modes.frequencies**2 == pytest.approx([(3 - 5**0.5) / 2 * k / m, (3 + 5**0.5) / 2 * k / m], rel=1e-9)
        assert modes.frequencies**2 * m / k == pytest.approx([0.381966, 2.618034], abs=1e-6)
        shapes = np.asarray(modes.shapes)
        assert shapes[1, 0] / shapes[0, 0] == pytest.approx(1.618034, abs=1e-6)
        assert shapes[1, 1] / shapes[0, 1] == pytest.approx(-0.618034, abs=1e-6)
        assert_mass_normalised(shapes, m * np.eye(2))


# ================================================================================ free-free chain: rigid mode
def test_free_free_chain_has_one_rigid_body_mode():
    """E001-6 / §001.3: a free-free chain (no spring to ground) has a zero-frequency rigid-body mode. Here
    M = diag(1, 2, 1), K = 100[[1,-1,0],[-1,2,-1],[0,-1,1]]: w = 0, 10, sqrt(200); modes [1,1,1] (rigid),
    [1,0,-1], [1,-1,1]; mass normalisation gives the rigid mode 0.5*[1,1,1]."""
    model = mechsys.load(DATA / "free_free_chain.yaml")
    modes = vibration_modes(model, at={"x1": 0.0, "x2": 0.0, "x3": 0.0})
    assert len(modes.frequencies) == 3
    assert abs(modes.frequencies[0]) <= 1e-6
    assert modes.frequencies[1:] == pytest.approx([10.0, math.sqrt(200.0)], rel=1e-9)
    assert list(modes.rigid_body) == [True, False, False]
    shapes = np.asarray(modes.shapes)
    assert np.abs(shapes[:, 0]) == pytest.approx([0.5, 0.5, 0.5], rel=1e-9)
    assert_parallel(shapes[:, 1], [1, 0, -1])
    assert_parallel(shapes[:, 2], [1, -1, 1])
    assert_mass_normalised(shapes, np.diag([1.0, 2.0, 1.0]))


def test_free_free_chain_rest_points_are_not_asymptotically_stable_or_unstable():
    """§001.3: the singular K gives a double eigenvalue 0 of A; 'classification must not call this unstable or
    asymptotically stable'."""
    from mechsys.analysis.equilibrium.equilibria import find_equilibria

    model = mechsys.load(DATA / "free_free_chain.yaml")
    res = find_equilibria(model, search={"x1": (-0.05, 0.05), "x2": (-0.05, 0.05), "x3": (-0.05, 0.05)})
    assert res.equilibria, res.message
    for e in res.equilibria:
        assert e.stability not in ("asymptotically stable", "unstable"), (e.coordinates, e.eigenvalues, e.reason)
        assert e.critical


# ================================================================================ indicator: damped 1-DOF
def test_indicator_small_oscillation_frequency_and_damping_ratio():
    """Part-2 digest §2.4 (7.13)-(7.22), Iz = 0.8, Omega = 150, omega1 = -10 about beta = 0: C = 20, B = c/Ix = 0.4,
    roots -0.2 +- 4.467662 i, so w_n = sqrt(C) = 4.472136 rad/s and zeta = B/(2 sqrt C) = 0.0447214."""
    model = load(SYSTEMS / "indicator.yaml", Iz=0.8, Omega=150, omega1=-10)
    modes = vibration_modes(model, at={"beta": 0.0})
    assert modes.coordinates == ["beta"]
    assert modes.frequencies == pytest.approx([math.sqrt(20.0)], rel=1e-9)
    assert modes.damping_ratios == pytest.approx([0.4 / (2 * math.sqrt(20.0))], rel=1e-9)
    assert_mass_normalised(modes.shapes, np.array([[0.5]]))


# ================================================================================ E002-1 principal inertia
@pytest.mark.parametrize("sign", [-1.0, 1.0])
def test_principal_moments_of_inertia(sign):
    """E002-1: I = [[20, -+2, 0], [-+2, 30, 0], [0, 0, 40]] -> 19.614835, 30.385165, 40 (= 25 -+ sqrt29, 40);
    axis of 19.615: +-(0.98196, 0.18911, 0) for the -2 entry, (0.98196, -0.18911, 0) for +2."""
    from mechsys.analysis.inertia import principal_inertia

    I = np.array([[20.0, 2 * sign, 0.0], [2 * sign, 30.0, 0.0], [0.0, 0.0, 40.0]])
    moments, axes = principal_inertia(I)
    assert moments == pytest.approx([19.614835, 30.385165, 40.0], abs=1e-6)
    assert moments == pytest.approx([25 - math.sqrt(29), 25 + math.sqrt(29), 40.0], rel=1e-12)
    axes = np.asarray(axes)
    assert axes.T @ axes == pytest.approx(np.eye(3), abs=1e-12)
    assert I @ axes == pytest.approx(axes @ np.diag(moments), abs=1e-10)
    a = axes[:, 0] * np.sign(axes[0, 0])
    assert a == pytest.approx([0.98196, -0.18911 * sign, 0.0], abs=1e-5)


def test_principal_inertia_repeated_moments():
    """seeds001_004 §002.3: axisymmetric bodies have repeated principal moments; the axes are not unique, but an
    orthonormal basis must be returned without failure."""
    from mechsys.analysis.inertia import principal_inertia

    I = np.diag([2.0, 5.0, 2.0])
    moments, axes = principal_inertia(I)
    assert moments == pytest.approx([2.0, 2.0, 5.0], abs=1e-12)
    axes = np.asarray(axes)
    assert axes.T @ axes == pytest.approx(np.eye(3), abs=1e-12)
    assert I @ axes == pytest.approx(axes @ np.diag(moments), abs=1e-12)
