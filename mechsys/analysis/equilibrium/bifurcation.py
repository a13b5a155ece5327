"""Equilibrium branches of a model as one parameter varies: continuation, stability and bifurcation points."""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable

import numpy as np
import sympy as sp

from mechsys.analysis.equilibrium.continuation import Bifurcation, Branch, Undefined, sweep_parameter
from mechsys.analysis.equilibrium.equilibria import (Equilibrium, EquilibriumProblem, drop_singular, is_isolated,
                                                     make_problem, singular_note, solve_equilibria, wrap)
from mechsys.analysis.equilibrium.stability import ZERO_RE, assess, pencil_eigenvalues
from mechsys.errors import AnalysisError, InputError
from mechsys.mechanics.model import MechanicalModel
from mechsys.numeric.lambdify import compile_exprs
from mechsys.numeric.parallel import fork_map
from mechsys.numeric.parameters import parameter_values

if TYPE_CHECKING:
    from mechsys.analysis.equilibrium.continuation import Compiled
    from mechsys.analysis.equilibrium.equilibria import SteadyOptions


@dataclass
class SweepResult:
    parameter: str
    names: list[str]  # unknowns reported: coordinates, then der(cyclic)
    angles: list[bool]
    branches: list[Branch]
    bifurcations: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def rows(self) -> list[list]:
        """(branch, parameter value, coordinates..., stable, verdict) for every continuation point."""
        out = []
        for b, branch in enumerate(self.branches, start=1):
            for pt in branch.points:
                vals = [wrap(v) if a else float(v) for v, a in zip(pt.x[: len(self.names)], self.angles)]
                out.append([b, float(pt.p), *vals, bool(pt.stable), pt.verdict])
        return out


def _dependence(model: MechanicalModel, name: str) -> tuple[sp.Symbol, dict[sp.Symbol, sp.Expr]]:
    """The swept parameter's symbol and every parameter as an expression of it (derived ones follow it)."""
    doc = model.doc
    if name not in doc.parameters:
        raise InputError(f"--sweep {name}: unknown parameter{doc.suggest(name, list(doc.parameters))}")
    base = doc.parameters[name]
    full: dict[sp.Symbol, sp.Expr] = {}
    for pname, expr in doc.parameter_exprs.items():
        sym = doc.parameters[pname]
        full[sym] = base if pname == name else expr.xreplace(full)
    return base, full


def parameter_sensitivity(model: MechanicalModel, name: str) -> Callable[[np.ndarray], np.ndarray]:
    """d(parameter vector)/d(name) as a function of the parameter vector: derived parameters follow the swept one
    (exact, from their expressions; compiled once, as continuation asks at every step)."""
    base, full = _dependence(model, name)
    syms = model.parameter_symbols
    derivs = [sp.sympify(sp.diff(full[s], base)) for s in syms]
    if all(d.is_number for d in derivs):
        constant = np.array([float(d) for d in derivs])
        return lambda P: constant
    fn = compile_exprs(derivs, syms)
    return lambda P: np.array(fn(*P), dtype=float)


def _given_rates(problem: EquilibriumProblem) -> list[sp.Expr]:
    """The given rates of the families of steady motions as expressions of the parameters (the file's ``rate:``),
    or as numbers where the model's rate no longer is that expression's value (set after loading)."""
    model = problem.model
    doc = model.doc
    nominal = {s: sp.Float(v) for s, v in zip(model.parameter_symbols, parameter_values(model))}
    out: list[sp.Expr] = []
    for c in problem.fixed_rates:
        value = doc.initial_rate[c]  # the model's, not the problem's (a sweep moves those)
        expr: sp.Expr = sp.Float(value)
        spec = doc.spec.coordinates.get(c)
        if spec is not None and spec.prescribed is None:
            try:
                given = doc.parse(spec.rate, ("coordinates", c, "rate"), "initial")
                if abs(float(sp.sympify(given).xreplace(nominal).evalf()) - value) <= 1e-12 * (1.0 + abs(value)):
                    expr = given
            except (InputError, TypeError, ValueError):
                pass
        out.append(expr)
    return out


