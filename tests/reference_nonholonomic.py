"""Independent reference derivations for the tests of nonholonomic steady motions and linearization.

Nothing here imports mechsys. Three references:

(a) Rolling axisymmetric wheel (knife edge, rolling without slip on a horizontal plane): the linearized lean
    dynamics about upright straight rolling and the critical speed above which that motion is stable.
(b) The same wheel in steady circular rolling at constant lean: the steady-turning condition (quadratic in the
    yaw rate), its roots, its residual, and a nonlinear ODE of the wheel to integrate from a steady state.
(c) The Whipple bicycle benchmark of Meijaard, Papadopoulos, Ruina & Schwab, Proc. R. Soc. A 463 (2007)
    1955-1982, doi:10.1098/rspa.2007.1857: the published M0, C1, K0, K2, weave and capsize speeds, its
    eigenvalues, sympy's own linearized A matrix (test_kane3.py) and a transcription of the paper's Table 2.

Wheel model and conventions (exactly those of systems/rolling_disk.yaml)
------------------------------------------------------------------------
Ground frame N: z up, gravity -g N.z. Heading frame H = N turned by the yaw psi about N.z. Lean frame
L = H turned by the lean theta about H.x. Wheel W = L turned by the wheel angle phi about L.y, its symmetry
axis. The geometric contact point C is on the ground; the centre is G = C + r L.z; the contact point seen from
the centre is [0, 0, -r] in lean axes. Rolling without slip: the material point of the wheel at C has zero
velocity, v_G + w_W x (-r L.z) = 0, with w_L = psi' N.z + theta' H.x and w_W = w_L + phi' L.y. Inertia about
G: Ia about L.y (symmetry axis), Id about any diameter; diag(Id, Ia, Id) in lean axes.

What the signs mean (x forward along H.x, y to the left, z up):
  * L.z = -sin(theta) H.y + cos(theta) H.z, so theta > 0 tilts the top of the wheel towards -H.y: the wheel
    leans to the RIGHT of its heading.
  * psi' > 0 turns the heading counter-clockwise seen from above: a LEFT turn.
  * spin = phi' (rate of W relative to L about L.y, i.e. der(spin) in the YAML). The contact point moves
    with v_C = r phi' H.x (so der(x) = r phi' cos(psi), der(y) = r phi' sin(psi), as the YAML says) and the
    centre with v_G = r (phi' + psi' sin(theta)) H.x: phi' > 0 rolls the wheel FORWARD along +H.x. The wheel's
    total spin about its axle is w_y = phi' + psi' sin(theta). In a steady turn the contact point runs on a
    circle of signed radius r phi' / psi' (centre to the left when positive).

Derivation (method): Kane's method written out by hand with plain sympy matrices, in lean-frame components.
Independent speeds u = (psi', theta', phi'); the rolling constraint is used to express v_G = r (w_y, -w_x, 0)
(lean axes), so the contact force does no work in the partial velocities and drops out. Angular momentum
H_G = diag(Id, Ia, Id) w_W; inertial derivatives d/dt|N = d/dt|L + w_L x (.). For each u_k:
dv_G/du_k . (F - m a_G) - dw_W/du_k . dH_G/dt = 0 with F = -m g N.z. This gives M(theta) u' = f(theta, u) with
(order psi', theta', phi'):

    M = [[Id cos^2 + (Ia + m r^2) sin^2, 0, (Ia + m r^2) sin], [0, Id + m r^2, 0], [(Ia + m r^2) sin, 0, Ia + m r^2]]
    f_psi   = -2 (Ia + m r^2 - Id) theta' psi' sin cos - Ia theta' phi' cos
    f_theta =  m g r sin + (Ia + m r^2 - Id) psi'^2 sin cos + (Ia + m r^2) psi' phi' cos
    f_phi   = -(Ia + 2 m r^2) theta' psi' cos

`derive_wheel_equations()` redoes this derivation symbolically and `__main__` checks that it equals these
closed forms, and (`kanes_method_cross_check()`) that sympy.physics.mechanics.KanesMethod with the contact point
coordinates x, y and the two nonholonomic rolling rows gives the same accelerations.

Upright straight rolling (theta = 0, psi' = 0, phi' = Omega = v / r, v the forward speed): linearizing, the spin
equation gives phi'' = 0, the yaw equation Id psi'' = -Ia Omega theta' (so psi' = -(Ia Omega / Id) theta + c)
and the lean equation (Id + m r^2) theta'' = m g r theta + (Ia + m r^2) Omega psi'. Eliminating psi':

    (Id + m r^2) theta'' + [Ia (Ia + m r^2) Omega^2 / Id - m g r] theta = 0,
    s^2 = [m g r - Ia (Ia + m r^2) v^2 / (Id r^2)] / (Id + m r^2).

In the reduced state (theta, theta', psi', phi') the linearization has eigenvalues {0, 0, +s, -s}: one zero
from the spin-rate perturbation (phi' is conserved to first order), one from the yaw-rate/lean combination
psi' + (Ia Omega / Id) theta (conserved: the neighbouring steady turns). The cyclic coordinates x, y, psi, phi
add four more zeros if included. `wheel_upright_eigenvalues` returns only the two lean roots +-s. Upright
rolling is (neutrally, all roots on the imaginary axis) stable iff s^2 < 0, i.e. for

    v > v_c = r sqrt(m g r Id / (Ia (Ia + m r^2)))            (thin uniform disk: v_c = sqrt(g r / 3)).

Steady turning (theta, psi', phi' constant, theta' = 0, all accelerations zero): the yaw and spin equations hold
identically, and the lean equation gives the steady-turning condition, quadratic in psi':

    (Ia + m r^2 - Id) sin(theta) cos(theta) psi'^2 + (Ia + m r^2) cos(theta) phi' psi' + m g r sin(theta) = 0.

Equivalently, with the total axle spin w_y = phi' + psi' sin(theta):
(Ia + m r^2) w_y psi' cos(theta) - Id psi'^2 sin(theta) cos(theta) + m g r sin(theta) = 0. For small lean and
forward rolling (phi' > 0), the slow root is psi' ~ -m g r theta / ((Ia + m r^2) phi'): a wheel leaning right
(theta > 0) turns right (psi' < 0).

Whipple bicycle
---------------
M0 q'' + v C1 q' + (g K0 + v^2 K2) q = 0, q = (lean, steer), g = 9.81, matrices from the paper (section 5).
`SYMPY_RES(v)` is the state matrix for (lean, steer, lean rate, steer rate) hard-coded in sympy's
test_kane3.py (``Res``); its lean/steer signs follow sympy's frames, the eigenvalues are the same.
`TABLE2_EIGENVALUES` is the paper's Table 2 (v = 0, 1, ..., 10 m/s) as transcribed, digit for digit, in
github:hazelnusse/OBD whipple/tests/whipple-eigs-unittest.cpp (commit 0e6fa4169ee838f8d20bba5a6b37e0ac79b0d3a1,
D. L. Peterson; "Every eigenvalue they published in Table 2 of that paper is hand coded as written in that
paper"); a second transcription in the same repository (whippleeig.cpp, MATLAB-formatted) agrees. The paper
itself was not available here: these numbers are second-hand.
"""
from __future__ import annotations

