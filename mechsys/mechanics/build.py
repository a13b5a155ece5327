"""Turn a validated document into kinematics: link frames, bodies, points, load and constraint elements."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import sympy as sp

from mechsys.mechanics.dag import identically_zero
from mechsys.mechanics.differentiate import Differentiator
from mechsys.mechanics.kinematics import AXES, FrameState, unit
from mechsys.model.expressions import names_in
from mechsys.model.load import T, Document
from mechsys.model.yamlpos import Path

# Joint class c = 6 - NCE (Krodkiewski eq. 1.2); 'transform' counts the coordinates it uses.
JOINT_CLASS = {"revolute": 1, "prismatic": 1, "cylindrical": 2, "universal": 2, "spherical": 3,
               "planar": 3, "fixed": 0, "free": 6}
ROTATION_JOINTS = {"revolute", "spherical", "universal"}


@dataclass
class Body:
    """A massive link: mass, ground position of its centre of mass and central inertia in link axes."""

    name: str
    mass: sp.Expr
    com_local: sp.Matrix
    inertia: sp.Matrix
    particle: bool


@dataclass
class JointInfo:
    link: str
    parent: str
    type: str
    coordinates: list[str]
    joint_class: int

    @property
    def reactions(self) -> int:
        return 6 - self.joint_class


@dataclass
class Load:
    """One force element, already in symbols: kind tells derive how to use the fields."""

    kind: str
    data: dict[str, Any]


@dataclass
class ConstraintRow:
    name: str
    kind: str  # "holonomic" or "nonholonomic"
    position: sp.Expr | None  # Phi(q, t) for holonomic rows
    velocity: sp.Expr  # linear in the rates
    equations: int = 1  # scalar equations this element contributes (for mobility counting)


@dataclass
class Kinematics:
    frames: dict[str, FrameState] = field(default_factory=dict)
    bodies: list[Body] = field(default_factory=list)
    joints: list[JointInfo] = field(default_factory=list)
    loads: list[Load] = field(default_factory=list)
    constraints: list[ConstraintRow] = field(default_factory=list)
    constraint_elements: list[tuple[str, int]] = field(default_factory=list)  # (type, NCE)
    contacts: list[dict] = field(default_factory=list)
    angles: dict[str, bool] = field(default_factory=dict)
    # structural choices made with the numeric parameter values (rows found identically zero, a helper axis):
    # (what, kind, expression, outcome); cache keys include the outcomes and `decisions_hold` re-checks them
    decisions: list[tuple[str, str, Any, bool]] = field(default_factory=list)


class Builder:
    def __init__(self, doc: Document) -> None:
        self.doc = doc
        self.kin = Kinematics()
        self.used_by: dict[str, str] = {}
        self.diff = Differentiator()  # the rates of the chain's angles and offsets share most subexpressions

    # ------------------------------------------------------------------------------------- helpers
    def axis(self, value: Any, path: Path) -> sp.Matrix:
        if isinstance(value, str):
            return sp.Matrix(AXES[value])
        vec = self.doc.parse_vec(value, path, "kinematic")
        if vec.free_symbols - set(self.doc.parameters.values()):
            raise self.doc.error(path, "an axis may depend on parameters only")
        values = [self.real_value(e, path) for e in vec]
        if max(abs(x) for x in values) == 0:
            raise self.doc.error(path, "axis must not be the zero vector (with the file's parameter values)")
        return unit(vec)

    def real_value(self, expr: sp.Expr, path: Path, nonnegative: bool = False) -> float:
        """The value of a parameter-only expression; it must be a finite real number."""
        try:
            values = {k: sp.Float(v) for k, v in self.doc.numeric_parameters().items()}
            val = complex(sp.sympify(expr).xreplace(values).evalf())
        except (TypeError, ValueError, ZeroDivisionError):
            raise self.doc.error(path, "does not evaluate to a number") from None
        if abs(val.imag) > 1e-12 * max(1.0, abs(val.real)) or not math.isfinite(val.real):
            raise self.doc.error(path, "must evaluate to a finite real number")
        if nonnegative and val.real < 0:
            raise self.doc.error(path, "must not be negative")
        return val.real

    def vanishes(self, expr: sp.Expr, what: str) -> bool:
        """Whether ``expr`` is identically zero with the file's parameter values (recorded as a decision)."""
        outcome = decide("zero", expr, self.doc.numeric_parameters())
        self.kin.decisions.append((what, "zero", expr, outcome))
        return outcome

    def complement(self, d: sp.Matrix, what: str) -> list[sp.Matrix]:
        """Two unit vectors orthogonal to unit vector ``d``; the helper axis chosen is recorded as a decision."""
        key = tuple(abs(e) if e.is_number else None for e in d)
        if key in ((1, 0, 0), (0, 1, 0), (0, 0, 1)):
            k = key.index(1)
            return [sp.Matrix(AXES["xyz"[(k + 1) % 3]]), sp.Matrix(AXES["xyz"[(k + 2) % 3]])]
        near_x = decide("near_x", d[0], self.doc.numeric_parameters())
        self.kin.decisions.append((what, "near_x", d[0], near_x))
        n1 = unit(d.cross(sp.Matrix([0, 1, 0]) if near_x else sp.Matrix([1, 0, 0])))
        return [n1, d.cross(n1)]

    def frame(self, name: str, path: Path) -> FrameState:
        if name == "ground":
            return FrameState.ground()
        if name not in self.kin.frames:
            options = ["ground"] + list(self.doc.spec.links)
            raise self.doc.error(path, f"unknown link {name!r}{self.doc.suggest(name, options)}")
        return self.kin.frames[name]

    def local_point(self, link: str, point: str, path: Path) -> sp.Matrix:
        """Coordinates of a named point in its link's axes."""
        if link == "ground":
            pts = self.doc.spec.ground.points
            base: Path = ("ground", "points", point)
        else:
            spec = self.doc.spec.links[link]
            pts = spec.points
            base = ("links", link, "points", point)
            if point == "com":
                return self.doc.parse_vec(spec.center_of_mass, ("links", link, "center_of_mass"))
            if point == "origin":
                return sp.zeros(3, 1)
        if point not in pts:
            options = list(pts) + ([] if link == "ground" else ["com", "origin"])
            raise self.doc.error(path, f"unknown point {point!r} of {link!r}{self.doc.suggest(point, options)}")
        return self.doc.parse_vec(pts[point], base)

    def point(self, ref: str, path: Path) -> sp.Matrix:
        """Ground position of a point reference ``link``, ``link.com``, ``link.NAME``, ``ground.NAME``."""
        frame, local = self.point_on(ref, path)
        return frame.point(local)

    def point_on(self, ref: str, path: Path) -> tuple[FrameState, sp.Matrix]:
        """The frame a point reference belongs to and its coordinates in that frame."""
        link, _, name = ref.partition(".")
        frame = self.frame(link, path)
        return frame, (self.local_point(link, name, path) if name else sp.zeros(3, 1))

    @staticmethod
    def relative_omega(axes: FrameState, axes_name: str, body: FrameState, body_name: str) -> sp.Matrix:
        """Angular velocity of ``body`` in the components of ``axes``."""
        if axes_name == body_name:
            return body.omega
        return axes.R.T * body.R * body.omega

    def claim(self, coord: str, link: str, path: Path) -> None:
        doc = self.doc
        if coord not in doc.coords and coord not in doc.prescribed:
            options = list(doc.coords) + list(doc.prescribed)
            raise doc.error(path, f"unknown coordinate {coord!r}{doc.suggest(coord, options)}")
        if coord in self.used_by:
            raise doc.error(path, f"coordinate {coord!r} is already used by the joint of link {self.used_by[coord]!r}")
        self.used_by[coord] = link

    def coord_expr(self, name: str) -> sp.Expr:
        return self.doc.coords.get(name, self.doc.prescribed.get(name))

    def rate_of(self, expr: sp.Expr) -> sp.Expr:
        out = self.diff(expr, T)
        for name, q in self.doc.coords.items():
            out += self.diff(expr, q) * self.doc.rates[name]
        return out

    # ------------------------------------------------------------------------------------- links
    def build(self) -> Kinematics:
        self.build_links()
        for name, c in self.doc.spec.coordinates.items():
            if c.angle is not None:  # an explicit 'angle:' overrides what the joints imply
                self.kin.angles[name] = c.angle
        self.build_bodies()
        self.build_constraints()
        self.build_loads()
        self.build_contacts()
        return self.kin

    def link_order(self) -> list[str]:
        links = self.doc.spec.links
        if "ground" in links:
            raise self.doc.error(("links", "ground"), "'ground' is reserved for the fixed frame", key=True)
        order: list[str] = []
        placed = {"ground"}
        for name, spec in links.items():
            parent = spec.joint.parent
            if parent != "ground" and parent not in links:
                options = ["ground"] + [n for n in links if n != name]
                raise self.doc.error(("links", name, "joint", "parent"),
                                     f"parent link {parent!r} does not exist{self.doc.suggest(parent, options)}")
            if parent == name:
                raise self.doc.error(("links", name, "joint", "parent"), "a link cannot be its own parent")
        pending = list(links)
        while pending:
            ready = [n for n in pending if links[n].joint.parent in placed]
            if not ready:
                name = pending[0]
                cycle = [name]
                nxt = links[name].joint.parent
                while nxt not in cycle and nxt in links:
                    cycle.append(nxt)
                    nxt = links[nxt].joint.parent
                raise self.doc.error(("links", name, "joint", "parent"),
                                     f"links form a cycle: {' -> '.join(cycle + [nxt])} (use a constraint to close a loop)")
            for n in ready:
                order.append(n)
                placed.add(n)
                pending.remove(n)
        return order

    def build_links(self) -> None:
        for name in self.link_order():
            spec = self.doc.spec.links[name]
            j = spec.joint
            jp: Path = ("links", name, "joint")
            parent = self.frame(j.parent, jp + ("parent",))
            if isinstance(j.origin, str):
                origin = self.local_point(j.parent, j.origin, jp + ("origin",))
            else:
                origin = self.doc.parse_vec(j.origin, jp + ("origin",))
            f = self.move(parent, origin)
            coords: list[str] = []
            if j.type == "transform":
                f, coords = self.transform(f, j.steps, name, jp)
                jclass = len(coords)
            else:
                names = [j.coordinate] if hasattr(j, "coordinate") else list(getattr(j, "coordinates", []))
                key = "coordinate" if hasattr(j, "coordinate") else "coordinates"
                for i, c in enumerate(names):
                    self.claim(c, name, jp + ((key,) if key == "coordinate" else (key, i)))
                coords = names
                f = self.joint_motion(f, j, names, jp)
                jclass = JOINT_CLASS[j.type]
            self.kin.frames[name] = f
            self.kin.joints.append(JointInfo(name, j.parent, j.type, coords, jclass))

    def rotate(self, f: FrameState, axis: sp.Matrix, angle: sp.Expr) -> FrameState:
        rate = self.rate_of(angle)
        return f.rotated(axis, angle, rate, self.rate_of(rate))

    def move(self, f: FrameState, offset: sp.Matrix) -> FrameState:
        rate = self.rate_of(offset)
        return f.translated(offset, rate, self.rate_of(rate))

    def joint_motion(self, f: FrameState, j: Any, names: list[str], jp: Path) -> FrameState:
        q = [self.coord_expr(n) for n in names]
        angles = self.kin.angles
        if j.type == "revolute":
            angles.setdefault(names[0], True)
            return self.rotate(f, self.axis(j.axis, jp + ("axis",)), q[0])
        if j.type == "prismatic":
            angles.setdefault(names[0], False)
            return self.move(f, self.axis(j.axis, jp + ("axis",)) * q[0])
        if j.type == "cylindrical":
            a = self.axis(j.axis, jp + ("axis",))
            angles.setdefault(names[0], True)
            angles.setdefault(names[1], False)
            return self.rotate(self.move(f, a * q[1]), a, q[0])
        if j.type == "universal":
            for n in names:
                angles.setdefault(n, True)
            for k in range(2):
                f = self.rotate(f, self.axis(j.axes[k], jp + ("axes", k)), q[k])
            return f
        if j.type in ("spherical", "free"):
            rot = q
            if j.type == "free":
                f = self.move(f, sp.Matrix(q[:3]))
                rot = q[3:]
                for n in names[:3]:
                    angles.setdefault(n, False)
            for n in names[-3:]:
                angles.setdefault(n, True)
            for ax, angle in zip(j.sequence, rot):
                f = self.rotate(f, sp.Matrix(AXES[ax]), angle)
            return f
        if j.type == "planar":
            n = j.normal.lstrip("-")
            e1, e2 = {"x": ("y", "z"), "y": ("z", "x"), "z": ("x", "y")}[n]
            angles.setdefault(names[0], False)
            angles.setdefault(names[1], False)
            angles.setdefault(names[2], True)
            f = self.move(f, sp.Matrix(AXES[e1]) * q[0] + sp.Matrix(AXES[e2]) * q[1])
            return self.rotate(f, sp.Matrix(AXES[j.normal]), q[2])
        if j.type == "fixed":
            return f
        raise AssertionError(j.type)

    def transform(self, f: FrameState, steps: list, link: str, jp: Path) -> tuple[FrameState, list[str]]:
        used: list[str] = []
        known = set(self.doc.coords) | set(self.doc.prescribed)
        for i, step in enumerate(steps):
            sp_path = jp + ("steps", i)
            if (step.rotate is None) == (step.translate is None):
                raise self.doc.error(sp_path, "each step needs exactly one of 'rotate' or 'translate'")
            if step.rotate is not None:
                raw = [step.rotate.angle]
                angle = self.doc.parse(step.rotate.angle, sp_path + ("rotate", "angle"))
                f = self.rotate(f, self.axis(step.rotate.axis, sp_path + ("rotate", "axis")), angle)
                if isinstance(step.rotate.angle, str) and step.rotate.angle.strip() in known:
                    self.kin.angles.setdefault(step.rotate.angle.strip(), True)
                where = sp_path + ("rotate", "angle")
            else:
                raw = list(step.translate)
                f = self.move(f, self.doc.parse_vec(step.translate, sp_path + ("translate",)))
                where = sp_path + ("translate",)
            for text in raw:
                for n in sorted(names_in(text) & known):
                    if n not in used:
                        if self.used_by.get(n, link) != link:
                            raise self.doc.error(where, f"coordinate {n!r} is already used by the joint of link "
                                                        f"{self.used_by[n]!r}")
                        self.used_by[n] = link
                        used.append(n)
        return f, used

    # ------------------------------------------------------------------------------------- bodies
    def build_bodies(self) -> None:
        for name, spec in self.doc.spec.links.items():
            lp: Path = ("links", name)
            for reserved in ("com", "origin"):
                if reserved in spec.points:
                    raise self.doc.error(lp + ("points", reserved), f"{reserved!r} is a reserved point name", key=True)
            m = self.doc.parse(spec.mass, lp + ("mass",), "parameter")
            self.real_value(m, lp + ("mass",), nonnegative=True)
            com = self.doc.parse_vec(spec.center_of_mass, lp + ("center_of_mass",), "parameter")
            for i, c in enumerate(com):
                self.real_value(c, lp + ("center_of_mass", i))
            if spec.particle and (spec.inertia is not None or spec.shape is not None):
                raise self.doc.error(lp + ("inertia" if spec.inertia is not None else "shape",),
                                     "a particle has no inertia tensor or shape")
            if spec.inertia is not None and spec.shape is not None:
                raise self.doc.error(lp + ("shape",), "give either 'inertia' or 'shape', not both")
            inertia = sp.zeros(3, 3)
            if spec.inertia is not None:
                ip = lp + ("inertia",)
                c = {k: self.doc.parse(getattr(spec.inertia, k), ip + (k,), "parameter")
                     for k in ("xx", "yy", "zz", "xy", "xz", "yz")}
                for k, v in c.items():
                    self.real_value(v, ip + (k,), nonnegative=k in ("xx", "yy", "zz"))
                inertia = sp.Matrix([[c["xx"], -c["xy"], -c["xz"]],
                                     [-c["xy"], c["yy"], -c["yz"]],
                                     [-c["xz"], -c["yz"], c["zz"]]])
                if spec.inertia_about == "origin":
                    # parallel-axis theorem: I_G = I_O - m (|c|^2 E - c c^T)
                    inertia = inertia - m * ((com.T * com)[0] * sp.eye(3) - com * com.T)
                self.possible_inertia(inertia, name, ip, spec.inertia_about == "origin")
            elif spec.shape is not None:
                inertia = self.shape_inertia(spec.shape, m, lp + ("shape",))
            if m == 0 and inertia == sp.zeros(3, 3):
                continue
            self.kin.bodies.append(Body(name, m, com, inertia, spec.particle))

    def possible_inertia(self, inertia: sp.Matrix, link: str, path: Path, about_origin: bool) -> None:
        """An error when the central inertia tensor gives the link a negative kinetic energy (negative_moment)."""
        values: dict = {k: sp.Float(v) for k, v in self.doc.numeric_parameters().items()}
        values.update({s: sp.Float(self.doc.initial.get(c, 0.0)) for c, s in self.doc.coords.items()})
        moment = negative_moment(inertia, self.kin.frames[link].omega, list(self.doc.rates.values()), values)
        if moment is None:
            return
        where = " about the centre of mass (the tensor given about the origin minus m (|c|² E − c cᵀ))" \
            if about_origin else ""
        raise self.doc.error(path, f"is not the inertia of a body: its moment{where} about an axis the link turns "
                                   f"about is {moment:.6g}, and the kinetic energy would be negative")

    def shape_inertia(self, shape: Any, m: sp.Expr, path: Path) -> sp.Matrix:
        given = [k for k in ("rod", "disk", "cylinder", "sphere", "box") if getattr(shape, k) is not None]
        if len(given) != 1:
            raise self.doc.error(path, "give exactly one shape: rod, disk, cylinder, sphere or box")
        kind = given[0]
        s = getattr(shape, kind)
        p = path + (kind,)
        par = lambda key: self.doc.parse(getattr(s, key), p + (key,), "parameter")  # noqa: E731
        if kind == "sphere":
            i = sp.Rational(2, 5) * m * par("radius") ** 2
            return sp.diag(i, i, i)
        if kind == "box":
            a, b, c = self.doc.parse_vec(s.size, p + ("size",), "parameter")
            return sp.diag(m * (b**2 + c**2), m * (a**2 + c**2), m * (a**2 + b**2)) / 12
        if kind == "rod":
            axial, trans = sp.Integer(0), m * par("length") ** 2 / 12
        elif kind == "disk":
            r = par("radius")
            axial, trans = m * r**2 / 2, m * r**2 / 4
        else:
            r, length = par("radius"), par("length")
            axial, trans = m * r**2 / 2, m * (3 * r**2 + length**2) / 12
        k = "xyz".index(s.axis.lstrip("-"))
        diag = [trans, trans, trans]
        diag[k] = axial
        return sp.diag(*diag)

    # ------------------------------------------------------------------------------------- constraints
    def build_constraints(self) -> None:
        for name, motion in self.doc.released.items():
            phi = self.doc.coords[name] - motion
            self.kin.constraints.append(ConstraintRow(f"drive({name})", "holonomic", phi, self.rate_of(phi)))
            self.kin.constraint_elements.append(("drive", 1))
        names: set[str] = set()
        for i, c in enumerate(self.doc.spec.constraints):
            cp: Path = ("constraints", i)
            name = c.name or f"{c.type}_{i + 1}"
            if name in names:  # its multipliers would be one row in the output and one multiplier(name)
                raise self.doc.error(cp + ("name",) if c.name else cp, f"duplicate constraint name {name!r}")
            names.add(name)
            rows: list[ConstraintRow] = []
            if c.type == "holonomic":
                phi = self.doc.parse(c.expression, cp + ("expression",))
                rows = [ConstraintRow(name, "holonomic", phi, self.rate_of(phi))]
            elif c.type == "nonholonomic":
                e = self.doc.parse(c.expression, cp + ("expression",), "force")
                rates = list(self.doc.rates.values())
                if any(sp.diff(e, u, 2) != 0 for u in rates) or any(
                        sp.diff(e, u, v) != 0 for u in rates for v in rates if u != v):
                    raise self.doc.error(cp + ("expression",), "a nonholonomic constraint must be linear in the rates")
                rows = [ConstraintRow(name, "nonholonomic", None, e)]
            elif c.type == "point_on_point":
                a = self.point(c.points[0], cp + ("points", 0))
                b = self.point(c.points[1], cp + ("points", 1))
                rows = [ConstraintRow(f"{name}.{ax}", "holonomic", a[k] - b[k], self.rate_of(a[k] - b[k]))
                        for k, ax in enumerate("xyz")]
            elif c.type in ("point_on_line", "point_on_plane"):
                p = self.point(c.point, cp + ("point",))
                o = self.point(c.through, cp + ("through",))
                fr = self.frame(c.frame, cp + ("frame",))
                if c.type == "point_on_line":
                    d = self.axis(c.direction, cp + ("direction",))
                    normals = self.complement(d, f"{name}.direction")
                else:
                    normals = [self.axis(c.normal, cp + ("normal",))]
                rows = []
                for k, n in enumerate(normals):
                    phi = (fr.R * n).dot(p - o)
                    rows.append(ConstraintRow(f"{name}.{k + 1}", "holonomic", phi, self.rate_of(phi)))
            elif c.type == "rolling":
                rows = self.rolling(c, name, cp)
            kept = [r for r in rows if not self.vanishes(r.velocity, r.name)]
            if not kept:
                raise self.doc.error(cp, "this constraint references no coordinate (it is identically satisfied)")
            self.kin.constraints.extend(kept)
            self.kin.constraint_elements.append((c.type, len(kept)))

    def rolling(self, c: Any, name: str, cp: Path) -> list[ConstraintRow]:
        body = self.frame(c.link, cp + ("link",))
        axes = self.frame(c.frame or c.link, cp + ("frame",))
        r_rel = axes.R * self.doc.parse_vec(c.contact, cp + ("contact",))
        turning = (axes.omega_ground - body.omega_ground).cross(r_rel)
        if all(self.vanishes(e, f"{name}.frame") for e in turning):
            # a contact vector that turns with the link is a material point of it: rows that hold its velocity are
            # the derivatives of its position, a pin (the spinning disk of the default frame 'rolled' 0.25 m of 2)
            raise self.doc.error(cp + ("frame",) if c.frame else cp + ("link",),
                                 f"the contact vector is given in axes that turn with '{c.link}' "
                                 f"({'frame' if c.frame else 'the default frame, the link itself'}), so it is a point "
                                 f"fixed in the link, not the contact: its rows would pin that point. Give 'frame' "
                                 f"a link in whose axes the contact stays the same vector as the body rolls (for a "
                                 f"disk or wheel a frame that leans with it but does not spin, for a ball 'ground'); "
                                 f"to pin a point, use point_on_point or point_on_plane")
        contact = body.origin + r_rel
        v_link = body.home_R * body.v + body.omega_ground.cross(r_rel)
        surface = self.frame(c.on, cp + ("on",))
        v_surf = surface.home_R * surface.v + surface.omega_ground.cross(contact - surface.origin)
        slip = v_link - v_surf
        if c.axes != "ground":  # the components along the axes of a link (an incline's tangents)
            slip = self.frame(c.axes, cp + ("axes",)).R.T * slip
        return [ConstraintRow(f"{name}.{ax}", "nonholonomic", None, slip["xyz".index(ax)]) for ax in c.components]

    # ------------------------------------------------------------------------------------- contacts
    PRIMITIVES = ("point_plane", "sphere_plane", "sphere_sphere", "point_line")

    def build_contacts(self) -> None:
        """Each contact: its normal relative velocity vn (linear in the rates; < 0 approaching), the gap (when
        given or built from a primitive), the restitution law e(vn), the friction coefficient, and, when the
        contact has points, the ground normal, the relative velocity of the touching material points (for the
        tangential impulse) and the links the impulse acts on (for joint impulses)."""
        vn_symbol = sp.Symbol("vn", real=True)
        names = set()
        for i, c in enumerate(self.doc.spec.contacts):
            cp: Path = ("contacts", i)
            if c.name in names:
                raise self.doc.error(cp + ("name",), f"duplicate contact name {c.name!r}")
            names.add(c.name)
            e = self.doc.parse(c.restitution, cp + ("restitution",), "parameter", extra={"vn": vn_symbol})
            if vn_symbol not in e.free_symbols:  # a constant law: e < 0 would send the bodies on into each other
                self.real_value(e, cp + ("restitution",), nonnegative=True)
            mu = self.doc.parse(c.friction, cp + ("friction",), "parameter")
            self.real_value(mu, cp + ("friction",), nonnegative=True)
            entry = {"name": c.name, "restitution": e, "vn_symbol": vn_symbol, "points": [], "friction": mu,
                     "vrel": None, "normal": None}
            given = [k for k in ("between", "gap", *self.PRIMITIVES) if getattr(c, k) is not None]
            if len(given) != 1:
                raise self.doc.error(cp, "give exactly one of 'between' (with 'normal'), 'gap', 'point_plane', "
                                         "'sphere_plane', 'sphere_sphere' or 'point_line'"
                                     + (f" (got {', '.join(given)})" if given else ""))
            kind = entry["kind"] = given[0]
            if kind != "between" and c.normal is not None:
                raise self.doc.error(cp + ("normal",), f"'normal' belongs to 'between' contacts, not to '{kind}'")
            if kind == "gap":
                gap = self.doc.parse(c.gap, cp + ("gap",))
                if mu != 0:
                    raise self.doc.error(cp + ("friction",), "friction needs the contact points: use 'between' or "
                                                              "a gap primitive (point_plane, sphere_plane, ...)")
                entry.update(gap=gap, vn=self.rate_of(gap))
            elif kind == "between":
                if c.normal is None:
                    raise self.doc.error(cp, "a contact 'between' two points needs a 'normal'")
                n = self.frame(c.frame, cp + ("frame",)).R * self.axis(c.normal, cp + ("normal",))
                velocities = []
                for k, ref in enumerate(c.between):
                    frame, local = self.point_on(ref, cp + ("between", k))
                    rate = self.rate_of(local)
                    v_home = frame.point_velocity(local) + (frame.R * rate if frame.pure else rate)
                    velocities.append(frame.home_R * v_home)
                    entry["points"].append((ref.partition(".")[0], frame.point(local), 1 if k == 0 else -1))
                vn = n.dot(velocities[0] - velocities[1])
                if self.vanishes(vn, f"{c.name}.vn"):
                    raise self.doc.error(cp, "the contact points cannot approach each other along the normal")
                entry.update(gap=None, vn=vn, normal=n, vrel=velocities[0] - velocities[1])
            else:
                entry.update(self.primitive(kind, getattr(c, kind), cp + (kind,)))
            if entry["gap"] is not None:
                where = cp + (kind,)
                if not (entry["gap"].free_symbols & set(self.doc.coords.values())):
                    raise self.doc.error(where, "the gap does not depend on any free coordinate")
                if kind != "gap" and self.vanishes(entry["vn"], f"{c.name}.vn"):
                    raise self.doc.error(where, "the two sides cannot approach each other along the normal")
            self.kin.contacts.append(entry)

    @staticmethod
    def material_velocity(frame: FrameState, x: sp.Matrix) -> sp.Matrix:
        """Ground velocity of the material point of ``frame``'s link at the ground position ``x``."""
        return frame.home_R * frame.v + frame.omega_ground.cross(x - frame.origin)

    def primitive(self, kind: str, spec: Any, path: Path) -> dict:
        """Gap, normal, relative velocity at the touching points and impulse points of a named gap primitive."""
        def side(ref: str, p: Path) -> tuple[str, FrameState, sp.Matrix]:
            frame, local = self.point_on(ref, p)
            return ref.partition(".")[0], frame, frame.point(local)

        def surface(pl: Any, p: Path, line: bool = False) -> tuple[str, FrameState, sp.Matrix, sp.Matrix]:
            link, frame, q = side(pl.point, p + ("point",))
            axes = self.frame(pl.frame if pl.frame is not None else link, p + ("frame",))
            if not line:
                return link, frame, q, axes.R * self.axis(pl.normal, p + ("normal",))
            d = self.axis(pl.direction, p + ("direction",))
            if self.real_value(d[0] ** 2 + d[1] ** 2, p + ("direction",)) <= 1e-24:
                raise self.doc.error(p + ("direction",), "the line direction must not be along the frame's z axis "
                                                         "(the line lies in the x-y plane of its frame)")
            return link, frame, q, axes.R * unit([-d[1], d[0], 0])

        def radius(value: Any, p: Path) -> sp.Expr:
            r = self.doc.parse(value, p, "parameter")
            self.real_value(r, p, nonnegative=True)
            return r

        if kind in ("point_plane", "sphere_plane", "point_line"):
            if kind == "point_line":
                link_a, fa, c = side(spec.point, path + ("point",))
                link_b, fb, q, n = surface(spec.line, path + ("line",), line=True)
                r = sp.Integer(0)
            else:
                point_key = "point" if kind == "point_plane" else "center"
                link_a, fa, c = side(getattr(spec, point_key), path + (point_key,))
                link_b, fb, q, n = surface(spec.plane, path + ("plane",))
                r = radius(spec.radius, path + ("radius",)) if kind == "sphere_plane" else sp.Integer(0)
            gap = n.dot(c - q) - r
            xa = xb = c - r * n
        else:
            link_a, fa, ca = side(spec.centers[0], path + ("centers", 0))
            link_b, fb, cb = side(spec.centers[1], path + ("centers", 1))
            ra, rb = radius(spec.radii[0], path + ("radii", 0)), radius(spec.radii[1], path + ("radii", 1))
            d = ca - cb
            dist = sp.sqrt(d.dot(d))
            n = d / dist
            gap = dist - ra - rb
            xa, xb = ca - ra * n, cb + rb * n
        vrel = self.material_velocity(fa, xa) - self.material_velocity(fb, xb)
        return {"gap": gap, "vn": self.rate_of(gap), "normal": n, "vrel": vrel,
                "points": [(link_a, xa, 1), (link_b, xb, -1)]}

    # ------------------------------------------------------------------------------------- loads
    def build_loads(self) -> None:
        doc = self.doc
        for i, f in enumerate(doc.spec.forces):
            fp: Path = ("forces", i)
            data: dict[str, Any] = {}
            if f.type == "gravity":
                data["g"] = doc.parse_vec(f.acceleration, fp + ("acceleration",), "prescribed")
            elif f.type == "force":
                frame, local = self.point_on(f.at, fp + ("at",))
                force = self.frame(f.frame, fp + ("frame",)).R * doc.parse_vec(f.value, fp + ("value",), "force")
                rate = self.rate_of(local)  # a point may slide along its link (coordinates in its position)
                data["v"] = frame.point_velocity(local) + (frame.R * rate if frame.pure else rate)
                data["F"] = frame.to_home(force)
            elif f.type == "torque":
                on = self.frame(f.on, fp + ("on",))
                axes = self.frame(f.frame or f.on, fp + ("frame",))
                if isinstance(f.value, list):
                    if f.axis is not None:
                        raise doc.error(fp + ("axis",), "give 'axis' only with a scalar 'value'")
                    vec = doc.parse_vec(f.value, fp + ("value",), "force")
                else:
                    if f.axis is None:
                        raise doc.error(fp + ("value",), "a scalar torque needs an 'axis'")
                    vec = self.axis(f.axis, fp + ("axis",)) * doc.parse(f.value, fp + ("value",), "force")
                # power = M . (omega_on - omega_reaction), both taken in the torque's axes
                frame_name = f.frame or f.on
                w = self.relative_omega(axes, frame_name, on, f.on)
                if f.reaction:
                    w = w - self.relative_omega(axes, frame_name, self.frame(f.reaction, fp + ("reaction",)),
                                                f.reaction)
                data["M"] = vec
                data["w"] = w
            elif f.type in ("spring", "damper", "actuator"):
                a = self.point(f.between[0], fp + ("between", 0))
                b = self.point(f.between[1], fp + ("between", 1))
                data["d"] = a - b
                data["between"] = tuple(f.between)
                if f.type == "spring":
                    data["k"] = doc.parse(f.stiffness, fp + ("stiffness",), "kinematic")
                    data["l0"] = doc.parse(f.free_length, fp + ("free_length",), "kinematic")
                elif f.type == "damper":
                    data["c"] = doc.parse(f.coefficient, fp + ("coefficient",), "force")
                else:
                    data["value"] = doc.parse(f.value, fp + ("value",), "force")
            elif f.type in ("torsional_spring", "torsional_damper", "generalized_force"):
                if f.coordinate not in doc.coords and f.coordinate not in doc.prescribed:
                    options = list(doc.coords) + list(doc.prescribed)
                    raise doc.error(fp + ("coordinate",),
                                    f"unknown coordinate {f.coordinate!r}{doc.suggest(f.coordinate, options)}")
                if f.type != "torsional_spring" and f.coordinate in doc.prescribed:
                    raise doc.error(fp + ("coordinate",), f"coordinate {f.coordinate!r} is prescribed: a force on it "
                                    "would only change the driving force; apply it to a free coordinate")
                data["coordinate"] = f.coordinate
                if f.type == "torsional_spring":
                    data["k"] = doc.parse(f.stiffness, fp + ("stiffness",), "kinematic")
                    data["q0"] = doc.parse(f.free_angle, fp + ("free_angle",), "kinematic")
                elif f.type == "torsional_damper":
                    data["c"] = doc.parse(f.coefficient, fp + ("coefficient",), "force")
                else:
                    data["value"] = doc.parse(f.value, fp + ("value",), "force")
            elif f.type == "dissipation":
                data["D"] = doc.parse(f.value, fp + ("value",), "force")
            elif f.type == "potential":
                data["V"] = doc.parse(f.value, fp + ("value",), "kinematic")
            self.kin.loads.append(Load(f.type, data))