@dataclass
class SweptParameter:
    """What ``--sweep NAME`` varies: a parameter (the parameters defined from it and the given rates of families
    of steady motions whose ``rate:`` uses it follow it), or ``der(NAME)``, the given rate of a family of steady
    motions of the cyclic coordinate NAME. ``at(p)`` puts the problem there (its given rates, and the parameters
    the stability tests read) and returns the parameter vector P. The derivatives take (p, P)."""

    name: str
    problem: EquilibriumProblem
    pvec: Callable[[float], np.ndarray]
    dpvec: Callable[[float, np.ndarray], np.ndarray]
    rates: Callable[[float, np.ndarray], np.ndarray]   # the given rates, problem.fixed_rates order
    drates: Callable[[float, np.ndarray], np.ndarray]
    affine: bool = False  # the parameter vector and the given rates are affine in p (dpvec, drates constant)

    def at(self, p: float) -> np.ndarray:
        last = self.__dict__.get("_last")
        if last is None or last[0] != p:  # F, its Jacobian and dF/dp of one point ask for the same p
            P = self.pvec(p)
            last = self.__dict__["_last"] = (p, P, [float(r) for r in self.rates(p, P)])
        _, P, rates = last
        fixed = self.problem.fixed_rates
        fixed.update(zip(list(fixed), rates))
        self.problem.current_parameters = P
        return P

    def Fp(self, z: np.ndarray, p: float) -> np.ndarray:
        P = self.at(p)
        along = getattr(self.problem, "Fp_along", None)  # a problem whose Fp is numeric: one direction only
        out = along(z, P, self.dpvec(p, P)) if along is not None else self.problem.Fp(z, P) @ self.dpvec(p, P)
        dr = self.drates(p, P)
        if np.any(dr):
            out = out + self.problem.Fr(z, P) @ dr
        return out


_RATE = re.compile(r"der\(\s*([A-Za-z_][A-Za-z_0-9]*)\s*\)")
AUX_ARC_WEIGHT = 1e3  # an auxiliary unknown (dependent rate, acceleration, multiplier) counts 1e-3 in the arclength


def swept_parameter(problem: EquilibriumProblem, name: str) -> SweptParameter:
    """The continuation parameter named by ``--sweep NAME`` (InputError when it cannot be one)."""
    model = problem.model
    m = _RATE.fullmatch(name.strip())
    if m:
        return _rate_parameter(problem, m.group(1))
    base, full = _dependence(model, name)
    sens = parameter_sensitivity(model, name)
    syms = model.parameter_symbols
    exprs = _given_rates(problem)
    value = compile_exprs(exprs, syms) if exprs else None
    slope = [sp.diff(sp.sympify(e).xreplace(full), base) for e in exprs]
    dvalue = compile_exprs(slope, syms) if any(d != 0 for d in slope) else None
    affine = all(sp.sympify(d).is_number for d in [*slope, *(sp.diff(full[s], base) for s in syms)])
    memo: dict[float, np.ndarray] = {}

    def pvec(p: float) -> np.ndarray:
        if p not in memo:  # one entry: F, J, dF/dp and the eigenvalues of one point share it
            memo.clear()
            memo[p] = parameter_values(model, {name: p})
        return memo[p]

    return SweptParameter(name, problem, pvec, lambda p, P: sens(P),
                          lambda p, P: np.array(value(*P) if value else [], dtype=float),
                          lambda p, P: np.array(dvalue(*P), dtype=float) if dvalue else np.zeros(len(exprs)),
                          affine)


def _rate_parameter(problem: EquilibriumProblem, coord: str) -> SweptParameter:
    """der(coord) swept: allowed only for the given rate of a family of steady motions."""
    model = problem.model
    name = f"der({coord})"
    if coord not in model.coordinates:
        raise InputError(f"--sweep {name}: unknown coordinate{model.doc.suggest(coord, model.coordinates)}")
    if coord in problem.rate_unknowns:
        raise InputError(f"--sweep {name}: the steady rate of the cyclic coordinate {coord} is an unknown that the "
                         f"equations of the steady motions fix (a generalized force acts on {coord} at rest, e.g. a "
                         "motor's torque balance), not a parameter; sweep a parameter of that force instead")
    if coord not in problem.fixed_rates:
        why = " (no coordinate of a constrained system is treated as cyclic)" if model.kin.constraints else ""
        raise InputError(f"--sweep {name}: {coord} is not a cyclic coordinate{why}, so its rate is zero at every "
                         "equilibrium; only the given rate of a family of steady motions of a cyclic coordinate "
                         "can be swept")
    k = list(problem.fixed_rates).index(coord)
    P = parameter_values(model)
    base = np.array([model.doc.initial_rate[c] for c in problem.fixed_rates], dtype=float)
    unit = np.zeros(len(base))
    unit[k] = 1.0

    def given(p: float, P: np.ndarray) -> np.ndarray:
        out = base.copy()
        out[k] = p
        return out

    return SweptParameter(name, problem, lambda p: P, lambda p, P: np.zeros(len(P)), given, lambda p, P: unit, True)