import functools
import math
import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, linear_sum_assignment

# =================================================================================================== (a), (b)
# rolling axisymmetric wheel


@functools.lru_cache(maxsize=None)
def derive_wheel_equations():
    """Kane's method by hand (see the module docstring). Returns a dict with the symbols
    (m, r, Ia, Id, g, theta, psi_d, theta_d, phi_d), the mass matrix M and forcing f (order psi', theta', phi';
    M u' = f) and the raw Kane rows (the generalized active + inertia forces, zero on solutions)."""
    t = sp.symbols("t")
    m, r, Ia, Id, g = sp.symbols("m r Ia Id g", positive=True)
    th = sp.Function("theta")(t)
    upsi, uth, uphi = (sp.Function(n)(t) for n in ("psi_d", "theta_d", "phi_d"))
    s, c = sp.sin(th), sp.cos(th)
    w_L = sp.Matrix([uth, upsi * s, upsi * c])                 # lean frame: psi' N.z + theta' H.x, in L axes
    w_W = w_L + sp.Matrix([0, uphi, 0])                         # wheel: + phi' L.y
    I_G = sp.diag(Id, Ia, Id)
    H_G = I_G * w_W
    v_G = w_W.cross(sp.Matrix([0, 0, r]))                       # rolling: v_G = w_W x (G - C), G - C = r L.z

    def d_dt(vec):                                              # inertial derivative of a vector in L axes
        return vec.diff(t).subs(th.diff(t), uth) + w_L.cross(vec)

    a_G = d_dt(v_G)
    dH = d_dt(H_G)
    F = -m * g * sp.Matrix([0, s, c])                           # gravity in L axes (N.z = sin L.y + cos L.z)
    speeds = [upsi, uth, uphi]
    rows = [sp.expand(v_G.diff(u).dot(F - m * a_G) - w_W.diff(u).dot(dH)) for u in speeds]
    accs = [u.diff(t) for u in speeds]
    M = sp.Matrix(3, 3, lambda i, j: -rows[i].coeff(accs[j]))
    f = sp.Matrix([sp.expand(rows[i] + sum(M[i, j] * accs[j] for j in range(3))) for i in range(3)])
    # plain symbols instead of functions of t
    TH, PSD, THD, PHD = sp.symbols("theta psi_d theta_d phi_d")
    rep = {th: TH, upsi: PSD, uth: THD, uphi: PHD}
    M = sp.simplify(M.xreplace(rep))
    f = sp.simplify(f.xreplace(rep))
    return dict(m=m, r=r, Ia=Ia, Id=Id, g=g, theta=TH, psi_d=PSD, theta_d=THD, phi_d=PHD, M=M, f=f,
                rows=rows)


