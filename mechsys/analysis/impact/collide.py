"""Impacts by impulse-momentum: M (u+ - u-) = J^T U + A^T Lambda, Newton's restitution, Coulomb friction."""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from mechsys.numeric import saddle
from mechsys.numeric.parameters import parameter_values
from mechsys.errors import AnalysisError, InputError
from mechsys.mechanics.model import MechanicalModel
from mechsys.numeric.lambdify import compile_matrix

if TYPE_CHECKING:
    from mechsys.numeric.runtime import StateFunction


@dataclass
class ImpactResult:
    coordinates: list[str]
    contacts: list[str]
    rates_before: np.ndarray
    rates_after: np.ndarray
    impulses: np.ndarray  # normal impulse of each contact (0 if it separated without impulse)
    normal_velocity_before: np.ndarray
    normal_velocity_after: np.ndarray
    joint_impulses: dict[str, list[float]] = field(default_factory=dict)
    energy_before: float = 0.0
    energy_after: float = 0.0
    tangential_impulses: np.ndarray | None = None  # (contacts, 3): friction impulse on the first side, ground axes
    modes: list[str | None] = field(default_factory=list)  # "stick" | "slip" per contact; None without impulse
    restitution_factor: float = 1.0  # < 1 when e was lowered so that friction does not create energy
    held: list[str] = field(default_factory=list)  # prescribed coordinates without mass, their motion kept
    apart: dict[str, str] = field(default_factory=dict)  # resolved contacts that do not touch here: what is apart
    further: list[str] = field(default_factory=list)  # touching contacts that approach after it: impacts to come

    @property
    def energy_loss(self) -> float:
        return self.energy_before - self.energy_after

    def to_dict(self) -> dict:
        single = len(self.impulses) == 1
        impulse = float(self.impulses[0]) if single else [float(x) for x in self.impulses]
        tangential = [[float(x) for x in row] for row in self._tangential()]
        return {"rates_after": {c: float(v) for c, v in zip(self.coordinates, self.rates_after)},
                "rates_before": {c: float(v) for c, v in zip(self.coordinates, self.rates_before)},
                "impulse": impulse, "contacts": self.contacts,
                "tangential_impulse": tangential[0] if single else tangential,
                "mode": (self.modes or [None])[0] if single else list(self.modes),
                "restitution_factor": self.restitution_factor,
                "normal_velocity_before": [float(x) for x in self.normal_velocity_before],
                "normal_velocity_after": [float(x) for x in self.normal_velocity_after],
                "joint_impulses": self.joint_impulses, "energy_loss": self.energy_loss,
                "energy_before": self.energy_before, "energy_after": self.energy_after,
                "further_impacts": list(self.further), "held": list(self.held), "apart": dict(self.apart)}

    def _tangential(self) -> np.ndarray:
        if self.tangential_impulses is None:
            return np.zeros((len(self.impulses), 3))
        return self.tangential_impulses