@dataclass
class SweptSystem:
    """A sweep's equations as continuation sees them: F(x, p) = E(D x, P(p))[rows], x the problem's unknowns divided
    by D (``sweep`` scales the auxiliary ones down), ``rows`` a square subset of the equations, p the swept value;
    ``eig`` raises Undefined where the linearization is not defined (the branch ends there, with the reason)."""

    problem: EquilibriumProblem
    par: SweptParameter
    D: np.ndarray
    rows: list[int] | slice = field(default_factory=lambda: slice(None))

    def F(self, z: np.ndarray, p: float) -> np.ndarray:
        return self.problem.F(self.D * z, self.par.at(p))[self.rows]

    def Fx(self, z: np.ndarray, p: float) -> np.ndarray:
        return self.problem.J(self.D * z, self.par.at(p))[self.rows] * self.D

    def Fp(self, z: np.ndarray, p: float) -> np.ndarray:
        return self.par.Fp(self.D * z, p)[self.rows]

    def eig(self, z: np.ndarray, p: float) -> np.ndarray:
        z = self.D * z
        self.par.at(p)
        try:
            return pencil_eigenvalues(self.problem, self.problem.equilibrium(z))
        except AnalysisError as exc:  # e.g. a singular saddle-point system: the branch ends here, with the reason
            raise Undefined(str(exc)) from None

    def compiled(self, starts: list[tuple[np.ndarray, float]]) -> Compiled | None:
        """The continuation's compiled corrector for F, Fx and Fp (a factory, see continuation.Compiled), where the
        problem has one and the swept p moves its arguments affinely; None otherwise (the Python loop)."""
        make = getattr(self.problem, "compiled_corrector", None)
        if make is None or not self.par.affine or not starts:
            return None
        p_ref = float(starts[0][1])
        P = self.par.at(p_ref)
        return make(p_ref, P, self.par.dpvec(p_ref, P), self.par.drates(p_ref, P), self.D, self.rows)


