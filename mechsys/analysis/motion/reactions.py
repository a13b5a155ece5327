"""Joint reactions: the force and moment each joint transmits to its child subtree, by Newton-Euler over the subtree.

For the joint of link L (its connection to its parent link or ground), with S the links at and below L:

    F = sum_S m a_G - sum (external forces on S)
    M_J = sum_S [(r_G - r_J) x m a_G + H_G'] - sum (moments of the external forces on S about J)

J is the joint point (the origin of L's frame: the hinge of a revolute joint), everything in ground axes. An
"external force on S" is a load with a point of application on a link of S: gravity at the centres of mass,
point forces, torques, springs, dampers and actuators between points (each end on its own link), and the forces
of the point_on_point, point_on_line, point_on_plane and rolling constraints (the multiplier times the row's
direction, at the constrained points), so closed loops are covered. Loads given only in coordinates
(torsional springs and dampers, generalized forces, potentials, dissipation functions), the rows of drive,
holonomic and nonholonomic constraints and resting gap contacts have no point of application: they are counted
as actuators inside the joints whose coordinates they act on, so they belong to the wrench of those joints (a
driven crank's torque appears in its M) and to no subtree's external loads. Evaluation uses the simulation's
q, q' and the q'', multipliers of ``RightHandSide.accelerations`` at each output time.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from mechsys.mechanics.build import Builder
from mechsys.mechanics.model import MechanicalModel

if TYPE_CHECKING:
    from mechsys.analysis.motion.simulate import SimulationResult

COMPONENTS = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")


def column_names(model: MechanicalModel) -> list[str]:
    """``reaction(LINK).Fx`` ... ``.Mz`` for each joint, in the model's link order."""
    return [f"reaction({j.link}).{c}" for j in model.kin.joints for c in COMPONENTS]


class _Items:
    """Symbolic wrench items (link, point r, force F, couple C; ground axes) acting on the links."""

    def __init__(self, model: MechanicalModel) -> None:
        self.model = model
        self.links: list[str] = []
        self.exprs: list[sp.Expr] = []
        self.builder = Builder(model.doc)
        self.builder.kin = model.kin  # only its point lookups are used, on the model's frames

    def add(self, link: str, r: sp.Matrix | None = None, F: sp.Matrix | None = None,
            C: sp.Matrix | None = None) -> None:
        if link == "ground":
            return  # never part of a subtree
        zero = sp.zeros(3, 1)
        self.links.append(link)
        self.exprs += [*(zero if r is None else r), *(zero if F is None else F), *(zero if C is None else C)]

    def point(self, ref: str, path: tuple) -> tuple[str, sp.Matrix]:
        frame, local = self.builder.point_on(ref, path)
        return ref.partition(".")[0], frame.point(local)


def _inertia_and_gravity(items: _Items) -> None:
    """d'Alembert items of each body (-m a_G at G, -H_G') and its weight."""
    model = items.model
    g = sum((ld.data["g"] for ld in model.kin.loads if ld.kind == "gravity"), sp.zeros(3, 1))
    a = sp.Matrix(model.a)
    for (b, r, _v, w, frame), (Jv, Jw) in zip(model._body_kinematics, model._body_partials):
        F = sp.zeros(3, 1)
        if b.mass != 0:
            acc = frame.point_acceleration(b.com_local) + (Jv * a if model.q else sp.zeros(3, 1))
            F = b.mass * (g - frame.home_R * acc)
        C = None
        if not b.particle and b.inertia != sp.zeros(3, 3):
            alpha = frame.alpha + (Jw * a if model.q else sp.zeros(3, 1))
            C = -frame.R * (b.inertia * alpha + w.cross(b.inertia * w))
        items.add(b.name, r, F, C)


def _loads(items: _Items) -> None:
    """Point forces, torques and the two-point elements (spring, damper, actuator) as items on their links."""
    model = items.model
    for i, (spec, load) in enumerate(zip(model.doc.spec.forces, model.kin.loads)):
        d, path = load.data, ("forces", i)
        if load.kind == "force":
            link, r = items.point(spec.at, path + ("at",))
            frame = model.kin.frames.get(link)
            items.add(link, r, frame.home_R * d["F"] if frame is not None else None)
        elif load.kind == "torque":
            axes = items.builder.frame(spec.frame or spec.on, path + ("frame",))
            M = axes.R * d["M"]
            items.add(spec.on, C=M)
            if spec.reaction:
                items.add(spec.reaction, C=-M)
        elif load.kind in ("spring", "damper", "actuator"):
            (la, ra), (lb, rb) = (items.point(spec.between[k], path + ("between", k)) for k in range(2))
            length = sp.sqrt((d["d"].T * d["d"])[0])
            if load.kind == "spring":
                F = -d["k"] * d["d"] if d["l0"] == 0 else -d["k"] * (length - d["l0"]) * d["d"] / length
            elif load.kind == "damper":
                F = -d["c"] * model.dt(length) * d["d"] / length
            else:
                F = d["value"] * d["d"] / length
            items.add(la, ra, F)
            items.add(lb, rb, -F)