def wheel_mass_matrix_and_forcing(m, r, Ia, Id, g, theta, psi_d, theta_d, phi_d):
    """Closed-form M, f of the wheel (numbers; order psi', theta', phi'; M u' = f)."""
    s, c = math.sin(theta), math.cos(theta)
    J = Ia + m * r * r
    M = np.array([[Id * c * c + J * s * s, 0.0, J * s],
                  [0.0, Id + m * r * r, 0.0],
                  [J * s, 0.0, J]])
    f = np.array([-2.0 * (J - Id) * theta_d * psi_d * s * c - Ia * theta_d * phi_d * c,
                  m * g * r * s + (J - Id) * psi_d**2 * s * c + J * psi_d * phi_d * c,
                  -(Ia + 2.0 * m * r * r) * theta_d * psi_d * c])
    return M, f


def wheel_rhs(t, state, m, r, Ia, Id, g):
    """ODE of the rolling wheel. state = [x, y, psi, theta, phi, psi', theta', phi'] (the YAML's coordinate
    order x, y, yaw, lean, spin; x, y = contact point). der(x) = r phi' cos(psi), der(y) = r phi' sin(psi)."""
    x, y, psi, th, phi, psd, thd, phd = state
    M, f = wheel_mass_matrix_and_forcing(m, r, Ia, Id, g, th, psd, thd, phd)
    acc = np.linalg.solve(M, f)
    return [r * phd * math.cos(psi), r * phd * math.sin(psi), psd, thd, phd, acc[0], acc[1], acc[2]]


def integrate_wheel(m, r, Ia, Id, g, state0, t_end, rtol=1e-12, atol=1e-12, t_eval=None):
    """Integrate wheel_rhs with DOP853; returns scipy's OdeResult (y has the 8 states as rows)."""
    return solve_ivp(wheel_rhs, (0.0, t_end), list(state0), method="DOP853", rtol=rtol, atol=atol,
                     args=(m, r, Ia, Id, g), t_eval=t_eval)


def wheel_reduced_jacobian(m, r, Ia, Id, g, theta, psi_d, phi_d):
    """Jacobian of the reduced dynamics (theta, theta', psi', phi') at theta' = 0 (exact: symbolic derivative of
    the closed forms, evaluated). Used for the linearization about upright rolling and about steady turns."""
    fn = _reduced_jacobian_function()
    return np.asarray(fn(m, r, Ia, Id, g, theta, psi_d, phi_d), dtype=float)


@functools.lru_cache(maxsize=None)
def _reduced_jacobian_function():
    m, r, Ia, Id, g, th, thd, psd, phd = sp.symbols("m r Ia Id g theta theta_d psi_d phi_d")
    s, c = sp.sin(th), sp.cos(th)
    J = Ia + m * r**2
    M = sp.Matrix([[Id * c**2 + J * s**2, 0, J * s], [0, Id + m * r**2, 0], [J * s, 0, J]])
    f = sp.Matrix([-2 * (J - Id) * thd * psd * s * c - Ia * thd * phd * c,
                   m * g * r * s + (J - Id) * psd**2 * s * c + J * psd * phd * c,
                   -(Ia + 2 * m * r**2) * thd * psd * c])
    acc = M.LUsolve(f)                                          # (psi'', theta'', phi'')
    x = [th, thd, psd, phd]
    rhs = sp.Matrix([thd, acc[1], acc[0], acc[2]])
    Jac = rhs.jacobian(x).subs(thd, 0)
    return sp.lambdify((m, r, Ia, Id, g, th, psd, phd), Jac, modules="numpy")


def wheel_upright_eigenvalues(m, r, Ia, Id, g, v) -> np.ndarray:
    """The two lean roots +-s of upright straight rolling at forward speed v (phi' = v / r):
    s^2 = [m g r - Ia (Ia + m r^2) v^2 / (Id r^2)] / (Id + m r^2). Complex array of 2, sorted by (real, imag).
    Dropped: the two zero eigenvalues of the reduced state (theta, theta', psi', phi') (spin-rate perturbation,
    and the conserved combination psi' + Ia phi' theta / Id), and the zeros of the cyclic x, y, psi, phi."""
    s2 = (m * g * r - Ia * (Ia + m * r * r) * v * v / (Id * r * r)) / (Id + m * r * r)
    root = np.sqrt(complex(s2))
    return np.sort_complex(np.array([root, -root], dtype=complex))


