"""Exhaustive equilibria: every isolated root of equations polynomial in the unknowns and in sin/cos of the angles."""
from __future__ import annotations

import itertools
import math
import signal
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Iterator

import numpy as np
import sympy as sp

from mechsys.analysis.equilibrium.equilibria import (EquilibriumProblem, SearchReport, _multiplier_guess, _polish,
                                                     is_new_root, search_plan, solve_equilibria)
from mechsys.errors import InputError

#: Size limits of the exhaustive mode: unknowns (coordinates and steady rates; the multipliers are eliminated), the
#: Bezout number of the polynomial system (product of the largest total degrees after clearing denominators, one
#: per unknown) and the wall-clock budget of the Groebner bases [s]. Beyond them the mode refuses (exit 2).
MAX_UNKNOWNS = 6
MAX_BEZOUT = 5000
TIME_BUDGET = 60.0
#: A complex root is a candidate real root when every coordinate has |Im| <= IMAG_TOL * (1 + |Re|); Newton on the
#: original equations decides (a multiple root comes out of the eigenvalues with an imaginary part ~ eps^(1/k)).
IMAG_TOL = 1e-3


class NotExhaustible(InputError):
    """The exhaustive mode does not apply to this system (not polynomial, too large, over the time budget)."""


class _OutOfTime(BaseException):
    """Raised by the budget alarm inside sympy (a BaseException, so that no ``except Exception`` swallows it)."""


@dataclass
class Exhaustive:
    """What the exhaustive solve computed, for the output."""

    unknowns: list[str]
    charts: int  # half-angle charts: every subset of the angles at pi
    complex_roots: int  # isolated complex roots of all charts, counted with multiplicity
    real_roots: int = 0  # distinct real roots accepted by Newton on the original equations
    positive_dimension: int = 0  # largest dimension of a non-isolated solution set (0: every root isolated)

    def text(self) -> str:
        what = (f"exhaustive: every isolated root of the polynomial equations in {', '.join(self.unknowns)} "
                f"(half-angle substitution, {self.charts} chart(s), Groebner bases): {self.complex_roots} complex "
                f"root(s) counted with multiplicity, {self.real_roots} real")
        if self.positive_dimension:
            what += (f"; NOT exhaustive: the solution set has a positive-dimensional part (dimension "
                     f"{self.positive_dimension}, a continuum of complex or real roots) that cannot be enumerated, "
                     f"so the multistart search was added")
        return what

    def to_dict(self) -> dict:
        return {"exhaustive": not self.positive_dimension, "unknowns": self.unknowns, "charts": self.charts,
                "complex_roots": self.complex_roots, "real_roots": self.real_roots,
                "positive_dimension": self.positive_dimension}


# ------------------------------------------------------------------------------------------ polynomial form
def _rational(x: float) -> sp.Rational:
    """A float as an exact rational: a short fraction when it is one to 1e-15 (50/7), else its decimal digits."""
    f = Fraction(x).limit_denominator(10**6)
    if abs(float(f) - x) <= 1e-15 * max(1.0, abs(x)):
        return sp.Rational(f.numerator, f.denominator)
    return sp.Rational(repr(float(x)))


def _exact(e: sp.Expr) -> sp.Expr:
    """Every constant that is not rational (pi, sqrt(2), floats, cos(1/3)) replaced by a rational approximation:
    the Groebner basis is computed over QQ and Newton restores full accuracy on the original equations."""
    if e.is_Rational or e.is_Symbol or not isinstance(e, sp.Expr):
        return e
    if not e.free_symbols and e.is_number:
        v = complex(sp.N(e, 30))
        if v.imag:
            raise NotExhaustible(f"--exhaustive: the equilibrium equations contain the complex constant {e}")
        return _rational(v.real)
    if not e.args:
        return e
    return e.func(*[_exact(a) for a in e.args])


def _short(e: sp.Expr, width: int = 60) -> str:
    text = str(e)
    return text if len(text) <= width else text[: width - 3] + "..."


@dataclass
class PolynomialForm:
    """The equilibrium equations as sin/cos polynomials in the coordinates and steady rates (the multipliers
    eliminated), with the angles that appear in sin/cos."""

    exprs: list[sp.Expr]
    unknowns: list[sp.Symbol]
    trig: list[sp.Symbol]  # angles that appear inside sin/cos (half-angle substituted)
    half: dict[sp.Symbol, sp.Dummy] = field(default_factory=dict)  # angle -> t = tan(angle/2)

    def __post_init__(self) -> None:
        self.half = {q: sp.Dummy(f"t_{q}") for q in self.trig}