def _constraints(items: _Items, lam: list[sp.Symbol]) -> None:
    """Constraint forces with a point of application: multiplier times the row's direction at its points."""
    model = items.model
    rows = {}
    for k, row in enumerate(model.kin.constraints):
        rows.setdefault(row.name, []).append(k)

    def take(name: str) -> int | None:
        ks = rows.get(name)
        return ks.pop(0) if ks else None

    for i, c in enumerate(model.doc.spec.constraints):
        path, name = ("constraints", i), c.name or f"{c.type}_{i + 1}"
        if c.type == "point_on_point":
            (la, ra), (lb, rb) = (items.point(c.points[k], path + ("points", k)) for k in range(2))
            for k, ax in enumerate("xyz"):
                row = take(f"{name}.{ax}")
                if row is not None:
                    F = sp.zeros(3, 1)
                    F[k] = lam[row]
                    items.add(la, ra, F)
                    items.add(lb, rb, -F)
        elif c.type in ("point_on_line", "point_on_plane"):
            lp, rp = items.point(c.point, path + ("point",))
            lo, ro = items.point(c.through, path + ("through",))
            fr = items.builder.frame(c.frame, path + ("frame",))
            if c.type == "point_on_line":
                normals = items.builder.complement(items.builder.axis(c.direction, path + ("direction",)),
                                                   f"{name}.direction")
            else:
                normals = [items.builder.axis(c.normal, path + ("normal",))]
            for k, n in enumerate(normals):
                row = take(f"{name}.{k + 1}")
                if row is not None:
                    F = lam[row] * (fr.R * n)  # phi = n.(p - o): force at p, its opposite at o, and the
                    items.add(lp, rp, F)       # couple n x (p - o) on the frame's link from its turning
                    items.add(lo, ro, -F)
                    items.add(c.frame, C=F.cross(rp - ro))
        elif c.type == "rolling":
            body = items.builder.frame(c.link, path + ("link",))
            axes = items.builder.frame(c.frame or c.link, path + ("frame",))
            contact = body.origin + axes.R * model.doc.parse_vec(c.contact, path + ("contact",))
            along = items.builder.frame(c.axes, path + ("axes",)).R  # the rows' axes (ground by default)
            for ax in c.components:
                row = take(f"{name}.{ax}")
                if row is not None:
                    F = lam[row] * along[:, "xyz".index(ax)]
                    items.add(c.link, contact, F)
                    items.add(c.on, contact, -F)


def reaction_source(model: MechanicalModel) -> dict:
    """Cacheable description: the link of each wrench item, the joints, and the generated source of
    [items (r, F, C) ..., joint points ...] as a function of (t, q, (q', q'', multipliers), p)."""
    from mechsys.numeric.lambdify import matrix_source

    items = _Items(model)
    lam = [sp.Dummy(f"lambda{k}") for k in range(len(model.kin.constraints))]
    _inertia_and_gravity(items)
    _loads(items)
    _constraints(items, lam)
    exprs = items.exprs + [e for j in model.kin.joints for e in model.kin.frames[j.link].origin]
    inputs = [*model.u, *model.a, *lam]
    return {"links": items.links, "joints": [[j.link, j.parent] for j in model.kin.joints],
            "m": len(lam), "expr": matrix_source(sp.Matrix(exprs), model.t, model.q, inputs, model.parameter_symbols)}


def _reactions_from(desc: dict) -> dict:
    from mechsys.numeric.lambdify import matrix_from_source

    below = subtrees(desc["joints"])
    membership = np.array([[x in below[link] for x in desc["links"]] for link, _parent in desc["joints"]], float)
    return {**desc, "fn": matrix_from_source(desc["expr"]), "m": int(desc["m"]),
            "membership": membership.reshape(len(desc["joints"]), len(desc["links"]))}


def compiled_reactions(model: MechanicalModel) -> dict:
    """The compiled reaction function and its layout, derived once per model structure (cached on disk)."""
    cached = model.__dict__.get("_reactions_compiled")
    if cached is not None:
        return cached
    from mechsys.numeric import cache

    key = cache.model_key(model, "reactions")
    desc = cache.load(key)
    try:
        out = _reactions_from(desc) if desc is not None else None
    except (KeyError, TypeError, ValueError, SyntaxError):
        out = None  # an entry in another format, or source that is not plain arithmetic: rebuild
    if out is None:
        desc = reaction_source(model)
        cache.store(key, desc)
        out = _reactions_from(desc)
    model.__dict__["_reactions_compiled"] = out
    return out