def wheel_critical_speed(m, r, Ia, Id, g) -> float:
    """v_c = r sqrt(m g r Id / (Ia (Ia + m r^2))): upright rolling is stable (lean roots purely imaginary) for
    |v| > v_c and unstable (a positive real root) below it."""
    return r * math.sqrt(m * g * r * Id / (Ia * (Ia + m * r * r)))


def thin_disk_critical_speed(r, g) -> float:
    """Thin uniform disk (Ia = m r^2/2, Id = m r^2/4): v_c = sqrt(g r / 3), independent of the mass."""
    return math.sqrt(g * r / 3.0)


def steady_turning_coefficients(m, r, Ia, Id, g, theta, spin) -> tuple[float, float, float]:
    """(a2, a1, a0) of the steady-turning condition a2 psi'^2 + a1 psi' + a0 = 0 (lean equation, all rates
    constant): a2 = (Ia + m r^2 - Id) sin cos, a1 = (Ia + m r^2) cos * spin, a0 = m g r sin."""
    s, c = math.sin(theta), math.cos(theta)
    J = Ia + m * r * r
    return (J - Id) * s * c, J * c * spin, m * g * r * s


def steady_turning_residual(m, r, Ia, Id, g, theta, spin, psi_dot) -> float:
    """The generalized lean force f_theta at theta' = 0 (N m): (Id + m r^2) theta'' at the given
    (theta, psi', phi' = spin) with theta' = 0. Zero exactly on steady turns."""
    a2, a1, a0 = steady_turning_coefficients(m, r, Ia, Id, g, theta, spin)
    return a2 * psi_dot**2 + a1 * psi_dot + a0


def steady_turning_yaw_rates(m, r, Ia, Id, g, theta, spin) -> list[float]:
    """Real roots psi' of the steady-turning condition, sorted. Two roots in general; [] if the discriminant is
    negative; if a2 = 0 (upright theta = 0, or theta = +-pi/2, or Ia + m r^2 = Id) the single root of the
    linear equation (psi' = 0 when upright and spin != 0)."""
    a2, a1, a0 = steady_turning_coefficients(m, r, Ia, Id, g, theta, spin)
    scale = max(abs(a1), abs(a0), 1e-300)
    if abs(a2) <= 1e-14 * scale:
        return [] if a1 == 0 else [-a0 / a1 + 0.0]
    disc = a1 * a1 - 4.0 * a2 * a0
    if disc < 0:
        return []
    sq = math.sqrt(disc)
    q = -0.5 * (a1 + math.copysign(sq, a1))                    # numerically stable quadratic roots
    roots = [q / a2, a0 / q] if q != 0 else [0.0, 0.0]
    return sorted(roots)


def steady_turning_state(m, r, Ia, Id, g, theta, spin, psi_dot):
    """Initial state [x, y, psi, theta, phi, psi', theta', phi'] of the steady turn (x = y = psi = phi = 0)."""
    return [0.0, 0.0, 0.0, theta, 0.0, psi_dot, 0.0, spin]


def steady_turning_lean_drift(m, r, Ia, Id, g, theta, spin, psi_dot, t_end=2.0) -> float:
    """max |theta(t) - theta| over [0, t_end] integrating wheel_rhs from the steady state (DOP853, 1e-12)."""
    t_eval = np.linspace(0.0, t_end, 401)
    sol = integrate_wheel(m, r, Ia, Id, g, steady_turning_state(m, r, Ia, Id, g, theta, spin, psi_dot),
                          t_end, t_eval=t_eval)
    return float(np.max(np.abs(sol.y[3] - theta)))