def sweep(model: MechanicalModel, name: str, start: float, stop: float, points: int = 101,
          search: dict | None = None, options: SteadyOptions | None = None,
          problem: EquilibriumProblem | None = None) -> SweepResult:
    """Follow every equilibrium branch found at the ends and the middle of [start, stop] by pseudo-arclength
    continuation; stability from the eigenvalues; folds, branch points, Hopf points and eigenvalue collisions on
    the imaginary axis located on the way. NAME is a parameter or der(NAME) of a family of steady motions.
    ``problem``: make_problem(model, options) already used (an EquilibriaResult's), whose searches are reused."""
    if start == stop:
        raise InputError(f"--sweep {name}: START and STOP must differ")
    problem = make_problem(model, options) if problem is None else problem
    par = swept_parameter(problem, name)
    name = par.name  # der(NAME) spelled without spaces
    lo, hi = min(start, stop), max(start, stop)

    # continuation measures arclength in the unknowns it is given: auxiliary unknowns of large size (a bicycle's
    # multipliers, hundreds of newtons) would shrink its steps in the parameter, so a problem may scale them down
    # (the unknowns the branches report are never scaled); and as they can grow by orders of magnitude along a
    # branch (multipliers with the square of a growing yaw rate), they are also weighted down in the arclength
    # (they follow from the reported unknowns; Newton still solves them to the full tolerance). The rows continued
    # on (a square system) are chosen below
    system = SweptSystem(problem, par, np.ones(len(problem.unknowns)))
    F, Fx, Fp = system.F, system.Fx, system.Fp

    starts = []
    undefined = []
    singular: dict[str, list[np.ndarray]] = {}
    samples = np.linspace(lo, hi, 5)  # branches born inside the range need a start of their own
    if hasattr(problem, "periodic_over"):
        problem.periodic_over([par.at(v) for v in samples])

    def multistart(k: int) -> list[np.ndarray] | str:
        problem.undefined = False
        try:
            found = solve_equilibria(problem, par.at(samples[k]), search)
        except (ValueError, ArithmeticError) as exc:  # e.g. sqrt of a negative parameter: math domain error
            return str(exc)
        # F and J answer NaN where a force is not defined; defined nowhere the search looked: no start here
        return "a force is not defined there" if problem.undefined and not found else found

    continua: list[float] = []  # sample values with roots that are not isolated
    for p, found in zip(samples, fork_map(multistart, len(samples))):  # independent: one worker each
        if isinstance(found, str):
            undefined.append(f"{name} = {p:g} ({found})")
        else:
            for z in drop_singular(problem, found, par.at(p), singular):
                # a continuum of steady motions (a free heading): its Jacobian is singular everywhere, so the
                # branch's tangent is not determined and every sign change of the determinant is noise (a
                # Chaplygin sleigh's sweep reported 359 branch points and folds)
                if is_isolated(problem, z, par.at(p)):
                    starts.append((z, float(p)))
                elif p not in continua:
                    continua.append(float(p))
    span = hi - lo if hi > lo else 1.0
    step = span / max(points - 1, 1)
    if starts:
        system.rows = _independent_rows(problem.J(starts[0][0], par.at(starts[0][1])))

    def smooth(z: np.ndarray, p: float) -> bool:
        try:
            return all(bool(np.all(np.isfinite(v))) for v in (F(z, p), Fx(z, p), Fp(z, p)))
        except (ValueError, ArithmeticError):
            return False

    scale = getattr(problem, "auxiliary_scale", None)
    arc = None  # the arclength weights: auxiliary unknowns count 1/AUX_ARC_WEIGHT of a reported one
    if scale is not None and starts:
        system.D = scale([z for z, _ in starts])
        starts = [(z / system.D, p) for z, p in starts]
        arc = np.where(np.arange(len(system.D)) >= len(problem.free) + len(problem.rate_unknowns), AUX_ARC_WEIGHT,
                       1.0)
    keep = [smooth(z, p) for z, p in starts]  # not smooth: e.g. d sqrt(mu)/d mu at mu = 0
    undefined += [f"{name} = {p:g} (the derivatives of the equations are not finite there)"
                  for p in sorted({p for (_, p), ok in zip(starts, keep) if not ok})]
    starts = [st for st, ok in zip(starts, keep) if ok]
    # the step limit grows with the points asked for (a branch needs at least points - 1 steps to cross the range)
    skipped: list[tuple[float, str]] = []
    try:
        # the point verdicts below read the linearizations the continuation's eigenvalues computed (in workers)
        share = ((problem.take_linearizations, problem.give_linearizations)
                 if hasattr(problem, "take_linearizations") else None)
        branches = sweep_parameter(F, Fx, Fp, starts, lo, hi, system.eig, skipped=skipped, share=share,
                                   compiled=system.compiled(starts), ds=step / 2,
                                   ds_max=min(step, 0.2 * max(span, 1.0)), tol_re=ZERO_RE * 10,
                                   max_steps=max(2000, 20 * points), x_scale=arc,
                                   tol_scale=None if arc is None else np.ones(len(arc))) if starts else []
    except (ValueError, ArithmeticError) as exc:
        raise AnalysisError(f"--sweep {name}: {exc}") from None
    for branch in branches:  # back to the problem's unknowns
        for pt in branch.points:
            pt.x = system.D * pt.x
        for bif in branch.bifurcations:
            bif.x = system.D * bif.x
    artefacts = {id(b) for b in _review(problem, branches, par.at, name)}
    for branch in branches:
        if id(branch) not in artefacts:
            branch.bifurcations += _changes_at_locks(problem, branch, par.at)
    states: dict = {}  # physical states of branch points, shared by the pairs compared
    twins = {id(b) for k, b in enumerate(branches) if id(b) not in artefacts
             and any(id(a) not in artefacts and _same_family(problem, a, b, par.at, states) for a in branches[:k])}
    branches = [b for b in branches if id(b) not in artefacts | twins]
    nreport = len(problem.free) + len(problem.rate_unknowns)
    names = list(problem.free) + [f"der({c})" for c in problem.rate_unknowns]
    angles = [problem.angles.get(c, False) for c in problem.free] + [False] * len(problem.rate_unknowns)
    result = SweepResult(name, names, angles, branches)
    if undefined:
        result.notes.append(f"the equations cannot be evaluated at {', '.join(undefined)}: no branch starts there")
    if continua:
        result.notes.append(f"the steady motions found at {name} = {', '.join(f'{v:g}' for v in continua)} are not "
                            "isolated (singular Jacobian: a continuum, e.g. a free heading or a free rigid-body "
                            "motion), so they are not continued: continuation follows isolated branches only")
    if singular:
        result.notes.append(f"starts at {name} = {', '.join(f'{v:g}' for v in np.linspace(lo, hi, 5))}: "
                            + singular_note(problem, singular, "continued"))
    if artefacts:
        result.notes.append(f"{len(artefacts)} branch(es) at a gimbal-lock point are no steady motions in a regular "
                            "chart (artefacts of the singular angles) and are not listed")
    if twins:
        result.notes.append(f"{len(twins)} branch(es) repeated another one in other angles (the same physical steady "
                            "motions) and are not listed")
    cut = [k for k, branch in enumerate(branches, start=1) if branch.truncated]
    if cut:
        result.notes.append(f"branch(es) {', '.join(map(str, cut))} ended at the step limit ({max(2000, 20 * points)} "
                            "steps) inside the range: they are incomplete, and a start found on their untraced part "
                            "may appear as a further branch (use fewer points or a narrower range)")
    for p0, why in skipped:
        result.notes.append(f"a steady motion found at {name} = {p0:g} is not continued: its linearization is not "
                            f"defined ({why})")
    for k, branch in enumerate(branches, start=1):
        for v, why in branch.undefined:
            where = "inside the range" if lo < v < hi else "at the end of the range,"
            result.notes.append(f"branch {k} ends {where} at {name} = {v:.6g}: the linearization is not defined "
                                f"there ({why}), so neither stability nor bifurcations are followed to that point")
        inside = [v for v in branch.stalled if lo < v < hi]
        if inside:
            where = " and ".join(f"{name} = {v:.6g}" for v in inside)
            result.notes.append(f"branch {k} ends inside the range at {where}: the Newton corrector did not converge "
                                "even with the smallest step, so the continuation cannot pass that point "
                                "(the equations are not smooth or not defined beyond it)")
    events = []
    for branch in branches:
        for bif in branch.bifurcations:
            refined = False
            if bif.kind in ("branch_point", "zero_eigenvalue"):
                p_arc = bif.p
                bif.p, bif.x = _refine_singular(problem, par, system.rows, bif.p, bif.x, step)
                refined = bif.p != p_arc
            coords = {n: (wrap(v) if a else float(v)) for n, v, a in zip(names, bif.x[:nreport], angles)}
            events.append({"kind": bif.kind, "parameter": name, "value": float(bif.p), "coordinates": coords,
                           "refined": refined})
    result.bifurcations = _merge_events(events, angles, step)
    # events at the same value to 9 digits (mirror images: a bicycle leaning left and right) are ordered by kind
    # and coordinates, not by the round-off in their values
    result.bifurcations.sort(key=lambda b: (float(f"{b['value']:.9g}"), b["kind"],
                                            tuple(round(v, 6) for v in b["coordinates"].values()), b["value"]))
    return result