class ImpactModel:
    """Compiled pieces of the impact equations: M, contact Jacobians (normal and relative point velocity),
    restitution and friction laws, constraint Jacobian, T, and the body velocities for joint impulses."""

    def __init__(self, model: MechanicalModel) -> None:
        if not model.kin.contacts:
            raise InputError(f"{model.doc.file}: the model declares no 'contacts'")
        self.model = model
        args = (model.t, model.q, model.u, model.parameter_symbols)
        contacts = model.kin.contacts
        self.names = [c["name"] for c in contacts]
        vn = sp.Matrix([c["vn"] for c in contacts])
        self.J = compile_matrix(model.partials(vn), *args)
        self.vn_t = compile_matrix(vn.xreplace({u: 0 for u in model.u}), *args)
        self.M = compile_matrix(model.equations("lagrange").M, *args)
        # drive constraints of prescribed coordinates are released during the impact (M = MO), except where the
        # driven coordinate carries no mass (resolve: held)
        rows = [k for k, c in enumerate(model.kin.constraints) if not c.name.startswith("drive(")]
        self.A = compile_matrix(model.constraint_jacobian[rows, :] if rows else sp.zeros(0, len(model.q)), *args)
        self.drives = [(c.name[len("drive("):-1], k) for k, c in enumerate(model.kin.constraints)
                       if c.name.startswith("drive(")]
        self.A_drive = compile_matrix(model.constraint_jacobian[[k for _, k in self.drives], :] if self.drives
                                      else sp.zeros(0, len(model.q)), *args)
        self.T = compile_matrix(sp.Matrix([model.kinetic_energy]), *args)
        # gaps (NaN for `between` contacts, which have none): which contacts touch
        self.gaps = compile_matrix(sp.Matrix([c["gap"] if c.get("gap") is not None else sp.nan for c in contacts]),
                                   *args)
        vs = sp.Symbol("vn", real=True)
        self.e = [compile_matrix(sp.Matrix([c["restitution"]]), model.t, [vs], [], model.parameter_symbols)
                  for c in contacts]
        self.mu = compile_matrix(sp.Matrix([c.get("friction", 0) for c in contacts]), model.t, [], [],
                                 model.parameter_symbols)
        # contacts with points: ground normal and relative velocity of the touching material points
        self.geometric = [c.get("normal") is not None for c in contacts]
        zero3 = sp.zeros(3, 1)
        normals = sp.Matrix.vstack(*[c["normal"] if c.get("normal") is not None else zero3 for c in contacts])
        vrel = sp.Matrix.vstack(*[c["vrel"] if c.get("vrel") is not None else zero3 for c in contacts])
        self.normals = compile_matrix(normals, *args)
        self.Jr = compile_matrix(model.partials(vrel), *args)
        self.vr_t = compile_matrix(vrel.xreplace({u: 0 for u in model.u}), *args)
        # `between` contacts: the vector from the second point to the first (they touch where it vanishes)
        self.apart = compile_matrix(sp.Matrix.vstack(*[
            c["points"][0][1] - c["points"][1][1] if c.get("gap") is None else zero3 for c in contacts]), *args)
        # whether a contact's impulse depends on the configuration (its row of J, or its normal, changes with q)
        jac = model.partials(vn)
        self.placed = [bool((jac[k, :].free_symbols | (normals[3 * k:3 * k + 3, :].free_symbols)) & set(model.q))
                       for k in range(len(contacts))]
        self._bodies = None
        self._loops = None

    def loop_items(self) -> tuple[list[str], StateFunction, StateFunction]:
        """The constraints with a point of application as impulses on their links (analysis/motion/reactions.py's
        constraint forces, linear in the multipliers): (link of each item, its ground-axes impulse as a function of
        (t, q, u, parameters + multipliers of every constraint row), the Jacobian of every constraint row).
        Compiled once."""
        if self._loops is None:
            from mechsys.analysis.motion.reactions import _constraints, _Items

            m = self.model
            lam = [sp.Symbol(f"_impulse{k}") for k in range(len(m.kin.constraints))]
            items = _Items(m)
            _constraints(items, lam)
            forces = [e for k in range(len(items.links)) for e in items.exprs[9 * k + 3:9 * k + 6]]
            impulses = compile_matrix(sp.Matrix(forces) if forces else sp.zeros(0, 1), m.t, m.q, m.u,
                                      [*m.parameter_symbols, *lam])
            rows = compile_matrix(m.constraint_jacobian if lam else sp.zeros(0, len(m.q)), m.t, m.q, m.u,
                                  m.parameter_symbols)
            self._loops = (items.links, impulses, rows)
        return self._loops

    def bodies(self) -> list[tuple[str, StateFunction, StateFunction]]:
        """(name, mass function, centre-of-mass ground velocity function) of each massive link (compiled once)."""
        if self._bodies is None:
            m = self.model
            args = (m.t, m.q, m.u, m.parameter_symbols)
            self._bodies = [(b.name, compile_matrix(sp.Matrix([b.mass]), *args),
                             compile_matrix(frame.home_R * v, *args)) for b, _r, v, _w, frame in m._body_kinematics]
        return self._bodies