def kanes_method_cross_check(samples: int = 3, seed: int = 1) -> float:
    """Largest |difference| of the accelerations (psi'', theta'', phi'') of the closed forms and of
    sympy.physics.mechanics.KanesMethod with the contact point coordinates x, y and the two nonholonomic
    rolling rows (dependent speeds der(x), der(y)), at random states."""
    import sympy.physics.mechanics as me

    x, y, psi, th, phi = me.dynamicsymbols("x y psi theta phi")
    ux, uy, upsi, uth, uphi = me.dynamicsymbols("ux uy upsi uth uphi")
    m, r, Ia, Id, g = sp.symbols("m r Ia Id g", positive=True)
    N = me.ReferenceFrame("N")
    H = N.orientnew("H", "Axis", [psi, N.z])
    L = H.orientnew("L", "Axis", [th, H.x])
    W = L.orientnew("W", "Axis", [phi, L.y])
    H.set_ang_vel(N, upsi * N.z)
    L.set_ang_vel(H, uth * H.x)
    W.set_ang_vel(L, uphi * L.y)
    O = me.Point("O")
    O.set_vel(N, 0)
    C = O.locatenew("C", x * N.x + y * N.y)
    C.set_vel(N, ux * N.x + uy * N.y)
    G = C.locatenew("G", r * L.z)
    G.v2pt_theory(C, N, L)
    P = G.locatenew("P", -r * L.z)                              # wheel material point at the contact
    P.v2pt_theory(G, N, W)
    KM = me.KanesMethod(N, q_ind=[x, y, psi, th, phi], u_ind=[upsi, uth, uphi], u_dependent=[ux, uy],
                        velocity_constraints=[P.vel(N) & N.x, P.vel(N) & N.y],
                        kd_eqs=[x.diff() - ux, y.diff() - uy, psi.diff() - upsi, th.diff() - uth,
                                phi.diff() - uphi])
    KM.kanes_equations([me.RigidBody("W", G, W, m, (me.inertia(L, Id, Ia, Id), G))], [(G, -m * g * N.z)])
    fn = sp.lambdify((m, r, Ia, Id, g, psi, th, upsi, uth, uphi), [KM.mass_matrix, KM.forcing], modules="numpy")
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(samples):
        p = (2.0, 0.3, 0.09, 0.05, 9.81)
        psv, thv, a, b, cc = rng.uniform(-1, 1), rng.uniform(-1.2, 1.2), *rng.uniform(-5, 5, 2), rng.uniform(-20, 20)
        MM, FF = fn(*p, psv, thv, a, b, cc)
        acc_k = np.linalg.solve(np.asarray(MM, float), np.asarray(FF, float).ravel())[:3]
        M, f = wheel_mass_matrix_and_forcing(*p, thv, a, b, cc)
        worst = max(worst, float(np.max(np.abs(acc_k - np.linalg.solve(M, f)))))
    return worst


# =================================================================================================== (c)
# Whipple bicycle benchmark (Meijaard et al. 2007)

G_BENCH = 9.81
BENCH_M0 = np.array([[80.81722, 2.31941332208709], [2.31941332208709, 0.29784188199686]])
BENCH_C1 = np.array([[0.0, 33.86641391492494], [-0.85035641456978, 1.68540397397560]])
BENCH_K0 = np.array([[-80.95, -2.59951685249872], [-2.59951685249872, -0.80329488458618]])
BENCH_K2 = np.array([[0.0, 76.59734589573222], [0.0, 2.65431523794604]])
WEAVE_SPEED = 4.292382536341
CAPSIZE_SPEED = 6.024262015388

# Table 2 of the paper, second-hand (github:hazelnusse/OBD, see the module docstring). Row k = speed k m/s,
# the 4 eigenvalues in the order weave pair, capsize (real), castering (real) -- at v = 0 all are real.
TABLE2_SPEEDS = np.arange(11.0)
TABLE2_EIGENVALUES = np.array([
    [3.13164324790656, -3.13164324790656, 5.53094371765393, -5.53094371765393],
    [3.52696170990070 + 0.80774027519930j, 3.52696170990070 - 0.80774027519930j, -3.13423125066578, -7.11008014637442],
    [2.68234517512745 + 1.68066296590675j, 2.68234517512745 - 1.68066296590675j, -3.07158645641514, -8.67387984831735],
    [1.70675605663975 + 2.31582447384325j, 1.70675605663975 - 2.31582447384325j, -2.63366137253667, -10.35101467245920],
    [0.41325331521125 + 3.07910818603206j, 0.41325331521125 - 3.07910818603206j, -1.42944427361326, -12.15861426576450],
    [-0.77534188219585 + 4.46486771378823j, -0.77534188219585 - 4.46486771378823j, -0.32286642900409, -14.07838969279820],
    [-1.52644486584142 + 5.87673060598709j, -1.52644486584142 - 5.87673060598709j, -0.00406690076970, -16.08537123098030],
    [-2.13875644258362 + 7.19525913329805j, -2.13875644258362 - 7.19525913329805j, 0.10268170574766, -18.15788466125262],
    [-2.69348683581097 + 8.46037971396931j, -2.69348683581097 - 8.46037971396931j, 0.14327879765713, -20.27940894394569],
    [-3.21675402252485 + 9.69377351531791j, -3.21675402252485 - 9.69377351531791j, 0.15790184030917, -22.43788559040858],
    [-3.72016840437287 + 10.90681139476287j, -3.72016840437287 - 10.90681139476287j, 0.16105338653172, -24.62459635017404],
], dtype=complex)
# Table 2 (a), same source: the speed where two positive real roots meet and leave the real axis as the (still
# unstable) weave pair, and that double root; the weave speed, the weave frequency there; the capsize speed.
TABLE2_BIFURCATION_SPEED = 0.68428307889246
TABLE2_BIFURCATION_EIGENVALUE = 3.78290405129320
TABLE2_WEAVE_SPEED = 4.29238253634111
TABLE2_WEAVE_FREQUENCY = 3.43503384866144
TABLE2_CAPSIZE_SPEED = 6.02426201538837