def polynomial_form(problem: EquilibriumProblem, p: np.ndarray) -> PolynomialForm:
    """Parameters substituted exactly, trig functions expanded to sin(q), cos(q) of single angles, and the
    multipliers eliminated: f(q) + A(q)^T lambda = 0 has a solution lambda exactly when every (m+1)-minor of
    [f | A^T] vanishes (A of full rank m), so those minors and Phi(q) = 0 are the equations, and lambda follows
    by least squares. Refuse (NotExhaustible) what is not polynomial in the unknowns, sin and cos of the angles."""
    unknowns = list(problem.unknowns)
    given = problem._args[len(unknowns):]  # fixed steady rates, then the parameters
    values = [*problem.extra(), *p]
    subs = {s: _rational(float(v)) for s, v in zip(given, values)}
    angles = {s for s, a in zip(unknowns, problem.is_angle()) if a}
    names = dict(zip(unknowns, problem.free))  # an angle of the model that its equations are not periodic in
    exprs = []
    for e in problem.residual_exprs:
        e = e.xreplace(subs)
        e = e.replace(sp.tan, lambda x: sp.sin(x) / sp.cos(x)).replace(sp.cot, lambda x: sp.cos(x) / sp.sin(x))
        e = e.replace(sp.sec, lambda x: 1 / sp.cos(x)).replace(sp.csc, lambda x: 1 / sp.sin(x))
        exprs.append(_exact(sp.expand_trig(e)))
    trig: set[sp.Symbol] = set()
    unknown_set = set(unknowns)
    for e in exprs:
        for f in e.atoms(sp.Pow):
            if f.base.free_symbols & unknown_set and not f.exp.is_Integer or f.exp.free_symbols & unknown_set:
                raise NotExhaustible(f"--exhaustive: the equilibrium equations are not polynomial in the unknowns, "
                                     f"sin and cos of the angles (they contain {_short(f)})")
        for f in e.atoms(sp.Function):
            if not (f.free_symbols & unknown_set):
                continue
            if f.func not in (sp.sin, sp.cos):
                raise NotExhaustible(f"--exhaustive: the equilibrium equations are not polynomial in the unknowns, "
                                     f"sin and cos of the angles (they contain {_short(f)})")
            arg = f.args[0]
            if arg in unknown_set and arg not in angles and problem.model.angles.get(names.get(arg, ""), False):
                raise NotExhaustible(f"--exhaustive: the angle {arg} appears both inside and outside sin/cos (the "
                                     "equations are transcendental)")
            if arg not in angles:
                what = (f"{arg} is not an angle (angle: true in the file makes it one)" if arg in unknown_set
                        else f"the argument {_short(arg)} is not a single angle or an integer multiple")
                raise NotExhaustible(f"--exhaustive: {_short(f)} cannot be half-angle substituted: {what}")
            trig.add(arg)
    if problem.m:
        lam = unknowns[-problem.m:]
        rows = sp.Matrix(exprs[: len(exprs) - problem.m])
        forces = sp.Matrix.hstack(rows.xreplace({x: 0 for x in lam}), rows.jacobian(lam))
        minors = [sp.expand(forces.extract(list(k), list(range(problem.m + 1))).det(method="berkowitz"))
                  for k in itertools.combinations(range(rows.rows), problem.m + 1)]
        exprs, unknowns = minors + exprs[len(exprs) - problem.m:], unknowns[: -problem.m]
    ordered = [s for s in unknowns if s in trig]
    return PolynomialForm(exprs, unknowns, ordered)


def _chart(form: PolynomialForm, at_pi: tuple[sp.Symbol, ...]) -> tuple[list[sp.Poly], list[sp.Symbol], list[sp.Expr]]:
    """One half-angle chart: the angles in at_pi are pi, the others q = 2 atan(t). Polynomial numerators (zero
    ones dropped), their generators, and the denominators (for saturation)."""
    tsym = {q: t for q, t in form.half.items() if q not in at_pi}
    subs = {}
    for q in form.trig:
        if q in at_pi:
            subs[sp.sin(q)], subs[sp.cos(q)] = sp.Integer(0), sp.Integer(-1)
        else:
            t = tsym[q]
            subs[sp.sin(q)], subs[sp.cos(q)] = 2 * t / (1 + t**2), (1 - t**2) / (1 + t**2)
    gens = [tsym.get(q, q) for q in form.unknowns if q not in at_pi]
    polys, dens = [], set()
    for e in form.exprs:
        e = e.xreplace(subs)
        left = e.free_symbols & set(form.trig)
        if left:
            raise NotExhaustible(f"--exhaustive: the angle {sorted(map(str, left))[0]} appears both inside and "
                                 f"outside sin/cos (the equations are transcendental)")
        num, den = sp.fraction(sp.cancel(sp.together(e)))
        try:
            poly = sp.Poly(num, *gens, domain="QQ") if gens else sp.Poly(num, sp.Dummy("x"), domain="QQ")
        except (sp.PolynomialError, sp.CoercionFailed, sp.GeneratorsNeeded) as exc:
            raise NotExhaustible(f"--exhaustive: the equilibrium equations are not polynomial in the unknowns, sin "
                                 f"and cos of the angles ({_short(num)} is not a polynomial)") from exc
        if not poly.is_zero:
            polys.append(poly)
        dens |= {f for f, _ in sp.factor_list(den)[1] if f.free_symbols}
    return polys, gens, sorted(dens, key=sp.default_sort_key)