def _independent_rows(J: np.ndarray) -> list[int]:
    """As many independent equations as there are unknowns (QR with column pivoting of J^T). The equilibrium
    equations are over-determined when a cyclic coordinate's rate is given (a family of steady motions): its
    equation then holds identically, and continuation needs a square system."""
    from scipy.linalg import qr

    m, n = J.shape
    if m <= n:
        return list(range(m))
    _, _, pivots = qr(J.T, pivoting=True, mode="economic")
    return sorted(int(k) for k in pivots[:n])


def _residual_error(problem: EquilibriumProblem, branch: Branch, at, name: str, k: int) -> str | None:
    """Every continued point must satisfy ALL equilibrium equations, not only the ones continuation solved: the
    message for the first point of branch k that does not, or None."""
    for pt in branch.points:
        P = at(pt.p)
        F = problem.F(pt.x, P)
        worst = float(np.max(np.abs(F), initial=0.0))
        if np.all(np.isfinite(F)) and worst <= 1e-6:
            continue  # within the tolerance whatever the scale (>= 1): the Jacobian is not needed
        scale = 1.0 + float(np.max(np.abs(problem.J(pt.x, P)), initial=0.0))
        if not np.all(np.isfinite(F)) or worst > 1e-6 * scale:
            return (f"--sweep {name}: on branch {k} at {name} = {pt.p:g} the equilibrium equations do not all hold "
                    f"(residual {float(np.max(np.abs(F))):.3g}): the steady-motion equations are over-determined "
                    "there, and continuation cannot follow them")
    return None


STABLE = ("stable", "asymptotically stable")


def _verdicts(problem: EquilibriumProblem, branch: Branch, at) -> tuple[list[str], int]:
    """The verdict a single equilibrium would get at each point of the branch (energy, Routh and gyroscopic
    arguments included), and how many points are no steady motion in a regular chart."""
    from mechsys.analysis.equilibrium.charts import Unchartable, reclassify, singularities

    verdicts, bad = [], 0
    for pt in branch.points:
        P = at(pt.p)  # first: the given rates of the point
        e = problem.equilibrium(pt.x)
        assess(problem, e, P)
        found = singularities(problem.model, e.coordinates, P)
        if found:
            try:
                if reclassify(problem, e, found[0], P) is None:
                    bad += 1
                    e.stability = "undecided"
            except (Unchartable, np.linalg.LinAlgError):
                e.stability = "undecided"
        verdicts.append(e.stability)
    return verdicts, bad


