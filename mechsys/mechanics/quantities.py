"""Output quantities of the file's `outputs:`: built-in mechanical quantities as symbolic expressions.

Every vector is in ground axes. Points are written as everywhere in the language: ``link`` (its frame origin,
the joint point), ``link.com``, ``link.NAME``, ``ground.NAME``. ``system`` means every massive link.

| function | value |
|---|---|
| position(P), velocity(P), acceleration(P) | r, v, a of point P |
| angular_velocity(L) | omega of link L |
| momentum(L or system) | sum of m v_G |
| angular_momentum(L or system [, P]) | sum of (r_G - r_P) x m v_G + R I omega, about P (default: the ground origin) |
| kinetic_energy(L or system) | T |
| momentum_of(q) | the generalized momentum dT/d(der(q)) |
| reaction(L[, K]) | (Fx, Fy, Fz, Mx, My, Mz): the wrench L's joint transmits to L's subtree (analysis/motion/reactions.py); in the axes of link K if given |
| constraint_force(C[, K]) | the force a point_on_point or rolling constraint C applies at its (first) point; in the axes of link K if given |
| multiplier(ROW) | the Lagrange multiplier of one constraint row (M q'' = f + A^T lambda), e.g. crank_pin.x or floor.1 |

Accelerations (acceleration(P), der(der(q))) contain the acceleration symbols of the coordinates; the
evaluation along a motion (analysis/motion/outputs.py) supplies them from the equations of motion. Multipliers and
reactions are not expressions of the state: they enter as placeholder symbols (``ModelQuantities.deferred``)
whose values the evaluation computes at each time from the multipliers and the Newton-Euler wrenches.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import sympy as sp

from mechsys.mechanics.build import Builder
from mechsys.errors import InputError
from mechsys.model.expressions import ExpressionError, Quantities

if TYPE_CHECKING:
    from mechsys.mechanics.kinematics import FrameState
    from mechsys.mechanics.model import MechanicalModel

#: name -> (smallest, largest) number of arguments
ARITY = {"position": (1, 1), "velocity": (1, 1), "acceleration": (1, 1), "angular_velocity": (1, 1),
         "momentum": (1, 1), "angular_momentum": (1, 2), "kinetic_energy": (1, 1), "momentum_of": (1, 1),
         "reaction": (1, 2), "constraint_force": (1, 2), "multiplier": (1, 1)}
WRENCH = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")
#: constraint types whose rows are the ground components of a force at their (first) point
POINT_FORCES = ("point_on_point", "rolling")


class ModelQuantities(Quantities):
    """The built-in quantity functions of one model (what the expression parser calls)."""

    functions = frozenset(ARITY)

    def __init__(self, model: MechanicalModel) -> None:
        self.model = model
        self.accels = {**{n: sp.diff(e, model.t, 2) for n, e in model.doc.prescribed.items()},
                       **{n: model.doc.accels[n] for n in model.coordinates}}
        self.builder = Builder(model.doc)
        self.builder.kin = model.kin  # only its point lookups are used, on the model's frames
        self.deferred: dict[sp.Symbol, tuple[str, object, int]] = {}  # placeholder -> (kind, row or link, index)

    def components(self, name: str) -> tuple[str, ...]:
        return WRENCH if name == "reaction" else ("x", "y", "z")

    def evaluate(self, name: str, refs: list[tuple[str, int]], pos: int) -> sp.Expr | sp.MatrixBase:
        lo, hi = ARITY[name]
        if not lo <= len(refs) <= hi:
            count = f"{lo}" if lo == hi else f"{lo} or {hi}"
            raise ExpressionError(f"{name}() takes {count} argument(s), got {len(refs)}", pos)
        ref, at = refs[0]
        if name in ("reaction", "constraint_force", "multiplier"):
            value = self.constraint_quantity(name, ref, at)
            return self.in_axes(value, *refs[1]) if len(refs) > 1 else value
        if name in ("position", "velocity", "acceleration"):
            frame, local = self.point(ref, at)
            if name == "position":
                return frame.point(local)
            v = frame.home_R * frame.point_velocity(local)
            return v if name == "velocity" else self.model.dt(v, with_accels=True)
        if name == "angular_velocity":
            return self.frame_of(ref, at).omega_ground
        if name == "momentum_of":
            if ref not in self.model.coordinates:
                raise ExpressionError(f"momentum_of() takes a free coordinate{_hint(ref, self.model.coordinates)}",
                                      at)
            return self.model.kinetic_energy.diff(self.model.u[self.model.coordinates.index(ref)])
        bodies = self.bodies(ref, at)
        if name == "kinetic_energy":
            return sum((_kinetic(b, v, w) for b, _r, v, w, _f in bodies), sp.Integer(0))
        if name == "momentum":
            return sum((b.mass * f.home_R * v for b, _r, v, _w, f in bodies), sp.zeros(3, 1))
        about = self.point(*refs[1]) if len(refs) > 1 else None
        r_P = about[0].point(about[1]) if about else sp.zeros(3, 1)
        H = sp.zeros(3, 1)
        for b, r, v, w, f in bodies:
            H += (r - r_P).cross(b.mass * f.home_R * v)
            if not b.particle:
                H += f.R * (b.inertia * w)
        return H

    def constraint_quantity(self, name: str, ref: str, at: int) -> sp.Expr | sp.MatrixBase:
        rows = [c.name for c in self.model.kin.constraints]
        if name == "reaction":
            joints = [j.link for j in self.model.kin.joints]
            if ref not in joints:
                raise ExpressionError(f"reaction() takes a link with a joint{_hint(ref, joints)}", at)
            return sp.Matrix([self.placeholder("reaction", ref, k) for k in range(6)])
        if name == "multiplier":
            if ref not in rows:
                raise ExpressionError(f"multiplier() takes a constraint row{_hint(ref, rows)}", at)
            return self.placeholder("multiplier", ref, rows.index(ref))
        kinds = {c.name or f"{c.type}_{i + 1}": c.type for i, c in enumerate(self.model.doc.spec.constraints)}
        if kinds.get(ref) not in POINT_FORCES:
            why = f"{ref!r} is a {kinds[ref]} constraint: use multiplier(ROW)" if ref in kinds else \
                f"unknown constraint{_hint(ref, list(kinds))}"
            raise ExpressionError(f"constraint_force() takes a point_on_point or rolling constraint; {why}", at)
        force = sp.zeros(3, 1)
        for k, row in enumerate(rows):
            if row.startswith(ref + ".") and row[len(ref) + 1:] in ("x", "y", "z"):
                force["xyz".index(row[-1])] = self.placeholder("multiplier", row, k)
        axes = next((getattr(c, "axes", "ground") for i, c in enumerate(self.model.doc.spec.constraints)
                     if (c.name or f"{c.type}_{i + 1}") == ref), "ground")
        return force if axes == "ground" else self.frame_of(axes, at).R * force  # rows along a link's axes

    def in_axes(self, value: sp.MatrixBase, link: str, at: int) -> sp.MatrixBase:
        """A ground-axes force (or wrench: force and moment) in the axes of ``link``."""
        R = self.frame_of(link, at).R
        if len(value) == 6:
            return sp.Matrix([*(R.T * value[:3, 0]), *(R.T * value[3:, 0])])
        return R.T * value

    def placeholder(self, kind: str, what: str, index: int) -> sp.Symbol:
        """A symbol standing for a value the evaluation computes (a multiplier, a joint wrench component)."""
        for sym, key in self.deferred.items():
            if key == (kind, what, index):
                return sym
        sym = sp.Dummy(f"{kind}_{index}", real=True)
        self.deferred[sym] = (kind, what, index)
        return sym

    # ------------------------------------------------------------------------------------- references
    def point(self, ref: str, at: int) -> tuple[FrameState, sp.Matrix]:
        try:
            return self.builder.point_on(ref, ("outputs",))
        except InputError as exc:  # naming the reference: reported at the argument's column
            raise ExpressionError(exc.message, at) from None

    def frame_of(self, ref: str, at: int) -> FrameState:
        if "." in ref:
            raise ExpressionError(f"expected a link name, got the point {ref!r}", at)
        return self.point(ref, at)[0]

    def bodies(self, ref: str, at: int) -> list:
        everything = self.model._body_kinematics
        if ref == "system":
            return everything
        self.frame_of(ref, at)  # an unknown link is an error, not an empty sum
        return [k for k in everything if k[0].name == ref]


def _kinetic(b, v: sp.Matrix, w: sp.Matrix) -> sp.Expr:
    T = b.mass * (v.T * v)[0] / 2
    if not b.particle:
        T += (w.T * b.inertia * w)[0] / 2
    return T


def _hint(name: str, options: list[str]) -> str:
    import difflib

    close = difflib.get_close_matches(name, options, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def parse_outputs(model: MechanicalModel) -> list[tuple[str, sp.Expr]]:
    """(column name, expression in t, q, der(q), der(der(q)), parameters and the placeholders of multipliers and
    reactions, kept as ``model.deferred_quantities``) for each of the file's `outputs:`; a vector quantity written
    as the whole expression gives the columns NAME.x, NAME.y, NAME.z (a reaction NAME.Fx ... NAME.Mz)."""
    doc = model.doc
    spec = doc.spec.outputs
    model.deferred_quantities = {}
    if not spec:
        return []
    taken = set(model.coordinates) | set(doc.parameters) | set(doc.prescribed) | {"t", "T", "V", "E", "residual"}
    quantities = ModelQuantities(model)
    out = []
    for name, text in spec.items():
        if name in taken:
            raise doc.error(("outputs", name), f"output {name!r} has the name of a coordinate, parameter or "
                                               "result column", key=True)
        value = doc.parse(text, ("outputs", name), "force", quantities=quantities)
        if isinstance(value, sp.MatrixBase):
            names = WRENCH if len(value) == 6 else ("x", "y", "z")
            out += [(f"{name}.{c}", e) for c, e in zip(names, value)]
        else:
            out.append((name, value))
    model.deferred_quantities = quantities.deferred
    return out