# -------------------------------------------------------------------------------------------- root finding
def _normal_set(leading: list[tuple[int, ...]], n: int, cap: int) -> list[tuple[int, ...]]:
    """Monomials not divisible by any leading monomial (the basis of the quotient ring), 1 first."""
    def divisible(m: tuple[int, ...]) -> bool:
        return any(all(a >= b for a, b in zip(m, lm)) for lm in leading)

    out, seen, frontier = [], set(), [(0,) * n]
    while frontier:
        m = frontier.pop(0)
        if m in seen or divisible(m):
            continue
        seen.add(m)
        out.append(m)
        if len(out) > cap:
            raise NotExhaustible(f"--exhaustive: more than {cap} complex roots: beyond the size limit")
        frontier += [tuple(a + (i == k) for k, a in enumerate(m)) for i in range(n)]
    return out


def _dimension(leading: list[tuple[int, ...]], n: int) -> int:
    """Krull dimension from the leading monomials: the largest set of variables no leading monomial lives in."""
    for size in range(n, -1, -1):
        for subset in itertools.combinations(range(n), size):
            if not any(all(lm[k] == 0 for k in range(n) if k not in subset) for lm in leading):
                return size
    return 0


def _complex_roots(G: sp.GroebnerBasis, gens: list[sp.Symbol], rng: np.random.Generator) -> np.ndarray:
    """All roots of a zero-dimensional ideal: eigenvalues of the multiplication matrices (Stickelberger)."""
    n = len(gens)
    leading = [g.monoms(order="grevlex")[0] for g in G.polys]
    basis = _normal_set(leading, n, cap=MAX_BEZOUT)
    index = {m: k for k, m in enumerate(basis)}
    D = len(basis)
    mats = []
    for i in range(n):
        M = np.zeros((D, D))
        for j, m in enumerate(basis):
            mono = sp.Mul(*[g**e for g, e in zip(gens, m)]) * gens[i]
            rem = sp.Poly(G.reduce(mono)[1], *gens, domain="QQ")
            for mm, c in rem.terms():
                M[index[mm], j] = float(c)
        mats.append(M)
    weights = rng.uniform(0.5, 1.5, n)
    Mf = sum(w * M for w, M in zip(weights, mats))
    _, vectors = np.linalg.eig(Mf.T)  # left eigenvectors: evaluations of the basis monomials at a root
    roots = np.empty((D, n), complex)
    for k in range(D):
        u = vectors[:, k]
        norm = np.vdot(u, u)
        roots[k] = [np.vdot(u, M.T @ u) / norm for M in mats]
    return roots