def _newton_at(problem: EquilibriumProblem, z: np.ndarray, P: np.ndarray, rows=slice(None)) -> np.ndarray:
    """z corrected by Newton (least squares) on the rest equations ``rows`` at the fixed parameters P, until the
    step is at round-off (20 steps at most)."""
    for _ in range(20):
        dz = np.linalg.lstsq(problem.J(z, P)[rows], -problem.F(z, P)[rows], rcond=None)[0]
        z = z + dz
        if np.linalg.norm(dz, np.inf) <= 1e-14 * (1.0 + np.linalg.norm(z, np.inf)):
            break
    return z


def _verdict_at(problem: EquilibriumProblem, x: np.ndarray, P: np.ndarray) -> Equilibrium | None:
    """The equilibrium at x (corrected by Newton at the parameters P) with the verdict a single one would get,
    classified in a regular chart at a gimbal lock; None where it is not one or no verdict is read."""
    from mechsys.analysis.equilibrium.charts import Unchartable, reclassify, singularities

    try:
        x = _newton_at(problem, x, P)
    except (np.linalg.LinAlgError, ValueError):  # not finite along the way
        return None
    if not np.all(np.isfinite(x)):
        return None
    e = problem.equilibrium(x)
    assess(problem, e, P)
    found = singularities(problem.model, e.coordinates, P)
    try:
        if found and reclassify(problem, e, found[0], P) is None:
            return None
    except (Unchartable, np.linalg.LinAlgError):
        return None
    return None if e.stability == "undecided" else e


def _changes_at_locks(problem: EquilibriumProblem, branch: Branch, at) -> list[Bifurcation]:
    """Where the verdict of a branch at a gimbal lock changes between two points with no event between them: the
    continuation's eigenvalues there are those of the singular chart, which miss what the regular chart's show (a
    sleeping top in zxz angles turned stable at C w = 2 sqrt(A m g l) with no event reported; in xyz angles the
    collision is found). Located by bisection on the regular chart's verdicts; a collision when a complex pair
    leaves the imaginary axis on the unstable side, a Hopf point when the stable side is asymptotically stable,
    else a zero eigenvalue."""
    from mechsys.analysis.equilibrium.charts import singularities

    out = []
    located = [b.p for b in branch.bifurcations]
    for k, (a, b) in enumerate(zip(branch.points, branch.points[1:])):
        if "undecided" in (a.verdict, b.verdict) or (a.verdict in STABLE) == (b.verdict in STABLE):
            continue
        lo, hi = sorted((a.p, b.p))
        if any(lo - 1e-12 * (1 + abs(lo)) <= v <= hi + 1e-12 * (1 + abs(hi)) for v in located):
            continue
        if not singularities(problem.model, problem.equilibrium(a.x).coordinates, at(a.p)):
            continue
        s0, s1, sides = 0.0, 1.0, {a.verdict in STABLE: None, b.verdict in STABLE: None}
        for _ in range(60):
            if abs(s1 - s0) * abs(b.p - a.p) <= 1e-11 * (1.0 + abs(a.p)):
                break
            mid = 0.5 * (s0 + s1)
            e = _verdict_at(problem, a.x + mid * (b.x - a.x), at(a.p + mid * (b.p - a.p)))
            if e is None:
                break
            stable = e.stability in STABLE
            sides[stable] = e
            s0, s1 = (mid, s1) if stable == (a.verdict in STABLE) else (s0, mid)
        s = 0.5 * (s0 + s1)
        unstable, stable = sides.get(False), sides.get(True)
        growing = [] if unstable is None else [v for v in unstable.eigenvalues if v.real > 0]
        kind = ("zero_eigenvalue" if not growing or all(abs(v.imag) <= 1e-9 * (1 + abs(v)) for v in growing) else
                "hopf" if stable is not None and stable.stability == "asymptotically stable" else "collision")
        out.append(Bifurcation(kind, a.p + s * (b.p - a.p), a.x + s * (b.x - a.x), k))
    return out


def _review(problem: EquilibriumProblem, branches: list[Branch], at, name: str) -> list[Branch]:
    """Check every point against all the equations (AnalysisError for the first branch that fails), then give
    each point the verdict a single equilibrium would: a conservative branch is stable where the point analysis
    says so (the eigenvalue test alone drew every conservative branch unstable), and points at a gimbal lock are
    classified in a regular chart as `equilibria` does (charts.py). Returns the branches made only of points that
    are no steady motion in a regular chart (artefacts of the singular chart). The branches are reviewed in
    forked workers (numeric/parallel.py), with the errors raised in the serial loop's order."""

    def review(k: int):
        error = _residual_error(problem, branches[k], at, name, k + 1)
        if error is not None:
            return error, None
        try:
            return None, _verdicts(problem, branches[k], at)
        except Exception as exc:  # noqa: BLE001 - raised below, after every branch's residual check
            return None, exc

    reviewed = fork_map(review, len(branches))
    for error, _ in reviewed:
        if error is not None:
            raise AnalysisError(error)
    artefacts = []
    for branch, (_, found) in zip(branches, reviewed):
        if isinstance(found, Exception):
            raise found
        verdicts, bad = found
        for pt, verdict in zip(branch.points, verdicts):
            pt.verdict, pt.stable = verdict, verdict in STABLE
        if branch.points and bad == len(branch.points):
            artefacts.append(branch)
    return artefacts


