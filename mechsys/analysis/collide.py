"""Impacts by impulse-momentum: M (u+ - u-) = J^T U + A^T Lambda, Newton's restitution on the normal velocities."""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from mechsys.analysis.equilibria import parameter_values
from mechsys.errors import AnalysisError, InputError
from mechsys.mechanics.model import MechanicalModel
from mechsys.numeric.lambdify import compile_matrix


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

    @property
    def energy_loss(self) -> float:
        return self.energy_before - self.energy_after

    def to_dict(self) -> dict:
        impulse = float(self.impulses[0]) if len(self.impulses) == 1 else [float(x) for x in self.impulses]
        return {"rates_after": {c: float(v) for c, v in zip(self.coordinates, self.rates_after)},
                "rates_before": {c: float(v) for c, v in zip(self.coordinates, self.rates_before)},
                "impulse": impulse, "contacts": self.contacts,
                "normal_velocity_before": [float(x) for x in self.normal_velocity_before],
                "normal_velocity_after": [float(x) for x in self.normal_velocity_after],
                "joint_impulses": self.joint_impulses, "energy_loss": self.energy_loss,
                "energy_before": self.energy_before, "energy_after": self.energy_after}


class ImpactModel:
    """Compiled pieces of the impact equations: M, contact Jacobians, restitution, constraint Jacobian, T."""

    def __init__(self, model: MechanicalModel) -> None:
        if not model.kin.contacts:
            raise InputError(f"{model.doc.file}: the model declares no 'contacts'")
        self.model = model
        args = (model.t, model.q, model.u, model.parameter_symbols)
        self.names = [c["name"] for c in model.kin.contacts]
        vn = sp.Matrix([c["vn"] for c in model.kin.contacts])
        self.J = compile_matrix(model.partials(vn), *args)
        self.vn_t = compile_matrix(vn.xreplace({u: 0 for u in model.u}), *args)
        self.M = compile_matrix(model.equations("lagrange").M, *args)
        # drive constraints of prescribed coordinates are released during the impact (M = MO)
        rows = [k for k, c in enumerate(model.kin.constraints) if not c.name.startswith("drive(")]
        self.A = compile_matrix(model.constraint_jacobian[rows, :] if rows else sp.zeros(0, len(model.q)), *args)
        self.T = compile_matrix(sp.Matrix([model.kinetic_energy]), *args)
        vs = sp.Symbol("vn", real=True)
        self.e = [compile_matrix(sp.Matrix([c["restitution"]]), model.t, [vs], [], model.parameter_symbols)
                  for c in model.kin.contacts]