def benchmark_state_matrix(v, g=G_BENCH) -> np.ndarray:
    """A for x = (lean, steer, lean rate, steer rate): [[0, I], [-M0^-1 (g K0 + v^2 K2), -M0^-1 v C1]]."""
    Minv = np.linalg.inv(BENCH_M0)
    A = np.zeros((4, 4))
    A[:2, 2:] = np.eye(2)
    A[2:, :2] = -Minv @ (g * BENCH_K0 + v * v * BENCH_K2)
    A[2:, 2:] = -Minv @ (v * BENCH_C1)
    return A


def benchmark_eigenvalues(v, g=G_BENCH) -> np.ndarray:
    """The 4 roots s of det(M0 s^2 + v C1 s + g K0 + v^2 K2) = 0 (eigenvalues of benchmark_state_matrix),
    complex, sorted by (real, imag) (numpy sort_complex)."""
    return np.sort_complex(np.linalg.eigvals(benchmark_state_matrix(v, g)).astype(complex))


def benchmark_characteristic_polynomial(v, g=G_BENCH) -> np.ndarray:
    """Coefficients [a4, a3, a2, a1, a0] of det(M0 s^2 + v C1 s + g K0 + v^2 K2) (highest power first)."""
    M, C, K = BENCH_M0, v * BENCH_C1, g * BENCH_K0 + v * v * BENCH_K2
    # det([[p11, p12], [p21, p22]]) with p_ij = M_ij s^2 + C_ij s + K_ij
    P = [[np.array([M[i, j], C[i, j], K[i, j]]) for j in range(2)] for i in range(2)]
    return np.polysub(np.polymul(P[0][0], P[1][1]), np.polymul(P[0][1], P[1][0]))


def SYMPY_RES(v) -> np.ndarray:  # noqa: N802  (the name of the matrix in sympy's test)
    """sympy's precomputed A matrix for (lean, steer, lean rate, steer rate), test_kane3.py ``Res``."""
    return np.array([
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        [9.48977444677355, -0.891197738059089 * v**2 - 0.571523173729245, -0.105522449805691 * v,
         -0.330515398992311 * v],
        [11.7194768719633, -1.97171508499972 * v**2 + 30.9087533932407, 3.67680523332152 * v,
         -3.08486552743311 * v],
    ])


def max_eigenvalue_difference(a, b) -> tuple[float, float]:
    """(largest |a_i - b_pi(i)|, that divided by max|b|) under the best one-to-one matching pi (robust to the
    order of nearly equal eigenvalues)."""
    a, b = np.asarray(a, complex), np.asarray(b, complex)
    cost = np.abs(a[:, None] - b[None, :])
    i, j = linear_sum_assignment(cost)
    d = float(cost[i, j].max())
    return d, d / max(float(np.abs(b).max()), 1e-300)


def _weave_real_part(v):
    ev = benchmark_eigenvalues(v)
    return float(ev[np.argmax(np.abs(ev.imag))].real)       # the complex (weave) pair


def _capsize_root(v):
    ev = benchmark_eigenvalues(v)
    real = ev[np.abs(ev.imag) == 0.0].real
    return float(real.max())                                 # the capsize root is the largest real root


def weave_speed_from_eigenvalues() -> float:
    """Speed where the weave pair crosses Re = 0 (brentq on its real part, bracket [4, 5])."""
    return brentq(_weave_real_part, 4.0, 5.0, xtol=1e-15, rtol=4 * np.finfo(float).eps)


def capsize_speed_from_eigenvalues() -> float:
    """Speed where the real capsize root crosses 0 (brentq, bracket [5.5, 6.5])."""
    return brentq(_capsize_root, 5.5, 6.5, xtol=1e-15, rtol=4 * np.finfo(float).eps)


def weave_speed_from_hurwitz() -> float:
    """Weave speed from the quartic's coefficients: a pair s = +-i w exists iff a3 a2 a1 - a3^2 a0 - a4 a1^2 = 0."""
    def h(v):
        a4, a3, a2, a1, a0 = benchmark_characteristic_polynomial(v)
        return a3 * a2 * a1 - a3 * a3 * a0 - a4 * a1 * a1
    return brentq(h, 4.0, 5.0, xtol=1e-15, rtol=4 * np.finfo(float).eps)