def _same_family(problem: EquilibriumProblem, a: Branch, b: Branch, at, memo: dict | None = None) -> bool:
    """``b`` is ``a`` in other coordinates (a rotation sequence reaches every orientation twice): at the first and
    the last of b's points at parameter values a reached, the same physical steady motion. One value is not enough:
    a branch leaving another at a branch point is the same motion there, and a heavy top's steady precession
    branch, born from the sleeping top at a gimbal lock of its zxz angles, was dropped as a twin of it."""
    from mechsys.analysis.equilibrium.charts import same_motion

    if not a.points or not b.points:
        return False
    # the points of b (in order) at parameter values a reached, and a's points there
    pa_, pb_ = np.array([pt.p for pt in a.points]), np.array([pt.p for pt in b.points])
    hit = np.abs(pb_[:, None] - pa_[None, :]) <= 1e-12 * (1 + np.abs(pb_))[:, None]
    rows = np.flatnonzero(hit.any(axis=1))
    if not rows.size:
        return False
    picks = rows[[0, -1]]  # where b meets a first and last (a branch point alone is not enough)
    # a branch that folds back reaches a parameter value twice: b's point matches either of a's there
    return all(any(same_motion(problem, problem.equilibrium(a.points[int(j)].x), problem.equilibrium(b.points[r].x),
                               at(b.points[r].p), memo) for j in np.flatnonzero(hit[r])) for r in picks)


def _merge_events(events: list[dict], angles: list[bool], step: float) -> list[dict]:
    """One entry per bifurcation point. A nontrivial branch folding back exactly where another branch has a
    branch point (a pitchfork) is one branch point, not a fold. The other kinds merge only with their own."""
    static = ("fold", "branch_point")

    def same_class(a: dict, b: dict) -> bool:
        return a["kind"] == b["kind"] or (a["kind"] in static and b["kind"] in static)

    def close(a: dict, b: dict) -> bool:
        if abs(a["value"] - b["value"]) > max(1e-6, step):
            return False
        for (x, y), is_angle in zip(zip(a["coordinates"].values(), b["coordinates"].values()), angles):
            d = wrap(x - y) if is_angle else x - y
            if abs(d) > 1e-3 * (1 + abs(x)):
                return False
        return True

    clusters: list[list[dict]] = []
    for ev in events:
        for cluster in clusters:
            if any(close(ev, other) for other in cluster) and same_class(ev, cluster[0]):
                cluster.append(ev)
                break
        else:
            clusters.append([ev])
    merged = []
    for cluster in clusters:
        kinds = {ev["kind"] for ev in cluster}
        folds = [ev for ev in cluster if ev["kind"] == "fold"]
        if "fold" in kinds and "branch_point" in kinds:
            # a pitchfork: the other branch folds back exactly here; the fold's parameter value is the
            # well-conditioned one, the branch point's coordinates are the exact ones
            # (unless the branch point was refined in the parameter itself: then it is the exact one)
            bp = next(ev for ev in cluster if ev["kind"] == "branch_point")
            merged.append(bp if bp["refined"] else {**bp, "value": folds[0]["value"]})
        else:
            merged.append((folds or cluster)[0])
    return [{k: v for k, v in ev.items() if k != "refined"} for ev in merged]


def _refine_singular(problem, par: SweptParameter, rows, p0: float, x0: np.ndarray,
                     step: float) -> tuple[float, np.ndarray]:
    """A branch point or real root crossing located along the arc is refined in the parameter itself: the
    steady state corrected by Newton at fixed p, and Brent's method on the sign of det(dF/dx) over
    [p0 - step, p0 + step] (at a pitchfork the fold of the other branch, located along its arc, was 4e-3 off at
    the bicycle's capsize speed). The original is kept when the refinement cannot bracket a sign change or the
    corrector leaves the branch."""
    from scipy.optimize import brentq

    def corrected(p: float) -> np.ndarray:
        z = _newton_at(problem, x0.copy(), par.at(p), rows)
        if np.linalg.norm(z - x0) > 1e-3 * (1.0 + np.linalg.norm(x0)):
            raise ValueError("left the branch")
        return z

    def g(p: float) -> float:
        J = problem.J(corrected(p), par.at(p))[rows]
        sign, logdet = np.linalg.slogdet(J)
        return float(sign * np.exp(logdet - scale))

    try:
        scale = np.linalg.slogdet(problem.J(x0, par.at(p0))[rows])[1]
        scale = 0.0 if not np.isfinite(scale) else scale
        a, b = p0 - step, p0 + step
        ga, gb = g(a), g(b)
        if ga * gb >= 0.0:
            return p0, x0
        p = float(brentq(g, a, b, xtol=1e-14, rtol=1e-15, maxiter=200))
        return p, corrected(p)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError, RuntimeError):
        return p0, x0
    finally:
        par.at(p0)