def subtrees(joints: list[list[str]]) -> dict[str, set[str]]:
    """The links at and below each joint's link."""
    children: dict[str, list[str]] = {}
    for link, parent in joints:
        children.setdefault(parent, []).append(link)

    def below(link: str) -> set[str]:
        out = {link}
        for ch in children.get(link, []):
            out |= below(ch)
        return out

    return {link: below(link) for link, _parent in joints}


def wrenches(model: MechanicalModel, t: float, q: np.ndarray, u: np.ndarray, a: np.ndarray, lam: np.ndarray,
             p: np.ndarray) -> dict[str, np.ndarray]:
    """[Fx, Fy, Fz, Mx, My, Mz] (ground axes, M about the joint point) of every joint at one state with given
    accelerations ``a`` and constraint multipliers ``lam`` (``M q'' = f + A^T lam``)."""
    comp = compiled_reactions(model)
    m = comp["m"]
    lam = np.zeros(m) if m and len(lam) == 0 else np.asarray(lam, float)[:m]
    values = comp["fn"](t, q, np.concatenate([u, a, lam]), p).ravel()
    k = 9 * len(comp["links"])
    r, F, C = (values[:k].reshape(-1, 9)[:, s] for s in (slice(0, 3), slice(3, 6), slice(6, 9)))
    points = values[k:].reshape(-1, 3)
    S = comp["membership"]  # S[j, i]: item i acts on a link of joint j's subtree
    force = S @ F
    moment = S @ (np.cross(r, F) + C) - np.cross(points, force)  # sum (r_i - r_J) x F_i + C_i
    return {link: -np.concatenate([force[j], moment[j]]) for j, (link, _parent) in enumerate(comp["joints"])}


def reaction_columns(model: MechanicalModel, result: SimulationResult, p: np.ndarray) -> dict[str, np.ndarray]:
    """``reaction(LINK).Fx`` ... ``.Mz`` at every output time of a simulation ``result`` (a SimulationResult of
    this model with parameter vector ``p``): the wrench the parent (or ground) exerts on the link's subtree."""
    from mechsys.analysis.motion.outputs import accelerations_along

    names = column_names(model)
    data = np.zeros((len(result.t), len(names)))
    for i, (t, q, u, (a, lam)) in enumerate(zip(result.t, result.q, result.u,
                                                accelerations_along(model, result, p))):
        w = wrenches(model, float(t), q, u, a, lam, p)
        data[i] = np.concatenate([w[j.link] for j in model.kin.joints])
    return {name: data[:, k] for k, name in enumerate(names)}


def reaction_notes(model: MechanicalModel, result: SimulationResult | None = None) -> list[str]:
    """What the reaction columns leave to the joints (loads and constraints without a point of application)."""
    notes = []
    kinds = sorted({ld.kind for ld in model.kin.loads if ld.kind in ("potential", "dissipation")})
    if kinds:
        notes.append(f"reactions: {' and '.join(kinds)} loads act inside the joints of their coordinates "
                     "(not as external forces of any subtree)")
    coordinate_only = [c.name or f"{c.type}_{i + 1}" for i, c in enumerate(model.doc.spec.constraints)
                       if c.type in ("holonomic", "nonholonomic")]
    if coordinate_only:
        notes.append(f"reactions: constraint {', '.join(coordinate_only)} has no point of application; its "
                     "force is counted inside the joints of its coordinates")
    if result is not None and any(im.get("captured") for im in result.impacts):
        notes.append("reactions: resting contact forces are counted inside the joints of the gap's coordinates")
    return notes


def append_reactions(model: MechanicalModel, result: SimulationResult, names: list[str], data: np.ndarray,
                     written: Path | None = None) -> tuple[list[str], np.ndarray]:
    """The result columns with the reaction columns appended; a one-line note (and the notes above) and the
    wall time go into ``result.warnings`` / ``result.timings`` for the summary."""
    import time

    from mechsys.numeric.parameters import parameter_values

    t0 = time.perf_counter()
    cols = reaction_columns(model, result, parameter_values(model))
    result.timings["joint reactions"] = time.perf_counter() - t0
    peaks = []
    for j in model.kin.joints:
        F = np.column_stack([cols[f"reaction({j.link}).{c}"] for c in COMPONENTS[:3]])
        peaks.append(f"{j.link} {float(np.max(np.linalg.norm(F, axis=1))) if len(F) else 0.0:.6g}")
    where = f"written to {written}" if written is not None else "not written (give -o FILE)"
    result.warnings.append(f"joint reactions reaction(LINK).Fx..Mz (ground axes, moments about each joint origin) "
                           f"{where}; peak |F|: {', '.join(peaks) or 'no joints'}")
    result.warnings += reaction_notes(model, result)
    if not cols:
        return names, data
    return [*names, *cols], np.column_stack([data, *cols.values()])
