"""Forward dynamics (mechsys.analysis.motion.simulate) against the textbook digests.

Sources (/work/shared/reference):
- seed000_part1_digest.md, P1 (motor-driven arm, Krodkiewski p. 19-24, eqs (1.43)-(1.44));
- seed000_part2_digest.md, §2.2 centrifuge (CEN-f, eqs (5.16)-(5.21)), §2.3 gyrostabilizer (GYR-b, GYR-c, eq. (6.23)),
  §2.4 indicator (IND-e, Fig. 12, eq. (7.8)), §3 hard cases 5, 6, 8;
- seeds001_004_digest.md: 003.3 (closed loops: projection, |C| < tol), 004.3 (heavily overdamped: stiff ODE;
  energy drift), 001 hard cases (stiffness disparity).

Besides the digest's numbers, every textbook scene is also compared with an independent integration (scipy, tight
tolerances) of the book's own equations of motion as printed in the digest, so a wrong derivation and a wrong
integration are both caught. Sample times are always points of the output grid (checked), never nearest neighbours:
the centrifuge oscillates at ~8 rad/s and a 0.2 s offset moves beta by 0.1 rad.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import double_pendulum_accelerations, load_data, load_system
from scipy.integrate import solve_ivp

from mechsys.analysis.motion.simulate import simulate

REF = dict(method="DOP853", rtol=1e-13, atol=1e-14)  # the "tight reference" settings of the brief / mechsys bench


# ----------------------------------------------------------------------------------------------------- helpers
def at(r, t: float) -> int:
    """Index of output time t (must be a grid point)."""
    i = int(np.argmin(np.abs(r.t - t)))
    assert abs(r.t[i] - t) < 1e-9, f"t = {t} is not an output time (nearest {r.t[i]})"
    return i


def col(r, name: str) -> int:
    return r.coordinates.index(name)


def book_trajectory(rhs, y0, t) -> np.ndarray:
    """Independent reference: the book's EOM integrated by scipy at tight tolerances, sampled at t."""
    sol = solve_ivp(rhs, (t[0], t[-1]), y0, method="DOP853", rtol=1e-12, atol=1e-13, t_eval=t)
    assert sol.success, sol.message
    return sol.y.T


def assert_traj_close(got: np.ndarray, want: np.ndarray, tol: float, what: str) -> None:
    """|got - want| <= tol * max(1, max |want|) column by column (absolute for O(1) columns)."""
    scale = np.maximum(1.0, np.max(np.abs(want), axis=0))
    err = np.max(np.abs(got - want), axis=0) / scale
    assert np.all(err <= tol), f"{what}: scaled max errors per column {err} > {tol}"