@contextmanager
def _budget(seconds: float) -> Iterator[None]:
    """Raise _OutOfTime after `seconds` (SIGALRM; only in the main thread, elsewhere no limit)."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "setitimer"):
        yield
        return

    def alarm(signum, frame):  # noqa: ARG001 - signal handler signature
        raise _OutOfTime

    old = signal.signal(signal.SIGALRM, alarm)
    previous, _ = signal.setitimer(signal.ITIMER_REAL, seconds)  # a timer someone else armed (pytest-timeout)
    started = time.monotonic()
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
        if previous:
            signal.setitimer(signal.ITIMER_REAL, max(previous - (time.monotonic() - started), 1e-3))


def exhaustive_roots(problem: EquilibriumProblem, p: np.ndarray, budget: float = TIME_BUDGET,
                     seed: int = 0) -> tuple[list[np.ndarray], Exhaustive]:
    """Every isolated real root (refined by Newton on the original equations), and what was computed. (A problem
    without unknowns is find_equilibria's every-state case, not solved here.)"""
    if not problem.unknowns:
        raise ValueError("exhaustive_roots needs unknowns")
    names = problem.unknown_names[: len(problem.unknown_names) - problem.m]  # the multipliers are eliminated
    if len(names) > MAX_UNKNOWNS:
        raise NotExhaustible(f"--exhaustive: {len(names)} unknowns ({', '.join(names)}) exceed the limit of "
                             f"{MAX_UNKNOWNS}")
    form = polynomial_form(problem, p)
    polys, gens, _ = _chart(form, ())
    bezout = math.prod(sorted((max(1, q.total_degree()) for q in polys), reverse=True)[: len(gens)])
    if bezout > MAX_BEZOUT:
        raise NotExhaustible(f"--exhaustive: Bezout number {bezout} (product of the equation degrees) exceeds the "
                             f"limit of {MAX_BEZOUT}")
    rng = np.random.default_rng(seed)
    charts = [c for k in range(len(form.trig) + 1) for c in itertools.combinations(form.trig, k)]
    found = Exhaustive(names, len(charts), 0)
    candidates = []
    try:
        with _budget(budget):
            for at_pi in charts:
                polys, gens, dens = _chart(form, at_pi)
                if not gens:  # every unknown is an angle at pi: a root if every equation vanishes there
                    if not polys:
                        found.complex_roots += 1
                        candidates.append(_unknowns(form, at_pi, gens, np.zeros(0)))
                    continue
                if not polys:
                    found.positive_dimension = max(found.positive_dimension, len(gens))
                    continue
                G = sp.groebner(polys, *gens, order="grevlex", domain="QQ")
                if G.exprs == [1]:
                    continue
                if not G.is_zero_dimensional and dens:  # a spurious continuum where a denominator vanishes
                    w = sp.Dummy("w")  # (complex t = +-i): saturate, w * (denominators) = 1 (Rabinowitsch)
                    G = sp.groebner([q.as_expr() for q in polys] + [w * sp.Mul(*dens) - 1], *gens, w,
                                    order="grevlex", domain="QQ")
                    gens_w = [*gens, w]
                else:
                    gens_w = gens
                if G.exprs == [1]:
                    continue
                if not G.is_zero_dimensional:
                    leading = [g.monoms(order="grevlex")[0] for g in G.polys]
                    found.positive_dimension = max(found.positive_dimension, _dimension(leading, len(gens_w)))
                    continue
                roots = _complex_roots(G, gens_w, rng)
                found.complex_roots += len(roots)
                for r in roots:
                    if np.all(np.abs(r.imag) <= IMAG_TOL * (1 + np.abs(r.real))):
                        candidates.append(_unknowns(form, at_pi, gens, r.real[: len(gens)]))
    except _OutOfTime:
        raise NotExhaustible(f"--exhaustive: the Groebner bases took longer than the time budget of {budget:g} s "
                             f"(the system is too large for the exhaustive mode)") from None
    roots: list[np.ndarray] = []
    for q in candidates:
        z = _polish(problem, np.concatenate([q, _multiplier_guess(problem, q, p)]), p)
        if z is None:
            continue
        z = problem.normalize(z)
        if is_new_root(problem, z, roots):
            roots.append(z)
    found.real_roots = len(roots)
    return roots, found


def _unknowns(form: PolynomialForm, at_pi: tuple[sp.Symbol, ...], gens: list[sp.Symbol],
              values: np.ndarray) -> np.ndarray:
    """A chart point (t for the half-angle substituted angles) as coordinates and rates (angles q = 2 atan t)."""
    byname = dict(zip(gens, values))
    out = []
    for q in form.unknowns:
        if q in at_pi:
            out.append(math.pi)
        elif q in form.trig:
            out.append(2 * math.atan(byname[form.half[q]]))
        else:
            out.append(byname[q])
    return np.array(out, dtype=float)


def exhaustive_search(problem: EquilibriumProblem, p: np.ndarray, starts: int | None = None,
                      seed: int = 0) -> tuple[list[np.ndarray], SearchReport | None, Exhaustive]:
    """The roots for find_equilibria: the exhaustive ones, plus the multistart's when part of the solution set is
    positive-dimensional (the continuum is then represented, not enumerated, and the search report says so)."""
    roots, found = exhaustive_roots(problem, p, seed=seed)
    if not found.positive_dimension:
        return roots, None, found
    plan = search_plan(problem, None, starts)
    for z in solve_equilibria(problem, p, None, starts, seed, plan):
        if is_new_root(problem, z, roots):
            roots.append(z)
    return roots, plan, found
