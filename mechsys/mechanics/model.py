"""The one symbolic model every analysis uses: lazy T, V, Q and M(q,t) q'' = f(q, q', t) (Lagrange or Kane)."""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING

import sympy as sp

from mechsys.mechanics.build import Body, Builder, Kinematics
from mechsys.mechanics.construct import Constructors
from mechsys.mechanics.dag import FreeSymbols, Interner
from mechsys.mechanics.differentiate import Differentiator
from mechsys.mechanics.kinematics import FrameState, rate_coefficients, time_derivative
from mechsys.mechanics.products import gram, nonzero, product
from mechsys.model.load import T as TIME
from mechsys.model.load import Document

if TYPE_CHECKING:
    from mechsys.mechanics.symmetry import CyclicDecision

METHODS = ("lagrange", "kane")
#: The formulation the commands read facts off (mass matrix, cyclic coordinates, explicit time): Kane's needs no
#: derivatives of the energy, 4x cheaper on the bicycle and 60x on a 20-link chain; the same decisions as Lagrange
#: on every bundled and test model. `derive --method` still chooses what is printed.
INTERNAL_METHOD = "kane"
#: What a model decides at its parameter values and keeps in its __dict__: a with_overrides copy (a sweep's task)
#: decides them again. A rod of mass 0 leaves its angle free of every force, so cyclic; the copy of mass 1 took
#: that decision over and vibrated about a wrong steady motion (damping ratio -402).
#: memos of compiled code and derived models, valid at any parameter values: shared with with_overrides copies
SHARED_MEMOS = ("_equilibrium_memo",)
VALUE_DEPENDENT = ("cyclic_decision", "_autonomous")


@dataclass
class Equations:
    """Equations of motion ``M q'' = f + A^T lambda`` with constraints ``A q'' = b`` (rows may be empty).

    For holonomic rows A = dPhi/dq; for nonholonomic rows A is the coefficient matrix of the rates.
    ``Q`` are the generalized forces not derived from V (dampers, applied forces and torques...).
    """

    method: str
    coordinates: list[str]
    q: list[sp.Symbol]
    u: list[sp.Symbol]
    a: list[sp.Symbol]
    M: sp.Matrix
    f: sp.Matrix
    Q: sp.Matrix
    T: sp.Expr
    V: sp.Expr
    A: sp.Matrix = field(default_factory=lambda: sp.zeros(0, 0))
    b: sp.Matrix = field(default_factory=lambda: sp.zeros(0, 1))
    constraint_names: list[str] = field(default_factory=list)

    def residual(self) -> sp.Matrix:
        """M q'' - f, in the acceleration symbols (constraint forces not included)."""
        return self.M * sp.Matrix(self.a) - self.f

    def interned(self) -> "Equations":
        """The same equations with one object per value across all their expressions (dag.Interner): what is
        keyed by value then meets equal subexpressions as one object (the printers: the 80-link chain's
        `derive --method kane` 25.9 s -> 21.9 s, interning included)."""
        one = Interner()
        return replace(self, M=one.matrix(self.M), f=one.matrix(self.f), Q=one.matrix(self.Q), A=one.matrix(self.A),
                       b=one.matrix(self.b), T=one.of(self.T), V=one.of(self.V))

    def _repr_latex_(self) -> str:
        """Jupyter: M q'' = f and the constraint rows, as `derive -f latex` prints them."""
        from mechsys.report.notebook import equations_latex

        return equations_latex(self)


class Sums:
    """A matrix summed from many terms at once: adding matrix after matrix rebuilds every growing sum at each step
    (quadratic in the number of bodies; a 25-link chain's Kane terms spent a third of their time there), while
    sympy's Add of all terms gives the same canonical sum once."""

    def __init__(self, rows: int, cols: int, start: sp.Matrix | None = None) -> None:
        self.shape = (rows, cols)
        self.terms: list[list[sp.Expr]] = [[] for _ in range(rows * cols)]
        if start is not None:
            self.add(start)

    def add(self, mat: sp.Matrix) -> None:
        for k, e in enumerate(e for row in mat.tolist() for e in row):
            if nonzero(e):
                self.terms[k].append(e)

    def matrix(self) -> sp.Matrix:
        build = Constructors()  # directly where Add's flatten would only sort
        return sp.Matrix(*self.shape, [build.add(t) for t in self.terms])


