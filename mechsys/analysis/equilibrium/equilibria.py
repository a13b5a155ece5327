"""Equilibria and steady motions: deflated multistart Newton with exact Jacobians, angles on the circle."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
import sympy as sp

from mechsys.analysis.equilibrium import loops
from mechsys.errors import AnalysisError, InputError
from mechsys.mechanics.dag import Substitution, identically_zero
from mechsys.mechanics.model import INTERNAL_METHOD, MechanicalModel
from mechsys.numeric import cache
from mechsys.numeric.lambdify import generate_source
from mechsys.numeric.runtime import function_from_source
from mechsys.numeric.parameters import parameter_values

if TYPE_CHECKING:
    import pandas as pd

    from mechsys.analysis.equilibrium.exhaustive import Exhaustive


def wrap(angle: float) -> float:
    """An angle in (-pi, pi]."""
    a = math.remainder(angle, 2 * math.pi)
    return math.pi if a == -math.pi else a + 0.0  # no negative zero


@dataclass
class Equilibrium:
    """One equilibrium (or steady motion) with its linear stability."""

    coordinates: dict[str, float]
    rates: dict[str, float]
    multipliers: list[float]
    eigenvalues: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    jacobian: np.ndarray | None = None
    stability: str = "undecided"
    critical: bool = False
    reason: str = ""
    chart: str = ""  # why the coordinates are a singular chart here ('' where they are regular): charts.py
    branch: str = ""  # why the closed loops are at a singular configuration here ('' where they are not): loops.py
    structural: str = ""  # zero eigenvalues reported apart (nonholonomic: ignorable coordinates, families)
    accelerations: dict[str, float] = field(default_factory=dict)  # of dependent ignorable speeds (nonholonomic)

    def to_dict(self) -> dict:
        return {
            "coordinates": dict(self.coordinates),
            "rates": dict(self.rates),
            "eigenvalues": [[float(e.real), float(e.imag)] for e in self.eigenvalues],
            "stability": self.stability,
            "critical": self.critical,
            "reason": self.reason,
            **({"structural_zeros": self.structural} if self.structural else {}),
        }


@dataclass
class EquilibriaResult:
    equilibria: list[Equilibrium]
    message: str = ""
    cyclic: list[str] = field(default_factory=list)
    fixed_rates: dict[str, float] = field(default_factory=dict)
    search: SearchReport | None = None
    exhaustive: Exhaustive | None = None  # what the exhaustive mode computed (analysis/equilibrium/exhaustive.py)
    formulation: str = ""  # nonholonomic: independent speeds, eliminated and ignorable coordinates
    problem: Any = field(default=None, repr=False, compare=False)  # the equations solved (a sweep may reuse them)

    def _repr_markdown_(self) -> str:
        """Jupyter: the tables of `mechsys equilibria -f markdown`."""
        from mechsys.report.notebook import equilibria_markdown

        return equilibria_markdown(self)

    def to_dataframe(self) -> pd.DataFrame:
        """One row per equilibrium or steady motion: coordinates, der(rates), stability, critical, reason,
        max_real and the eigenvalues (needs pandas: ``pip install 'mechsys[notebook]'``)."""
        from mechsys.report.notebook import equilibria_frame

        return equilibria_frame(self)


#: what the generated code of the rest equations raises where a force is not defined (math.log(-1), 1/0)
_UNDEFINED = (ValueError, ZeroDivisionError, OverflowError)

#: functions whose derivative jumps or does not exist somewhere (EquilibriumProblem.non_smooth)
#: and the reasons EquilibriumProblem.discontinuity gives
_JUMPS = ("the forces at rest jump (a spring of zero length, a sign() law)", "the forces at rest are not defined nearby")
_NON_SMOOTH = (sp.Abs, sp.sign, sp.Heaviside, sp.Min, sp.Max, sp.Piecewise, sp.floor, sp.ceiling)


def _contains(exprs: list, kinds: tuple) -> bool:
    """Whether a node of one of ``kinds`` occurs in the expressions, each shared node visited once."""
    seen: set[int] = set()
    stack = [e for m in exprs for e in (m if isinstance(m, sp.MatrixBase) else [m])]
    while stack:
        node = stack.pop()
        if isinstance(node, kinds):
            return True
        for arg in node.args:
            if id(arg) not in seen:
                seen.add(id(arg))
                stack.append(arg)
    return False


def refuse_time_dependence(model: MechanicalModel, method: str, what: str) -> None:
    """An AnalysisError when the model depends explicitly on time: t in the equations of motion (model.is_autonomous),
    or, with equations free of t, a holonomic constraint that moves with time (no configuration satisfies
    psi - W*t at rest; its velocity row psi' - W has no t, it was read at t = 0, and the arm it drives found at
    rest)."""
    if not model.is_autonomous(method):
        raise AnalysisError(f"the equations depend explicitly on time (non-autonomous): there are no {what} in the "
                            "ordinary sense")
    moving = model.moving_constraints
    if moving:
        one = len(moving) == 1
        raise AnalysisError(
            f"the constraint{'' if one else 's'} {', '.join(repr(n) for n in moving)} move{'s' if one else ''} with "
            f"time (d/dt at fixed coordinates is not zero): no configuration satisfies {'it' if one else 'them'} at "
            f"rest, so there are no {what} in the ordinary sense; for steady motions relative to a coordinate driven "
            "at a constant rate, make it prescribed (psi: {prescribed: W*t})")


class EquilibriumProblem:
    """The algebraic equations of rest: f(q, u) + A^T lambda = 0 and Phi(q) = 0, with u = 0 except the steady
    rates of cyclic coordinates, which are unknowns (or fixed at their initial rate when the system leaves
    them free: a family of steady motions)."""

    #: (rows, unknowns) in consecutive blocks of one kind each, or None (equation_scales)
    blocks: tuple[list[int], list[int]] | None = None

    def __init__(self, model: MechanicalModel) -> None:
        self.model = model
        if not model.is_holonomic:
            raise AnalysisError("equilibria of nonholonomic systems are not supported")
        refuse_time_dependence(model, INTERNAL_METHOD, "equilibria")
        self.eq = model.equations(INTERNAL_METHOD)
        ignorable = model.cyclic_coordinates()
        self.cyclic = [c for c in ignorable if not model.kin.constraints]
        #: cyclic coordinates not reduced because of constraints (steady motions spinning them are not sought)
        self.unreduced = [] if self.cyclic else list(ignorable)
        self.free = [c for c in model.coordinates if c not in self.cyclic]
        self.nq = len(self.free)
        self.m = len(model.kin.constraints)
        self.lam = sp.symbols(f"lambda1:{self.m + 1}", real=True) if self.m else ()
        self.angles = model.angles
        self.fixed_rates = self._family_rates()
        self.rate_unknowns = [c for c in self.cyclic if c not in self.fixed_rates]
        self.angles = self._periodic_angles()

    def _periodic_angles(self, values: Sequence[np.ndarray] = ()) -> dict[str, bool]:
        """model.angles, less the free angles the rest equations are not 2 pi-periodic in (checked at two random
        points, at the file's parameter values and at each of ``values``): a torsional spring's k*theta makes
        theta = 5.6 and theta = 5.6 - 2 pi different states, and wrapped they were one (a pendulum with a spring
        and a torque had 'no equilibrium' in th = 0:7, and a sweep's branch jumped by 2 pi). A constant torque keeps
        F periodic (its potential is not)."""
        angles = dict(self.model.angles)
        names = [c for c in self.free if angles.get(c, False)]
        if not names or not self.unknowns:
            return angles
        rng = np.random.default_rng(5)
        for p in [parameter_values(self.model), *values]:
            for _ in range(2):
                z = rng.uniform(-np.pi, np.pi, len(self.unknowns))
                F = self.F(z, p)
                for c in names:
                    shifted = z.copy()
                    shifted[self.free.index(c)] += 2 * np.pi
                    G = self.F(shifted, p)
                    if np.all(np.isfinite(F)) and np.all(np.isfinite(G)) and \
                            np.max(np.abs(G - F)) > 1e-9 * (1 + float(np.max(np.abs(F)))):
                        angles[c] = False
        self.undefined = False  # a draw where a force is not defined says nothing about the search
        return angles

    def periodic_over(self, values: Sequence[np.ndarray]) -> None:
        """Decide again which angles wrap, with the parameter vectors a sweep visits too: a spring of stiffness k
        swept from a file's k = 0 made theta non-periodic along the sweep, whose rows were wrapped 2 pi off (68 of
        89) and whose folds were lost."""
        if any(self.angles.get(c, False) for c in self.free):
            angles = self._periodic_angles(values)
            if angles != self.angles:
                self.angles = angles
                self.__dict__.pop("_angle_mask", None)  # the wrapping of is_angle(), decided from them

    # ------------------------------------------------------------------------------------- symbols
    def _q(self, name: str) -> sp.Symbol:
        return self.model.doc.coords[name]

    def _u(self, name: str) -> sp.Symbol:
        return self.model.doc.rates[name]

    @cached_property
    def rest_substitution(self) -> dict:
        """u = 0 for non-cyclic coordinates, t = 0 (autonomous), cyclic angles at 0 (they do not appear)."""
        subs = {self._u(c): 0 for c in self.free}
        subs.update({self._q(c): 0 for c in self.cyclic})
        subs[self.model.t] = 0
        return subs

    @cached_property
    def residual_exprs(self) -> sp.Matrix:
        eq = self.eq
        F = eq.f
        if self.m:
            F = F + eq.A.T * sp.Matrix(self.lam)
        rows = list(Substitution(self.rest_substitution, self.model.diff.symbols).matrix(F))  # each shared node once
        rows += list(self.model.holonomic_constraints.xreplace({self.model.t: 0}))
        return sp.Matrix(rows)

    @cached_property
    def residual_count(self) -> int:
        """len(residual_exprs) without forming them (the shapes of the cached code's outputs)."""
        return len(self.model.q) + sum(1 for c in self.model.kin.constraints if c.kind == "holonomic")

    def _family_rates(self) -> dict[str, float]:
        """Cyclic rates whose equation vanishes identically at rest (e.g. a free rotor): fixed at the initial rate."""
        fixed = {}
        if not self.cyclic:
            return fixed
        # each shared node substituted once (residual_exprs' way): xreplace walked the 3-D chain's f as a tree, 50 s;
        # compiled once per model and split, kept with the compiled equations (shared by with_overrides copies: the
        # re-charted problem of each root at a gimbal lock compiled it again, 12 s each on a 6-box chain)
        store = self.model.__dict__.setdefault("_equilibrium_memo", {})
        key = ("family", tuple(self.cyclic))
        if key not in store:
            F = Substitution(self.rest_substitution).matrix(self.eq.f)
            store[key] = [F[self.model.coordinates.index(c)] for c in self.cyclic]
        values = dict(zip(self.model.parameter_symbols, parameter_values(self.model)))
        for c, row in zip(self.cyclic, store[key]):
            # at random states, relative to the row's own terms (dag.identically_zero): an absolute 1e-12 took a
            # watch-sized rotor's torque for none
            if identically_zero(row, values):
                fixed[c] = self.model.doc.initial_rate[c]
        return fixed

    @cached_property
    def linear_rates(self) -> bool:
        """The rest equations of the cyclic coordinates whose steady rates are unknowns are linear in those rates
        (e.g. a motor's torque balance Mo - dM*der(alpha) = 0): each start's rates are then solved, not guessed."""
        if not self.rate_unknowns:
            return False
        us = [self._u(c) for c in self.rate_unknowns]
        rows = [self.residual_exprs[self.model.coordinates.index(c)] for c in self.rate_unknowns]
        return all(sp.expand(sp.diff(r, a, b)) == 0 for r in rows for a in us for b in us)

    def start(self, start: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The Newton start from drawn coordinates and rates: onto the constraints, the steady rates solved where
        they enter linearly, the multipliers by least squares."""
        start = self.solve_rates(loops.onto_constraints(self, start, p), p)
        return np.concatenate([start, _multiplier_guess(self, start, p)])

    def solve_rates(self, start: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``start`` with its steady rates solved from their linear equations at its coordinates (unchanged when
        the equations are not linear in the rates or singular there)."""
        if not self.linear_rates:
            return start
        k = len(self.rate_unknowns)
        cols = slice(self.nq, self.nq + k)
        rows = [self.model.coordinates.index(c) for c in self.rate_unknowns]
        z = np.concatenate([start, np.zeros(self.m)])
        z[cols] = 0.0
        b = self.F(z, p)[rows]
        A = self.J(z, p)[np.ix_(rows, range(self.nq, self.nq + k))]
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(b))):
            return start
        sv = np.linalg.svd(A, compute_uv=False)
        if sv[-1] <= 1e-12 * max(1e-300, sv[0]):
            return start
        out = start.copy()
        out[cols] = np.linalg.solve(A, -b)
        return out

    @cached_property
    def unknowns(self) -> list[sp.Symbol]:
        return [self._q(c) for c in self.free] + [self._u(c) for c in self.rate_unknowns] + list(self.lam)

    @cached_property
    def unknown_names(self) -> list[str]:
        return list(self.free) + [f"der({c})" for c in self.rate_unknowns] + [str(s) for s in self.lam]

    @cached_property
    def _args(self) -> list[sp.Symbol]:
        return self.unknowns + [self._u(c) for c in self.fixed_rates] + list(self.model.parameter_symbols)

    def _memo(self, what: str, exprs):
        """The compiled function of the expressions ``exprs()`` returns, kept on the model (shared by with_overrides
        copies: a sweep compiles once) and its generated code cached on disk, keyed by the model's structure
        (cache.model_key: names, decisions, code) and the problem's split into free and cyclic coordinates,
        steady-rate unknowns and given rates (decided with parameter values), so a second command on the model
        differentiates and compiles nothing."""
        store = self.model.__dict__.setdefault("_equilibrium_memo", {})
        key = (what, tuple(self.rate_unknowns), tuple(self.fixed_rates))
        if key not in store:
            disk = _source_key(self, what)
            entry = cache.load(disk) if disk is not None else None
            try:
                store[key] = function_from_source(entry["source"])
            except (TypeError, KeyError, ValueError, SyntaxError):  # none stored, or not what this code writes
                source = generate_source(list(exprs()), self._args)
                if disk is not None:
                    cache.store(disk, {"source": source})
                store[key] = function_from_source(source)
        return store[key]

    def _jacobian(self, wrt: list) -> sp.Matrix:
        """d(residual_exprs)/d(wrt) by the model's memoized differentiation (sympy's expressions)."""
        rows = self.residual_exprs
        return sp.Matrix(rows.shape[0], len(wrt), lambda i, j: self.model.diff(rows[i], wrt[j]))

    @cached_property
    def _F(self):
        return self._memo("F", lambda: self.residual_exprs)

    @cached_property
    def _J(self):
        return self._memo("J", lambda: self._jacobian(self.unknowns))

    def _dF_dp_exprs(self) -> sp.Matrix:
        return self._jacobian(self.model.parameter_symbols)

    @cached_property
    def _Fp(self):
        return self._memo("Fp", self._dF_dp_exprs)

    @cached_property
    def _Fr(self):
        return self._memo("Fr", lambda: self._jacobian([self._u(c) for c in self.fixed_rates]))

    # ------------------------------------------------------------------------------------- numerics
    def extra(self) -> list[float]:
        return [self.fixed_rates[c] for c in self.fixed_rates]

    def F(self, z: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The rest equations at z; NaN where a force is not defined there (log or sqrt of a negative number, a
        division by zero: the generated code raises; the searches drop such starts)."""
        try:
            return np.array(self._F(*z, *self.extra(), *p), dtype=float)
        except _UNDEFINED:
            self.undefined = True
            return np.full(self.residual_count, np.nan)

    def J(self, z: np.ndarray, p: np.ndarray) -> np.ndarray:
        n = len(self.unknowns)
        if n == 0:  # nothing to solve for (every coordinate cyclic with its rate fixed): sympy refuses jacobian([])
            return np.zeros((self.residual_count, 0))
        try:
            return np.array(self._J(*z, *self.extra(), *p), dtype=float).reshape(self.residual_count, n)
        except _UNDEFINED:
            self.undefined = True
            return np.full((self.residual_count, n), np.nan)

    def Fp(self, z: np.ndarray, p: np.ndarray) -> np.ndarray:
        """dF/dp for every parameter (columns in model.parameter_symbols order)."""
        return np.array(self._Fp(*z, *self.extra(), *p), dtype=float).reshape(self.residual_count, -1)

    def Fr(self, z: np.ndarray, p: np.ndarray) -> np.ndarray:
        """dF/d(given rates) (columns in fixed_rates order): a family's rate as a continuation parameter."""
        if not self.fixed_rates:
            return np.zeros((self.residual_count, 0))
        return np.array(self._Fr(*z, *self.extra(), *p), dtype=float).reshape(self.residual_count, -1)

    #: "compiled" when _newton runs numeric/newton.c for this problem (see compiled_newton), else "python"
    newton_path = "python"
    #: set when F or J met a point where a force is not defined (the search's message says so)
    undefined = False

    def is_angle(self) -> np.ndarray:
        mask = self.__dict__.get("_angle_mask")
        if mask is None:
            mask = np.array([self.angles.get(c, False) for c in self.free] + [False] * (len(self.unknowns) - self.nq))
            self.__dict__["_angle_mask"] = mask
        return mask

    def normalize(self, z: np.ndarray) -> np.ndarray:
        z = z.copy()
        for k, is_angle in enumerate(self.is_angle()):
            if is_angle:
                z[k] = wrap(z[k])
        return z

    def distance(self, a: np.ndarray, b: np.ndarray) -> float:
        return float(self.distances(a, np.asarray(b, dtype=float)[None, :])[0])

    def distances(self, z: np.ndarray, others: np.ndarray) -> np.ndarray:
        """The distance of z to each row of ``others`` in the coordinates and rates, angle differences taken on
        the circle (the remainder of 2 pi, as wrap())."""
        d = np.asarray(others, dtype=float) - z
        ang = self.is_angle()
        d[:, ang] -= 2 * math.pi * np.rint(d[:, ang] / (2 * math.pi))
        return np.linalg.norm(d[:, : self.nq + len(self.rate_unknowns)], axis=1)

    def split_singularity(self, z: np.ndarray, p: np.ndarray) -> str | None:
        """Why the coordinates the analysis eliminates are not determined at z (a coordinate singularity of the
        model, not a steady motion one can linearize about), or None. Only systems with velocity constraints
        eliminate coordinates and speeds (analysis/equilibrium/nonholonomic.py); gimbal locks are charts.py's."""
        return None

    @cached_property
    def non_smooth(self) -> bool:
        """The equations of motion contain a function that is not smooth everywhere (a 1-D spring's length |x|, a
        sign() law, Heaviside, min, max): their rest equations may jump where it switches (see discontinuity)."""
        eq = self.model.equations(INTERNAL_METHOD)
        return _contains([eq.M, eq.f, eq.A, eq.b, self.model.holonomic_constraints], _NON_SMOOTH)

    def discontinuity(self, z: np.ndarray, p: np.ndarray) -> str | None:
        """Why z is not a rest although F(z) = 0: the rest equations jump across z (a spring of zero length pushes
        both ways, its direction undefined; sympy's sign(0) = 0 makes F vanish there), or None. A jump is a
        difference F(z + h e_k) - F(z - h e_k) that does not shrink with h."""
        if not self.non_smooth:
            return None
        for k in range(len(z)):
            h = 1e-6 * (1 + abs(z[k]))
            wide, narrow = (self.F(z + d * np.eye(len(z))[k], p) - self.F(z - d * np.eye(len(z))[k], p)
                            for d in (h, h / 100))
            if not (np.all(np.isfinite(wide)) and np.all(np.isfinite(narrow))):
                return _JUMPS[1]
            size = float(np.max(np.abs(wide)))
            if size > 1e-9 * max(1.0, float(np.max(np.abs(self.J(z, p))))) and np.max(np.abs(narrow)) > 0.5 * size:
                return _JUMPS[0]
        return None

    def equilibrium(self, z: np.ndarray) -> Equilibrium:
        z = self.normalize(z)
        coords = {c: float(z[k]) for k, c in enumerate(self.free)}
        rates = {c: float(z[self.nq + k]) for k, c in enumerate(self.rate_unknowns)}
        rates.update(self.fixed_rates)
        rates = {c: rates[c] for c in self.cyclic}
        lam = [float(x) for x in z[self.nq + len(self.rate_unknowns):]]
        return Equilibrium(coords, rates, lam)

    def state(self, e: Equilibrium) -> np.ndarray:
        return np.array([e.coordinates[c] for c in self.free] + [e.rates[c] for c in self.rate_unknowns]
                        + list(e.multipliers), dtype=float)


def _source_key(problem: EquilibriumProblem, what: str) -> str | None:
    """The cache key of a holonomic problem's generated function ``what`` (None when the cache is off)."""
    if cache.cache_dir() is None:
        return None
    import hashlib
    import json

    split = [problem.free, problem.cyclic, problem.rate_unknowns, list(problem.fixed_rates), problem.m]
    payload = json.dumps([cache.model_key(problem.model, f"equilibrium-{what}"), split])
    return hashlib.sha256(payload.encode()).hexdigest()[:32]


# ----------------------------------------------------------------------------------------- solving
def _newton(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray, roots: list[np.ndarray],
            max_iter: int = 60) -> np.ndarray | None:
    """Deflated Newton (Farrell et al.): roots already found repel the iteration; backtracking on |G|. A problem
    with compiled pieces runs the same loop as compiled code (numeric/newton.c)."""
    n = len(z)
    rows, sizes = newton_scales(problem, p)
    unit = rows.size == 1  # (the compiled loop takes F and J as they are)
    compiled = getattr(problem, "compiled_newton", None) if unit else None
    run = compiled(p) if compiled is not None else None
    if run is not None:
        end = run(z, np.array(roots, dtype=float).reshape(len(roots), n), max_iter)
        return None if end is None else _polish(problem, problem.normalize(end), p)

    ang = np.flatnonzero(problem.is_angle())
    every = len(ang) == n  # all unknowns angles (a chain): wrapped in place, no gather and scatter
    known = np.array(roots, dtype=float).reshape(len(roots), n)

    def distances(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """z - r for every root found (angles on the circle) and the squared distances."""
        d = z - known
        if every:
            _wrap(d)
        elif len(ang):
            d[:, ang] = _wrap(d[:, ang])
        return d, np.maximum(np.einsum("ij,ij->i", d, d), 1e-28)

    def deflation(z: np.ndarray) -> tuple[float, np.ndarray]:
        """mu = prod(1/|z - r|^2 + 1) over the roots found, and grad log mu (one array operation for all roots)."""
        if not len(known):
            return 1.0, np.zeros(n)
        d, d2 = distances(z)
        factor = 1.0 / d2 + 1.0
        return float(np.prod(factor)), (-2.0 * d / (d2**2 * factor)[:, None]).sum(axis=0)

    def G_only(z: np.ndarray) -> float:
        """|mu F| for the line search (mu only: no gradient)."""
        F = problem.F(z, p) / rows
        if not np.all(np.isfinite(F)):
            return np.inf
        mu = float(np.prod(1.0 / distances(z)[1] + 1.0)) if len(known) else 1.0
        return float(np.linalg.norm(mu * F))

    stalls = 0
    for _ in range(max_iter):
        # each row and unknown in its own size where they are far from 1 (newton_scales): at MEMS scale the force
        # rows (1e-17 N m) beside the loop rows (1e-5 m) left Newton at its starts
        F = problem.F(z, p) / rows
        J = problem.J(z, p) / rows[:, None]
        mu, grad_log = deflation(z)
        G = mu * F
        JG = mu * J + np.outer(F, mu * grad_log)
        if not (np.all(np.isfinite(JG)) and np.all(np.isfinite(G))):
            return None
        try:
            step = sizes * np.linalg.lstsq(JG * sizes, -G, rcond=None)[0]
        except np.linalg.LinAlgError:
            return None
        scale = 1.0
        g0 = float(np.linalg.norm(G))
        while scale > 1e-4:
            try:
                g1 = G_only(z + scale * step)
            except (ValueError, ZeroDivisionError, OverflowError):
                g1 = np.inf
            if np.isfinite(g1) and g1 <= (1 - 1e-4 * scale) * g0 + 1e-300:
                break
            scale *= 0.5
        stalls = stalls + 1 if scale < 1e-2 else 0
        if stalls >= 4:
            return None  # stagnating far from a root: another start will do better
        z = z + scale * step
        if np.linalg.norm(scale * step, np.inf) < 1e-12 * (1 + np.linalg.norm(z, np.inf)):
            break
    return _polish(problem, problem.normalize(z), p)


_TWO_PI = 2 * np.pi


def _wrap(d: np.ndarray) -> np.ndarray:
    """d wrapped onto [-pi, pi) in place: remainder(d + pi, 2 pi) - pi, bit for bit, at a third of the time. numpy's
    remainder is fmod plus the divisor where fmod's result is negative (and +0.0 for a zero, which - pi makes
    -pi either way); fmod is exact. The multistart's deflation wraps its distances to every root found at every
    step (the 40-link chain: 22,000 times, up to 984 roots)."""
    d += np.pi
    np.fmod(d, _TWO_PI, out=d)
    np.add(d, _TWO_PI, out=d, where=d < 0)
    d -= np.pi
    return d


def _polish(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray) -> np.ndarray | None:
    """Plain Newton to full accuracy, then accept only a genuine zero of F; entries within rounding of 0 are set
    to 0 where that is a root as well (Newton's last step leaves -2.35e-38 where the root is at 0)."""
    rows, sizes = newton_scales(problem, p)
    for _ in range(8):
        F = problem.F(z, p)
        J = problem.J(z, p)
        if not (np.all(np.isfinite(F)) and np.all(np.isfinite(J))):
            return None
        # in the equations' and unknowns' own sizes where they are far from 1: least squares weighs a MEMS loop's
        # 1e-12 N m force rows as its 1e-4 m loop rows (and a 1 km four-bar's 1e10 N m ones as its 1e3 m ones)
        step = sizes * np.linalg.lstsq(J / rows[:, None] * sizes, -F / rows, rcond=None)[0]
        z = z + step
        if np.linalg.norm(step, np.inf) < 1e-14 * (1 + np.linalg.norm(z, np.inf)):
            break
    if not _is_root(problem, z, p):
        return None
    snapped = np.where(np.abs(z) < 1e-14 * (1 + np.linalg.norm(z, np.inf)), 0.0, z)
    return snapped if not np.array_equal(snapped, z) and _is_root(problem, snapped, p) else z


def _is_root(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray) -> bool:
    """F(z) vanishes to 1e-10 of the Jacobian's largest entry (at least 1), and Newton's step from z is below 1e-4
    (1 + |z|): the acceptance of every root. A row or an unknown smaller than 1 where the search looks is measured
    in its own size (equation_scales): a MEMS linkage's rest equations are 1e-12 N m and its multipliers 1e-8 N,
    and against a floor of 1 N m every configuration on its loop passed F = 0. The step test drops the zeros at
    infinity of a force that only tends to 0 (1/x at x = 1e20: F = 1e-20 passed, but Newton's step there doubles
    x). An F above rounding (1e-13 of that scale) must also be one Newton's linear model can reduce: near a loop's
    dead point the multipliers reach 1e4 and J's scale with them, and Newton stalls at |F| ~ 1e-7 where J is
    singular, in no root's basin."""
    rows, sizes = small_scales(problem, p)
    F = problem.F(z, p) / rows
    J = problem.J(z, p) / rows[:, None] * sizes  # in the unknowns' own sizes
    scale = max(1.0, float(np.max(np.abs(J)))) if J.size else 1.0
    if not (np.all(np.isfinite(F)) and np.all(np.isfinite(J)) and np.max(np.abs(F), initial=0.0) <= 1e-10 * scale):
        return False
    if not J.size:
        return True
    step = np.linalg.lstsq(J, -F, rcond=None)[0]
    if np.max(np.abs(F)) > 1e-13 * scale and np.linalg.norm(F + J @ step) > 0.25 * np.linalg.norm(F):
        return False  # above rounding, and no step reduces F: a minimum of |F| where J is singular, not a zero
    step = step * sizes
    return bool(np.max(np.abs(step), initial=0.0) <= 1e-4 * (1 + float(np.max(np.abs(z), initial=0.0))))


def newton_scales(problem: EquilibriumProblem, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """equation_scales where a row or unknown lies outside [1e-6, 1e6] (a MEMS or a 1 km linkage), else single
    ones: at ordinary units Newton and its polish run on F and J as they are (and their roots to the last digit)."""
    rows, sizes = equation_scales(problem, p)
    if np.all((rows >= 1e-6) & (rows <= 1e6)) and np.all((sizes >= 1e-6) & (sizes <= 1e6)):
        return np.ones(1), np.ones(1)
    return rows, sizes


def small_scales(problem: EquilibriumProblem, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """equation_scales capped at 1: rows and unknowns smaller than 1 in their own sizes, the others as they are
    (so a model at ordinary units is judged and polished exactly as before, and a degenerate root, where J
    vanishes, is not measured against the size J has elsewhere)."""
    rows, sizes = equation_scales(problem, p)
    return np.minimum(rows, 1.0), np.minimum(sizes, 1.0)


def equation_scales(problem: EquilibriumProblem, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, sizes): the size of each unknown and of each rest equation's terms where the search looks, medians
    over the file's initial state and four random starts of the default boxes, each as the search starts it (on
    the constraints, rates solved, multipliers guessed; a start near a loop's dead point has huge multipliers).
    An unknown's size is its |z_j| (an angle's at least 1, 1 where it is 0), a row's the largest of |F_i| and
    |dF_i/dz_j| times the sizes (the largest dynamics row's for a fixed-rate cyclic coordinate's row, which
    vanishes at rest; 1 when a row vanishes at every start). Remembered per parameter values. The first rows are each
    coordinate's (residual_exprs', and the nonholonomic problem's dynamics rows)."""
    memo = problem.__dict__.setdefault("_equation_scales", {})
    key = np.asarray(p, dtype=float).tobytes()
    if key not in memo:
        rng = np.random.default_rng(3)
        boxes = _boxes(problem, None)
        initial = [problem.model.doc.initial.get(c, 0.0) for c in problem.free] + [
            problem.model.doc.initial_rate.get(c, 0.0) for c in problem.rate_unknowns]
        draws = [np.array(initial, dtype=float)] + [np.array([rng.uniform(lo, hi) for lo, hi in boxes])
                                                      for _ in range(4)]
        samples = []
        for draw in draws:
            try:
                z = problem.start(draw, p)
                F, J = problem.F(z, p), problem.J(z, p)
            except (ValueError, ArithmeticError, np.linalg.LinAlgError):
                continue
            if np.all(np.isfinite(F)) and np.all(np.isfinite(J)):
                samples.append((z, F, J))
        size, sizes = np.zeros(problem.residual_count), np.ones(len(problem.unknowns))
        if samples and problem.blocks is not None:
            size, sizes = _block_scales(problem, samples)
        elif samples:
            sizes = np.median([np.abs(z) for z, _, _ in samples], axis=0)
            sizes = np.where(problem.is_angle(), np.maximum(sizes, 1.0), np.where(sizes > 0, sizes, 1.0))
            size = np.median([np.maximum(np.abs(F), np.max(np.abs(J) * sizes, axis=1, initial=0.0))
                              for _z, F, J in samples], axis=0)
        # the rows that vanish at rest whatever the state (a cyclic coordinate's whose rate is fixed: at rounding
        # of terms of any size) are measured against the largest row
        largest = float(np.max(size[:problem.blocks[0][0]] if problem.blocks else size, initial=0.0))  # in N, N m
        for c in problem.fixed_rates:
            size[problem.model.coordinates.index(c)] = largest
        memo[key] = np.where(size > 0, size, 1.0), sizes
    return memo[key]


def _block_scales(problem: EquilibriumProblem, samples: list[tuple]) -> tuple[np.ndarray, np.ndarray]:
    """equation_scales' (rows, sizes) for a problem whose rows and unknowns come in blocks of one kind each
    (problem.blocks: the nonholonomic one, whose unknowns include rates solved from the constraints and
    multipliers). A size at 1e-12 of its block's largest is rounding (a bicycle's der(y) heading along x, 1e-15).
    An unknown without a size where the search starts (a multiplier or an acceleration that vanishes there) takes
    its block's largest, else the one its column gives the rows it enters (the smallest row size / |dF_i/dz_j|),
    else 1. A size of 1 for it made a MEMS disk's dynamics rows 1 N through their -A^T lambda terms."""
    rows_blocks, unknown_blocks = problem.blocks
    J = np.median([np.abs(J) for _z, _F, J in samples], axis=0)
    F = np.median([np.abs(F) for _z, F, _J in samples], axis=0)
    sizes = _rounding_as_zero(np.median([np.abs(z) for z, _, _ in samples], axis=0), unknown_blocks)
    sizes = np.where(problem.is_angle(), np.maximum(sizes, 1.0), sizes)
    start = 0
    for length in unknown_blocks:
        part = sizes[start:start + length]
        part[part == 0] = float(np.max(part, initial=0.0))
        start += length

    def rows() -> np.ndarray:
        return _rounding_as_zero(np.maximum(F, np.max(J * sizes, axis=1, initial=0.0)), rows_blocks)

    size = rows()
    for j in np.flatnonzero(sizes == 0):
        enters = (J[:, j] > 0) & (size > 0)
        sizes[j] = float(np.min(size[enters] / J[enters, j])) if np.any(enters) else 1.0
    return rows(), sizes


def _rounding_as_zero(values: np.ndarray, blocks: list[int]) -> np.ndarray:
    """values with those at 1e-12 of their block's largest (blocks: consecutive lengths) set to 0."""
    out, start = values.copy(), 0
    for length in blocks:
        part = out[start:start + length]
        part[part <= 1e-12 * float(np.max(part, initial=0.0))] = 0.0
        start += length
    return out


def settle(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray, max_steps: int = 400) -> np.ndarray | None:
    """The rest the flow z' = F(z) comes to from z, polished (_polish), or None if it does not come to one.

    Pseudo-transient continuation with switched evolution relaxation (Kelley and Keyes, SIAM J. Numer. Anal. 35,
    1998): steps (I/delta - J) s = F, delta growing as |F| falls, so the first steps follow the flow and the last
    ones are Newton's. The flow's rests that attract are those where J has no eigenvalue with a positive real
    part; with F the generalized force at rest, F = -grad V for conservative forces and the flow descends the
    potential to a minimum. Its verdict is still the caller's to assess: the steps may end on any root."""
    F = problem.F(z, p)
    J = problem.J(z, p)
    if not (np.all(np.isfinite(F)) and np.all(np.isfinite(J))):
        return None
    eye = np.eye(len(z))
    # the first step is explicit Euler's, inside its stability and at most 0.1 long (J vanishes where F peaks: a
    # chain held horizontal)
    delta = 0.1 / max(float(np.linalg.norm(J, np.inf)), float(np.linalg.norm(F, np.inf)), 1e-300)
    for _ in range(max_steps):
        try:
            step = np.linalg.solve(eye / delta - J, F)
        except np.linalg.LinAlgError:
            delta *= 0.25
            continue
        trial = z + step
        F_trial = problem.F(trial, p)
        g, g_trial = float(np.linalg.norm(F)), float(np.linalg.norm(F_trial))
        if not np.all(np.isfinite(F_trial)) or g_trial > 2.0 * g:
            delta *= 0.25  # overshot: back towards the flow
            continue
        z, F = trial, F_trial
        if np.linalg.norm(step, np.inf) < 1e-12 * (1 + np.linalg.norm(z, np.inf)):
            break
        delta = min(delta * min(g / max(g_trial, 1e-300), 10.0), 1e15)
        J = problem.J(z, p)
        if not np.all(np.isfinite(J)):
            return None
    return _polish(problem, problem.normalize(z), p)


def _boxes(problem: EquilibriumProblem, search: dict[str, tuple[float, float]] | None) -> list[tuple[float, float]]:
    search = dict(search or {})
    model = problem.model
    known = set(problem.free) | set(problem.rate_unknowns) | {f"der({c})" for c in problem.rate_unknowns}
    for name in search:
        if name not in known:
            from mechsys.errors import InputError

            raise InputError(f"--search {name}: not a free non-cyclic coordinate or cyclic rate "
                             f"(choose from {', '.join(sorted(known)) or 'none'})")
    boxes = []
    for c in problem.free:
        if c in search:
            boxes.append(search[c])
        elif problem.angles.get(c, False):
            boxes.append((-math.pi, math.pi))
        else:
            s = max(10.0, 10 * abs(model.doc.initial.get(c, 0.0)))
            boxes.append((-s, s))
    for c in problem.rate_unknowns:
        box = search.get(c) or search.get(f"der({c})")
        if box is None:
            s = max(10.0, 3 * abs(model.doc.initial_rate.get(c, 0.0)))
            box = (-s, s)
        boxes.append(box)
    return boxes


#: Steady rates whose equations are not linear in them: starts spread log-uniformly over these magnitudes (times
#: max(1, |initial rate|)), both signs, so slow and fast steady motions are both reached.
RATE_DECADES = (-1.0, 3.0)


@dataclass
class SearchReport:
    """How the multistart search was done, for the output (text and JSON) whatever it found."""

    starts: int
    region: dict[str, tuple[float, float]]  # where the starts were drawn (angles: the whole circle)
    restricted: list[str]  # names whose box the user gave with --search (roots outside it are discarded)
    solved_rates: list[str]  # steady rates solved from their linear equations at every start
    spread_rates: list[str]  # steady rates drawn log-uniformly (RATE_DECADES)
    outside: list[str] = field(default_factory=list)  # "name = value" of roots beyond the default start boxes
    deflation: bool = True
    eliminated: list[str] = field(default_factory=list)  # solved from the holonomic constraints, not drawn

    def text(self) -> str:
        parts = []
        for name, (lo, hi) in self.region.items():
            if name in self.eliminated:
                parts.append(f"{name} solved from the holonomic constraints at each start")
            elif name in self.solved_rates:
                parts.append(f"{name} solved from its linear equation at each start")
            elif name in self.spread_rates:
                parts.append(f"|{name}| log-spread over [{lo:.4g}, {hi:.4g}], both signs")
            else:
                parts.append(f"{name} in [{lo:.4g}, {hi:.4g}]" + (" (--search)" if name in self.restricted else ""))
        text = f"deflated Newton from {self.starts} starts: {', '.join(parts) or 'no coordinate or rate to search'}"
        if self.outside:
            text += f"; roots beyond the start box (kept): {', '.join(self.outside)}"
        return text

    def to_dict(self) -> dict:
        return {"starts": self.starts, "region": {k: list(v) for k, v in self.region.items()},
                "restricted": self.restricted, "solved_rates": self.solved_rates, "spread_rates": self.spread_rates,
                "outside": self.outside, "deflation": self.deflation,
                **({"eliminated": self.eliminated} if self.eliminated else {})}


def search_plan(problem: EquilibriumProblem, search: dict | None, starts: int | None = None) -> SearchReport:
    boxes = _boxes(problem, search)
    search = search or {}
    names = list(problem.free) + [f"der({c})" for c in problem.rate_unknowns]
    eliminated = [c for c in getattr(problem, "eliminated", ()) if c in names and c not in search]
    count = starts if starts is not None else 24 + 24 * (len(boxes) - len(eliminated))
    given = [n for n, c in zip(names, list(problem.free) + list(problem.rate_unknowns)) if n in search or c in search]
    rates = [f"der({c})" for c in problem.rate_unknowns]
    solved = [r for r in rates if problem.linear_rates and r not in given]
    spread = [r for r in rates if not problem.linear_rates and r not in given]
    region = dict(zip(names, boxes))
    for r, c in zip(rates, problem.rate_unknowns):
        if r in spread:
            scale = max(1.0, abs(problem.model.doc.initial_rate.get(c, 0.0)))
            region[r] = (scale * 10 ** RATE_DECADES[0], scale * 10 ** RATE_DECADES[1])
    return SearchReport(count + 2, region, given, solved, spread, eliminated=eliminated)


def search_report(problem: EquilibriumProblem, search: dict | None, starts: int | None = None) -> str:
    """What the multistart search covered, in words (for messages that say what could not be found)."""
    return search_plan(problem, search, starts).text()


def _draw(plan: SearchReport, rng: np.random.Generator) -> np.ndarray:
    out = []
    for name, (lo, hi) in plan.region.items():
        if name in plan.eliminated:
            out.append(0.0)  # replaced by the projection onto the holonomic constraints
        elif name in plan.spread_rates:
            out.append(rng.choice((-1.0, 1.0)) * 10 ** rng.uniform(math.log10(lo), math.log10(hi)))
        else:
            out.append(rng.uniform(lo, hi))
    return np.array(out)


def solve_equilibria(problem: EquilibriumProblem, p: np.ndarray, search: dict | None = None, starts: int | None = None,
                     seed: int = 0, report: SearchReport | None = None) -> list[np.ndarray]:
    """All roots found from multistart deflated Newton inside the search box (multipliers start from lstsq)."""
    plan = search_plan(problem, search, starts) if report is None else report
    # remembered per problem (a sweep through the file's parameter values repeats the search equilibria made there)
    # and on disk (the next command on the model: modes after equilibria). The key is everything the search reads
    # besides the problem's equations; a stored root is used only when it verifies
    key = (np.asarray(p, dtype=float).tobytes(), tuple(sorted(problem.fixed_rates.items())),
           tuple(sorted(getattr(problem, "given", {}).items())), repr(sorted((search or {}).items())), plan.starts,
           repr(plan.region), seed)
    memo = problem.__dict__.setdefault("_searches", {})
    if key not in memo:
        disk = _disk_key(problem, key)
        stored = _stored_search(problem, p, disk)
        if stored is None:
            before, was = len(plan.outside), problem.undefined
            problem.undefined = False
            roots = _search(problem, p, plan, seed)
            stored = (roots, plan.outside[before:], problem.undefined)
            problem.undefined = problem.undefined or was
            plan.outside = plan.outside[:before]  # added back below, as from the memo
            _store_search(disk, stored)
        memo[key] = ([z.copy() for z in stored[0]], list(stored[1]), stored[2])
    roots, outside, undefined = memo[key]
    plan.outside += outside
    problem.undefined = problem.undefined or undefined  # the search met points where a force is not defined
    return [z.copy() for z in roots]


def _disk_key(problem: EquilibriumProblem, key: tuple) -> str | None:
    """The on-disk key of a search: the model's structure, names and code (cache.model_key: its code fingerprint
    covers this module and nonholonomic.py, the search's own code), the problem as posed (class, formulation,
    unknowns, split of a nonholonomic one), the starts' source (the file's initial values and rates) and every
    number of the in-memory key; None when the cache is off."""
    import hashlib
    import json

    from mechsys.numeric import cache

    if cache.cache_dir() is None:
        return None
    model = problem.model
    payload = {"model": cache.model_key(model, "steady-search"),
               "problem": type(problem).__name__, "method": str(getattr(problem, "method", "")),
               "unknowns": [str(u) for u in problem.unknowns],
               "free": list(problem.free), "rates": list(problem.rate_unknowns),
               "split": repr(getattr(problem, "split", None)),
               "angles": sorted(c for c, a in problem.angles.items() if a),
               "initial": sorted((str(k), float(v)) for k, v in model.doc.initial.items()),
               "initial_rate": sorted((str(k), float(v)) for k, v in model.doc.initial_rate.items()),
               "search": [key[0].hex(), *map(repr, key[1:])],
               # the compiled Newton (numeric/newton.c) and the Python loop differ in round-off, so a start may
               # end at another root: the search is kept per numeric path (and per compiler of the pieces)
               "newton": problem.newton_path}
    return hashlib.sha256(json.dumps(payload).encode()).hexdigest()[:32]


def _stored_search(problem: EquilibriumProblem, p: np.ndarray, disk: str | None):
    """(roots, outside, whether it met undefined forces) of a stored search, each root verified to be one (F = 0 as
    _polish accepts it); None when absent or when anything in it does not verify."""
    from mechsys.numeric import cache

    entry = cache.load(disk) if disk is not None else None
    if entry is None:
        return None
    try:
        roots = [np.array(r, dtype=float) for r in entry["roots"]]
        outside = [str(x) for x in entry["outside"]]
        undefined = entry["undefined"]
        if not isinstance(undefined, bool):
            return None
        for z in roots:
            if z.shape != (len(problem.unknowns),) or not np.all(np.isfinite(z)):
                return None
            if not _is_root(problem, z, p):
                return None
    except (KeyError, TypeError, ValueError, ArithmeticError):
        return None
    return roots, outside, undefined


def _store_search(disk: str | None, stored: tuple[list[np.ndarray], list[str], bool]) -> None:
    from mechsys.numeric import cache

    if disk is not None:
        cache.store(disk, {"roots": [[float(x) for x in z] for z in stored[0]], "outside": list(stored[1]),
                           "undefined": bool(stored[2])})


def _search(problem: EquilibriumProblem, p: np.ndarray, plan: SearchReport, seed: int) -> list[np.ndarray]:
    """solve_equilibria's multistart (plan.outside collects the roots beyond the default start boxes)."""
    boxes = list(plan.region.values())
    names = list(plan.region)
    given = [n in plan.restricted for n in names]
    default_box = _boxes(problem, None)
    nz = len(boxes)
    rng = np.random.default_rng(seed)
    count = plan.starts - 2
    candidates = []
    initial = [problem.model.doc.initial.get(c, 0.0) for c in problem.free] + [
        problem.model.doc.initial_rate.get(c, 0.0) for c in problem.rate_unknowns]
    candidates.append(np.array(initial, dtype=float))
    candidates.append(np.zeros(nz))
    for _ in range(count):
        candidates.append(_draw(plan, rng))
    roots: list[np.ndarray] = []
    jumps: list[np.ndarray] = []  # where the rest equations jump (drop_singular reports them): not deflated, a
    # spring of zero length's x = 0 repelled Newton from the rest at x = -0.1 (only x = 0.1 was found)
    for start in candidates:
        z = _newton(problem, problem.start(start, p), p, roots)
        if z is None:
            continue
        z = problem.normalize(z)
        if problem.non_smooth and problem.discontinuity(z, p):
            if is_new_root(problem, z, jumps):
                jumps.append(z)
            continue
        # a box the user gave (--search) restricts the answer; the default boxes only place the starts, so a root
        # Newton reaches outside them is kept (a steady speed of 12 rad/s was dropped by the default +-10 box)
        inside = all(lo - 1e-9 <= z[k] <= hi + 1e-9 or problem.is_angle()[k] or not given[k]
                     for k, (lo, hi) in enumerate(boxes))
        if not inside:
            continue
        if not is_new_root(problem, z, roots):
            continue
        roots.append(z)
        plan.outside += [f"{n} = {z[k]:.6g}" for k, (n, (lo, hi)) in enumerate(zip(names, default_box))
                         if not (given[k] or problem.is_angle()[k] or n in plan.solved_rates
                                 or n in plan.spread_rates or lo <= z[k] <= hi)]
    return roots + jumps


def drop_singular(problem: EquilibriumProblem, roots: list[np.ndarray], p: np.ndarray,
                  dropped: dict[str, list[np.ndarray]] | None = None) -> list[np.ndarray]:
    """The roots at which the coordinates the analysis eliminates are determined and the rest equations do not
    jump; the others (singular points of the model: no linearization, no continuation, no verdict there) are
    added to ``dropped`` by reason (see singular_note)."""
    kept = []
    for z in roots:
        why = problem.split_singularity(z, p) or problem.discontinuity(z, p) or loops.unbalanced(problem, z, p)
        if why is None:
            kept.append(z)
        elif dropped is not None:
            dropped.setdefault(why, []).append(z)
    return kept


def singular_note(problem: EquilibriumProblem, dropped: dict[str, list[np.ndarray]], what: str = "listed") -> str:
    """What drop_singular left out, in words, with one example."""
    notes = []
    for why, zs in dropped.items():
        where = ", ".join(f"{c} = {wrap(v) if problem.angles.get(c, False) else v:.6g}"
                          for c, v in zip(problem.free, zs[0]))
        if why in (loops.UNBALANCED, loops.ROUNDING):
            notes.append(f"{len(zs)} root(s) where {why} (e.g. {where}) are not rests: the multipliers grow without "
                         f"bound there and F vanishes only to their rounding; not {what}")
            continue
        kind = "points where the equations of motion are not smooth" if why in _JUMPS else \
            "coordinate singularities of the model"
        notes.append(f"{len(zs)} root(s) where {why} (e.g. {where}) are {kind}, not steady motions one can "
                     f"linearize about: not {what}")
    return "; ".join(notes)


def is_new_root(problem: EquilibriumProblem, z: np.ndarray, roots: list[np.ndarray]) -> bool:
    """z is not a root already found: none closer than 1e-7 (1 + |z|) in the coordinates and rates (angles on the
    circle)."""
    if not len(roots):
        return True
    size = float(np.linalg.norm(z[: problem.nq + len(problem.rate_unknowns)]))
    return not bool(np.any(problem.distances(z, np.asarray(roots)) < 1e-7 * (1 + size)))


def _multiplier_guess(problem: EquilibriumProblem, start: np.ndarray, p: np.ndarray) -> np.ndarray:
    if not problem.m:
        return np.zeros(0)
    z = np.concatenate([start, np.zeros(problem.m)])
    F0 = problem.F(z, p)[: len(problem.model.coordinates)]
    J = problem.J(z, p)[: len(problem.model.coordinates), -problem.m:]
    return np.linalg.lstsq(J, -F0, rcond=None)[0]


@dataclass
class SteadyOptions:
    """How the steady motions of a nonholonomic system are posed (analysis/equilibrium/nonholonomic.py): coordinates held at
    their file values (--given), given rates of families freed as unknowns (--solve), coordinates whose rates
    must be independent speeds (--independent)."""

    given: list[str] = field(default_factory=list)
    solve: list[str] = field(default_factory=list)
    independent: list[str] = field(default_factory=list)

    def __bool__(self) -> bool:
        return bool(self.given or self.solve or self.independent)


def make_problem(model: MechanicalModel, options: SteadyOptions | None = None) -> EquilibriumProblem:
    """The steady-motion equations of a model: holonomic (this module) or with velocity constraints
    (analysis/equilibrium/nonholonomic.py)."""
    options = options or SteadyOptions()
    if model.is_holonomic:
        if options:
            raise InputError("--given, --solve and --independent pose the steady motions of nonholonomic systems "
                             "(velocity constraints such as rolling); this model is holonomic")
        return EquilibriumProblem(model)
    from mechsys.analysis.equilibrium.nonholonomic import NonholonomicProblem

    return NonholonomicProblem(model, options.given, options.solve, options.independent)


def find_equilibria(model: MechanicalModel, search: dict[str, tuple[float, float]] | None = None,
                    starts: int | None = None, seed: int = 0, exhaustive: bool = False,
                    options: SteadyOptions | None = None) -> EquilibriaResult:
    """Equilibria (and steady motions of cyclic coordinates) with their Lyapunov stability. exhaustive: every
    isolated root of polynomial sin/cos equations (analysis/equilibrium/exhaustive.py) instead of the multistart (search is
    then not used)."""
    from mechsys.analysis.equilibrium.stability import assess_all

    problem = make_problem(model, options)
    if exhaustive and not model.is_holonomic:
        raise InputError("--exhaustive is not available for nonholonomic systems (the steady-motion equations "
                         "carry accelerations and multipliers); use the multistart search")
    p = parameter_values(model)
    if not problem.unknowns:
        return _every_state(problem, p, search)
    exact = None
    if exhaustive:
        from mechsys.analysis.equilibrium.exhaustive import exhaustive_search

        roots, plan, exact = exhaustive_search(problem, p, starts, seed)
    else:
        plan = search_plan(problem, search, starts)
        roots = solve_equilibria(problem, p, search, starts, seed, plan)
    from mechsys.analysis.equilibrium.charts import mark_unchartable, review

    dropped: dict[str, list[np.ndarray]] = {}
    roots = loops.merge_branch_points(problem, drop_singular(problem, roots, p, dropped), p)
    message = ""
    isolated, families = [], []
    for z in roots:
        # (at a gimbal lock the chart, not the physics, makes roots a continuum: charts.py)
        (isolated if is_isolated(problem, z, p) else families).append(z)
    if families:
        families = continua(problem, families, p)
        isolated += families
        message = ("the equilibria are not isolated (singular Jacobian: e.g. a free rigid-body motion); "
                   + ("one representative of the continuum is shown" if len(families) == 1 else
                      f"one representative of each of {len(families)} continua is shown"))
    equilibria = [problem.equilibrium(z) for z in isolated]
    assess_all(problem, equilibria, p)
    for z, e in zip(isolated, equilibria):
        e.branch = loops.branch_point(problem, z, p) or ""
        if e.branch:
            e.stability, e.critical, e.reason = "undecided", False, e.branch
    equilibria, chart_note = (review if model.is_holonomic else mark_unchartable)(problem, equilibria, p)
    undefined = ("the forces are not defined at some points the search met (a log or square root of a negative "
                 "number, a division by zero): no root is found there or at the edge of their domain"
                 if problem.undefined else "")
    unreduced = getattr(problem, "unreduced", [])
    unreduced = (f"with constraints the cyclic coordinate(s) {', '.join(unreduced)} are not reduced: only states "
                 f"at rest are sought, not steady motions at a constant rate of {', '.join(unreduced)} "
                 f"(equilibria.md §2.3; `simulate` follows such a motion)" if unreduced else "")
    message = "; ".join(m for m in (message, chart_note, singular_note(problem, dropped), undefined, unreduced) if m)
    equilibria.sort(key=_order)
    if not equilibria:
        message = (f"no equilibrium found: {plan.text()}; widen it with --search" if plan is not None
                   else "no equilibrium: the equations have no real root (exhaustive search)")
        message = "; ".join(m for m in (message, undefined, unreduced) if m)
    split = getattr(problem, "split", None)
    return EquilibriaResult(equilibria, message, problem.cyclic, dict(problem.fixed_rates), plan, exact,
                            split.text() if split is not None else "", problem)


def _order(e: Equilibrium) -> tuple:
    """The listing order: by coordinates, then rates, each rounded to 9 significant digits first, so that roots
    one rounding apart in a coordinate are ordered by the next one (a sweep's eq1 and eq2 swapped between rows
    where their first coordinate differed by one ulp)."""
    return tuple(float(f"{v:.9g}") for v in (*e.coordinates.values(), *e.rates.values()))


def is_isolated(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray) -> bool:
    """The root z is isolated: its Jacobian (unit columns and rows) has no null direction that moves the coordinates
    or rates (one of the multipliers alone is a redundant constraint row), or its rank loss is a gimbal lock of the
    chart (charts.py), not a continuum of steady motions (a free heading, a free rigid-body motion)."""
    from mechsys.analysis.equilibrium.charts import singularities

    motions = _motions(problem, z, p)
    return (not motions.size or bool(singularities(problem.model, problem.equilibrium(z).coordinates, p))
            or not _continues(problem, z, p, motions))


def degenerate_root(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray) -> bool:
    """Whether the root z may be a degenerate root found off by its accuracy: along the Jacobian's weakest direction
    that moves the coordinates or rates (v, left vector w, in the unknowns' and equations' own sizes), the point
    where w^T J v vanishes (three Newton steps along v) fits the equations as well as z does (to 10 times its
    residual; no floor: a soft spring's exact rest is no double root). Newton finds a double
    root only to ~1e-8 (F ~ c (x - x*)**2), where the stiffness takes the sign of the side it lands on: x = +-2 of
    F = -x (x**2 - b**2) (x**2 - 4)**2 were 'stable (strict minimum)', where the force pushes away on one side."""
    rows, sizes = small_scales(problem, p)

    def scaled_J(y: np.ndarray) -> np.ndarray:
        return problem.J(y, p) / rows[:, None] * sizes

    J = scaled_J(z)
    if not J.size or J.shape[0] < J.shape[1] or not np.all(np.isfinite(J)):
        return False
    U, S, Vt = np.linalg.svd(J)
    k = problem.nq + len(problem.rate_unknowns)
    # the weakest direction that moves the coordinates or rates (one in the multipliers alone is a redundant
    # constraint row: lambda not unique, the rest regular)
    weakest = next((j for j in range(len(S) - 1, -1, -1) if np.linalg.norm(Vt[j, :k]) >= 1e-3), None)
    if weakest is None:
        return False
    w, v = U[:, weakest], Vt[weakest]
    h = 1e-6 * (1.0 + float(np.linalg.norm(z / sizes)))

    def g(x: float) -> float:  # the weakest singular value along v, signed
        return float(w @ scaled_J(z + x * sizes * v) @ v)

    x = 0.0
    for _ in range(3):  # Newton on g along v (a central difference of its slope)
        slope = (g(x + h) - g(x - h)) / (2 * h)
        if not np.isfinite(slope) or slope == 0:
            return False
        x -= g(x) / slope
    F0, Fd = (float(np.max(np.abs(problem.F(y, p) / rows))) for y in (z, z + x * sizes * v))
    # (no floor: a soft spring's exact rest, F = 0, beside a singular point where F = 2e-14 is no double root)
    return bool(np.isfinite(Fd) and Fd <= 10.0 * F0)


def _continues(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray, motions: np.ndarray) -> bool:
    """Whether the roots go on from z along one of its null directions (``motions``): from z moved 1e-3 along it
    (in the unknowns' own sizes), Newton with that component held finds a root. A double root of an isolated rest
    does not (V' = x (x - 1)**2 at x = 1: its Jacobian is singular, and it was listed as 'a continuum')."""
    rows, sizes = small_scales(problem, p)
    k = motions.shape[1]
    for b in motions:
        d = np.zeros(len(z))
        d[:k] = b
        d_own = d / sizes
        d_own /= np.linalg.norm(d_own)
        y = z + 1e-3 * (1.0 + float(np.linalg.norm(z / sizes))) * sizes * d_own
        for _ in range(12):
            F, J = problem.F(y, p), problem.J(y, p)
            if not (np.all(np.isfinite(F)) and np.all(np.isfinite(J))):
                break
            held = np.vstack([J / rows[:, None] * sizes, d_own])
            step = sizes * np.linalg.lstsq(held, np.concatenate([-F / rows, [0.0]]), rcond=None)[0]
            y = y + step
            if np.linalg.norm(step / sizes, np.inf) < 1e-14 * (1 + np.linalg.norm(y / sizes, np.inf)):
                break
        if _is_root(problem, y, p):
            return True
    return False


def _motions(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray) -> np.ndarray:
    """An orthonormal basis (rows) of the directions in the coordinates and rates along which the root z continues
    as roots to first order: the null space of its Jacobian (unit columns and rows) projected on them; empty where
    z is isolated. A null direction of the multipliers alone is a redundant constraint row (lambda not unique),
    not a continuum."""
    J = problem.J(z, p)
    if not J.size:
        return np.zeros((0, len(z)))
    # first in the equations' and unknowns' own sizes: one pass of unit columns and rows leaves a MEMS four-bar's
    # stiffness (1e-17 N m beside its loop rows' 1e-5 m) at 1e-12 and called its equilibria 'not isolated'
    rows, sizes = small_scales(problem, p)
    J = J / rows[:, None] * sizes
    columns = np.linalg.norm(J, axis=0)
    # a column of rounding (a ball's orientation at rest: 1e-16 beside 1) is a zero column: scaled to unit length it
    # was a direction like any other, and the null vectors came out 1e16 times its size
    J[:, columns <= 1e-12 * max(float(np.max(columns, initial=0.0)), 1e-300)] = 0.0
    columns = np.linalg.norm(J, axis=0)
    columns[columns == 0] = 1.0  # a zero column: its unit vector is a null vector either way
    _, sv, Vt = np.linalg.svd(_equilibrated(J))
    sv = np.concatenate([sv, np.zeros(J.shape[1] - sv.size)])
    null = Vt[sv <= 1e-9 * max(1.0, sv[0])] / columns * sizes  # null vectors of J itself (the scalings undone)
    null /= np.linalg.norm(null, axis=1, keepdims=True)  # each to unit size: a direction counts by its own size
    moves = null[:, : problem.nq + len(problem.rate_unknowns)]
    if not moves.size:
        return moves
    _, S, Wt = np.linalg.svd(moves, full_matrices=False)
    return Wt[S > 1e-6]


def continua(problem: EquilibriumProblem, roots: list[np.ndarray], p: np.ndarray) -> list[np.ndarray]:
    """One representative of each continuum among roots that are not isolated: a root joins the first kept one
    whose tangent space (_motions) holds their difference (angles on the circle), to 1e-6 of it. A pendulum beside
    a free flywheel rests hanging and upright at every flywheel angle: two continua, both listed (only the first
    was, and the upright pendulum disappeared)."""
    kept: list[tuple[np.ndarray, np.ndarray]] = []
    for z in roots:
        if not any(_along(problem, z, r, basis) for r, basis in kept):
            kept.append((z, _motions(problem, z, p)))
    return [z for z, _ in kept]


def _along(problem: EquilibriumProblem, z: np.ndarray, r: np.ndarray, basis: np.ndarray) -> bool:
    """z - r lies in the span of ``basis`` (rows, orthonormal) to 1e-6 of its size, up to whole turns of the angles:
    a winch's drum and gears turn together at their ratios, so two of its rests far along the line differ by the
    line's direction minus turns the wrapping took off (the integer turns by least squares, then rounded)."""
    k = problem.nq + len(problem.rate_unknowns)
    d = (z - r)[:k]
    ang = np.flatnonzero(problem.is_angle()[:k])
    d[ang] -= 2 * math.pi * np.rint(d[ang] / (2 * math.pi))

    def off(x: np.ndarray) -> np.ndarray:
        return x - basis.T @ (basis @ x) if basis.size else x

    tol = 1e-6 * (1 + np.linalg.norm(d))
    if np.linalg.norm(off(d)) <= tol:
        return True
    if not len(ang):
        return False
    turns = np.zeros((k, len(ang)))
    turns[ang, np.arange(len(ang))] = 2 * math.pi
    shifts = np.rint(np.linalg.lstsq(np.column_stack([off(c) for c in turns.T]), off(d), rcond=None)[0])
    return bool(np.linalg.norm(off(d - turns @ shifts)) <= tol)


def _equilibrated(J: np.ndarray) -> np.ndarray:
    """J with unit columns, then unit rows: the same rank, but a conditioning that does not depend on the units of
    the unknowns (a bicycle's multipliers are hundreds of newtons, its angles radians)."""
    if not J.size:
        return J
    J = J / np.maximum(np.linalg.norm(J, axis=0), 1e-300)
    return J / np.maximum(np.linalg.norm(J, axis=1), 1e-300)[:, None]


def _every_state(problem: EquilibriumProblem, p: np.ndarray, search: dict | None) -> EquilibriaResult:
    """No unknowns: every coordinate is cyclic and nothing acts on it at rest (free carriages, a free rotor), so
    each configuration is a steady motion at the rates the file gives (an equilibrium when they are zero). One
    representative, its stability (of the rates), and a message that says so."""
    from mechsys.analysis.equilibrium.stability import assess

    _boxes(problem, search)  # an unknown --search name is still an input error
    model = problem.model
    if not model.coordinates:
        return EquilibriaResult([], "the model has no free coordinates: there is nothing to find")
    e = problem.equilibrium(np.zeros(0))
    assess(problem, e, p)
    rates = ", ".join(f"der({c}) = {v:g}" for c, v in problem.fixed_rates.items())
    if any(v != 0 for v in problem.fixed_rates.values()):
        what = (f"every configuration is a steady motion at the initial rates ({rates}); with all rates zero every "
                "configuration is an equilibrium")
    else:
        what = f"every configuration is an equilibrium ({rates})"
    message = (f"no generalized force acts at rest on any coordinate ({', '.join(model.coordinates)} are all cyclic): "
               f"{what}; the equilibria are not isolated, one representative is shown")
    return EquilibriaResult([e], message, problem.cyclic, dict(problem.fixed_rates))