def capsize_speed_from_determinant() -> float:
    """Capsize speed in closed form: a0 = det(g K0 + v^2 K2) = 0, a quadratic in w = v^2."""
    K0, K2, g = BENCH_K0, BENCH_K2, G_BENCH
    # det(g K0 + w K2) = c2 w^2 + c1 w + c0
    c2 = K2[0, 0] * K2[1, 1] - K2[0, 1] * K2[1, 0]
    c1 = g * (K0[0, 0] * K2[1, 1] + K2[0, 0] * K0[1, 1] - K0[0, 1] * K2[1, 0] - K2[0, 1] * K0[1, 0])
    c0 = g * g * (K0[0, 0] * K0[1, 1] - K0[0, 1] * K0[1, 0])
    if c2 == 0:
        w = -c0 / c1
    else:
        roots = np.roots([c2, c1, c0])
        w = float(min(r.real for r in roots if r.real > 0 and abs(r.imag) == 0))
    return math.sqrt(w)


# =================================================================================================== checks


def _check_wheel() -> None:
    d = derive_wheel_equations()
    m, r, Ia, Id, g, th, psd, thd, phd = (d[k] for k in ("m", "r", "Ia", "Id", "g", "theta", "psi_d", "theta_d",
                                                          "phi_d"))
    s, c = sp.sin(th), sp.cos(th)
    J = Ia + m * r**2
    M_cf = sp.Matrix([[Id * c**2 + J * s**2, 0, J * s], [0, Id + m * r**2, 0], [J * s, 0, J]])
    f_cf = sp.Matrix([-2 * (J - Id) * thd * psd * s * c - Ia * thd * phd * c,
                      m * g * r * s + (J - Id) * psd**2 * s * c + J * psd * phd * c,
                      -(Ia + 2 * m * r**2) * thd * psd * c])
    assert sp.simplify(d["M"] - M_cf) == sp.zeros(3, 3), "mass matrix"
    assert sp.simplify(d["f"] - f_cf) == sp.zeros(3, 1), "forcing"
    print("wheel: hand-Kane derivation == closed-form M, f (symbolic)")
    # steady-turning condition = lean forcing at theta' = 0 with all accelerations 0
    quad = sp.expand(f_cf[1].subs(thd, 0))
    assert sp.simplify(quad - ((J - Id) * s * c * psd**2 + J * c * phd * psd + m * g * r * s)) == 0
    assert f_cf[0].subs(thd, 0) == 0 and f_cf[2].subs(thd, 0) == 0
    print("wheel: steady turning: yaw and spin rows vanish identically, lean row is the quadratic")
    print(f"wheel: KanesMethod (x, y + 2 rolling rows) vs closed form, max |acc diff| = "
          f"{kanes_method_cross_check():.2e}")

    # upright linearization: closed form vs exact Jacobian, several inertias and speeds
    worst = 0.0
    for (mm, rr, ia, idd) in [(2.0, 0.3, 0.09, 0.045), (1.3, 0.5, 0.2, 0.15), (3.0, 0.25, 0.05, 0.06)]:
        for v in (0.0, 0.3, 1.0, 2.5, 7.0):
            Jac = wheel_reduced_jacobian(mm, rr, ia, idd, 9.81, 0.0, 0.0, v / rr)
            ev = np.linalg.eigvals(Jac)
            ev_nz = ev[np.argsort(np.abs(ev))][2:]                 # drop the 2 zeros
            want = wheel_upright_eigenvalues(mm, rr, ia, idd, 9.81, v)
            zeros = np.sort(np.abs(ev))[:2]
            assert zeros.max() < 1e-9, zeros
            worst = max(worst, max_eigenvalue_difference(ev_nz, want)[0])
    print(f"wheel: upright lean roots closed form vs eigenvalues of the exact Jacobian: max diff {worst:.2e}")

    # critical speed
    mm, rr, gg = 2.0, 0.3, 9.81
    ia, idd = mm * rr**2 / 2, mm * rr**2 / 4
    vc = wheel_critical_speed(mm, rr, ia, idd, gg)
    assert abs(vc - thin_disk_critical_speed(rr, gg)) < 1e-14 * vc
    for (m_, r_, ia_, id_) in [(2.0, 0.3, 0.09, 0.045), (1.3, 0.5, 0.2, 0.15)]:
        v_c = wheel_critical_speed(m_, r_, ia_, id_, 9.81)
        below = wheel_upright_eigenvalues(m_, r_, ia_, id_, 9.81, v_c * (1 - 1e-6))
        above = wheel_upright_eigenvalues(m_, r_, ia_, id_, 9.81, v_c * (1 + 1e-6))
        at = wheel_upright_eigenvalues(m_, r_, ia_, id_, 9.81, v_c)
        assert below.real.max() > 0 and abs(above.real).max() == 0 and np.abs(at).max() < 1e-6
    print(f"wheel: thin disk m={mm} r={rr}: v_c = {vc:.12f} = sqrt(g r/3) = {math.sqrt(gg * rr / 3):.12f}; "
          f"roots real above/below switch at v_c")

    # steady turning roots: residual and direct integration
    cases = [(0.2, 15.0), (0.5, 8.0), (-0.3, 12.0), (0.3, -12.0)]
    for theta, spin in cases:
        roots = steady_turning_yaw_rates(mm, rr, ia, idd, gg, theta, spin)
        assert len(roots) == 2
        for pd in roots:
            res = steady_turning_residual(mm, rr, ia, idd, gg, theta, spin, pd)
            drift = steady_turning_lean_drift(mm, rr, ia, idd, gg, theta, spin, pd, t_end=2.0)
            ev = np.linalg.eigvals(wheel_reduced_jacobian(mm, rr, ia, idd, gg, theta, pd, spin))
            ev_nz = ev[np.argsort(np.abs(ev))][2:]
            print(f"wheel: steady turn theta={theta:+.2f} spin={spin:+.1f}: psi'={pd:+.12f} residual={res:+.1e} "
                  f"lean drift over 2 s={drift:.1e}  (lean roots {np.round(ev_nz, 4)})")
            assert abs(res) < 1e-10 and drift < 1e-8