def decide(kind: str, expr: Any, values: dict) -> bool:
    """A structural decision that depends on parameter values: "zero" (``expr`` vanishes identically) or
    "near_x" (the direction component ``expr`` is at least 0.9, so x is no helper axis)."""
    if kind == "near_x":
        return abs(float(sp.sympify(expr).subs(values))) >= 0.9
    return identically_zero(expr, values)


def decisions_hold(kin: Kinematics, values: dict) -> bool:
    """True when every value-dependent decision of ``kin`` comes out the same with these parameter values
    (symbol -> number): the same structure, derivations and compiled code serve them."""
    try:
        return all(decide(kind, expr, values) == outcome for _what, kind, expr, outcome in kin.decisions)
    except (TypeError, ValueError, ZeroDivisionError):
        return False


def negative_moment(inertia: sp.Matrix, omega: sp.Matrix, rates: list, values: dict) -> float | None:
    """The negative moment of the central inertia tensor ``inertia`` about an axis the link turns about (the span
    of d omega / d rates, link axes) at ``values`` (parameters and coordinates; time 0), or None when there is none.
    A tensor with xx = yy = zz = 1 and xy = 5 on a ball joint made T negative along the motion. Only those axes
    count: a planar model's {zz: I} given about the hinge has xx = -m d^2 about the centre of mass, never used."""
    try:
        I = np.array(inertia.xreplace(values).evalf(), dtype=float)
        W = omega.jacobian(rates).xreplace(values)
        W = np.array(W.xreplace({x: 0 for x in W.free_symbols}).evalf(), dtype=float)  # t = 0
    except (TypeError, ValueError):
        return None  # not evaluated here (each entry was checked to be a finite real number)
    if not (np.all(np.isfinite(I)) and np.all(np.isfinite(W))) or not W.size:
        return None
    U, sv, _ = np.linalg.svd(W, full_matrices=False)
    U = U[:, sv > 1e-9 * max(float(sv[0]), 1e-300)]
    if not U.shape[1]:
        return None
    moment = float(np.linalg.eigvalsh(U.T @ ((I + I.T) / 2) @ U)[0])
    scale = max(float(np.max(np.abs(np.linalg.eigvalsh((I + I.T) / 2)))), 1e-300)
    return moment if moment < -1e-12 * scale else None