def plot_sweep(result: SweepResult, path: str, coordinate: str | None = None) -> None:
    """Bifurcation diagram: stable branches solid, unstable dashed, undecided dotted, bifurcation points marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if coordinate == "eigenvalues":
        return _plot_eigenvalues(result, path, plt)
    if not result.names:
        raise InputError("nothing to plot: the system has no free coordinates")
    if coordinate is not None and coordinate not in result.names:
        raise InputError(f"--plot-coordinate {coordinate}: choose from {', '.join(result.names)} or eigenvalues")
    k = result.names.index(coordinate) if coordinate is not None else 0
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for b, branch in enumerate(result.branches):
        ps = np.array([pt.p for pt in branch.points])
        ys = np.array([pt.x[k] for pt in branch.points], dtype=float)
        if result.angles[k]:
            ys = np.array([wrap(y) for y in ys])
        style = ["-" if pt.stable else ":" if pt.verdict == "undecided" else "--" for pt in branch.points]
        start = 0
        for i in range(1, len(ps) + 1):  # one line per run of equal verdict (so dashes show)
            jump = i < len(ps) and result.angles[k] and abs(ys[i] - ys[i - 1]) > np.pi
            if i == len(ps) or style[i] != style[start] or jump:
                end = i if jump or i == len(ps) else i + 1
                ax.plot(ps[start:end], ys[start:end], style[start], color=f"C{b % 10}", lw=1.8)
                start = i
    for bif in result.bifurcations:
        y = list(bif["coordinates"].values())[k] if bif["coordinates"] else 0.0
        ax.plot([bif["value"]], [y], "o", color="k", ms=5)
        ax.annotate(bif["kind"], (bif["value"], y), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set_xlabel(result.parameter)
    ax.set_ylabel(result.names[k])
    ax.set_title("equilibrium branches (solid: stable, dashed: unstable, dotted: undecided)")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _plot_eigenvalues(result: SweepResult, path: str, plt) -> None:
    """Real parts (solid) and imaginary parts (dotted) of the eigenvalues along each branch against the parameter
    (the stability plot of the bicycle benchmark, Meijaard et al. 2007, Fig. 3); bifurcations marked on Re = 0."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for b, branch in enumerate(result.branches):
        ps = np.array([pt.p for pt in branch.points])
        width = max((len(pt.eigenvalues) for pt in branch.points), default=0)
        ev = np.full((len(ps), width), np.nan, dtype=complex)
        for i, pt in enumerate(branch.points):
            ev[i, :len(pt.eigenvalues)] = pt.eigenvalues
        label = f"branch {b + 1}" if len(result.branches) > 1 else None
        for j in range(width):  # one legend entry per branch
            ax.plot(ps, ev[:, j].real, ".", color=f"C{b % 10}", ms=3, label=label if j == 0 else None)
            ax.plot(ps, np.abs(ev[:, j].imag), ":", color=f"C{b % 10}", lw=1.0)
    for bif in result.bifurcations:
        ax.plot([bif["value"]], [0.0], "o", color="k", ms=5)
        ax.annotate(bif["kind"], (bif["value"], 0.0), textcoords="offset points", xytext=(4, 4), fontsize=8)
    values = np.array([x for branch in result.branches for pt in branch.points for v in pt.eigenvalues
                       for x in (v.real, abs(v.imag)) if np.isfinite(x)])
    if values.size:  # a few huge roots (a branch through a singular point) must not flatten the rest
        lo, hi = np.percentile(values, [2, 98])
        pad = 0.15 * max(hi - lo, 1e-9)
        ax.set_ylim(min(lo, 0.0) - pad, max(hi, 0.0) + pad)
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel(result.parameter)
    ax.set_ylabel("eigenvalues: Re (dots), |Im| (dotted) [1/s]")
    ax.set_title("eigenvalues along the branches")
    if len(result.branches) > 1:
        ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