class MechanicalModel:
    """A mechanical system: the document it came from, its kinematics, and derivations made on demand."""

    def __init__(self, doc: Document) -> None:
        self.doc = doc
        self.kin: Kinematics = Builder(doc).build()
        self.name = doc.spec.name
        self.coordinates = list(doc.coords)
        self.q = [doc.coords[n] for n in self.coordinates]
        self.u = [doc.rates[n] for n in self.coordinates]
        self.a = [doc.accels[n] for n in self.coordinates]
        self.t = TIME
        self._eqs: dict[str, Equations] = {}
        self.events  # parse now: a bad expression is an input error at load time
        self.outputs

    def with_overrides(self, values: dict[str, float], as_set: bool = False) -> "MechanicalModel":
        """The same symbolic model (derivations and compiled code shared) with other numeric parameter values,
        initial values (``name``) or initial rates (``der(name)``): what a sweep worker reuses between tasks.
        ``as_set``: the initial values are the user's, as --set gives them (the start's assembly onto the
        constraints holds them: a sweep's); not a state the code carries over (a re-charted run's window)."""
        import copy
        import re

        doc = copy.copy(self.doc)
        doc.parameter_exprs = dict(doc.parameter_exprs)
        doc.initial = dict(doc.initial)
        doc.initial_rate = dict(doc.initial_rate)
        doc.overridden = dict(doc.overridden)
        for key, value in values.items():
            m = re.fullmatch(r"der\((\w+)\)", key)
            if m and m.group(1) in doc.initial_rate:
                doc.initial_rate[m.group(1)] = float(value)
                if as_set:
                    doc.overridden[("coordinates", m.group(1), "rate")] = f"{key}={value}"
            elif key in doc.parameter_exprs:
                doc.parameter_exprs[key] = sp.Float(float(value))
            elif key in doc.initial:
                doc.initial[key] = float(value)
                if as_set:
                    doc.overridden[("coordinates", key, "initial")] = f"{key}={value}"
            else:
                from mechsys.errors import InputError

                raise InputError(f"unknown parameter or coordinate {key!r}{doc.suggest(key, list(doc.parameters) + list(doc.initial))}")
        values_now: dict = {}
        doc.parameter_values = {}
        for name, expr in doc.parameter_exprs.items():
            val = float(expr.xreplace(values_now).evalf())
            values_now[doc.parameters[name]] = sp.Float(val)
            doc.parameter_values[name] = val
        from mechsys.mechanics.build import decisions_hold

        numeric = doc.numeric_parameters()
        # the decisions hold at this model's own values: only other values are checked (a re-charted run's windows
        # change initial values alone, and the check of a rolling ball's zero rows took 0.17 s per window)
        if numeric != self.doc.numeric_parameters() and not decisions_hold(self.kin, numeric):
            return MechanicalModel(doc)  # these values change the structure (a constraint row vanishes or not)
        for name in SHARED_MEMOS:  # created here, so that the clone shares them (compiled once for all copies)
            self.__dict__.setdefault(name, {})
        clone = copy.copy(self)
        clone.doc = doc
        if numeric != self.doc.numeric_parameters():
            for name in VALUE_DEPENDENT:  # decided at the parameter values: decided again at the clone's
                clone.__dict__.pop(name, None)
        return clone

    def _repr_markdown_(self) -> str:
        """Jupyter: the `info` tables, the initial state and the parameter values."""
        from mechsys.report.notebook import model_markdown

        return model_markdown(self)

    # ------------------------------------------------------------------------------------- basics
    @property
    def parameters(self) -> dict[str, float]:
        return dict(self.doc.parameter_values)

    @property
    def parameter_symbols(self) -> list[sp.Symbol]:
        return list(self.doc.parameters.values())

    @property
    def angles(self) -> dict[str, bool]:
        """Whether each free coordinate is an angle (wraps modulo 2 pi): 'angle:' in the file, else the joint."""
        return {n: bool(self.kin.angles.get(n, False)) for n in self.coordinates}

    @property
    def prescribed(self) -> dict[str, sp.Expr]:
        return dict(self.doc.prescribed)

    def dt(self, expr: sp.Expr | sp.Matrix, with_accels: bool = False) -> sp.Expr | sp.Matrix:
        return time_derivative(expr, self.q, self.u, self.t, self.a if with_accels else None, self.diff)

    @cached_property
    def diff(self) -> Differentiator:
        """d(expr)/d(symbol) as sympy gives it, each subexpression differentiated once per model."""
        return Differentiator()

    def velocity(self, r: sp.Matrix) -> sp.Matrix:
        """Ground velocity of a point with ground position ``r(q, t)``, linear in the rates."""
        return r.jacobian(self.q) * sp.Matrix(self.u) + r.diff(self.t) if self.q else r.diff(self.t)

    def com(self, body: Body) -> sp.Matrix:
        return self.kin.frames[body.name].point(body.com_local)

    @cached_property
    def _body_kinematics(self) -> list[tuple[Body, sp.Matrix, sp.Matrix, sp.Matrix, FrameState]]:
        """(body, r_G in ground axes, v_G in home axes, omega in body axes, frame) for each massive link."""
        out = []
        for b in self.kin.bodies:
            frame = self.kin.frames[b.name]
            out.append((b, self.com(b), frame.point_velocity(b.com_local), frame.omega, frame))
        return out

    def partials(self, expr: sp.Matrix) -> sp.Matrix:
        """Coefficients of the rates in an expression linear in them (partial velocities)."""
        return rate_coefficients(expr, self.u)

    @cached_property
    def _body_partials(self) -> list[tuple[sp.Matrix, sp.Matrix]]:
        """Partial velocities of each body's centre of mass (home axes) and angular velocity (body axes)."""
        return [(self.partials(v), self.partials(w)) for _b, _r, v, w, _f in self._body_kinematics]

    # ------------------------------------------------------------------------------------- energies
    @cached_property
    def kinetic_energy(self) -> sp.Expr:
        T = sp.Integer(0)
        for b, _r, v, w, _f in self._body_kinematics:
            T += b.mass * (v.T * v)[0] / 2
            if not b.particle and b.inertia != sp.zeros(3, 3):
                T += (w.T * b.inertia * w)[0] / 2
        return T

    @cached_property
    def potential_energy(self) -> sp.Expr:
        V = sp.Integer(0)
        for load in self.kin.loads:
            d = load.data
            if load.kind == "gravity":
                for b, r, _v, _w, _f in self._body_kinematics:
                    if b.mass != 0:
                        V -= b.mass * (d["g"].T * r)[0]
            else:
                V += self._elastic_potential(load.kind, d)
        return V

    def _elastic_potential(self, kind: str, d: dict) -> sp.Expr:
        if kind == "spring":
            sq = (d["d"].T * d["d"])[0]
            if d["l0"] == 0:
                return d["k"] * sq / 2
            return d["k"] * (sp.sqrt(sq) - d["l0"]) ** 2 / 2
        if kind == "torsional_spring":
            q = self.doc.coords.get(d["coordinate"], self.doc.prescribed.get(d["coordinate"]))
            return d["k"] * (q - d["q0"]) ** 2 / 2
        if kind == "potential":
            return d["V"]
        return sp.Integer(0)

    # ------------------------------------------------------------------------------------- forces
    @cached_property
    def generalized_forces(self) -> sp.Matrix:
        """Generalized forces not derived from V, by virtual power: Q_i = sum F . dv/d(der(q_i))."""
        return self.nonconservative_forces(self.kin.loads)

    def zero_length_elements(self, coordinates: dict[str, float], values: dict) -> list[str]:
        """The dampers and actuators whose length vanishes at ``coordinates`` (with ``values`` of the parameters,
        symbols to numbers), as 'the damper between A and B': along their line the force has no direction there,
        and their linearization (sympy's sign(0) = 0) drops them: a damper between a block and its anchor gave a
        damping ratio of 0 at the rest where it is 0.1. The squared lengths are compiled once per model (a sweep
        asks at every point)."""
        memo = self.__dict__.get("_element_lengths")
        if memo is None:
            elements = [load for load in self.kin.loads if load.kind in ("damper", "actuator")]
            args = [*self.doc.coords.values(), *self.parameter_symbols, self.t]
            squares = [sp.expand((load.data["d"].T * load.data["d"])[0]) for load in elements]
            names = [f"the {load.kind} between {' and '.join(load.data.get('between', ('?', '?')))}"
                     for load in elements]
            memo = self.__dict__["_element_lengths"] = (names, sp.lambdify(args, squares, "math") if elements
                                                        else None)
        names, lengths = memo
        if lengths is None:
            return []
        q = [coordinates.get(c, self.doc.initial.get(c, 0.0)) for c in self.doc.coords]
        try:
            squared = lengths(*q, *(float(values.get(s, 0.0)) for s in self.parameter_symbols), 0.0)
        except (TypeError, ValueError, ZeroDivisionError, OverflowError):
            return []
        tol = 1e-12 * (1 + max((abs(v) for v in coordinates.values()), default=0.0))
        return [name for name, l2 in zip(names, squared) if abs(l2) <= tol * tol]

    def nonconservative_forces(self, loads: list) -> sp.Matrix:
        """Generalized forces of the given loads' non-potential parts."""
        n = len(self.q)
        Q = sp.zeros(n, 1)
        for load in loads:
            d = load.data
            if load.kind == "force":
                Q += self.partials(d["v"]).T * d["F"] if n else sp.zeros(0, 1)
            elif load.kind == "torque":
                Q += self.partials(d["w"]).T * d["M"] if n else sp.zeros(0, 1)
            elif load.kind in ("damper", "actuator"):
                length = sp.sqrt((d["d"].T * d["d"])[0])
                dl = sp.Matrix([sp.diff(length, q) for q in self.q])
                if load.kind == "damper":
                    Q += -d["c"] * self.dt(length) * dl
                else:
                    Q += d["value"] * dl
            elif load.kind in ("torsional_damper", "generalized_force"):
                name = d["coordinate"]
                if name in self.coordinates:
                    i = self.coordinates.index(name)
                    Q[i] += -d["c"] * self.u[i] if load.kind == "torsional_damper" else d["value"]
            elif load.kind == "dissipation":
                Q += -sp.Matrix([sp.diff(d["D"], u) for u in self.u])
        return Q

    def _potential_force_kane(self) -> sp.Matrix:
        """Conservative generalized forces for Kane's route: gravity as forces at the centres of mass,
        the other potentials as -dV/dq."""
        n = len(self.q)
        Qc = Sums(n, 1)
        for load in self.kin.loads:
            if load.kind == "gravity":
                for (b, _r, _v, _w, frame), (Jv, _Jw) in zip(self._body_kinematics, self._body_partials):
                    if b.mass != 0 and n:
                        Qc.add(product(Jv.T, b.mass * frame.to_home(load.data["g"])))
            else:
                V = self._elastic_potential(load.kind, load.data)
                if V != 0:
                    Qc.add(-sp.Matrix([self.diff(V, q) for q in self.q]))
        return Qc.matrix()

    # ------------------------------------------------------------------------------------- constraints
    @cached_property
    def constraint_velocity(self) -> sp.Matrix:
        """Velocity-level constraint expressions, each linear in the rates (holonomic rows differentiated)."""
        return sp.Matrix([c.velocity for c in self.kin.constraints])

    def _load_stored(self, skip: str | None = None) -> None:
        """Once per model with constraints: a formulation's stored derivation (mechanics/derivations.py), which
        fills A, b, T, V and Q as it loads: reading them costs less than deriving A and b (the bicycle's info and
        a Lagrange derive after a Kane one: about 0.4 and 0.9 s). ``skip``: a formulation known not stored."""
        if not self.kin.constraints or self.__dict__.get("_stored_tried"):
            return
        self.__dict__["_stored_tried"] = True
        from mechsys.mechanics import derivations

        for method in METHODS:
            if method != skip and method not in self._eqs:
                eq = derivations.load(self, method)
                if eq is not None:
                    self._eqs[method] = eq
                    return

    @cached_property
    def constraint_jacobian(self) -> sp.Matrix:
        if not self.kin.constraints:
            return sp.zeros(0, len(self.q))
        self._load_stored()
        stored = self.__dict__.get("constraint_jacobian")  # set by the loaded derivation
        return stored if stored is not None else self.partials(self.constraint_velocity)

    @cached_property
    def constraint_rhs(self) -> sp.Matrix:
        """b in A q'' = b: minus the part of d/dt(A q' + a_t) without accelerations."""
        if not self.kin.constraints:
            return sp.zeros(0, 1)
        self._load_stored()
        stored = self.__dict__.get("constraint_rhs")
        return stored if stored is not None else -self.dt(self.constraint_velocity)

    @cached_property
    def holonomic_constraints(self) -> sp.Matrix:
        return sp.Matrix([c.position for c in self.kin.constraints if c.kind == "holonomic"])

    # ------------------------------------------------------------------------------------- equations
    def equations(self, method: str = "lagrange") -> Equations:
        """Derive (once per method) the equations of motion; never inverts M, never simplifies."""
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; use one of {METHODS}")
        if method not in self._eqs:
            from mechsys.mechanics import derivations

            eq = derivations.load(self, method)
            if eq is None:
                self._load_stored(skip=method)
                M, f = self._lagrange() if method == "lagrange" else self._kane()
                eq = Equations(method, self.coordinates, self.q, self.u, self.a, M, f, self.generalized_forces,
                               self.kinetic_energy, self.potential_energy, self.constraint_jacobian,
                               self.constraint_rhs, [c.name for c in self.kin.constraints])
                derivations.store(self, eq)
            self._eqs[method] = eq
        return self._eqs[method]

    def _lagrange(self) -> tuple[sp.Matrix, sp.Matrix]:
        """d/dt(dT/du) - dT/dq + dV/dq = Q. With the momenta p = dT/du (linear in the rates): M = dp/du, and
        d/dt(p) = M q'' + dp/dq u + dp/dt, so f = Q - dV/dq + dT/dq - (dp/dq u + dp/dt): one total derivative per
        coordinate (the momentum's), not one per entry of M."""
        T, V, Q = self.kinetic_energy, self.potential_energy, self.generalized_forces
        n = len(self.q)
        M = sp.zeros(n, n)
        diff = self.diff
        p = [diff(T, u) for u in self.u]
        for i in range(n):
            for j in range(i, n):
                M[i, j] = M[j, i] = diff(p[i], self.u[j])
        f = sp.Matrix([Q[i] - diff(V, self.q[i]) + diff(T, self.q[i]) - self.dt(p[i]) for i in range(n)])
        return M, f

    def _kane(self) -> tuple[sp.Matrix, sp.Matrix]:
        """Kane: F_r + F*_r = 0 with partial velocities; gravity enters as forces, not through V."""
        n = len(self.q)
        M = Sums(n, n)
        f = Sums(n, 1, self.generalized_forces + self._potential_force_kane())
        for (b, _r, v, w, frame), (Jv, Jw) in zip(self._body_kinematics, self._body_partials):
            a0 = frame.point_acceleration(b.com_local)  # acceleration of G with q'' = 0, home axes
            if b.mass != 0:
                M.add(gram(Jv, b.mass))
                f.add(-product(b.mass * Jv.T, a0))
            if not b.particle and b.inertia != sp.zeros(3, 3):
                I = b.inertia
                M.add(product(product(Jw.T, I), Jw))
                f.add(-product(Jw.T, I * frame.alpha + w.cross(I * w)))  # Euler's equations in body axes
        return M.matrix(), f.matrix()

    @cached_property
    def events(self) -> list[tuple[str, sp.Expr, str, str]]:
        """(name, expression, direction, action) of the file's events, expressions in q, der(q), t."""
        out = []
        names = set()
        for i, ev in enumerate(self.doc.spec.events):
            if ev.name in names:
                raise self.doc.error(("events", i, "name"), f"duplicate event name {ev.name!r}")
            names.add(ev.name)
            expr = self.doc.parse(ev.expression, ("events", i, "expression"), "force")
            out.append((ev.name, expr, ev.direction, ev.action))
        return out

    @cached_property
    def outputs(self) -> list[tuple[str, sp.Expr]]:
        """(column, expression in t, q, der(q), der(der(q))) of the file's `outputs:` (mechanics/quantities.py)."""
        from mechsys.mechanics.quantities import parse_outputs

        return parse_outputs(self)

    # ------------------------------------------------------------------------------------- classification
    @property
    def is_holonomic(self) -> bool:
        return all(c.kind == "holonomic" for c in self.kin.constraints)

    @cached_property
    def is_rheonomic(self) -> bool:
        """Time in the kinematics: a frame's pose, a constraint row, or a constraint that moves with time (a
        holonomic one written with t, psi - W*t, whose velocity row psi' - W has no t left in it); a prescribed
        coordinate used only in a force leaves them alone: scleronomic, non-autonomous."""
        exprs = [f.origin for f in self.kin.frames.values()] + [f.R for f in self.kin.frames.values()]
        exprs += [c.velocity for c in self.kin.constraints]
        return any(self.t in sp.sympify(e).free_symbols for e in exprs) or bool(self.moving_constraints)

    @cached_property
    def moving_constraints(self) -> list[str]:
        """The holonomic constraints that depend on time (d/dt at fixed coordinates is not zero: x - v*t): no
        configuration satisfies them at rest."""
        from mechsys.mechanics.dag import identically_zero

        values = {s: self.parameters[s.name] for s in self.parameter_symbols}
        return [c.name for c in self.kin.constraints if c.kind == "holonomic" and c.position is not None
                and c.position.has(self.t) and not identically_zero(self.diff(c.position, self.t), values)]

    def is_autonomous(self, method: str = INTERNAL_METHOD) -> bool:
        """No explicit t in M, f, A, b (a holonomic constraint that moves with time may leave them autonomous:
        moving_constraints). Decided symbolically when t is absent; a step or kink in t (abs, sign, min, max of t)
        is time dependence; else by d/dt = 0 at random states to the rounding of its terms (constant prescribed
        spins leave cos(W t)**2 + sin(W t)**2, which is never simplified on this path).
        Remembered per model object and on disk (mechanics/derivations.py)."""
        memo = self.__dict__.setdefault("_autonomous", {})
        if method not in memo:
            from mechsys.mechanics import derivations

            memo[method] = derivations.autonomous_decision(self, method, lambda: self._decide_autonomous(method))
        return memo[method]

    def _decide_autonomous(self, method: str) -> bool:
        eq = self.equations(method)
        symbols = FreeSymbols()
        parts = [m for m in (eq.M, eq.f, eq.A, eq.b) if m.shape[0] and self.t in symbols.of_all(m)]
        if not parts:
            return True
        from mechsys.mechanics.dag import identically_zero, switches

        # a step or kink in t (min(t, T), sign(t - t1)) is time dependence that d/dt at a few random times misses:
        # its derivative is zero or a DiracDelta almost everywhere (a hoop spun up over [0, 1] s, a step load)
        if switches([e for part in parts for e in part], self.t):
            return False

        # d/dt of each entry with t vanishes at random states, to the rounding of its own terms (dag: at any units;
        # against max(1, |value|) a MEMS pivot driven at 1.8 m/s^2 was taken for autonomous)
        values = {s: self.parameters[s.name] for s in self.parameter_symbols}
        return all(identically_zero(self.diff(entry, self.t), values)
                   for part in parts for entry in part if symbols.has(entry, self.t))

    def cyclic_coordinates(self, method: str = INTERNAL_METHOD) -> list[str]:
        """Coordinates the equations of motion do not depend on (mechanics/symmetry.py: decided at random states,
        confirmed symbolically), plus those the file declares with `cyclic: true`, minus `cyclic: false`."""
        return list(self.cyclic_decision.names)

    @cached_property
    def cyclic_decision(self) -> CyclicDecision:
        from mechsys.mechanics import derivations
        from mechsys.mechanics.symmetry import decide

        return derivations.cyclic_decision(self, decide)
