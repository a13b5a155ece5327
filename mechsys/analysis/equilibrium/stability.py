"""Lyapunov stability of equilibria: eigenvalues first; in critical cases an energy (Lagrange-Dirichlet/Routh) test."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg as sla
import sympy as sp

from mechsys.analysis.equilibrium.linearize import pieces, state_at
from mechsys.mechanics.dag import identically_zero
from mechsys.numeric.lambdify import compile_exprs

if TYPE_CHECKING:
    from mechsys.analysis.equilibrium.equilibria import Equilibrium, EquilibriumProblem

#: Real parts with |Re| <= ZERO_RE * max(1, max |eigenvalue|) count as zero (critical case).
ZERO_RE = 1e-9
#: Eigenvalues with |lambda| <= SPLIT_ZERO * max(1, max |eigenvalue|) may be a multiple zero eigenvalue split by
#: rounding (a Jordan block's zero splits as +-sqrt(eps)-sized pairs): their real parts decide nothing.
SPLIT_ZERO = 1e-6
#: Hessian eigenvalues with |h| <= ZERO_H * max(1, max |h|) count as zero (degenerate minimum).
ZERO_H = 1e-9


def reduced_pencil(problem: EquilibriumProblem, e: Equilibrium) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(A, B) with B x' = A x for the reduced linearized state, and N (tangent basis) for constrained systems.

    Unconstrained: state (non-cyclic q, all rates). Constrained: state (eta, eta') with q = q0 + N eta.
    Nonholonomic problems have their own (analysis/equilibrium/nonholonomic.py)."""
    if hasattr(problem, "pencil"):
        return problem.pencil(e)
    model = problem.model
    q, u = state_at(model, e.coordinates, e.rates)
    v = pieces(model).evaluate(q, u, np.array(e.multipliers), problem_parameters(problem))
    M, dfdq, dfdu = v["M"], v["dfdq"], v["dfdu"]
    n = len(model.coordinates)
    if problem.m:
        N = sla.null_space(v["A"])
        d = N.shape[1]
        Mr, Kr, Cr = N.T @ M @ N, -N.T @ dfdq @ N, -N.T @ dfdu @ N
        A = np.block([[np.zeros((d, d)), np.eye(d)], [-Kr, -Cr]])
        B = sla.block_diag(np.eye(d), Mr)
        return A, B, N
    nc = [model.coordinates.index(c) for c in problem.free]
    S = np.zeros((len(nc), n))
    for k, i in enumerate(nc):
        S[k, i] = 1.0
    A = np.block([[np.zeros((len(nc), len(nc))), S], [dfdq[:, nc], dfdu]])
    B = sla.block_diag(np.eye(len(nc)), M)
    return A, B, None


def problem_parameters(problem: EquilibriumProblem) -> np.ndarray:
    p = getattr(problem, "current_parameters", None)
    if p is None:
        from mechsys.numeric.parameters import parameter_values

        p = parameter_values(problem.model)
    return p


def pencil_eigenvalues(problem: EquilibriumProblem, e: Equilibrium) -> np.ndarray:
    """The finite eigenvalues of reduced_pencil(problem, e), sorted; a problem that has them already (the
    nonholonomic linearization computes those of its deflated Jacobian) gives them without a second eigensolve."""
    if hasattr(problem, "pencil_eigenvalues"):
        return problem.pencil_eigenvalues(e)
    A, B, N = reduced_pencil(problem, e)
    return eigen(A, B, pencil_positions(problem, N))[0]


def eigen(A: np.ndarray, B: np.ndarray, positions: int = 0) -> tuple[np.ndarray, np.ndarray | None]:
    """Finite eigenvalues of the pencil (massless coordinates give infinite ones, dropped) and the Jacobian. Whether
    B is singular is judged on the balanced pencil (a picometre linkage's M ~ 1e-24 beside the identity's 1s is
    regular), and its QZ eigenvalues are the balanced ones scaled back. ``positions``: reduced_pencil's rows q' = u
    (pencil_positions); 0 balances any pencil as a whole."""
    Ab, Bb, w = _balanced(A, B, positions)
    try:
        if np.linalg.cond(Bb) > 1e12:
            raise np.linalg.LinAlgError
        J = np.linalg.solve(B, A)
        vals = np.linalg.eigvals(J)
    except np.linalg.LinAlgError:
        J = None
        vals = sla.eigvals(Ab, Bb)
        vals = w * vals[np.isfinite(vals)]
    order = np.lexsort((vals.imag, vals.real))
    return vals[order], J


