"""Equilibrium branches of a model as one parameter varies: continuation, stability and bifurcation points."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from mechsys.analysis.continuation import Branch, sweep_parameter
from mechsys.analysis.equilibria import EquilibriumProblem, parameter_values, solve_equilibria, wrap
from mechsys.analysis.stability import ZERO_RE, assess, eigen, reduced_pencil
from mechsys.errors import AnalysisError, InputError
from mechsys.mechanics.model import MechanicalModel


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


def parameter_sensitivity(model: MechanicalModel, name: str):
    """d(parameter vector)/d(name): derived parameters follow the swept one (exact, from their expressions)."""
    doc = model.doc
    if name not in doc.parameters:
        raise InputError(f"--sweep {name}: unknown parameter{doc.suggest(name, list(doc.parameters))}")
    base = doc.parameters[name]
    full: dict[sp.Symbol, sp.Expr] = {}
    for pname, expr in doc.parameter_exprs.items():
        sym = doc.parameters[pname]
        full[sym] = base if pname == name else expr.xreplace(full)
    derivs = [sp.diff(full[s], base) for s in model.parameter_symbols]

    def at(values: dict[str, float]) -> np.ndarray:
        subs = {doc.parameters[k]: sp.Float(float(v)) for k, v in values.items()}  # sympy Floats: d may be a Symbol
        return np.array([float(sp.sympify(d).xreplace(subs).evalf()) for d in derivs])

    return at


def sweep(model: MechanicalModel, name: str, start: float, stop: float, points: int = 101,
          search: dict | None = None) -> SweepResult:
    """Follow every equilibrium branch found at the ends and the middle of [start, stop] by pseudo-arclength
    continuation; stability from the eigenvalues; folds, branch points and Hopf points located on the way."""
    if start == stop:
        raise InputError(f"--sweep {name}: START and STOP must differ")
    problem = EquilibriumProblem(model)
    sens = parameter_sensitivity(model, name)
    lo, hi = min(start, stop), max(start, stop)

    def pvec(p: float) -> np.ndarray:
        return parameter_values(model, {name: p})

    rows: list[int] | slice = slice(None)  # the equations continued on (a square system), chosen below

    def F(z, p):
        return problem.F(z, pvec(p))[rows]

    def Fx(z, p):
        return problem.J(z, pvec(p))[rows]

    def Fp(z, p):
        values = dict(zip([s.name for s in model.parameter_symbols], pvec(p)))
        return (problem.Fp(z, pvec(p)) @ sens(values))[rows]

    def eig(z, p):
        problem.current_parameters = pvec(p)
        A, B, _ = reduced_pencil(problem, problem.equilibrium(z))
        return eigen(A, B)[0]

    starts = []
    for p in np.linspace(lo, hi, 5):  # branches born inside the range need a start of their own
        for z in solve_equilibria(problem, pvec(p), search):
            starts.append((z, float(p)))
    span = hi - lo if hi > lo else 1.0
    step = span / max(points - 1, 1)
    if starts:
        rows = _independent_rows(problem.J(starts[0][0], pvec(starts[0][1])))
    # the step limit grows with the points asked for (a branch needs at least points - 1 steps to cross the range)
    try:
        branches = sweep_parameter(F, Fx, Fp, starts, lo, hi, eig, ds=step / 2,
                                   ds_max=min(step, 0.2 * max(span, 1.0)), tol_re=ZERO_RE * 10,
                                   max_steps=max(2000, 20 * points)) if starts else []
    except ValueError as exc:
        raise AnalysisError(f"--sweep {name}: {exc}") from None
    _check_all_equations(problem, branches, pvec, name)
    _point_verdicts(problem, branches, pvec)
    nreport = len(problem.free) + len(problem.rate_unknowns)
    names = list(problem.free) + [f"der({c})" for c in problem.rate_unknowns]
    angles = [problem.angles.get(c, False) for c in problem.free] + [False] * len(problem.rate_unknowns)
    result = SweepResult(name, names, angles, branches)
    cut = [k for k, branch in enumerate(branches, start=1) if branch.truncated]
    if cut:
        result.notes.append(f"branch(es) {', '.join(map(str, cut))} ended at the step limit ({max(2000, 20 * points)} "
                            "steps) inside the range: they are incomplete, and a start found on their untraced part "
                            "may appear as a further branch (use fewer points or a narrower range)")
    events = []
    for branch in branches:
        for bif in branch.bifurcations:
            coords = {n: (wrap(v) if a else float(v)) for n, v, a in zip(names, bif.x[:nreport], angles)}
            events.append({"kind": bif.kind, "parameter": name, "value": float(bif.p), "coordinates": coords})
    result.bifurcations = _merge_events(events, angles, step)
    result.bifurcations.sort(key=lambda b: (b["value"], b["kind"]))
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


def _check_all_equations(problem: EquilibriumProblem, branches: list[Branch], pvec, name: str) -> None:
    """Every continued point must satisfy ALL equilibrium equations, not only the ones continuation solved."""
    for k, branch in enumerate(branches, start=1):
        for pt in branch.points:
            F = problem.F(pt.x, pvec(pt.p))
            scale = 1.0 + float(np.max(np.abs(problem.J(pt.x, pvec(pt.p))), initial=0.0))
            if not np.all(np.isfinite(F)) or float(np.max(np.abs(F), initial=0.0)) > 1e-6 * scale:
                raise AnalysisError(f"--sweep {name}: on branch {k} at {name} = {pt.p:g} the equilibrium equations "
                                    f"do not all hold (residual {float(np.max(np.abs(F))):.3g}): the steady-motion "
                                    "equations are over-determined there, and continuation cannot follow them")


STABLE = ("stable", "asymptotically stable")


def _point_verdicts(problem: EquilibriumProblem, branches: list[Branch], pvec) -> None:
    """Each branch point gets the verdict a single equilibrium would (energy, Routh and gyroscopic arguments
    included), not only the eigenvalue test: a conservative branch is stable where the point analysis says so
    (the eigenvalue test alone drew every conservative branch unstable)."""
    for branch in branches:
        for pt in branch.points:
            e = problem.equilibrium(pt.x)
            assess(problem, e, pvec(pt.p))
            pt.verdict = e.stability
            pt.stable = e.stability in STABLE


def _merge_events(events: list[dict], angles: list[bool], step: float) -> list[dict]:
    """One entry per bifurcation point. A nontrivial branch folding back exactly where another branch has a
    branch point (a pitchfork) is one branch point, not a fold."""

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
            if any(close(ev, other) for other in cluster) and (ev["kind"] == "hopf") == (cluster[0]["kind"] == "hopf"):
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
            bp = next(ev for ev in cluster if ev["kind"] == "branch_point")
            merged.append({**bp, "value": folds[0]["value"]})
        else:
            merged.append((folds or cluster)[0])
    return merged


def plot_sweep(result: SweepResult, path: str, coordinate: str | None = None) -> None:
    """Bifurcation diagram: stable branches solid, unstable dashed, undecided dotted, bifurcation points marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not result.names:
        raise InputError("nothing to plot: the system has no free coordinates")
    if coordinate is not None and coordinate not in result.names:
        raise InputError(f"--plot-coordinate {coordinate}: choose from {', '.join(result.names)}")
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