def upcrossings(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Times where x crosses zero upwards (linear interpolation between output points)."""
    i = np.where((x[:-1] < 0) & (x[1:] >= 0))[0]
    return t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])


# ----------------------------------------------------------------------------------------------------- P1
# digest part 1, P1: m = 5, a = 0.2, l = 0.4, Mo = 1, dM = 0.2; beta(0) = beta'(0) = omega(0) = 0.
# "The simulation gives beta(20 s) = 0.7550 and omega(20 s) = 4.8974 ... t = 10 s -> (0.6561, 4.5963);
#  t = 30 s -> (0.7724, 4.9821); t = 100 s -> (0.778897, 5.000006)"; exact equilibrium beta_o = 0.778899, omega_o = 5.
P1_DIGEST = {10.0: (0.6561, 4.5963), 20.0: (0.7550, 4.8974), 30.0: (0.7724, 4.9821)}


@pytest.fixture(scope="module")
def p1_run():
    model = load_system("motor_arm")
    return simulate(model, 100.0, dt=0.1)


def test_p1_motor_arm_beta_and_omega_at_20s(p1_run):
    r = p1_run
    i = at(r, 20.0)
    beta, omega = r.q[i, col(r, "beta")], r.u[i, col(r, "alpha")]
    assert abs(beta - 0.755) <= 0.005  # the book's plot reading, as the digest's test suggests
    assert abs(omega - 4.8974) <= 1e-3
    # the digest prints 4 decimals: its own rounding is the tolerance
    for t, (beta_d, omega_d) in P1_DIGEST.items():
        i = at(r, t)
        assert abs(r.q[i, col(r, "beta")] - beta_d) <= 5e-5, (t, r.q[i], beta_d)
        assert abs(r.u[i, col(r, "alpha")] - omega_d) <= 5e-5, (t, r.u[i], omega_d)


def test_p1_motor_arm_settles_at_the_exact_equilibrium_by_100s(p1_run):
    r = p1_run
    i = at(r, 100.0)
    beta, omega = r.q[i, col(r, "beta")], r.u[i, col(r, "alpha")]
    assert abs(beta - 0.778899) <= 1e-4 and abs(omega - 5.0) <= 1e-4
    # the digest's simulated values at t = 100 s, 6 decimals
    assert abs(beta - 0.778897) <= 1e-6 and abs(omega - 5.000006) <= 1e-6
    assert abs(r.u[i, col(r, "beta")]) <= 1e-4


def test_p1_motor_arm_trajectory_matches_book_eom_1_43():
    """(1.43) with J = m l^2/12 + m (l/2)^2, state (alpha, beta, omega, beta')."""
    m, a, l, Mo, dM, g = 5.0, 0.2, 0.4, 1.0, 0.2, 9.81
    J = m * l**2 / 12 + m * (l / 2) ** 2

    def rhs(t, y):
        _alpha, b, w, bd = y
        s, c = math.sin(b), math.cos(b)
        wd = ((Mo - dM * w) - (2 * J * s * c + m * l * a * c) * w * bd) / (m * a**2 + J * s**2 + m * a * l * s)
        bdd = (J * w**2 * s * c + m * a * (l / 2) * w**2 * c - m * g * (l / 2) * s) / J
        return [w, bd, wd, bdd]

    r = simulate(load_system("motor_arm"), 20.0, dt=0.05)
    assert r.coordinates == ["alpha", "beta"]
    want = book_trajectory(rhs, [0.0, 0.0, 0.0, 0.0], r.t)
    assert_traj_close(np.column_stack([r.q, r.u]), want, 1e-7, "P1 vs (1.43)")


# ----------------------------------------------------------------------------------------------------- centrifuge
# digest part 2 §2.2: I1 = 2.5, m = 8, I2x = I2y = 2, I2z = 0.2, a = 0.3, l = 0.5, Mo = 50, dM = 50/7 -> omega_s = 7.
# Simulations (Figs 6, 7), initial (beta, omega, Omega)(0):
#   (0, 0, -2.5) -> beta_s2 = -1.249420; "by t = 40 s: beta = -1.2493, Omega ~ 0.0019. Settled to 1e-6 by t ~ 100 s"
#   (0, 0, 0)    -> beta_s4 = 1.410445; "beta(40) ~ 1.394, beta(100) ~ 1.399, beta(600) = 1.410446"
BETA_S2, BETA_S4 = -1.249420, 1.410445


def centrifuge_rhs():
    """Book reduced state form (5.17)-(5.21), state (beta, omega, Omega = beta')."""
    I1, m, I2x, I2y, I2z, a, l, g, Mo = 2.5, 8.0, 2.0, 2.0, 0.2, 0.3, 0.5, 9.81, 50.0
    dM = Mo / 7
    B, C, D = -2 * (I2y - I2z + m * l**2), -2 * m * a * l, I2x + m * l**2
    E, F, G = I2y - I2z + m * l**2, m * a * l, -m * g * l

    def rhs(t, x):
        b, w, W = x
        s, c = math.sin(b), math.cos(b)
        A = (I1 + m * a**2) + (I2y + m * l**2) * s**2 + 2 * m * a * l * s + I2z * c**2
        return [W, (B * W * w * s * c + C * W * w * c + Mo - dM * w) / A, (E * w**2 * s * c + F * w**2 * c + G * s) / D]

    return rhs


def test_cen_f_file_default_start_is_fig7_omega_minus_2p5():
    model = load_system("centrifuge")
    assert model.coordinates == ["alpha", "beta"]
    assert model.doc.initial == {"alpha": 0.0, "beta": 0.0}
    assert model.doc.initial_rate == {"alpha": 0.0, "beta": -2.5}  # (beta, omega, Omega) = (0, 0, -2.5)


def test_cen_f_from_omega_minus_2p5_settles_at_beta_s2():
    r = simulate(load_system("centrifuge"), 100.0, dt=0.1)
    b, a = col(r, "beta"), col(r, "alpha")
    i40, i100 = at(r, 40.0), at(r, 100.0)
    assert abs(r.q[i40, b] - (-1.2493)) <= 5e-5 and abs(r.u[i40, b] - 0.0019) <= 5e-5
    # "settled to 1e-6 by t ~ 100 s" (+ the half unit of the printed 6th decimal)
    assert abs(r.q[i100, b] - BETA_S2) <= 1e-6 + 5e-7
    assert abs(r.u[i100, a] - 7.0) <= 1e-6 and abs(r.u[i100, b]) <= 1e-6
    assert abs(r.q[-1, b] - BETA_S2) <= 1e-3  # the brief's tolerance


@pytest.mark.slow
def test_cen_f_from_rest_slowly_settles_at_beta_s4_600s():
    """Hard case 6: Re = -0.018968 at beta_s4, ~600 s to settle to 1e-4 (about 20 s of wall time)."""
    r = simulate(load_system("centrifuge", {"der(beta)": "0"}), 600.0, dt=0.5)
    b, a = col(r, "beta"), col(r, "alpha")
    assert r.q[0, b] == 0.0 and r.u[0, b] == 0.0 and r.u[0, a] == 0.0
    i40, i100 = at(r, 40.0), at(r, 100.0)
    assert abs(r.q[i40, b] - 1.394) <= 5e-4 and abs(r.q[i100, b] - 1.399) <= 5e-4  # digest "~", 3 decimals
    assert abs(r.q[-1, b] - BETA_S4) <= 1e-3
    assert abs(r.q[-1, b] - 1.410446) <= 1e-6  # digest: beta(600) = 1.410446
    assert abs(r.u[-1, a] - 7.0) <= 1e-4 and abs(r.u[-1, b]) <= 1e-3


@pytest.mark.parametrize("omega0", [-2.5, 0.0], ids=["Omega0=-2.5", "Omega0=0"])
def test_cen_f_trajectory_matches_book_reduced_eom_5_17(omega0):
    r = simulate(load_system("centrifuge", {"der(beta)": repr(omega0)}), 40.0, dt=0.05)
    b, a = col(r, "beta"), col(r, "alpha")
    want = book_trajectory(centrifuge_rhs(), [0.0, 0.0, omega0], r.t)
    got = np.column_stack([r.q[:, b], r.u[:, a], r.u[:, b]])
    assert_traj_close(got, want, 1e-7, f"centrifuge vs (5.17)-(5.21), Omega(0) = {omega0}")


# ----------------------------------------------------------------------------------------------------- gyrostabilizer
# digest part 2 §2.3. The file reads the printed "m2a2+m3a3 = 1e3" as S = 1e3 kg m (S*g = 9810 N m): the digest's main
# variant. The other reading (S*g = 1e3 N m) is reached with S = 1e3/g.
GYRO_VARIANTS = {
    # Omega = 0: period, max alpha, up-crossings;  Omega = 300: max alpha, min beta
    "Sg=9810 (file)": dict(S=None, T=29.93, max_a0=0.4740, up=(29.93, 59.85, 89.78, 119.71), max_a=0.14440,
                           min_b=-1.3403),
    "Sg=1e3": dict(S=repr(1e3 / 9.81), T=29.94, max_a0=0.4743, up=None, max_a=0.1434, min_b=-1.361),
}


def test_gyr_file_uses_S_1e3_kg_m():
    model = load_system("gyrostabilizer")
    assert model.parameters["S"] == pytest.approx(1e3) and model.parameters["g"] == pytest.approx(9.81)
    assert model.parameters["Omega"] == pytest.approx(300.0)
    assert model.doc.initial_rate == {"alpha": 0.1, "beta": 0.0}  # (6.27)


@pytest.mark.parametrize("variant", list(GYRO_VARIANTS))
def test_gyr_b_omega0_housing_never_moves_and_ship_period(variant):
    v = GYRO_VARIANTS[variant]
    over = {"Omega": "0", **({"S": v["S"]} if v["S"] else {})}
    r = simulate(load_system("gyrostabilizer", over), 130.0, dt=0.01)
    a, b = col(r, "alpha"), col(r, "beta")
    assert np.max(np.abs(r.q[:, b])) < 1e-12 and np.max(np.abs(r.u[:, b])) < 1e-12  # beta = beta' = 0 is invariant
    up = upcrossings(r.t, r.q[:, a])
    assert len(up) == 4
    periods = np.diff(up)
    assert np.all(np.abs(periods - v["T"]) <= 0.05)  # the brief's tolerance
    assert np.all(np.abs(periods - v["T"]) <= 0.005 + 1e-3)  # the digest's 2 decimals (+ interpolation)
    if v["up"]:
        assert np.all(np.abs(up - np.array(v["up"])) <= 0.005 + 1e-3), up
    assert abs(np.max(np.abs(r.q[:, a])) - v["max_a0"]) <= 5e-5
    # undamped ship mode: no decay (every swing reaches the same amplitude)
    peaks = [np.max(r.q[(r.t >= s) & (r.t < s + 29.9), a]) for s in (0.0, 30.0, 60.0, 90.0)]
    assert np.ptp(peaks) <= 1e-6


@pytest.mark.parametrize("variant", list(GYRO_VARIANTS))
def test_gyr_c_omega300_reduced_swing_and_decay(variant):
    v = GYRO_VARIANTS[variant]
    r = simulate(load_system("gyrostabilizer", {"S": v["S"]} if v["S"] else None), 200.0, dt=0.01)
    a, b = col(r, "alpha"), col(r, "beta")
    alpha, beta = r.q[:, a], r.q[:, b]
    assert abs(alpha.max() - v["max_a"]) <= 0.02 * v["max_a"]  # the brief's +-2 %
    assert abs(beta.min() - v["min_b"]) <= 1e-3
    # alpha, beta -> 0: the slowest mode decays like exp(-0.0198 t) (digest §2.3.4: Re = -0.019777, or -0.020077 for
    # Sg = 1e3), so over 150 s the envelope shrinks to 0.05; a factor 2 is left for the mix of modes
    early, late = r.t < 50.0, r.t >= 150.0
    for x in (alpha, beta):
        assert np.max(np.abs(x[late])) <= 2 * math.exp(-0.0198 * 150) * np.max(np.abs(x[early]))
    if v["S"] is None:  # the digest's detailed samples are for Sg = 9810
        assert abs(alpha[at(r, 200.0)]) < 1e-3
        assert abs(alpha.max() - 0.14440) <= 1e-5
        assert abs(r.t[np.argmax(alpha)] - 5.47) <= 0.01 and abs(r.t[np.argmin(beta)] - 4.75) <= 0.01
        for t, want in {10.0: 0.0957, 20.0: 0.0460, 50.0: 0.0120}.items():
            assert abs(alpha[at(r, t)] - want) <= 5e-5, (t, alpha[at(r, t)], want)
        for t, want in {30.0: -0.054, 75.0: 0.281, 200.0: -0.007}.items():
            assert abs(beta[at(r, t)] - want) <= 5e-4, (t, beta[at(r, t)], want)


@pytest.mark.parametrize("spin", [0.0, 300.0], ids=["Omega=0", "Omega=300"])
def test_gyr_a_trajectory_matches_book_eom_6_23(spin):
    """(6.23) with Mr = -Mro sin(alpha), Mb = -k beta - c beta' (6.24)-(6.26), S = m2a2 + m3a3 = 1e3, g = 9.81."""
    I1y, I2x, I2y, I2z, I3, I3z = 198.5e6, 0.2e6, 0.1e6, 0.2e6, 0.1e6, 0.05e6
    Mro, Sg, k, c = 9.0e6, 1e3 * 9.81, 1.0e4, 1.0e6

    def rhs(t, y):
        al, be, ad, bd = y
        sb, cb = math.sin(be), math.cos(be)
        m11 = I1y + (I2y + I3) * cb**2 + (I2z + I3z) * sb**2
        f1 = -((I2z - I2y + I3z - I3) * ad * bd * math.sin(2 * be) - I3z * spin * bd * cb
               + Sg * cb * math.sin(al) + Mro * math.sin(al))
        f2 = -(0.5 * (I3 - I3z + I2y - I2z) * ad**2 * math.sin(2 * be) + I3z * spin * ad * cb
               + Sg * math.cos(al) * sb + k * be + c * bd)
        return [ad, bd, f1 / m11, f2 / (I2x + I3)]

    r = simulate(load_system("gyrostabilizer", {"Omega": repr(spin)}), 40.0, dt=0.02)
    assert r.coordinates == ["alpha", "beta"]
    want = book_trajectory(rhs, [0.0, 0.0, 0.1, 0.0], r.t)
    assert_traj_close(np.column_stack([r.q, r.u]), want, 1e-7, f"gyrostabilizer vs (6.23), Omega = {spin}")


# ----------------------------------------------------------------------------------------------------- indicator
# digest part 2 §2.4 / §3 item 5, Fig. 12: Iz = 0.8, Omega = 150, omega1 = -10: beta = 0 stable (C = 20), beta = pi
# stable (C = 60), beta = pi/3 unstable (C = -30); B = c/Ix = 0.4. "1.0471 vs 1.0473 differ too."
IND_FIG12 = {"Iz": "0.8", "Omega": "150", "omega1": "-10"}


@pytest.mark.parametrize("beta0, target", [(math.pi / 3 - 0.01, 0.0), (math.pi / 3 + 0.01, math.pi),
                                           (1.0471, 0.0), (1.0473, math.pi)],
                         ids=["pi/3-0.01", "pi/3+0.01", "1.0471", "1.0473"])
def test_ind_e_fig12_two_attractors_either_side_of_pi_over_3(beta0, target):
    r = simulate(load_system("indicator", {**IND_FIG12, "beta": repr(beta0), "der(beta)": "0"}), 80.0)
    assert r.coordinates == ["beta"]
    assert r.q[0, 0] == pytest.approx(beta0, abs=1e-15)
    assert abs(r.q[-1, 0] - target) <= 1e-3 and abs(r.u[-1, 0]) <= 1e-3
    # it leaves the separatrix on its own side and never crosses it back (no overshoot beyond the unstable point)
    side = np.sign(beta0 - math.pi / 3)
    assert np.all(side * (r.q[1:, 0] - math.pi / 3) > 0)


def test_ind_a_trajectory_matches_book_eom_7_8():
    Ix, Iy, Iz, I3z, Om, w1, MG, c = 0.5, 0.6, 0.8, 0.01, 150.0, -10.0, 5.0, 0.2

    def rhs(t, y):
        b, bd = y
        return [bd, -((Iz - Iy) * w1**2 * math.sin(b) * math.cos(b) + I3z * Om * w1 * math.sin(b)
                      + MG * math.sin(b) + c * bd) / Ix]

    r = simulate(load_system("indicator", {**IND_FIG12, "beta": "0.5", "der(beta)": "2"}), 30.0, dt=0.02)
    want = book_trajectory(rhs, [0.5, 2.0], r.t)
    assert_traj_close(np.column_stack([r.q, r.u]), want, 1e-7, "indicator vs (7.8)")


# ----------------------------------------------------------------------------------------------------- double pendulum
def test_double_pendulum_energy_drift_10s_default_settings():
    r = simulate(load_system("double_pendulum"), 10.0)
    assert r.method in ("native", "DOP853")  # not stiff: the compiled DOP853 loop when a compiler exists
    assert np.allclose(r.t, np.linspace(0.0, 10.0, 1001), rtol=0, atol=1e-12)  # default output step t_end/1000
    assert r.q.shape == r.u.shape == (1001, 2) and r.coordinates == ["theta1", "theta2"]
    assert r.energy_drift <= 1e-9
    assert np.max(np.abs(r.residual)) == 0.0  # no constraints


def test_double_pendulum_matches_tight_reference_2s():
    model = load_system("double_pendulum")
    r = simulate(model, 2.0)
    ref = simulate(model, 2.0, **REF)
    assert ref.method == "DOP853" and np.array_equal(r.t, ref.t)
    assert np.max(np.abs(r.q - ref.q)) <= 1e-6 and np.max(np.abs(r.u - ref.u)) <= 1e-6


def test_double_pendulum_matches_file_header_eom_2s():
    """The equations written in systems/double_pendulum.yaml (relative second angle), integrated independently."""
    m1, m2, l1, l2, g = 1.0, 0.8, 0.6, 0.5, 9.81

    def rhs(t, y):
        return [y[2], y[3], *double_pendulum_accelerations(y[:2], y[2:], m1, m2, l1, l2, g)]

    r = simulate(load_system("double_pendulum"), 2.0)
    want = book_trajectory(rhs, [0.5, 0.3, 0.0, 0.0], r.t)
    assert_traj_close(np.column_stack([r.q, r.u]), want, 1e-7, "double pendulum vs header EOM")


# ----------------------------------------------------------------------------------------------------- four-bar
def four_bar_checks(r, drift: float = 1e-9) -> None:
    assert r.coordinates == ["theta2", "theta3", "theta4"]
    assert np.max(r.residual) <= 1e-10
    assert r.energy_drift <= drift
    # the linkage really moves (a frozen result would pass the two checks above)
    assert np.ptp(r.q[:, 0]) > 0.5


def test_four_bar_constraint_residual_and_energy_2s():
    r = simulate(load_system("four_bar"), 2.0)
    assert r.residual.shape == r.t.shape
    four_bar_checks(r)


@pytest.mark.slow
def test_four_bar_constraint_residual_and_energy_20s():
    """About 25 s of wall time: one solve_ivp call and one projection per output interval."""
    four_bar_checks(simulate(load_system("four_bar"), 20.0))


def test_four_bar_work_of_the_crank_torque_equals_energy_change():
    """Non-conservative check: E(t) - E(0) = M2 (theta2(t) - theta2(0)) for a constant crank torque M2."""
    r = simulate(load_system("four_bar", {"M2": "0.5"}), 1.0)
    assert np.max(r.residual) <= 1e-10
    work = 0.5 * (r.q[:, 0] - r.q[0, 0])
    assert np.max(np.abs(work)) > 0.1
    assert np.max(np.abs((r.E - r.E[0]) - work)) <= 1e-8 * max(1.0, float(np.max(np.abs(r.E))))


# ----------------------------------------------------------------------------------------------------- stiff chain
def test_stiff_overdamped_chain_auto_picks_implicit_and_stays_cheap():
    """tests/data/stiff_chain.yaml: k/m ~ 1e6 with c = k/100 (eigenvalues -2.9e4 ... -100 s^-1, all real).
    auto over 10 s must pick an implicit method and cost fewer RHS evaluations than RK45 needs for 1 s."""
    model = load_data("stiff_chain")
    r = simulate(model, 10.0)
    assert r.method in {"CVODE", "Radau", "BDF", "LSODA"}
    assert r.rhs_evaluations < 1e5
    rk = simulate(model, 1.0, dt=0.01, method="RK45")
    assert rk.rhs_evaluations > r.rhs_evaluations
    # the implicit result is as accurate as the explicit one where both exist (same output grid up to 1 s)
    n = len(rk.t)
    assert np.allclose(r.t[:n], rk.t)
    assert np.max(np.abs(r.q[:n] - rk.q)) <= 1e-10
    assert np.max(np.abs(r.q[-1])) <= 1e-12  # at rest after 10 s


# ----------------------------------------------------------------------------------------------------- cart pole
def cartpole_invariants(r, mc: float, m: float = 1.0, lc: float = 0.5) -> None:
    """No horizontal force: p_x = (mc + m) x' + m lc cos(theta) theta' stays 0; conservative: E constant."""
    x, th = col(r, "x"), col(r, "theta")
    p = (mc + m) * r.u[:, x] + m * lc * np.cos(r.q[:, th]) * r.u[:, th]
    assert np.max(np.abs(p)) <= 1e-8
    assert r.energy_drift <= 1e-9


def badly_conditioned_warning(r) -> bool:
    return any("badly conditioned" in w for w in r.warnings)


def test_cartpole_light_rod_never_silently_wrong():
    """tests/data/cartpole_light.yaml: cart 1e-6 kg, uniform rod. Either a warning or the tight reference to 1e-6."""
    model = load_data("cartpole_light")
    r = simulate(model, 2.0)
    cartpole_invariants(r, 1e-6)
    if not badly_conditioned_warning(r):
        ref = simulate(model, 2.0, **REF)
        assert_traj_close(np.column_stack([r.q, r.u]), np.column_stack([ref.q, ref.u]), 1e-6, "light cart pole")


def test_cartpole_light_point_mass_never_silently_wrong_1s():
    """J = 0 (point mass on a massless rod): det M -> mc m lc^2 = 2.5e-7 whenever the rod passes the vertical; the bob
    bounces vertically (period ~0.135 s) and the cart whips across at ~115 m/s. Either a warning or accurate."""
    model = load_data("cartpole_light", {"J": "0"})
    r = simulate(model, 1.0)
    cartpole_invariants(r, 1e-6)
    if not badly_conditioned_warning(r):
        ref = simulate(model, 1.0, **REF)
        assert_traj_close(np.column_stack([r.q, r.u]), np.column_stack([ref.q, ref.u]), 1e-6, "point-mass cart pole")


@pytest.mark.slow
def test_cartpole_light_point_mass_never_silently_wrong_2s():
    """As above over 2 s (15 bounces; ~12 s of wall time). Positions and invariants must match everywhere; the rates
    are compared where the rod is more than 0.05 rad from the vertical: at a bounce the rates swing through
    +-230 rad/s within microseconds, so a sample that falls on one measures timing (1e-10 s), not accuracy."""
    model = load_data("cartpole_light", {"J": "0"})
    r = simulate(model, 2.0)
    cartpole_invariants(r, 1e-6)
    if not badly_conditioned_warning(r):
        ref = simulate(model, 2.0, **REF)
        assert np.max(np.abs(r.q - ref.q)) <= 1e-6
        away = np.abs(ref.q[:, col(ref, "theta")]) > 0.05
        assert away.sum() > 0.5 * len(away)
        scale = np.max(np.abs(ref.u), axis=0)
        assert np.all(np.max(np.abs(r.u - ref.u)[away], axis=0) <= 1e-6 * scale)


@pytest.mark.slow
def test_lightly_damped_stiff_chain_auto_is_not_much_costlier_than_dop853():
    """systems/spring_chain.yaml with k/m ~ 1e6 (springs x1000) and the file's light dampers: eigenvalues
    -0.85 +- 727i, -2.5 +- 1333i, -3.3 +- 1706i s^-1, a ringing that must be resolved for ~27 s (until it is below
    atol) whatever the method: not stiff in the sense that helps an implicit method. Over 30 s the auto heuristic
    (spectral radius x horizon = 5.1e4 > 5e4) picks Radau. Whatever it picks, it must not cost much more than DOP853
    at the same settings. DOP853 is run as the compiled loop (scipy's DOP853 steps, tests/test_native.py; scipy's
    Python loop alone took ~25 s here); while auto picked Radau (measured: 6.33e6 RHS evaluations against 5.61e5)
    this test failed after ~10 min."""
    stiff = {"k1": "2e6", "k12": "1.5e6", "k23": "1e6", "k3": "8e5"}
    model = load_system("spring_chain", stiff)
    dop = simulate(model, 30.0, method="native")
    auto = simulate(model, 30.0)
    assert auto.rhs_evaluations <= 2 * dop.rhs_evaluations, (auto.method, auto.rhs_evaluations, dop.rhs_evaluations)
    assert np.max(np.abs(auto.q - dop.q)) <= 1e-8
