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

Accelerations (acceleration(P), der(der(q))) contain the acceleration symbols of the coordinates; the
evaluation along a motion (analysis/outputs.py) supplies them from the equations of motion.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import sympy as sp

from mechsys.mechanics.build import Builder
from mechsys.errors import InputError
from mechsys.model.expressions import ExpressionError, Quantities

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel

#: name -> (smallest, largest) number of arguments
ARITY = {"position": (1, 1), "velocity": (1, 1), "acceleration": (1, 1), "angular_velocity": (1, 1),
         "momentum": (1, 1), "angular_momentum": (1, 2), "kinetic_energy": (1, 1), "momentum_of": (1, 1)}
SCALAR = {"kinetic_energy", "momentum_of"}


class ModelQuantities(Quantities):
    """The built-in quantity functions of one model (what the expression parser calls)."""

    functions = frozenset(ARITY)

    def __init__(self, model: MechanicalModel) -> None:
        self.model = model
        self.accels = {**{n: sp.diff(e, model.t, 2) for n, e in model.doc.prescribed.items()},
                       **{n: model.doc.accels[n] for n in model.coordinates}}
        self.builder = Builder(model.doc)
        self.builder.kin = model.kin  # only its point lookups are used, on the model's frames

    def components(self, name: str) -> tuple[str, ...]:
        return ("x", "y", "z")

    def evaluate(self, name: str, refs: list[tuple[str, int]], pos: int) -> sp.Expr | sp.MatrixBase:
        lo, hi = ARITY[name]
        if not lo <= len(refs) <= hi:
            count = f"{lo}" if lo == hi else f"{lo} or {hi}"
            raise ExpressionError(f"{name}() takes {count} argument(s), got {len(refs)}", pos)
        ref, at = refs[0]
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

    # ------------------------------------------------------------------------------------- references
    def point(self, ref: str, at: int):
        try:
            return self.builder.point_on(ref, ("outputs",))
        except InputError as exc:  # naming the reference: reported at the argument's column
            raise ExpressionError(exc.message, at) from None

    def frame_of(self, ref: str, at: int):
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
    """(column name, expression in t, q, der(q), der(der(q)) and parameters) for each of the file's `outputs:`;
    a vector quantity written as the whole expression gives the columns NAME.x, NAME.y, NAME.z."""
    doc = model.doc
    spec = doc.spec.outputs
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
            out += [(f"{name}.{c}", e) for c, e in zip(quantities.components(""), value)]
        else:
            out.append((name, value))
    return out