def _check_bicycle() -> None:
    speeds = np.arange(0.0, 10.0 + 1e-12, 0.5)
    worst_res = max(max_eigenvalue_difference(np.linalg.eigvals(SYMPY_RES(v)), benchmark_eigenvalues(v))[1]
                    for v in speeds)
    print(f"bicycle: sympy test_kane3 Res vs benchmark_eigenvalues, v = 0..10 step 0.5: "
          f"max relative diff {worst_res:.2e}")
    assert worst_res < 1e-10
    worst_tab = 0.0
    worst_abs = 0.0
    for v, want in zip(TABLE2_SPEEDS, TABLE2_EIGENVALUES):
        d_abs, d_rel = max_eigenvalue_difference(benchmark_eigenvalues(v), want)
        worst_tab, worst_abs = max(worst_tab, d_rel), max(worst_abs, d_abs)
    print(f"bicycle: benchmark_eigenvalues vs Table 2 (transcribed), v = 0..10: max |diff| {worst_abs:.2e}, "
          f"relative {worst_tab:.2e}")
    assert worst_abs < 1e-11
    ev = benchmark_eigenvalues(TABLE2_BIFURCATION_SPEED)
    print(f"bicycle: at the Table 2 bifurcation speed the double root: {np.round(ev, 6)} "
          f"(table {TABLE2_BIFURCATION_EIGENVALUE})")
    assert np.abs(ev - TABLE2_BIFURCATION_EIGENVALUE).min() < 1e-6       # a double root: only ~sqrt(eps) accurate
    vw, vc = weave_speed_from_eigenvalues(), capsize_speed_from_eigenvalues()
    vw_h, vc_d = weave_speed_from_hurwitz(), capsize_speed_from_determinant()
    print(f"bicycle: weave speed   eig root {vw:.14f}  Hurwitz {vw_h:.14f}  const {WEAVE_SPEED}  "
          f"diff {abs(vw - WEAVE_SPEED):.1e} (Table 2: {TABLE2_WEAVE_SPEED}, diff {abs(vw - TABLE2_WEAVE_SPEED):.1e})")
    print(f"bicycle: capsize speed eig root {vc:.14f}  det=0   {vc_d:.14f}  const {CAPSIZE_SPEED}  "
          f"diff {abs(vc - CAPSIZE_SPEED):.1e} (Table 2: {TABLE2_CAPSIZE_SPEED}, diff {abs(vc - TABLE2_CAPSIZE_SPEED):.1e})")
    w_freq = float(np.abs(benchmark_eigenvalues(vw).imag).max())
    print(f"bicycle: weave frequency at the weave speed {w_freq:.14f} (Table 2: {TABLE2_WEAVE_FREQUENCY})")
    assert abs(vw - WEAVE_SPEED) < 1e-10 and abs(vc - CAPSIZE_SPEED) < 1e-10
    assert abs(vw_h - WEAVE_SPEED) < 1e-10 and abs(vc_d - CAPSIZE_SPEED) < 1e-10


if __name__ == "__main__":
    _check_wheel()
    _check_bicycle()
    print("all reference checks passed")