def contact_degeneracy(model: MechanicalModel, t: float, q: np.ndarray, u: np.ndarray,
                       p: np.ndarray) -> AnalysisError | None:
    """An AnalysisError naming the first contact whose geometry is degenerate at (t, q): its normal velocity's
    Jacobian, normal or relative velocity divides by zero or is not finite (coincident points, a zero radius:
    the gap's derivative is undefined), with the parameters of its gap that are zero. None if every contact is
    regular. Evaluated contact by contact (only when something already failed, so compiling here is fine)."""
    args = (model.t, model.q, model.u, model.parameter_symbols)
    values = dict(zip(model.parameter_symbols, p))
    for c in model.kin.contacts:
        vn = sp.Matrix([c["vn"]])
        pieces = [model.partials(vn), vn.xreplace({w: 0 for w in model.u})]
        if c.get("normal") is not None:
            pieces += [c["normal"], model.partials(c["vrel"])]
        try:
            regular = all(np.all(np.isfinite(compile_matrix(x, *args)(t, q, u, p))) for x in pieces)
        except (ZeroDivisionError, ValueError, OverflowError):
            regular = False
        if regular:
            continue
        shape = c["gap"] if c.get("gap") is not None else vn
        used = [s for s in model.parameter_symbols if s in shape.free_symbols]
        zero = [f"{s} = 0" for s in used if values[s] == 0]
        state = ", ".join(f"{name} = {x:g}" for name, x in zip(model.coordinates, q))
        if zero:
            hint = f"; its gap uses {' and '.join(zero)} (a zero size: the contact points coincide)"
        elif used:
            hint = f"; check the parameters in its gap ({', '.join(f'{s} = {values[s]:g}' for s in used)})"
        else:
            hint = ""
        return AnalysisError(f"contact {c['name']!r}: degenerate geometry at {state or 'this state'}: the contact "
                             f"normal (the derivative of its gap) is undefined (a division by zero or not finite)"
                             f"{hint}")
    return None


def _apart(im: ImpactModel, contacts: list[int], t: float, q: np.ndarray, u: np.ndarray,
           p: np.ndarray) -> dict[str, str]:
    """The contacts to resolve that do not touch at this state (|gap|, or the distance between a `between` contact's
    points, above 1e-6 (1 + max |q|)) and whose impulse depends on where the bodies are (its row of J changes with
    q), each with what is apart: their impulse acts through points that are not where the sides meet. A bullet set
    0.3 m below the pendulum's point C was resolved as if it struck C; a disk 0.25 m above the floor bounced off
    it. (Carriages on a line give the same impulse anywhere: no entry.)"""
    with np.errstate(all="ignore"):
        gaps, apart = im.gaps(t, q, u, p).ravel(), im.apart(t, q, u, p).ravel()
    tol = 1e-6 * (1 + float(np.max(np.abs(q), initial=0.0)))
    out = {}
    for k in contacts:
        if not im.placed[k]:
            continue
        c = im.model.kin.contacts[k]
        if c.get("gap") is not None:
            distance, what = abs(float(gaps[k])), "its gap is"
        else:
            distance = float(np.linalg.norm(apart[3 * k:3 * k + 3]))
            spec = next((x for x in im.model.doc.spec.contacts if x.name == im.names[k]), None)
            refs = spec.between if spec is not None and spec.between else [pt[0] for pt in c["points"]]
            what = f"its points {refs[0]} and {refs[1]} are"
        if not distance <= tol:
            out[im.names[k]] = f"{what} {distance:.6g} apart"
    return out