def pencil_positions(problem: EquilibriumProblem, N: np.ndarray | None) -> int:
    """The number of position rows (q' = u) of reduced_pencil's (A, B), given its N."""
    return N.shape[1] if N is not None else len(problem.free)


def singular_pencil(A: np.ndarray, B: np.ndarray, positions: int) -> bool:
    """det(A - s B) vanishes for every s: the linearized equations do not determine the motion (a coordinate with
    neither mass nor inertia on which nothing acts), and any 'eigenvalue' of the pencil is meaningless. ``A``, ``B``
    as reduced_pencil gives them (the first ``positions`` rows q' = u); the test is on the balanced pencil."""
    if A.size == 0:
        return False
    A, B, _w = _balanced(A, B, positions)
    rng = np.random.default_rng(11)
    for _ in range(2):
        s = complex(rng.uniform(-3, 3), rng.uniform(-3, 3))
        sv = np.linalg.svd(A - s * B, compute_uv=False)
        if sv[-1] > 1e-12 * A.shape[0] * float(sv[0]):
            return False
    return True


def _balanced(A: np.ndarray, B: np.ndarray, positions: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The pencil in units where mass, stiffness and the rows q' = u are all of size 1: rates measured in
    w = sqrt(k/m) (u = w v), the equations of motion divided by m w (then q' = u reads (s/w) q = v). Returns
    (R A T / w, R B T, w) with R = diag(1, 1/(m w)), T = diag(1, w): its eigenvalues are those of (A, B) divided
    by w and it is singular exactly when (A, B) is, but a rank test sees the same pencil at any units (a
    picometre linkage has M ~ 1e-24 and K ~ 1e-12 beside the identity's 1s)."""
    p = positions
    m = float(np.max(np.abs(B[p:, p:]))) if B[p:, p:].size else 0.0
    k = float(np.max(np.abs(A[p:, :p]))) if A[p:, :p].size else 0.0
    c = float(np.max(np.abs(A[p:, p:]))) if A[p:, p:].size else 0.0
    if m == 0.0:
        return A, B, 1.0
    w = math.sqrt(k / m) if k > 0 else (c / m if c > 0 else 1.0)
    rows = np.r_[np.ones(p), np.full(A.shape[0] - p, 1.0 / (m * w))]
    cols = np.r_[np.ones(p), np.full(A.shape[1] - p, w)]
    return rows[:, None] * A * cols / w, rows[:, None] * B * cols, w


def massless_coordinates(problem: EquilibriumProblem, e: Equilibrium) -> list[str]:
    """Coordinates whose row of the mass matrix vanishes at the equilibrium (no mass or inertia moves with them)."""
    model = problem.model
    q, u = state_at(model, e.coordinates, e.rates)
    M = pieces(model).evaluate(q, u, np.array(e.multipliers), problem_parameters(problem))["M"]
    scale = max(1e-300, float(np.max(np.abs(M)))) if M.size else 1.0
    return [c for i, c in enumerate(model.coordinates) if np.max(np.abs(M[i, :])) <= 1e-12 * scale]


def _massive_elsewhere(problem, names: list[str], p: np.ndarray) -> bool:
    """Each of ``names`` (or, with none named, every combination of the coordinates) carries mass at a random
    configuration: its masslessness here is the chart's, not the model's."""
    from mechsys.analysis.crosscheck import random_states

    model = problem.model
    if problem.m:
        return False  # with constraints a singular pencil may be the loop's own (a dead centre), not the chart's
    ev = pieces(model)
    for t, q, u in random_states(model, 3, seed=13):
        M = ev.evaluate(q, u, np.zeros(problem.m), p)["M"]
        scale = max(1e-300, float(np.max(np.abs(M))))
        if names and all(abs(M[model.coordinates.index(c), model.coordinates.index(c)]) > 1e-9 * scale
                         for c in names):
            return True
        if not names and M.size and np.linalg.svd(M, compute_uv=False)[-1] > 1e-9 * scale:
            return True
    return False


#: equilibria from which assess_all evaluates their linearizations in one pass: a pass costs about as much as
#: evaluating 25 to 30 points one by one (numpy's call per operation), then little per point
AHEAD_FROM = 32


def assess_all(problem: EquilibriumProblem, equilibria: list, p: np.ndarray) -> None:
    """assess() each equilibrium; from AHEAD_FROM of them on, their linearizations evaluated in one pass first
    (LinearPieces.evaluated_ahead: the same values, computed together)."""
    if hasattr(problem, "assess") or hasattr(problem, "pencil") or len(equilibria) < AHEAD_FROM:
        for e in equilibria:
            assess(problem, e, p)
        return
    model = problem.model
    states = [(*state_at(model, e.coordinates, e.rates), np.array(e.multipliers), p) for e in equilibria]
    with pieces(model).evaluated_ahead(states):
        for e in equilibria:
            assess(problem, e, p)


#: the verdict's reason where the linearization has no degree of freedom
LOCKED = ("no motion: the constraints leave no degree of freedom at this configuration (it is locked), so nothing "
          "moves away from it; not asymptotic, there being nothing to decay")


def assess(problem: EquilibriumProblem, e: Equilibrium, p: np.ndarray) -> None:
    """Fill eigenvalues, Jacobian and verdict of equilibrium ``e`` in place."""
    if hasattr(problem, "assess"):
        return problem.assess(e, p)
    problem.current_parameters = p
    A, B, N = reduced_pencil(problem, e)
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
        e.eigenvalues, e.jacobian, e.critical = np.zeros(0, complex), None, False
        e.stability = "undecided"
        e.reason = ("the linearized equations are not finite here (an overflow or a division by zero: check the "
                    "parameter values, e.g. a length of 1e200 squared), so no verdict is read from them")
        return
    if singular_pencil(A, B, pencil_positions(problem, N)):
        names = massless_coordinates(problem, e)
        who = (f"{', '.join(names)} carr{'ies' if len(names) == 1 else 'y'} no mass or inertia" if names
               else "a combination of the coordinates carries no mass or inertia")
        e.eigenvalues, e.jacobian, e.critical = np.zeros(0, complex), None, False
        e.stability = "undecided"
        them = "it" if len(names) == 1 else "them"
        if _massive_elsewhere(problem, names, p):
            one = len(names) == 1
            what = (f"{', '.join(names)} move{'s' if one else ''} no mass at this configuration but "
                    f"{'does' if one else 'do'} elsewhere (e.g. a particle on the axis of its own azimuth)" if names
                    else "a combination of the coordinates moves no mass at this configuration, while the mass "
                         "matrix is regular elsewhere (e.g. a gimbal of revolute joints whose first and last "
                         "axes line up)")
            e.reason = (f"coordinate singularity: {what}: "
                        f"the coordinates are a singular chart here and no verdict is read from them; write the "
                        f"joint so that this position is regular (another axis order or sequence)")
            return
        e.reason = (f"the linearized equations do not determine the motion: {who} and no stiffness or damping "
                    f"acts on {them} (a singular pencil); give {them} mass or inertia, or make {them} prescribed")
        return
    vals, J = eigen(A, B, pencil_positions(problem, N))
    e.eigenvalues, e.jacobian = vals, J
    lost = problem.model.zero_length_elements(e.coordinates, dict(zip(problem.model.parameter_symbols, p)))
    if lost:
        e.critical = False
        e.stability, e.reason = "undecided", zero_length_reason(lost)
        return
    if not len(vals):  # not 'all eigenvalues have negative real parts', which held only for want of any
        e.critical = False
        e.stability, e.reason = "stable", LOCKED
        return
    scale = max(1.0, float(np.max(np.abs(vals)))) if len(vals) else 1.0
    tol = ZERO_RE * scale
    zero_like = zero_like_eigenvalues(vals, scale)
    e.critical = bool(len(vals) and np.any(zero_like))
    if np.any(vals.real[~zero_like] > tol):
        e.stability, e.reason = "unstable", "an eigenvalue has a positive real part"
        return
    if len(vals) == 0 or np.max(vals.real) < -tol:
        e.stability, e.reason = "asymptotically stable", "all eigenvalues have negative real parts"
        return
    zero = int(np.sum(zero_like))
    e.stability, e.reason = energy_verdict(problem, e, p, zero)
    if e.stability == "undecided" and not _degenerate(problem, e, p):
        e.stability, e.reason = _conservative_linear(problem, e, p, vals, tol, e.stability, e.reason)


def zero_length_reason(lost: list[str]) -> str:
    """Why no verdict (or modes) at a configuration where dampers or actuators have zero length."""
    return (f"{', '.join(lost)} {'has' if len(lost) == 1 else 'have'} zero length here: along its line the force has "
            "no direction, so the linearization does not hold it (attach it between points that stay apart)")


def oscillating_eigenvalues(vals: np.ndarray, zeros: int = 0) -> list[complex]:
    """The eigenvalues with a positive imaginary part, by increasing frequency, less those among the ``zeros``
    smallest in size that lie within SPLIT_ZERO of zero: ``zeros`` = 2 per rigid-body mode, whose double zero
    eigenvalue rounding splits (a top with two cyclic angles: +-6.9e-8 i beside 27.86 rad/s, read as a first damped
    frequency)."""
    vals = np.asarray(vals, dtype=complex)
    top = max(1.0, float(np.max(np.abs(vals)))) if vals.size else 1.0
    split = {int(k) for k in np.argsort(np.abs(vals))[:zeros] if abs(vals[k]) <= SPLIT_ZERO * top}
    return sorted((complex(v) for k, v in enumerate(vals) if k not in split and v.imag > 1e-9 * top),
                  key=lambda v: v.imag)


def zero_like_eigenvalues(vals: np.ndarray, scale: float) -> np.ndarray:
    """Which eigenvalues count as zero in the critical case: a real part within ZERO_RE of the scale, or a positive
    real part on an eigenvalue within SPLIT_ZERO of it (a double zero eigenvalue split by rounding: a spinning chain
    of ball joints with free twists had +-4.8e-8 beside 15 rad/s, and was called unstable)."""
    return (np.abs(vals.real) <= ZERO_RE * scale) | ((vals.real > 0) & (np.abs(vals) <= SPLIT_ZERO * scale))


def _conservative_linear(problem, e, p, vals, tol, stability, reason) -> tuple[str, str]:
    """Conservative systems (no non-conservative forces at all) whose linearization is purely oscillatory with
    simple frequencies are gyroscopically stabilized: reported stable, with the basis stated (linear stability;
    e.g. the free rigid body spinning about its minor axis, where the energy test alone is inconclusive)."""
    model = problem.model
    Q = model.generalized_forces.xreplace({model.t: 0})
    values = dict(zip(model.parameter_symbols, p))
    if not all(identically_zero(entry, values) for entry in Q):  # relative to each force's own terms
        return stability, reason
    if np.max(np.abs(vals.real)) > tol:
        return stability, reason
    # a zero eigenvalue of a Jordan block (rigid-body drift) splits numerically into +-sqrt(eps)-sized pairs
    tiny = SPLIT_ZERO * max(1.0, float(np.max(np.abs(vals))))
    zeros = int(np.sum(np.abs(vals) <= tiny))
    if zeros > len(getattr(problem, "fixed_rates", {})):
        return stability, reason  # a zero eigenvalue that is not a family of steady motions: drift is possible
    osc = sorted(abs(v.imag) for v in vals if abs(v.imag) > tiny)
    if any(abs(a - b) <= 1e-7 * max(1.0, a) for a, b in zip(osc[::2][1:], osc[::2][:-1])):
        return stability, reason  # repeated frequencies: possible resonance, secular growth
    return "stable", reason.split(";")[0] + "; conservative system with a purely oscillatory, simple spectrum " \
                                           "(gyroscopic stabilization): stable in the linear sense"


# ----------------------------------------------------------------------------------------- energy argument
def energy_verdict(problem: EquilibriumProblem, e: Equilibrium, p: np.ndarray, zero_count: int) -> tuple[str, str]:
    """Critical case: with only dissipative (or no) non-conservative forces, a strict minimum of the effective
    potential (V - T0, amended by Routh for cyclic momenta) is stable (Lagrange-Dirichlet); no minimum with
    complete damping is unstable (Kelvin-Tait-Chetaev). Otherwise undecided, with the reason."""
    prefix = f"{zero_count} eigenvalue(s) with zero real part (critical case); "
    dissipative, complete, why, positional = _dissipation(problem, e, p)
    if not dissipative:
        return "undecided", prefix + why
    q0 = np.array([e.coordinates[c] for c in problem.free], dtype=float)
    H = _compiled_hessian(problem, e, p) if not problem.m and problem.free else None
    U = None
    if H is None:
        try:
            U, qn = _effective_potential(problem, e)
        except _MasslessCyclic as exc:
            return "undecided", prefix + str(exc)
        if not qn:
            return "stable", prefix + "no positional degrees of freedom and no energy input"
        H = _hessian(U, qn, problem, q0, p) - positional  # curl-free positional forces belong to the potential
    elif isinstance(H, str):
        return "undecided", prefix + H
    qn = [problem.model.doc.coords[c] for c in problem.free]
    if problem.m:
        H = _constrained_hessian(problem, e, p, H)
    h, vectors = np.linalg.eigh((H + H.T) / 2) if H.size else (np.zeros(0), np.zeros((0, 0)))
    htol = ZERO_H * max(_stiffness_scale(problem, p), float(np.max(np.abs(h)))) if h.size else 0.0
    flat = np.abs(h) <= htol
    if h.size == 0 or np.min(h) > htol:
        from mechsys.analysis.equilibrium.equilibria import degenerate_root

        if not (h.size and degenerate_root(problem, problem.state(e), p)):
            return "stable", prefix + "energy argument: strict minimum of the effective potential and no energy " \
                                      "input (Lagrange-Dirichlet): stable; asymptotic stability is not decided by " \
                                      "this test"
        flat[np.argmin(h)] = True  # a degenerate root found off by rounding: its least stiffness is no minimum's
    elif np.min(h) < -htol:
        if complete:
            return "unstable", prefix + "the effective potential has no minimum and the damping is complete " \
                                        "(Kelvin-Tait-Chetaev)"
        return "undecided", prefix + "the effective potential has no minimum; without complete damping " \
                                     "gyroscopic forces may still stabilize"
    null = vectors[:, flat]
    if null.shape[1] == 1 and not problem.m and len(qn) == 1:  # along a line is a proof only in one dimension
        if U is None:
            U, qn = _effective_potential(problem, e)
        order, value = _higher_order(U, qn, problem, q0, p, null[:, 0])
        if order and order % 2 == 0 and value > 0:
            return "stable", prefix + f"energy argument: the effective potential has a strict minimum (order-{order} " \
                                      "term positive along the degenerate direction); stable, not asymptotically"
        if order:
            if complete:
                return "unstable", prefix + f"the effective potential has no minimum (order-{order} term along the " \
                                            "degenerate direction) and the damping is complete"
            return "undecided", prefix + NO_MINIMUM_ALONG
    return "undecided", prefix + FLAT


def _stiffness_scale(problem, p: np.ndarray) -> float:
    """The size of a stiffness in the model's own units: its coordinates' force rows over the coordinates' sizes
    (small_scales: 1 at ordinary units). Against a floor of 1 N m, a MEMS linkage's stiffness (1e-12) read as flat,
    and only the spectrum rule called it stable."""
    from mechsys.analysis.equilibrium.equilibria import small_scales

    if not problem.nq:
        return 1.0
    rows, sizes = small_scales(problem, p)
    return float(np.max(rows[:problem.nq] / sizes[:problem.nq]))


def _degenerate(problem, e, p: np.ndarray) -> bool:
    """The energy argument found a direction without stiffness, and the root is degenerate within its accuracy
    (degenerate_root): a frequency of the linearization along it is the rounding of a zero one (+-1.6e-6 i at a
    double root), no proof. A soft direction of a stiff model (k = 1 beside 1e10, flat against ZERO_H) is not."""
    from mechsys.analysis.equilibrium.equilibria import degenerate_root

    return e.reason.endswith((NO_MINIMUM_ALONG, FLAT)) and degenerate_root(problem, problem.state(e), p)


#: the energy argument's reasons where a stiffness vanishes
NO_MINIMUM_ALONG = "the effective potential has no minimum along the degenerate direction"
FLAT = "the potential is flat along some direction (neutral equilibrium or a family)"


def _dissipation(problem, e, p: np.ndarray) -> tuple[bool, bool, str, np.ndarray]:
    """(non-conservative forces only dissipate, damping complete on the positional coordinates, reason if not,
    dQ0/dq at the equilibrium for curl-free positional forces Q0 = Q(q, 0) such as a righting moment)."""
    model = problem.model
    nq = len(problem.free)
    Q = model.generalized_forces
    none = np.zeros((nq, nq))
    if Q == sp.zeros(*Q.shape):
        return True, False, "", none
    rng = np.random.default_rng(4)
    Qt = Q.xreplace({model.t: 0})
    values = dict(zip(model.parameter_symbols, p))
    for c in problem.cyclic:
        if not identically_zero(Qt[model.coordinates.index(c)], values):  # relative to the force's own terms
            return False, False, f"a force acts on the cyclic coordinate {c}, so its momentum is not conserved", none
    rest = {u: 0 for u in model.u}
    rest[model.t] = 0
    nc = [model.coordinates.index(c) for c in problem.free]
    qn = [model.q[i] for i in nc]
    Q0 = sp.Matrix([Q[i] for i in nc]).xreplace(rest)
    args = list(model.q) + list(model.parameter_symbols)
    J0 = compile_exprs(list(Q0.jacobian(qn)), args)
    for _ in range(3):
        Jr = np.array(J0(*rng.uniform(-2, 2, len(model.q)), *p), dtype=float).reshape(nq, nq)
        if np.max(np.abs(Jr - Jr.T)) > 1e-9 * max(1.0, np.max(np.abs(Jr))):
            return False, False, "circulatory (non-conservative positional) forces act, so no energy argument", none
    q, u = state_at(model, e.coordinates, e.rates)
    positional = np.array(J0(*q, *p), dtype=float).reshape(nq, nq)
    dQdu = Q.jacobian(model.u).xreplace({model.t: 0})
    D = -np.array(compile_exprs(list(dQdu), list(model.q) + list(model.u) + list(model.parameter_symbols))(
        *q, *u, *p), dtype=float).reshape(len(model.q), len(model.q))
    D = (D + D.T) / 2
    Dn = D[np.ix_(nc, nc)]
    if np.min(np.linalg.eigvalsh(D)) < -1e-12 * np.max(np.abs(D)):  # relative: damping of any size
        return False, False, "the velocity-dependent forces can feed energy in", none
    complete = bool(Dn.size and np.min(np.linalg.eigvalsh(Dn)) > 1e-12 * np.max(np.abs(Dn)))
    if problem.m:
        complete = False
    return True, complete, "", (positional + positional.T) / 2


def _compiled_hessian(problem, e, p: np.ndarray) -> np.ndarray | str | None:
    """Hess U - dQ0/dq over the free coordinates of an unconstrained problem, from the compiled linearization at
    the steady motion (the symbolic Hessian of Routh's potential took 30 s of a spinning 6-box chain's `modes`).
    With the conserved momenta p_c = M_cc u_c + b_c of the cyclic coordinates, U = V - T0 + (p - b)^T M_cc^-1
    (p - b) / 2 has the gradient -f over the free coordinates at fixed rates (f: the forcing, Q at the steady rates
    included), and at fixed momenta the rates move with q as M_cc du_c = -G dq, G = dp_c/dq = -df_c/du over the
    free rates (no force acts on a cyclic coordinate: _dissipation). So Hess U - dQ/dq = -df/dq + G^T M_cc^-1 G,
    at a rest as well. Cyclic coordinates whose rates leave T with the free rates at zero carry no momentum and are
    left out, as in _effective_potential; a singular M_cc gives its reason (a string). None where Q depends on
    a cyclic rate (dQ/dq at the steady rates is then not dQ0/dq): the symbolic path decides."""
    from mechsys.mechanics.dag import FreeSymbols, Substitution

    model = problem.model
    rates = {c: model.doc.rates[c] for c in problem.cyclic}
    symbols = FreeSymbols()
    if any(symbols.has(x, w) for x in model.generalized_forces for w in rates.values()):
        return None
    free_rest = Substitution({**{model.doc.rates[c]: 0 for c in problem.free}, model.t: 0}, symbols)
    Tc = free_rest.of(model.kinetic_energy)
    moving = [c for c, w in rates.items() if symbols.has(Tc, w)]
    q, u = state_at(model, e.coordinates, e.rates)
    v = pieces(model).evaluate(q, u, np.zeros(0), p)
    s = [model.coordinates.index(c) for c in problem.free]
    c = [model.coordinates.index(name) for name in moving]
    H = -v["dfdq"][np.ix_(s, s)]
    if c:
        Mcc = v["M"][np.ix_(c, c)]
        scale = max(1e-300, float(np.max(np.abs(Mcc))))
        if np.linalg.matrix_rank(Mcc, tol=1e-12 * scale) < len(c):
            zero = [name for i, name in enumerate(moving) if abs(Mcc[i, i]) <= 1e-12 * scale]
            return _massless(zero or moving)
        G = -v["dfdu"][np.ix_(c, s)]
        H = H + G.T @ np.linalg.solve(Mcc, G)
    return H


class _MasslessCyclic(Exception):
    """The cyclic block of the mass matrix is singular: no Routh potential."""


def _massless(names: list[str]) -> str:
    return (f"the cyclic coordinate(s) {', '.join(names)} carry no mass or inertia at this state (singular inertia "
            f"of the cyclic block), so Routh's amended potential is not defined")


def _effective_potential(problem, e) -> tuple[sp.Expr, list[sp.Symbol]]:
    """U = V - T0 (rates of non-cyclic coordinates at zero), plus Routh's term for conserved cyclic momenta."""
    model = problem.model
    T, V = model.kinetic_energy, model.potential_energy
    rest_nc = {model.doc.rates[c]: 0 for c in problem.free}
    cyc_u = [model.doc.rates[c] for c in problem.cyclic]
    all_rest = {**rest_nc, **{u: 0 for u in cyc_u}, model.t: 0}
    U = V.xreplace({model.t: 0}) - T.xreplace(all_rest)
    Tc = T.xreplace({**rest_nc, model.t: 0})
    # a cyclic coordinate whose rate is absent from T has neither momentum nor a Routh term (no mass moves with it)
    cyc_u = [w for w in cyc_u if w in Tc.free_symbols]
    if cyc_u:
        Mcc = sp.hessian(Tc, cyc_u)
        b = sp.Matrix([sp.diff(Tc, u) for u in cyc_u]).xreplace({u: 0 for u in cyc_u})
        # conserved momenta p = Mcc u_c + b at the steady motion, as numbers
        q0 = {model.doc.coords[c]: e.coordinates[c] for c in problem.free}
        q0.update({model.doc.coords[c]: 0 for c in problem.cyclic})
        values = {s: sp.Float(float(v)) for s, v in zip(model.parameter_symbols, problem_parameters(problem))}
        names = [c for c in problem.cyclic if model.doc.rates[c] in cyc_u]
        uc = sp.Matrix([e.rates[c] for c in names])
        pmom = (Mcc * uc + b).xreplace(q0).xreplace(values).evalf()
        Mnum = np.array(Mcc.xreplace(q0).xreplace(values).evalf(), dtype=float)
        if np.linalg.matrix_rank(Mnum, tol=1e-12 * max(1e-300, float(np.max(np.abs(Mnum))))) < len(cyc_u):
            zero = [c for i, c in enumerate(names) if abs(Mnum[i, i]) <= 1e-12 * max(1e-300, float(np.max(np.abs(Mnum))))]
            raise _MasslessCyclic(_massless(zero or names))
        # inverse of the small cyclic block only, by adjugate and determinant: sympy's default inverse searches
        # pivots with simplify(), seconds per verdict for a rigid body's 1x1 block
        inverse = Mcc.adjugate() / Mcc.det(method="berkowitz") if Mcc.shape[0] > 1 else sp.Matrix([[1 / Mcc[0, 0]]])
        U = U + ((pmom - b).T * inverse * (pmom - b))[0] / 2
        U = U.xreplace({model.doc.coords[c]: 0 for c in problem.cyclic})
    qn = [model.doc.coords[c] for c in problem.free]
    return U, qn


def _hessian(U: sp.Expr, qn: list, problem, q0: np.ndarray, p: np.ndarray) -> np.ndarray:
    diff = problem.model.diff  # sympy.hessian's entries (upper triangle, mirrored), each subexpression once
    n = len(qn)
    H = sp.zeros(n, n) if n else sp.hessian(U, qn)  # sympy refuses an empty list of variables: so do we
    for i in range(n):
        for j in range(i, n):
            H[i, j] = H[j, i] = diff(diff(U, qn[i]), qn[j])
    fn = compile_exprs(list(H), qn + list(problem.model.parameter_symbols))
    return np.array(fn(*q0, *p), dtype=float).reshape(len(qn), len(qn))


def _constrained_hessian(problem, e, p: np.ndarray, H: np.ndarray) -> np.ndarray:
    """N^T (Hess U - sum lambda_k Hess Phi_k) N on the constraint manifold's tangent space."""
    model = problem.model
    qn = [model.doc.coords[c] for c in problem.free]
    Phi = model.holonomic_constraints.xreplace({model.t: 0})
    total = np.array(H)
    q0 = np.array([e.coordinates[c] for c in problem.free], dtype=float)
    for k in range(Phi.shape[0]):
        Hk = _hessian(Phi[k], qn, problem, q0, p)
        total = total - e.multipliers[k] * Hk
    _A, _B, N = reduced_pencil(problem, e)
    return N.T @ total @ N


def _higher_order(U: sp.Expr, qn: list, problem, q0: np.ndarray, p: np.ndarray, v: np.ndarray) -> tuple[int, float]:
    """First non-vanishing derivative (order 3..6) of U along q0 + s v at s = 0; (0, 0.0), undecided, where a
    derivative is not a finite number (U not smooth there). A coefficient c_k vanishes when it is within ten times
    what the root's inaccuracy (DEGENERATE_SHIFT (1 + |q0|), a degenerate root being found ~1e-8 off) makes of the
    higher ones, sum over j > k of C(j, k) |c_j| shift**(j - k), or of rounding: an x**4 minimum found 1e-8 off has
    c3 = 4e-8. (Against 1e-6 of the largest, V = x**3/3 + 1e7 x**6 dropped its cubic: 'stable (order-6 term
    positive)' where V < 0 for small negative x.)"""
    s = sp.Symbol("s_dir", real=True)
    line = U.xreplace({q: float(q0[i]) + float(v[i]) * s for i, q in enumerate(qn)})
    line = line.xreplace({s: sp.Float(float(x)) for s, x in zip(problem.model.parameter_symbols, p)})
    deriv = sp.diff(line, s, 2)
    terms = []
    for order in range(3, 7):
        deriv = sp.diff(deriv, s)
        try:
            value = float(deriv.xreplace({s: 0}).evalf()) / math.factorial(order)
        except TypeError:  # a complex or unevaluated value (the derivative of sign(), Abs() at its switch)
            return 0, 0.0
        if not math.isfinite(value):
            return 0, 0.0
        terms.append((order, value))
    scale = max(abs(c) for _, c in terms)
    shift = DEGENERATE_SHIFT * (1.0 + float(np.max(np.abs(q0), initial=0.0)))
    for k, (order, coeff) in enumerate(terms):
        noise = sum(math.comb(j, order) * abs(c) * shift ** (j - order) for j, c in terms[k + 1:])
        if scale > 0 and abs(coeff) > max(10.0 * noise, 1e-12 * scale):
            return order, coeff
    return 0, 0.0


#: how far from a degenerate rest the root found may lie, relative to 1 + |q0|: Newton's ~1e-8 (docs §2.5) x 100
DEGENERATE_SHIFT = 1e-6