def resolve(model: MechanicalModel, contact: str | None = None, q: np.ndarray | None = None,
            u: np.ndarray | None = None, t: float = 0.0, only: list[str] | None = None,
            restitution: float | None = None) -> ImpactResult:
    """Resolve one impact at the state (q, u) (default: the file's initial state). All approaching contacts (or
    just ``contact``) are solved together: U >= 0 with v+ + e v- >= 0, complementary (an active-set search)."""
    im = model.__dict__.get("_impact_model") or ImpactModel(model)
    model.__dict__["_impact_model"] = im
    p = parameter_values(model)
    q = np.array([model.doc.initial[c] for c in model.coordinates]) if q is None else np.asarray(q, float)
    u = np.array([model.doc.initial_rate[c] for c in model.coordinates]) if u is None else np.asarray(u, float)
    if contact is not None and contact not in im.names:
        raise InputError(f"--impact {contact}: unknown contact{model.doc.suggest(contact, im.names)} "
                         f"(choose from {', '.join(im.names)})")
    M, J, A = im.M(t, q, u, p), im.J(t, q, u, p), im.A(t, q, u, p)
    vt = im.vn_t(t, q, u, p).ravel()
    v_before = J @ u + vt
    candidates = [k for k, name in enumerate(im.names) if (contact is None or name == contact)
                  and (only is None or name in only)]
    approaching = [k for k in candidates if v_before[k] < 0]
    if not approaching:
        raise AnalysisError("no contact is approaching (normal velocity >= 0): there is no impact to resolve")
    e = np.array([float(im.e[k](t, [v_before[k]], [], p)[0, 0]) if restitution is None else restitution
                  for k in range(len(im.names))])
    n, m = len(u), A.shape[0]
    best = None
    for size in range(1, len(approaching) + 1):
        for active in itertools.combinations(approaching, size):
            active = list(active)
            Ja = J[active]
            K = np.block([[M, -Ja.T, -A.T], [Ja, np.zeros((len(active), len(active) + m))],
                          [A, np.zeros((m, len(active) + m))]])
            rhs = np.concatenate([M @ u, -e[active] * v_before[active] - vt[active], np.zeros(m)])
            try:
                sol = np.linalg.lstsq(K, rhs, rcond=None)[0]
            except np.linalg.LinAlgError:
                continue
            u_after = sol[:n]
            U = np.zeros(len(im.names))
            U[active] = sol[n:n + len(active)]
            v_after = J @ u_after + vt
            ok = np.all(U[active] >= -1e-12) and all(
                v_after[k] + e[k] * min(v_before[k], 0) >= -1e-9 * max(1.0, abs(v_before[k]))
                for k in approaching if k not in active)
            if ok:
                best = (u_after, U, v_after, sol[n + len(active):])
                break
        if best is not None:
            break
    if best is None:
        raise AnalysisError("no consistent set of contact impulses (the complementarity problem has no solution "
                            "in the active-set search)")
    u_after, U, v_after, _lam = best
    res = ImpactResult(list(model.coordinates), im.names, u, u_after, U, v_before, v_after,
                       energy_before=float(im.T(t, q, u, p)[0, 0]), energy_after=float(im.T(t, q, u_after, p)[0, 0]))
    res.joint_impulses = joint_impulses(model, q, u, u_after, U, p, t)
    return res


def joint_impulses(model: MechanicalModel, q, u_before, u_after, U, p, t: float) -> dict[str, list[float]]:
    """Impulse each joint applies to its child link (ground axes): the momentum change of the child's subtree
    minus the contact impulses acting on that subtree (per-body Newton-Euler impulse balance)."""
    if any(c["gap"] is not None for c in model.kin.contacts):
        return {}
    from mechsys.numeric.lambdify import compile_matrix as cm

    momentum: dict[str, np.ndarray] = {}
    for b, _r, v, _w, frame in model._body_kinematics:
        vg = cm(frame.home_R * v, model.t, model.q, model.u, model.parameter_symbols)
        mass = float(sp.sympify(b.mass).xreplace(dict(zip(model.parameter_symbols, map(sp.Float, p)))))
        momentum[b.name] = mass * (vg(t, q, u_after, p).ravel() - vg(t, q, u_before, p).ravel())
    external: dict[str, np.ndarray] = {}
    for k, c in enumerate(model.kin.contacts):
        n = cm(sp.Matrix(c["normal"]), model.t, model.q, model.u, model.parameter_symbols)(t, q, u_before, p).ravel()
        for link, _pos, sign in c["points"]:
            external[link] = external.get(link, np.zeros(3)) + sign * U[k] * n
    children: dict[str, list[str]] = {}
    for j in model.kin.joints:
        children.setdefault(j.parent, []).append(j.link)

    def subtree(link: str) -> list[str]:
        out = [link]
        for ch in children.get(link, []):
            out += subtree(ch)
        return out

    result = {}
    for j in model.kin.joints:
        links = subtree(j.link)
        total = sum((momentum.get(x, np.zeros(3)) - external.get(x, np.zeros(3)) for x in links), np.zeros(3))
        result[j.link] = [float(x) if abs(x) > 1e-12 * (1 + np.max(np.abs(total))) else 0.0 for x in total]
    return result


def centre_of_percussion(model: MechanicalModel, link: str | None = None) -> dict:
    """For a body hinged to ground by a revolute joint: rC = I_O / (m r_G) along the line from the hinge axis
    through the centre of mass (an impact there produces no impulse at the hinge)."""
    hinged = [j for j in model.kin.joints if j.type == "revolute" and j.parent == "ground"
              and any(b.name == j.link and b.mass != 0 for b in model.kin.bodies)]
    if link is not None:
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
                    [float(sp.sympify(x).xreplace(values)) if not isinstance(x, (int, float)) else x
                     for x in spec.joint.axis], dtype=float)
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