def _held_drives(im: ImpactModel, M: np.ndarray, A: np.ndarray, t: float, q: np.ndarray, u: np.ndarray,
                 p: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """A with the drive rows of the prescribed coordinates that carry no mass (M[i, i] = 0) added, and their names.
    Released, such a coordinate takes any impulse without changing it: a ball on a massless table driven up and
    down passed through it (impulse 1e-17). Held, the table moves as prescribed through the impact, the
    vibrating-table model: v+ = (1 + e) v_table - e v_ball."""
    if not im.drives:
        return A, []
    scale = max(float(np.max(np.abs(M))), 1e-300)
    index = {name: i for i, name in enumerate(im.model.coordinates)}
    keep = [r for r, (name, _k) in enumerate(im.drives) if abs(M[index[name], index[name]]) <= 1e-12 * scale]
    if not keep:
        return A, []
    return np.vstack([A, im.A_drive(t, q, u, p)[keep]]), [im.drives[r][0] for r in keep]


def _tangent_basis(n: np.ndarray, Jr: np.ndarray) -> np.ndarray:
    """Orthonormal rows spanning the tangent directions (normal to n) in which the contact can slide at all:
    2 rows for a 3-D contact, 1 for a planar one, 0 when no rate moves the contact point tangentially."""
    n = n / np.linalg.norm(n)
    e = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = e - n * (n @ e)
    t1 /= np.linalg.norm(t1)
    T = np.vstack([t1, np.cross(n, t1)])
    Uu, S, _ = np.linalg.svd(T @ Jr)
    rank = int(np.sum(S > 1e-9 * max(float(S.max(initial=0.0)), 1e-300))) if S.size else 0
    return Uu[:, :rank].T @ T


def resolve(model: MechanicalModel, contact: str | None = None, q: np.ndarray | None = None,
            u: np.ndarray | None = None, t: float = 0.0, only: list[str] | None = None,
            restitution: float | None = None) -> ImpactResult:
    """Resolve one impact at the state (q, u) (default: the file's initial state). All approaching contacts (or
    just ``contact``) are solved together: U >= 0 with v+ + e v- >= 0, complementary, and with friction each
    active contact sticks (|U_t| <= mu U_n) or slips (U_t = -mu U_n along the tangential approach velocity);
    an active-set search over (inactive, stick, slip) picks the first consistent combination."""
    im = model.__dict__.get("_impact_model") or ImpactModel(model)
    model.__dict__["_impact_model"] = im
    p = parameter_values(model)
    q = np.array([model.doc.initial[c] for c in model.coordinates]) if q is None else np.asarray(q, float)
    u = np.array([model.doc.initial_rate[c] for c in model.coordinates]) if u is None else np.asarray(u, float)
    if contact is not None and contact not in im.names:
        raise InputError(f"--impact {contact}: unknown contact{model.doc.suggest(contact, im.names)} "
                         f"(choose from {', '.join(im.names)})")
    try:
        M, J, A = im.M(t, q, u, p), im.J(t, q, u, p), im.A(t, q, u, p)
        vt = im.vn_t(t, q, u, p).ravel()
        geometry = [im.Jr(t, q, u, p), im.vr_t(t, q, u, p), im.normals(t, q, u, p)]
    except (ZeroDivisionError, ValueError, OverflowError):
        M = J = A = vt = None
        geometry = []
    if M is None or not all(np.all(np.isfinite(x)) for x in (M, J, A, vt, *geometry)):
        raise contact_degeneracy(model, t, q, u, p) or AnalysisError(
            "the impact equations are not finite at this state (a division by zero in the mass matrix or the "
            "constraints: check the parameters)")
    A, held = _held_drives(im, M, A, t, q, u, p)
    # A u+: 0 on the model's constraints (scleronomic here), the drive's speed (unchanged) on a held drive row
    target = np.concatenate([np.zeros(A.shape[0] - len(held)), A[A.shape[0] - len(held):] @ u])
    v_before = J @ u + vt
    candidates = [k for k, name in enumerate(im.names) if (contact is None or name == contact)
                  and (only is None or name in only)]
    approaching = [k for k in candidates if v_before[k] < 0]
    if not approaching:
        raise AnalysisError("no contact is approaching (normal velocity >= 0): there is no impact to resolve")
    apart = _apart(im, approaching, t, q, u, p)
    e = np.array([float(im.e[k](t, [v_before[k]], [], p)[0, 0]) if restitution is None else restitution
                  for k in range(len(im.names))])
    mu = im.mu(t, [], [], p).ravel()
    # tangential rows of the frictional contacts: Jt u + vtt is the sliding velocity in the basis Tb
    Jr_all, vr_all, normals = im.Jr(t, q, u, p), im.vr_t(t, q, u, p).ravel(), im.normals(t, q, u, p).ravel()
    Tb, Jt, vtt, slide = {}, {}, {}, {}
    for k in approaching:
        if mu[k] > 0 and im.geometric[k]:
            Tb[k] = _tangent_basis(normals[3 * k:3 * k + 3], Jr_all[3 * k:3 * k + 3])
            Jt[k] = Tb[k] @ Jr_all[3 * k:3 * k + 3]
            vtt[k] = Tb[k] @ vr_all[3 * k:3 * k + 3]
            slide[k] = Jt[k] @ u + vtt[k]
    n, m = len(u), A.shape[0]
    tol_v = {k: 1e-9 * max(1.0, abs(v_before[k]), *(np.abs(slide[k]) if k in slide else [])) for k in approaching}

    def solve(ee: np.ndarray, active: list[int], modes: dict[int, str], directions: dict[int, np.ndarray]):
        stick = [k for k in active if k in Jt and modes.get(k) == "stick" and len(Jt[k])]
        W = J[active].copy()
        for i, k in enumerate(active):
            if k in Jt and modes.get(k) == "slip" and len(Jt[k]):
                W[i] = W[i] - mu[k] * directions[k] @ Jt[k]
        Jst = np.vstack([Jt[k] for k in stick]) if stick else np.zeros((0, n))
        a, s = len(active), Jst.shape[0]
        K = np.zeros((n + a + s + m, n + a + s + m))
        K[:n, :n] = M
        K[:n, n:n + a] = -W.T
        K[:n, n + a:n + a + s] = -Jst.T
        K[:n, n + a + s:] = -A.T
        K[n:n + a, :n] = J[active]
        K[n + a:n + a + s, :n] = Jst
        K[n + a + s:, :n] = A
        rhs = np.concatenate([M @ u, -ee[active] * v_before[active] - vt[active],
                              -np.concatenate([vtt[k] for k in stick]) if stick else np.zeros(0), target])
        # in balanced units (numeric/saddle.py): least squares weighs a MEMS pendulum's M ~ 1e-17 as its contact
        # rows ~ 1e-4, and its rank cut no longer drops the masses (the bullet bounced off a 'fixed' pendulum)
        D = np.concatenate(saddle.balance(M, K[n:, :n]))
        sol = D * np.linalg.lstsq(D[:, None] * K * D, D * rhs, rcond=None)[0]
        if s and np.linalg.norm(K @ sol - rhs) > 1e-9 * (np.linalg.norm(rhs) + np.linalg.norm(K) * np.linalg.norm(sol)):
            return None  # sticking is kinematically impossible here (more velocity conditions than freedoms)
        u_after = sol[:n]
        U = np.zeros(len(im.names))
        U[active] = sol[n:n + a]
        Ut = {}
        pos = n + a
        for k in stick:
            Ut[k] = sol[pos:pos + len(Jt[k])]
            pos += len(Jt[k])
        for k in active:
            if k in Jt and modes.get(k) == "slip" and len(Jt[k]):
                Ut[k] = -mu[k] * U[k] * directions[k]
        return u_after, U, Ut

    def consistent(ee, active, modes, directions, trial, strict_slip: bool) -> bool:
        if trial is None:
            return False
        u_after, U, Ut = trial
        if not np.all(U[active] >= -1e-12):
            return False
        v_after = J @ u_after + vt
        if not all(v_after[k] + ee[k] * min(v_before[k], 0) >= -1e-9 * max(1.0, abs(v_before[k]))
                   for k in approaching if k not in active):
            return False
        for k in active:
            if k not in Jt or not len(Jt[k]):
                continue
            if modes[k] == "stick" and np.linalg.norm(Ut[k]) > mu[k] * U[k] * (1 + 1e-9) + 1e-12:
                return False
            if modes[k] == "slip" and strict_slip and directions[k] @ (Jt[k] @ u_after + vtt[k]) < -tol_v[k]:
                return False  # the cone-limited impulse reversed the sliding: the contact sticks instead
        return True

    def search(ee: np.ndarray):
        for strict_slip in (True, False):
            for size in range(1, len(approaching) + 1):
                for active in itertools.combinations(approaching, size):
                    active = list(active)
                    frictional = [k for k in active if k in Jt and len(Jt[k])]
                    stuck = solve(ee, active, {k: "stick" for k in frictional}, {})
                    stuck_impulse = stuck[2] if stuck is not None else {}
                    # slip direction: along the tangential approach velocity (the impulse opposes it); with no
                    # sliding before the impact, against the impulse that sticking would need
                    directions = {}
                    for k in frictional:
                        d = slide[k] if np.linalg.norm(slide[k]) > tol_v[k] else -stuck_impulse.get(k, slide[k])
                        directions[k] = d / np.linalg.norm(d) if np.linalg.norm(d) > 0 else np.zeros_like(d)
                    combos = sorted(itertools.product(("stick", "slip"), repeat=len(frictional)),
                                    key=lambda c: c.count("slip"))
                    for combo in combos:
                        modes = dict(zip(frictional, combo))
                        trial = stuck if "slip" not in combo else solve(ee, active, modes, directions)
                        if consistent(ee, active, modes, directions, trial, strict_slip):
                            return (active, modes, *trial)
        raise AnalysisError("no consistent set of contact impulses (the complementarity problem has no solution "
                            "in the active-set search)")

    T_before = float(im.T(t, q, u, p)[0, 0])

    def gain(result) -> float:
        return float(im.T(t, q, result[2], p)[0, 0]) - T_before

    best = search(e)
    factor = 1.0
    if Jt and gain(best) > 1e-12 * max(T_before, 1e-300):
        # Newton's law with friction can create energy when the normal and tangential impulses are coupled
        # (Kane's paradox): lower the restitution of this impact until the kinetic energy does not increase
        lo, hi = 0.0, 1.0
        best_lo = search(e * 0.0)
        if gain(best_lo) <= 1e-12 * max(T_before, 1e-300):
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                trial = search(e * mid)
                if gain(trial) <= 0.0:
                    lo, best_lo = mid, trial
                else:
                    hi = mid
        best, factor = best_lo, lo
    active, modes, u_after, U, Ut = best
    v_after = J @ u_after + vt
    tangential = np.zeros((len(im.names), 3))
    for k, vec in Ut.items():
        tangential[k] = vec @ Tb[k]
    mode_list: list[str | None] = [None] * len(im.names)
    for k in active:
        mode_list[k] = modes.get(k, "stick" if k in Jt else "slip")
    with np.errstate(invalid="ignore"):
        touching = np.abs(im.gaps(t, q, u, p).ravel()) <= 1e-9 * (1 + np.max(np.abs(q), initial=0.0))
    scale = 1e-12 * max(1.0, float(np.max(np.abs(u_after), initial=0.0)))
    further = [name for k, name in enumerate(im.names) if touching[k] and v_after[k] < -scale]
    res = ImpactResult(list(model.coordinates), im.names, u, u_after, U, v_before, v_after,
                       energy_before=T_before, energy_after=float(im.T(t, q, u_after, p)[0, 0]),
                       tangential_impulses=tangential, modes=mode_list, restitution_factor=factor, further=further,
                       held=held, apart=apart)
    res.joint_impulses = joint_impulses(model, q, u, u_after, U, p, t, tangential)
    return res


def joint_impulses(model: MechanicalModel, q: np.ndarray, u_before: np.ndarray, u_after: np.ndarray, U: np.ndarray,
                   p: np.ndarray, t: float,
                   tangential: np.ndarray | None = None) -> dict[str, list[float]]:
    """Impulse each joint applies to its child link (ground axes): the momentum change of the child's subtree
    minus the contact impulses (normal and friction) acting on that subtree (per-body Newton-Euler impulse
    balance). A plain ``gap`` contact does not say which bodies it pushes, or in which direction: while one
    carries an impulse, joints whose subtree moves with the gap's coordinates are left out."""
    im = model.__dict__.get("_impact_model") or ImpactModel(model)
    model.__dict__["_impact_model"] = im
    contacts = model.kin.contacts
    momentum: dict[str, np.ndarray] = {}
    for name, mass, vg in im.bodies():
        mass_value = float(mass(t, q, u_after, p)[0, 0])
        momentum[name] = mass_value * (vg(t, q, u_after, p).ravel() - vg(t, q, u_before, p).ravel())
    normals = im.normals(t, q, u_before, p).ravel()
    external: dict[str, np.ndarray] = {}
    unknown: set = set()  # coordinates of plain gap contacts that carry an impulse
    for k, c in enumerate(contacts):
        if U[k] == 0:
            continue
        if not im.geometric[k]:
            unknown |= set(c["gap"].free_symbols) & set(model.q)
            continue
        impulse = U[k] * normals[3 * k:3 * k + 3] + (tangential[k] if tangential is not None else 0.0)
        for link, _pos, sign in c["points"]:
            external[link] = external.get(link, np.zeros(3)) + sign * impulse
    for link, impulse in _constraint_impulses(im, q, u_before, u_after, U, p, t, tangential):
        external[link] = external.get(link, np.zeros(3)) + impulse
    children: dict[str, list[str]] = {}
    for j in model.kin.joints:
        children.setdefault(j.parent, []).append(j.link)

    def subtree(link: str) -> list[str]:
        out = [link]
        for ch in children.get(link, []):
            out += subtree(ch)
        return out

    def moves_with_unknown(link: str) -> bool:
        frame = model.kin.frames[link]
        return bool((frame.origin.free_symbols | frame.R.free_symbols) & unknown)

    result = {}
    for j in model.kin.joints:
        links = subtree(j.link)
        if unknown and any(moves_with_unknown(x) for x in links):
            continue
        terms = [momentum.get(x, np.zeros(3)) for x in links] + [external.get(x, np.zeros(3)) for x in links]
        total = sum((momentum.get(x, np.zeros(3)) - external.get(x, np.zeros(3)) for x in links), np.zeros(3))
        # rounding is relative to the momenta and impulses whose difference the total is (against 1 N s, a MEMS
        # pendulum's 4.5e-13 N s hinge impulse was printed as 0)
        scale = max(float(np.max(np.abs(terms), initial=0.0)), 1e-300)
        result[j.link] = [float(x) if abs(x) > 1e-12 * scale else 0.0 for x in total]
    return result


def _constraint_impulses(im: ImpactModel, q: np.ndarray, u_before: np.ndarray, u_after: np.ndarray, U: np.ndarray,
                         p: np.ndarray, t: float, tangential: np.ndarray | None) -> list[tuple[str, np.ndarray]]:
    """(link, impulse in ground axes) of the constraints with a point of application (a loop's pin, a point on a
    line or plane, a rolling contact): their multipliers Lambda from the impulse balance M (u+ - u-) = P + A^T
    Lambda over every constraint row, P the contact impulses in coordinates (least squares: a drive row released
    for the impact gets 0), mapped to the constrained points as reactions.py maps the forces. A four-bar struck on
    its rocker: without them, every joint impulse was off by the pin's impulse."""
    links, impulses, rows = im.loop_items()
    if not links:
        return []
    A = np.atleast_2d(rows(t, q, u_before, p))
    M = im.M(t, q, u_before, p)
    P = np.zeros(len(q))
    J, Jr, normals = im.J(t, q, u_before, p), im.Jr(t, q, u_before, p), im.normals(t, q, u_before, p).ravel()
    for k in range(len(im.names)):
        if U[k] == 0 and (tangential is None or not np.any(tangential[k])):
            continue
        if im.geometric[k]:  # the impulse on the first point, its opposite on the second: Jr maps their difference
            impulse = U[k] * normals[3 * k:3 * k + 3] + (tangential[k] if tangential is not None else 0.0)
            P += Jr[3 * k:3 * k + 3].T @ impulse
        else:
            P += J[k] * U[k]
    lam = np.linalg.lstsq(A.T, M @ (u_after - u_before) - P, rcond=None)[0]
    values = np.asarray(impulses(t, q, u_before, np.concatenate([p, lam])), dtype=float).reshape(len(links), 3)
    return list(zip(links, values))


def centre_of_percussion(model: MechanicalModel, link: str | None = None) -> dict:
    """For a body hinged to ground by a revolute joint: rC = I_O / (m r_G) along the line from the hinge axis
    through the centre of mass (an impact there produces no impulse at the hinge)."""
    hinged = [j for j in model.kin.joints if j.type == "revolute" and j.parent == "ground"
              and any(b.name == j.link and b.mass != 0 for b in model.kin.bodies)]
    if link is not None:
        links = [j.link for j in model.kin.joints]
        if link not in links:
            raise InputError(f"--link {link}: unknown link{model.doc.suggest(link, links)} "
                             f"(choose from {', '.join(links)})")
        hinged = [j for j in hinged if j.link == link]
    if len(hinged) != 1:
        raise InputError("--percussion needs exactly one massive link hinged to ground by a revolute joint "
                         "(choose it with --link)")
    j = hinged[0]
    body = next(b for b in model.kin.bodies if b.name == j.link)
    values = dict(zip(model.parameter_symbols, map(sp.Float, parameter_values(model))))
    spec = model.doc.spec.links[j.link]
    from mechsys.mechanics.kinematics import AXES

    axis = np.array(AXES[spec.joint.axis] if isinstance(spec.joint.axis, str) else
                    model.doc.parse_vec(spec.joint.axis, ("links", j.link, "joint", "axis"), "parameter")
                    .xreplace(values), dtype=float).ravel()
    axis = axis / np.linalg.norm(axis)
    c = np.array(body.com_local.xreplace(values), dtype=float).ravel()
    m = float(sp.sympify(body.mass).xreplace(values))
    I_G = np.array(body.inertia.xreplace(values), dtype=float)
    c_perp = c - axis * (axis @ c)
    r_G = float(np.linalg.norm(c_perp))
    I_O = float(axis @ I_G @ axis) + m * r_G**2
    if r_G == 0:
        raise AnalysisError("the centre of mass lies on the hinge axis: there is no centre of percussion")
    r_C = I_O / (m * r_G)
    return {"link": j.link, "I_O": I_O, "r_G": r_G, "distance": r_C,
            "point_in_link_axes": [float(x) for x in c_perp / r_G * r_C]}
