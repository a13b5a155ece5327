"""Steady motions of systems with velocity (rolling) constraints, linearized on the constraint manifold.

The equations of motion are M a = f + A^T lambda with the velocity constraints g(q, u) = A u + c = 0 (holonomic
rows are Phi_q u, and Phi(q) = 0 holds as well). A steady motion is a motion in which the *shape* (every
coordinate the reduced equations depend on) is constant and the independent speeds are constant, while the
*ignorable* coordinates (position on the ground, heading, wheel angles: coordinates the reduced equations do not
depend on) drift. It is found as a root of the augmented equations

    R = M a - f - A^T lambda = 0,   S = A a - b = 0,   g(q, u) = 0,   Phi(q) = 0

with the shape rates zero, the independent accelerations zero and the ignorable coordinates at 0 (they do not
matter): the unknowns are the shape coordinates, the rates of the ignorable coordinates (the independent ones are
the given rates of a family of steady motions, fixed at the file's values, unless ``--solve`` frees them), the
accelerations of the dependent ignorable speeds (a disk rolling in a circle turns its velocity) and the
multipliers. Every derivative is exact (symbolic Jacobians of R, S, g, Phi, compiled once).

The linearization uses independent coordinates and speeds: holonomic constraints eliminated at position level,
velocity constraints at velocity level, the accelerations from the differentiated saddle-point system
[M -A^T; A 0] [da; dlam] = -[dR; dS]. Its state is (independent shape coordinates, independent speeds); the
ignorable coordinates' zero eigenvalues are structural and reported apart, and so is the zero eigenvalue of each
family of steady motions (its direction is the family's tangent, deflated exactly).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from mechsys.analysis.equilibrium.equilibria import (Equilibrium, EquilibriumProblem, newton_scales,
                                                     refuse_time_dependence, wrap)
from mechsys.analysis.equilibrium.stability import zero_like_eigenvalues
from mechsys.numeric.parameters import parameter_values
from mechsys.errors import AnalysisError, InputError
from mechsys.mechanics.dag import FreeSymbols, Substitution
from mechsys.mechanics.model import MechanicalModel
from mechsys.numeric import native, tangents
from mechsys.numeric.lambdify import (ForwardProgram, compile_exprs, differentiate_program, function_from_source,
                                       generate_source, shared_program, value_and_jacobian_sources)

if TYPE_CHECKING:
    from mechsys.analysis.equilibrium.continuation import Compiled

#: relative size below which a column, a singular value or a shift difference counts as zero
ZERO = 1e-9


# ----------------------------------------------------------------------------------------- compiled pieces
class ConstrainedPieces:
    """E = [R; S; g; Phi] and dE/dq, dE/du, M, A compiled as one function of (q, u, a, lambda, p) at t = 0.

    The generated source is cached on disk (numeric/cache.py: keyed by the model's structure, its decisions and
    the code version; signed; checked to be arithmetic before it runs), so a second command on the same model
    does no symbolic work: neither the equations of motion nor their derivatives."""

    def __init__(self, model: MechanicalModel, method: str) -> None:
        from mechsys.numeric import cache

        rows = model.kin.constraints
        self.names = list(model.coordinates)
        self.n, self.m = len(model.q), len(rows)
        self.mh = sum(1 for r in rows if r.kind == "holonomic")
        self.size = self.n + 2 * self.m + self.mh
        self.lam = list(sp.symbols(f"lambda1:{self.m + 1}", real=True)) if self.m else []
        n = self.n
        self.layout = {"E": (0, (self.size, 1)), "M": (self.size, (n, n)), "A": (self.size + n * n, (self.m, n))}
        self._outputs = self.size + n * n + self.m * n
        # the search's compiled Newton, built (once per machine) on the other core beside this symbolic work
        native.prepare_newton()
        key = cache.model_key(model, f"constrained-pieces-{method}")
        entry = cache.load(key)
        if not self._usable(entry, model):
            entry = self._generate(model, method)
            cache.store(key, entry)
        self.read = np.array(entry["read"], dtype=bool)  # which parameters E reads (its expressions' symbols)
        self.n_args = 3 * self.n + self.m + len(model.parameter_symbols)
        self._full_size = self._outputs + self.size * 2 * self.n
        # the same code compiled by the system C compiler (numeric/native.py) when there is one: a bicycle's
        # pieces in microseconds instead of milliseconds; the Python functions otherwise
        self._native = native.load_program(key, entry["c"], {"mechsys_values": self.size,
                                                              "mechsys_full": self._full_size}, self.n_args)
        if self._native is None and entry["source"] is None:  # compiled when stored, not here: Python after all
            entry = {**entry, **self._python_sources(*self._expressions(model, method))}
            cache.store(key, entry)
        self._origin = (model, method)
        self._sources_text = (entry["source"], entry["values"])
        self._last: tuple[bytes, dict] | None = None

    def _usable(self, entry: dict | None, model: MechanicalModel) -> bool:
        """A stored entry of this shape: C source or None, both Python sources or (with C) neither."""
        if not (isinstance(entry, dict) and entry.get("size") == self.size
                and isinstance(entry.get("c"), (str, type(None)))
                and isinstance(entry.get("read"), list) and len(entry["read"]) == len(model.parameter_symbols)
                and all(isinstance(r, bool) for r in entry["read"])):
            return False
        python = [entry.get("source"), entry.get("values")]
        return all(isinstance(x, str) for x in python) or (python == [None, None] and isinstance(entry["c"], str))

    # the generated Python, made (when a compiler took the C form), checked and compiled only when it runs (no
    # compiler, or a test comparing the two)
    def _python_text(self) -> tuple[str, str]:
        if self._sources_text[0] is None:
            made = self._python_sources(*self._expressions(*self._origin))
            self._sources_text = (made["source"], made["values"])
        return self._sources_text

    @cached_property
    def _fn(self):
        return function_from_source(self._python_text()[0])

    @cached_property
    def _values(self):
        return function_from_source(self._python_text()[1])

    def _expressions(self, model: MechanicalModel, method: str) -> tuple[list, list, ForwardProgram]:
        """The outputs E (R; S; g; Phi), M, A at t = 0, the arguments (q, u, a, lambda, p), and their program (one
        CSE; the derivatives dE/d(q, u) are formed by whoever prints it)."""
        eq = model.equations(method)
        rows = model.kin.constraints
        t0 = {model.t: 0}
        R, S = saddle_residuals(eq.M, eq.f, eq.A, eq.b, model.a, self.lam)
        g = [r.velocity for r in rows]
        Phi = [r.position for r in rows if r.kind == "holonomic"]
        outputs = [sp.sympify(e) for e in list(R) + list(S) + g + Phi + list(eq.M) + list(eq.A)]
        at_t0 = Substitution(t0, model.diff.symbols)  # each shared node once (xreplace walks every path)
        outputs = [at_t0.of(e) for e in outputs]
        args = [*model.q, *model.u, *model.a, *self.lam, *model.parameter_symbols]
        return outputs, args, shared_program(outputs, args, [*model.q, *model.u], light=True)

    def _python_sources(self, outputs: list, args: list, program: ForwardProgram) -> dict:
        """Python sources of E alone (what a line search evaluates, its own CSE) and of E, M, A followed by
        dE/d(q, u) row by row (differentiated symbolically: lambdify.differentiate_program)."""
        wrt = args[:2 * self.n]
        _values, source = value_and_jacobian_sources(outputs, args, wrt,
                                                     program=differentiate_program(program, wrt, self.size))
        return {"source": source, "values": generate_source(outputs[:self.size], args)}

    def _generate(self, model: MechanicalModel, method: str) -> dict:
        """The cache entry: the C source of the program (None when an expression has no C form) and, unless a C
        compiler is there to build it, the Python sources; which parameters E reads. (Not whether it is autonomous:
        that depends on the parameter values, which this key leaves out; model.is_autonomous keys them.)"""
        outputs, args, program = self._expressions(model, method)
        wrt, functions = args[:2 * self.n], {"mechsys_values": (self.size, False), "mechsys_full": (len(outputs), True)}
        # the tangents printed straight to C (numeric/tangents.py); a node without a rule there: sympy's derivatives
        c_source = tangents.program_source(program, wrt, self.size, functions)
        if c_source is None:
            c_source = native.program_source(differentiate_program(program, wrt, self.size), functions)
        python = ({"source": None, "values": None} if c_source is not None and native.compiler() is not None
                  else self._python_sources(outputs, args, program))
        used = FreeSymbols().of_all(outputs[:self.size])
        return {"size": self.size, "c": c_source, **python, "read": [s in used for s in model.parameter_symbols]}

    def residual(self, q: np.ndarray, u: np.ndarray, a: np.ndarray, lam: np.ndarray, p: np.ndarray) -> np.ndarray:
        """E alone (no derivatives): what a line search evaluates."""
        if self._native is not None:
            return self._native("mechsys_values", np.concatenate([q, u, a, lam, p]))
        with np.errstate(all="ignore"):
            return np.asarray(self._values(*q, *u, *a, *lam, *p), dtype=float)

    def evaluate(self, q: np.ndarray, u: np.ndarray, a: np.ndarray, lam: np.ndarray,
                 p: np.ndarray) -> dict[str, np.ndarray]:
        """E, M, A, dE/dq and dE/du (the last point's are kept: a Jacobian and dF/dp at one point share them)."""
        args = np.concatenate([q, u, a, lam, p]).astype(float)
        tag = args.tobytes()
        if self._last is not None and self._last[0] == tag:
            return self._last[1]
        if self._native is not None:
            out = self._native("mechsys_full", args)
        else:
            with np.errstate(all="ignore"):  # overflow far from the roots gives inf/nan, which the callers reject
                out = np.asarray(self._fn(*args), dtype=float)
        v = {key: out[s:s + shape[0] * shape[1]].reshape(shape) for key, (s, shape) in self.layout.items()}
        v["E"] = v["E"].ravel()
        jac = out[self._outputs:self._outputs + self.size * 2 * self.n].reshape(self.size, 2 * self.n)
        v["Eq"], v["Eu"] = jac[:, :self.n], jac[:, self.n:]
        v["raw"] = np.append(out, 0.0)  # every number above, and a zero last (NonholonomicProblem._gather)
        for block in v.values():
            block.flags.writeable = False  # shared by the callers of the same point
        self._last = (tag, v)
        return v

    def accelerations(self, q: np.ndarray, u: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """a and lambda of the saddle-point system M a - A^T lambda = f, A a = b."""
        n, m = self.n, self.m
        v = self.evaluate(q, u, np.zeros(n), np.zeros(m), p)
        K = np.block([[v["M"], -v["A"].T], [v["A"], np.zeros((m, m))]])
        rhs = -np.concatenate([v["E"][:n], v["E"][n:n + m]])
        x = np.linalg.solve(K, rhs)
        return x[:n], x[n:]


def constrained_pieces(model: MechanicalModel, method: str = "kane") -> ConstrainedPieces:
    """The model's ConstrainedPieces for a formulation, built once per model object (shared by sweep copies)."""
    store = model.__dict__.setdefault("_constrained_pieces", {})
    if method not in store:
        store[method] = ConstrainedPieces(model, method)
    return store[method]


# ----------------------------------------------------------------------------------------- the split
def saddle_residuals(M: sp.Matrix, f: sp.Matrix, A: sp.Matrix, b: sp.Matrix, a: list, lam: list) -> tuple[list, list]:
    """R = M a - f - A^T lambda and S = A a - b, entry by entry: the expressions sympy's matrix products give
    (tests/test_nonholonomic.py compares them), without its check of every nonzero entry of M for infinities (a
    zero times each entry, whose assumptions queries walk the bicycle's large entries: a second of a cold modes)."""
    n, m = M.shape[0], A.shape[0]

    def dot(pairs) -> sp.Expr:
        return sp.Add(*[x * y for x, y in pairs if x != 0])

    R = [dot((M[i, j], a[j]) for j in range(n)) - f[i] - dot((A[k, i], lam[k]) for k in range(m)) for i in range(n)]
    S = [dot((A[k, j], a[j]) for j in range(n)) - b[k] for k in range(m)]
    return R, S


@dataclass
class Split:
    """Which speeds and coordinates are independent, and which coordinates are ignorable."""

    independent: list[str]  # coordinates whose rates are the independent speeds
    dependent: list[str]  # coordinates whose rates the velocity constraints give
    eliminated: list[str]  # coordinates the holonomic constraints give (position level)
    ignorable: list[str]  # the reduced equations do not depend on them
    shape: list[str]  # the others: constant in a steady motion

    def text(self) -> str:
        parts = [f"independent speeds der({'), der('.join(self.independent)})" if self.independent
                 else "no independent speeds"]
        if self.eliminated:
            parts.append(f"{', '.join(self.eliminated)} eliminated by the holonomic constraints")
        if self.ignorable:
            parts.append(f"ignorable: {', '.join(self.ignorable)}")
        return "; ".join(parts)


def _greedy(columns: np.ndarray, order: list[int], need: int) -> list[int]:
    """Columns (in preference order) that each raise the rank, until ``need`` are chosen."""
    chosen: list[int] = []
    scale = max(1e-300, float(np.max(np.abs(columns)))) if columns.size else 1.0
    for j in order:
        if len(chosen) == need:
            break
        trial = columns[:, chosen + [j]]
        sv = np.linalg.svd(trial, compute_uv=False)
        if sv[-1] > 1e-7 * scale:
            chosen.append(j)
    return chosen


def choose_split(model: MechanicalModel, pieces: ConstrainedPieces, q0: np.ndarray, p: np.ndarray,
                 independent: list[str] | None = None) -> Split:
    """Dependent speeds by rank at q0 in the order: massless coordinates, coordinates that appear nowhere but
    in rates (translations first, then angles from the last), then the rest in file order; never one the user
    named independent. Holonomic dependents among the dependent speeds' coordinates. Then the ignorable ones."""
    names = model.coordinates
    n, m, mh = pieces.n, pieces.m, pieces.mh
    forced = list(independent or [])
    for c in forced:
        if c not in names:
            raise InputError(f"--independent {c}: unknown coordinate{model.doc.suggest(c, names)}")
    v = pieces.evaluate(q0, np.zeros(n), np.zeros(n), np.zeros(m), p)
    M, A = v["M"], v["A"]
    Mscale = max(1e-300, float(np.max(np.abs(M))))
    massless = [i for i in range(n) if np.max(np.abs(M[i])) <= 1e-12 * Mscale]
    absent = [i for i in _absent(pieces, p) if i not in massless]
    translations = [i for i in absent if not model.angles.get(names[i], False)]
    angles = [i for i in reversed(absent) if model.angles.get(names[i], False)]
    order = massless + translations + angles + [i for i in range(n) if i not in massless + absent]
    order = [i for i in order if names[i] not in forced]
    dep = _greedy(A, order, m)
    if len(dep) < m:
        why = (f" with {', '.join(forced)} independent" if forced else "")
        rank = int(np.linalg.matrix_rank(A)) if A.size else 0
        hint = (f"; their rank is {rank} of {m} rows: keep independent ones only (a rolling constraint's "
                f"`components:` lists the ground axes it holds, e.g. [x, y] on a level floor; two wheels on one axle "
                f"share their sideways row)" if rank < m else "")
        raise AnalysisError(f"the velocity constraints cannot be solved for {m} dependent speeds at the initial "
                            f"state{why} (redundant or singular constraint rows there){hint}")
    elim: list[int] = []
    if mh:
        Phi_q = v["Eq"][n + 2 * m:, :]
        elim = _greedy(Phi_q, [i for i in order if i in dep] + [i for i in order if i not in dep], mh)
        if len(elim) < mh:
            raise AnalysisError("the holonomic constraints cannot be solved for dependent coordinates at the "
                                "initial state (redundant or singular rows there)")
    indep = [i for i in range(n) if i not in dep]
    split = Split([names[i] for i in indep], [names[i] for i in dep], [names[i] for i in elim], [], [])
    ignorable = _ignorable(model, pieces, split, p)
    split.ignorable = [c for c in names if c in ignorable]
    split.shape = [c for c in names if c not in ignorable]
    return split


def _absent(pieces: ConstrainedPieces, p: np.ndarray) -> list[int]:
    """Coordinates on which neither M, f nor Phi depend (d(M a - f)/dq and dPhi/dq vanish at random states with
    lambda = 0): a wheel's angle, a position on the ground."""
    n, m = pieces.n, pieces.m
    rng = np.random.default_rng(23)
    total = np.zeros(n)
    rows = list(range(n)) + list(range(n + 2 * m, pieces.size))
    for _ in range(3):
        v = pieces.evaluate(rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), np.zeros(m), p)
        block = np.abs(v["Eq"][rows])
        total = np.maximum(total, block.max(axis=0) / max(1e-300, float(block.max())) if block.size else 0.0)
    return [i for i in range(n) if total[i] <= 1e-12]


def _ignorable(model: MechanicalModel, pieces: ConstrainedPieces, split: Split, p: np.ndarray) -> set[str]:
    """Coordinates whose shift leaves the reduced equations (the other rates and the independent accelerations,
    with the dependent speeds solved from the constraints) unchanged at random states on the constraints."""
    names = model.coordinates
    n, m = pieces.n, pieces.m
    rng = np.random.default_rng(17)
    states = []
    for _ in range(3):
        q = rng.uniform(-0.6, 0.6, n)
        q = _onto_holonomic(pieces, split, q, p)
        if q is None:
            continue
        states.append((q, rng.uniform(-1.0, 1.0, len(split.independent))))
    if not states:
        return set()
    v0 = pieces.evaluate(states[0][0], np.zeros(n), np.zeros(n), np.zeros(m), p)
    Phi_q = v0["Eq"][n + 2 * m:, :]
    candidates = [c for i, c in enumerate(names) if c not in split.eliminated
                  and not (Phi_q.size and np.max(np.abs(Phi_q[:, i])) > 0)]
    found = set()
    for c in candidates:
        k = names.index(c)
        others = [i for i in range(n) if names[i] not in candidates]
        same = True
        for q, uI in states:
            base = _quotient(pieces, split, q, uI, p, others)
            shifted = q.copy()
            shifted[k] += rng.uniform(0.5, 1.5)
            moved = _quotient(pieces, split, shifted, uI, p, others)
            if base is None or moved is None or np.max(np.abs(base - moved)) > ZERO * (1 + np.max(np.abs(base))):
                same = False
                break
        if same:
            found.add(c)
    return found


def speeds(pieces: ConstrainedPieces, split: Split, names: list[str], q: np.ndarray, uI: np.ndarray,
           p: np.ndarray) -> np.ndarray:
    """All rates from the independent ones: A_D u_D = -(A_I u_I + c)."""
    n, m = pieces.n, pieces.m
    I = [names.index(c) for c in split.independent]
    D = [names.index(c) for c in split.dependent]
    u = np.zeros(n)
    u[I] = uI
    v = pieces.evaluate(q, u, np.zeros(n), np.zeros(m), p)
    g = v["E"][n + m:n + 2 * m]  # A_I u_I + c (u_D = 0 here)
    u[D] = np.linalg.solve(v["A"][:, D], -g)
    return u


def _quotient(pieces, split, q, uI, p, others) -> np.ndarray | None:
    names_all = pieces.names
    try:
        u = speeds(pieces, split, names_all, q, uI, p)
        a, _lam = pieces.accelerations(q, u, p)
    except np.linalg.LinAlgError:
        return None
    I = [names_all.index(c) for c in split.independent]
    return np.concatenate([u[others], a[I]])


def _onto_holonomic(pieces: ConstrainedPieces, split: Split, q: np.ndarray, p: np.ndarray) -> np.ndarray | None:
    """q with its eliminated coordinates moved onto Phi = 0 (Newton), None if that fails."""
    if not pieces.mh:
        return q
    names = pieces.names
    n, m = pieces.n, pieces.m
    D = [names.index(c) for c in split.eliminated]
    q = q.copy()
    for _ in range(40):
        v = pieces.evaluate(q, np.zeros(n), np.zeros(n), np.zeros(m), p)
        phi = v["E"][n + 2 * m:]
        if np.max(np.abs(phi)) < 1e-13:
            return q
        J = v["Eq"][n + 2 * m:, :][:, D]
        try:
            q[D] -= np.linalg.solve(J, phi)
        except np.linalg.LinAlgError:
            return None
    return q if np.max(np.abs(phi)) < 1e-10 else None


# ----------------------------------------------------------------------------------------- steady motions
class NonholonomicProblem(EquilibriumProblem):
    """The augmented steady-motion equations (see the module docstring) with the interface of EquilibriumProblem
    (multistart, continuation and sweeps use it unchanged)."""

    @cached_property
    def residual_count(self) -> int:
        """Its rows: dynamics (n, one per coordinate, as residual_exprs'), velocity constraints and their rates
        (m each), holonomic constraints (mh); equation_scales measures each."""
        return self.pieces.size

    @property
    def blocks(self) -> tuple[list[int], list[int]]:
        """(rows, unknowns) in blocks of one kind each (equation_scales: a size at 1e-12 of its block's largest is
        rounding): dynamics, velocity constraints, their rates, holonomic constraints; shape coordinates, free
        rates, dependent rates, their rates, multipliers. A dependent rate solved where it vanishes (a bicycle's
        der(y) heading along x) comes out at 1e-15, which is no size."""
        nd = len(self.dependent_rates)
        return [self.n, self.m, self.m, self.mh], [self.nq, len(self.rate_unknowns), nd, nd, self.m]

    @cached_property
    def deflation_scales(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, sizes) in which a family's direction is solved (_deflate and newton.c's mechsys_linearize): the
        equations' own sizes at the file's parameters where they are far from 1 (newton_scales), else ones. A MEMS
        disk's dynamics rows (1e-18 kg m^2/s^2) beside its 3e-5 m constraint rows lost the direction in the least
        squares, and its family's zero eigenvalue was left in ('undecided')."""
        rows, sizes = newton_scales(self, parameter_values(self.model))
        return np.broadcast_to(rows, (self.pieces.size,)).copy(), np.broadcast_to(sizes, (len(self.unknowns),)).copy()

    def __init__(self, model: MechanicalModel, given: list[str] | None = None, solve: list[str] | None = None,
                 independent: list[str] | None = None, method: str = "kane") -> None:
        self.model = model
        self.method = method
        self.pieces = constrained_pieces(model, method)
        refuse_time_dependence(model, method, "steady motions")
        names = model.coordinates
        p = parameter_values(model)
        q0 = np.array([model.doc.initial.get(c, 0.0) for c in names], dtype=float)
        self.split = _cached_split(model, self.pieces, q0, p, independent)
        split = self.split
        self.angles = model.angles
        self.n, self.m, self.mh = self.pieces.n, self.pieces.m, self.pieces.mh
        given = list(given or [])
        for c in given:
            if c not in names:
                raise InputError(f"--given {c}: unknown coordinate{model.doc.suggest(c, names)}")
            if c in split.ignorable:
                raise InputError(f"--given {c}: {c} is ignorable (the reduced equations do not depend on it), so "
                                 "its value does not select a steady motion")
            if c in split.eliminated:
                raise InputError(f"--given {c}: {c} follows from the holonomic constraints; give an independent "
                                 "coordinate instead")
        self.given = {c: float(model.doc.initial.get(c, 0.0)) for c in given}
        group = [c for c in split.independent if c in split.ignorable]
        freed = []
        for item in solve or []:
            c = item[4:-1].strip() if item.startswith("der(") and item.endswith(")") else item
            if c not in group:
                raise InputError(f"--solve {item}: not the independent rate of an ignorable coordinate (choose "
                                 f"from {', '.join(f'der({g})' for g in group) or 'none'})")
            freed.append(c)
        self.free = [c for c in split.shape if c not in self.given]
        self.eliminated = [c for c in split.eliminated if c in self.free]
        self.nq = len(self.free)
        self.cyclic = list(split.ignorable)
        self.rate_unknowns = [c for c in group if c in freed]
        self.fixed_rates = {c: float(model.doc.initial_rate.get(c, 0.0)) for c in group if c not in freed}
        self.dependent_rates = [c for c in split.dependent if c in split.ignorable]
        self.lam = tuple(self.pieces.lam)
        self._index = {c: i for i, c in enumerate(names)}
        # every shape coordinate may be --given: the multipliers (a velocity constraint at least) remain unknowns

    # the base class's symbolic residual is replaced by the compiled augmented one
    @cached_property
    def unknowns(self) -> list[str]:
        return self.unknown_names

    @cached_property
    def unknown_names(self) -> list[str]:
        return (list(self.free) + [f"der({c})" for c in self.rate_unknowns]
                + [f"der({c})" for c in self.dependent_rates] + [f"der(der({c}))" for c in self.dependent_rates]
                + [str(s) for s in self.lam])

    @cached_property
    def linear_rates(self) -> bool:
        return False

    # ------------------------------------------------------------------------------------- state maps
    @cached_property
    def _layout(self) -> tuple[np.ndarray, np.ndarray]:
        """Where the entries of z (unknown_names, multipliers excluded) go in the stacked (q, u, a) of 3n entries."""
        ix, n = self._index, self.n
        where = ([ix[c] for c in self.free] + [n + ix[c] for c in self.rate_unknowns]
                 + [n + ix[c] for c in self.dependent_rates] + [2 * n + ix[c] for c in self.dependent_rates])
        return np.array(where, dtype=int), np.arange(len(where))

    def full_state(self, z: np.ndarray, values: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(q, u, a, lambda) of the unknown vector z; values=False: of a direction (given values left at 0)."""
        ix, n = self._index, self.n
        qua = np.zeros(3 * n)
        if values:
            for c, val in self.given.items():
                qua[ix[c]] = val
            for c, val in self.fixed_rates.items():
                qua[n + ix[c]] = val
        where, k = self._layout
        z = np.asarray(z, dtype=float)
        qua[where] = z[k]
        return qua[:n], qua[n:2 * n], qua[2 * n:], z[len(k):len(k) + self.m]

    @cached_property
    def _gather(self) -> tuple[np.ndarray, np.ndarray]:
        """dE/dz as (index, sign) into a point's raw output: d/dq and d/du from the Jacobian block, d/da from M
        (rows of R) and A (rows of S), d/dlambda = -A^T (rows of R); the index of the trailing zero elsewhere."""
        n, m, pieces = self.n, self.m, self.pieces
        size = pieces.size
        index = np.full((size, 3 * n + m), pieces._full_size)
        sign = np.ones((size, 3 * n + m))
        rows, cols = np.arange(size)[:, None], np.arange(2 * n)[None, :]
        index[:, :2 * n] = pieces._outputs + rows * 2 * n + cols
        M0, A0 = pieces.layout["M"][0], pieces.layout["A"][0]
        index[:n, 2 * n:3 * n] = M0 + np.arange(n)[:, None] * n + np.arange(n)[None, :]
        index[n:n + m, 2 * n:3 * n] = A0 + np.arange(m)[:, None] * n + np.arange(n)[None, :]
        index[:n, 3 * n:] = A0 + np.arange(m)[None, :] * n + np.arange(n)[:, None]
        sign[:n, 3 * n:] = -1.0
        keep = np.concatenate([self._layout[0], 3 * n + np.arange(m)])
        return index[:, keep], sign[:, keep]

    @property
    def newton_path(self) -> str:
        """"python", or "compiled" and the compiler of the pieces' program (native.quick_compiler)."""
        return f"compiled-{Path(native.quick_compiler()).name}" if self._compiled is not None else "python"

    @property
    def _compiled(self):
        """(the pieces' compiled program, newton.c's library), or None without them (no C compiler)."""
        program = self.pieces._native
        lib = native.newton_library() if program is not None else None
        return None if lib is None else (program, lib)

    def compiled_newton(self, p: np.ndarray) -> native.CompiledNewton | None:
        """The multistart's deflated Newton as compiled code over the pieces' program (numeric/newton.c) at the
        parameters p and the current given values and rates; None without the compiled pieces or a compiler."""
        if self._compiled is None:
            return None
        program, lib = self._compiled
        n, m = self.n, self.m
        nz = len(self.unknowns)
        q, u, a, lam = self.full_state(np.zeros(nz))
        base = np.concatenate([q, u, a, lam, np.asarray(p, dtype=float)])
        last = self.__dict__.get("_compiled_newton")
        if last is None or last[0] != base.tobytes():  # one per search: its starts share the given values and p
            pos = np.concatenate([self._layout[0], 3 * n + np.arange(m)])
            index, sign = self._gather
            last = self.__dict__["_compiled_newton"] = (
                base.tobytes(), native.CompiledNewton(lib, program, "mechsys_values", "mechsys_full", base, pos,
                                                      index, sign, self.is_angle()))
        return last[1]

    def compiled_corrector(self, p_ref: float, P: np.ndarray, dP: np.ndarray, drates: np.ndarray, D: np.ndarray,
                           rows: list[int] | slice) -> Compiled | None:
        """The continuation's corrector as compiled code (numeric/newton.c) for a sweep's F(x, p) = E(D x)[rows]
        whose parameters P and given rates move affinely with p (slopes dP and drates, fixed_rates order; the given
        rates now are those at p_ref): a factory (s, r, tol) -> corrector (continuation.Compiled); None without
        the compiled pieces or a compiler."""
        if self._compiled is None:
            return None
        program, lib = self._compiled
        n, m, ix = self.n, self.m, self._index
        nz = len(self.unknowns)
        base = np.concatenate([*self.full_state(np.zeros(nz)), np.asarray(P, dtype=float)])
        slope = np.zeros(len(base))
        for c, d in zip(self.fixed_rates, drates):
            slope[n + ix[c]] = d
        dP = np.asarray(dP, dtype=float)
        slope[3 * n + m:] = dP
        pos = np.concatenate([self._layout[0], 3 * n + np.arange(m)])
        slope[pos] = 0.0
        index, sign = self._gather
        fp_params = bool(np.linalg.norm(dP) > 0 and np.any(dP[self._parameters_read]))  # Fp_along's test
        rows = np.arange(self.pieces.size)[rows]
        if len(rows) != nz:  # not a square system: the Python loop's least squares
            return None

        def make(s: np.ndarray, r: np.ndarray, tol: float) -> native.CompiledCorrector:
            return native.CompiledCorrector(lib, program, "mechsys_values", "mechsys_full", base=base, slope=slope,
                                            p_ref=p_ref, pos=pos, D=D, s=s, r=r, rows=rows, index=index,
                                            sign=sign, n=n, jac_offset=self.pieces._outputs, pfirst=3 * n + m,
                                            fp_params=fp_params, tol=tol)
        return make

    @cached_property
    def families(self) -> list[str]:
        """The families of steady motions a linearization deflates: der(rate) of each given rate, then each --given
        coordinate (the order of SteadyLinearization.families and undeflated)."""
        return [f"der({c})" for c in self.fixed_rates] + list(self.given)

    @cached_property
    def compiled_linearization(self) -> native.CompiledLinearization | None:
        """linearize_steady's numeric steps as compiled code (numeric/newton.c) for this split and these families;
        None without the compiled pieces or a compiler, or with no state to linearize (numpy then)."""
        pieces, split, n, m = self.pieces, self.split, self.n, self.m
        ix = _indices(pieces.names, split)
        xi, nu = [pieces.names[i] for i in ix.rows_q], list(split.independent)
        if self._compiled is None or not xi + nu:
            return None
        lib = self._compiled[1]
        index, sign = self._gather
        # a family's direction t = (dq[xi], du[nu]) is read from its dz where z places the entries (full_state)
        src = {int(w): k for k, w in enumerate(self._layout[0])}
        tsrc = [src.get(self._index[x], -1) for x in xi] + [src.get(n + self._index[c], -1) for c in nu]
        column = pieces._outputs + np.arange(pieces.size) * 2 * n  # row starts of dE/d(q, u) in the output
        rhs = [column + n + self._index[c] for c in self.fixed_rates] + [column + self._index[c] for c in self.given]
        tone = ([len(xi) + nu.index(c) if c in nu else -1 for c in self.fixed_rates]
                + [xi.index(c) if c in xi else -1 for c in self.given])
        lists = {"I": ix.independent, "D": ix.dependent, "keep": ix.keep, "elim": ix.eliminated,
                 "rows_q": ix.rows_q, "cols_all": ix.cols_all, "cols_ign": ix.cols_ign}
        sizes = {"n": n, "m": m, "mh": self.mh, "size": pieces.size, "jac": pieces._outputs, "hfirst": n + 2 * m}
        return native.CompiledLinearization(lib, sizes=sizes, lists=lists, index=index, sign=sign,
                                            rhs=np.array(rhs, dtype=int).reshape(-1, pieces.size),
                                            tsrc=np.array(tsrc, dtype=int),
                                            tone=np.array(tone, dtype=int), rtol=LINEARIZATION_RTOL,
                                            full_size=pieces._full_size, scales=self.deflation_scales)

    def _columns(self, v: dict) -> np.ndarray:
        """dE/dz from dE/dq, dE/du and the blocks of a and lambda (one gather from the point's raw output)."""
        index, sign = self._gather
        return v["raw"][index] * sign

    def _at(self, z: np.ndarray, p: np.ndarray) -> dict:
        return self.pieces.evaluate(*self.full_state(z), p)

    def F(self, z: np.ndarray, p: np.ndarray) -> np.ndarray:
        return self.pieces.residual(*self.full_state(z), p)

    def split_singularity(self, z: np.ndarray, p: np.ndarray, rtol: float = 1e-8) -> str | None:
        """The holonomic constraints do not determine the eliminated coordinates at z (their Jacobian in them
        loses rank: the bicycle's front contact frame when the wheel lies flat), or the velocity constraints the
        dependent speeds; None when both are regular (smallest singular value of the block above rtol times the
        largest entry of the constraint rows)."""
        return self.singular_block(self._at(z, p), rtol)

    @cached_property
    def _split_blocks(self) -> list[tuple[str, int, np.ndarray, str]]:
        """(output, first row, columns, text) of the blocks that give the eliminated coordinates (rows of Phi in
        dE/dq) and the dependent speeds (A), in the order split_singularity reports them."""
        n, m, ix = self.n, self.m, self._index
        dep = self.split.dependent
        blocks = [("A", 0, np.array([ix[c] for c in dep], dtype=int),
                   "the velocity constraints do not determine " + ", ".join(f"der({c})" for c in dep))]
        if self.mh:
            elim = self.split.eliminated
            blocks.insert(0, ("Eq", n + 2 * m, np.array([ix[c] for c in elim], dtype=int),
                              "the holonomic constraints do not determine " + ", ".join(elim)))
        return blocks

    def singular_block(self, v: dict, rtol: float) -> str | None:
        """split_singularity on a point's evaluated pieces ``v``."""
        for key, first, cols, text in self._split_blocks:
            rows = v[key][first:]
            block = rows[:, cols]
            # a single entry (one holonomic constraint, one eliminated coordinate) is its own singular value
            smallest = abs(float(block[0, 0])) if block.shape == (1, 1) else \
                np.linalg.svd(block, compute_uv=False)[-1] if block.size else None
            if smallest is None:
                continue
            scale = max(float(np.abs(rows).max(initial=0.0)), 1e-300)
            if not np.isfinite(smallest) or smallest <= rtol * scale:
                return text
        return None

    def J(self, z: np.ndarray, p: np.ndarray) -> np.ndarray:
        return self._columns(self._at(z, p))

    def Fr(self, z: np.ndarray, p: np.ndarray) -> np.ndarray:
        v = self._at(z, p)
        cols = [v["Eu"][:, self._index[c]] for c in self.fixed_rates]
        return np.column_stack(cols) if cols else np.zeros((self.pieces.size, 0))

    def Fp(self, z: np.ndarray, p: np.ndarray) -> np.ndarray:
        """dF/dp, one column per parameter (see Fp_along)."""
        return np.column_stack([self.Fp_along(z, p, np.eye(len(p))[k]) for k in range(len(p))]) if len(p) else \
            np.zeros((self.pieces.size, 0))

    @cached_property
    def _parameters_read(self) -> np.ndarray:
        """Which parameters the residual E reads: the symbols of its expressions (stored with the pieces). A
        bicycle's speed only sets the given rates, so dE/dv = 0 exactly and a speed sweep skips two evaluations per
        Jacobian."""
        return self.pieces.read

    def Fp_along(self, z: np.ndarray, p: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """dF/dp . direction by a central difference (the parameters enter M, f and the constraints everywhere;
        exact derivatives would double the symbolic work for what only a continuation predictor uses)."""
        size = float(np.linalg.norm(direction))
        if size == 0 or not np.any(np.asarray(direction)[self._parameters_read]):
            return np.zeros(self.pieces.size)  # what the difference gives: E does not read these parameters
        h = 1e-6 * max(1.0, float(np.linalg.norm(p))) / size
        return (self.F(z, p + h * direction) - self.F(z, p - h * direction)) / (2 * h)

    def auxiliary_scale(self, roots: list[np.ndarray]) -> np.ndarray:
        """Scale of the unknowns for continuation: 1 for the reported ones (shape coordinates, free rates), the
        largest size seen at the roots for the dependent rates, accelerations and multipliers."""
        D = np.ones(len(self.unknowns))
        k = self.nq + len(self.rate_unknowns)
        if roots and len(D) > k:
            D[k:] = np.maximum(1.0, np.max(np.abs(np.array(roots))[:, k:], axis=0))
        return D

    def extra(self) -> list[float]:
        return []

    def start(self, start: np.ndarray, p: np.ndarray) -> np.ndarray:
        """A start of the Newton iteration from drawn shape coordinates and free rates: the shape moved onto the
        holonomic constraints, the dependent rates solved from the velocity constraints, the dependent
        accelerations and the multipliers by least squares."""
        k = self.nq + len(self.rate_unknowns)
        z = np.concatenate([start[:k], np.zeros(2 * len(self.dependent_rates) + self.m)])
        n, m = self.n, self.m
        if self.mh:
            cols = [self.free.index(c) for c in self.eliminated] or list(range(self.nq))
            for c in self.eliminated:  # not drawn: from the file's configuration
                z[self.free.index(c)] = self.model.doc.initial.get(c, 0.0)
            for _ in range(30):
                v = self._at(z, p)
                phi = v["E"][n + 2 * m:]
                Jq = self._columns(v)[n + 2 * m:, cols]
                if not (np.all(np.isfinite(phi)) and np.all(np.isfinite(Jq))):
                    break
                if np.max(np.abs(phi)) <= 1e-13:
                    break
                z[cols] += np.linalg.lstsq(Jq, -phi, rcond=None)[0]
        nd = len(self.dependent_rates)
        if nd:
            v = self._at(z, p)
            cols = self._columns(v)[n + m:n + 2 * m, k:k + nd]
            z[k:k + nd] += np.linalg.lstsq(cols, -v["E"][n + m:n + 2 * m], rcond=None)[0]
        v = self._at(z, p)
        tail = self._columns(v)[:n + m, k + nd:]
        z[k + nd:] += np.linalg.lstsq(tail, -v["E"][:n + m], rcond=None)[0]
        return z

    def equilibrium(self, z: np.ndarray) -> Equilibrium:
        z = self.normalize(z)
        q, u, a, lam = self.full_state(z)
        ix = self._index
        coords = {c: float(q[ix[c]]) for c in self.split.shape}
        for c in coords:
            if self.angles.get(c, False):
                coords[c] = wrap(coords[c])
        rates = {c: float(u[ix[c]]) for c in self.split.ignorable}
        e = Equilibrium(coords, rates, [float(x) for x in lam])
        e.accelerations = {c: float(a[ix[c]]) for c in self.dependent_rates}
        return e

    def state(self, e: Equilibrium) -> np.ndarray:
        acc = getattr(e, "accelerations", {})
        return np.array([e.coordinates[c] for c in self.free] + [e.rates[c] for c in self.rate_unknowns]
                        + [e.rates[c] for c in self.dependent_rates] + [acc.get(c, 0.0) for c in self.dependent_rates]
                        + list(e.multipliers), dtype=float)

    def point(self, e: Equilibrium) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(q, u, a, lambda) of a steady motion (ignorable coordinates at 0)."""
        return self.full_state(self.state(e))

    # ------------------------------------------------------------------------------------- linearization
    def linearization(self, e: Equilibrium, p: np.ndarray | None) -> SteadyLinearization:
        """linearize_steady, remembered per point: a sweep's eigenvalues and its point verdicts linearize about
        the same points (the key is every number the linearization reads: q, u, a, lambda and the parameters)."""
        p = parameter_values(self.model) if p is None else np.asarray(p, dtype=float)
        key = b"".join(np.asarray(x, dtype=float).tobytes() for x in (*self.point(e), p))
        memo = self.__dict__.setdefault("_linearizations", {})
        if key not in memo:
            if len(memo) >= 20000:
                memo.clear()
            memo[key] = linearize_steady(self, e, p)
        return memo[key]

    def take_linearizations(self) -> dict:
        """The linearizations remembered here, handed over and forgotten (a forked worker's, for its parent)."""
        memo = self.__dict__.get("_linearizations") or {}
        self.__dict__["_linearizations"] = {}
        return memo

    def give_linearizations(self, memo: dict | None) -> None:
        """Remember linearizations a worker computed (same keys: every number they read)."""
        if memo:
            self.__dict__.setdefault("_linearizations", {}).update(memo)

    def pencil(self, e: Equilibrium) -> tuple[np.ndarray, np.ndarray, None]:
        """(A, I): the reduced Jacobian with the structural zero directions removed (continuation's eigenvalues)."""
        lin = self.linearization(e, getattr(self, "current_parameters", None))
        return lin.deflated, np.eye(lin.deflated.shape[0]), None

    def pencil_eigenvalues(self, e: Equilibrium) -> np.ndarray:
        """The eigenvalues of the pencil (A, I) above, as the linearization sorted them."""
        return self.linearization(e, getattr(self, "current_parameters", None)).eigenvalues

    def assess(self, e: Equilibrium, p: np.ndarray) -> None:
        self.current_parameters = p
        lin = self.linearization(e, p)
        vals = lin.eigenvalues
        e.eigenvalues, e.jacobian = vals, lin.jacobian
        e.structural = lin.structural_text()
        if _massless_speeds(lin.M):
            e.eigenvalues, e.jacobian, e.critical = np.zeros(0, complex), None, False
            e.stability = "undecided"
            e.reason = ("coordinate singularity: a combination of the independent speeds moves no mass at this "
                        "steady motion, while the equations of motion are regular elsewhere (e.g. a universal "
                        "joint whose arm lies along its first axis): the coordinates are a singular chart here and "
                        "no verdict is read from them; write the joint so that this position is regular")
            return
        scale = max(1.0, float(np.max(np.abs(vals)))) if len(vals) else 1.0
        tol = 1e-9 * scale
        zero_like = zero_like_eigenvalues(vals, scale)
        e.critical = bool(len(vals) and np.any(zero_like))
        apart = f" ({lin.structural_text()} apart)" if lin.structural else ""
        if np.any(vals.real[~zero_like] > tol):
            e.stability, e.reason = "unstable", f"an eigenvalue has a positive real part{apart}"
        elif len(vals) == 0 or np.max(vals.real) < -tol:
            e.stability, e.reason = ("asymptotically stable",
                                     f"all eigenvalues have negative real parts{apart}: the shape and the speeds "
                                     "return to the steady motion; the ignorable coordinates keep an offset")
        else:
            zero = int(np.sum(zero_like))
            e.stability = "undecided"
            e.reason = (f"{zero} eigenvalue(s) with zero real part (critical case){apart}; the energy arguments "
                        "of holonomic systems do not apply to nonholonomic ones")
            if _conservative(self, p) and _simple_imaginary(vals, tol):
                e.stability = "stable"
                e.reason = (f"{zero} eigenvalue(s) with zero real part{apart}; conservative system with a purely "
                            "oscillatory, simple spectrum: stable in the linear sense")


#: The smallest eigenvalue of the reduced mass matrix scaled to a unit diagonal below which a combination of the
#: independent speeds carries no mass (a ball in a bowl on a universal joint whose arm lies along the joint's first
#: axis: 2e-16, where its eigenvalues, 6e8, were printed with a verdict; 0.3 and more at regular points).
MASSLESS_RTOL = 1e-9


def _massless_speeds(Mr: np.ndarray) -> bool:
    """Whether the reduced mass matrix is singular, measured in each speed's own size (a unit diagonal), so that
    speeds of very different units (a MEMS part beside a metre one) are not mistaken for a singular matrix."""
    if not Mr.size:
        return False
    d = np.sqrt(np.abs(np.diag(Mr)))
    if not np.all(np.isfinite(Mr)) or np.any(d <= 1e-150 * max(1e-300, float(np.max(d)))):
        return bool(np.all(np.isfinite(Mr)))
    scaled = Mr / d[:, None] / d[None, :]
    return float(np.min(np.linalg.eigvalsh((scaled + scaled.T) / 2))) <= MASSLESS_RTOL


def _conservative(problem: NonholonomicProblem, p: np.ndarray) -> bool:
    model = problem.model
    Q = model.generalized_forces
    if Q == sp.zeros(*Q.shape):
        return True
    fn = compile_exprs(list(Q.xreplace({model.t: 0})), list(model.q) + list(model.u) + list(model.parameter_symbols))
    rng = np.random.default_rng(9)
    n = len(model.q)
    return all(np.max(np.abs(fn(*rng.uniform(-2, 2, 2 * n), *p))) <= 1e-12 for _ in range(3))


def _simple_imaginary(vals: np.ndarray, tol: float) -> bool:
    if not len(vals) or np.max(np.abs(vals.real)) > tol:
        return False
    tiny = 1e-6 * max(1.0, float(np.max(np.abs(vals))))
    if np.any(np.abs(vals) <= tiny):
        return False
    osc = sorted(abs(v.imag) for v in vals if v.imag > 0)
    return not any(abs(a - b) <= 1e-7 * max(1.0, a) for a, b in zip(osc[1:], osc[:-1]))


def _cached_split(model, pieces, q0, p, independent) -> Split:
    """The split is chosen once per model object, initial configuration, parameter values and --independent."""
    store = model.__dict__.setdefault("_nonholonomic_split", {})
    key = (tuple(independent or ()), tuple(np.round(q0, 12)), tuple(np.round(p, 12)))
    if key not in store:
        store[key] = choose_split(model, pieces, q0, p, independent)
    return store[key]


# ----------------------------------------------------------------------------------------- linearization
@dataclass
class SteadyLinearization:
    """Linear equations about a steady motion in independent shape coordinates xi and independent speeds nu:
    xi' = W xi + V nu (kinematics), Mr nu' + C nu + K xi = B tau (Kane's form: rows are the independent speeds,
    tau the generalized forces along them). ``jacobian`` is the first-order matrix of (xi, nu); ``deflated`` is
    it with the structural zero directions of the families removed (the ignorable coordinates are not states)."""

    coordinates: list[str]  # xi: independent shape coordinates
    speeds: list[str]  # nu: independent speeds (coordinate names)
    jacobian: np.ndarray
    deflated: np.ndarray
    eigenvalues: np.ndarray
    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    W: np.ndarray
    V: np.ndarray
    ignorable: list[str]
    families: list[str]  # der(rate) or coordinate given, whose family direction was deflated
    undeflated: list[str] = field(default_factory=list)  # those whose direction is not a zero eigenvector

    @property
    def structural(self) -> list[str]:
        return list(self.ignorable) + list(self.families)

    def structural_text(self) -> str:
        parts = []
        if self.ignorable:
            parts.append(f"{len(self.ignorable)} structural zero eigenvalue(s) of the ignorable coordinates "
                         f"{', '.join(self.ignorable)}")
        if self.families:
            parts.append(f"{len(self.families)} of the family of steady motions along {', '.join(self.families)}")
        return " and ".join(parts)

    @property
    def states(self) -> list[str]:
        return list(self.coordinates) + [f"der({c})" for c in self.speeds]

    def second_order(self, names: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """M, C, K over the coordinates ``names`` (their rates must be independent speeds and their equations must
        not involve the other states): the form M q'' + C q' + K q = tau of a benchmark."""
        for c in names:
            if c not in self.coordinates or c not in self.speeds:
                raise InputError(f"--independent {c}: not an independent shape coordinate whose rate is an "
                                 f"independent speed here (shape: {', '.join(self.coordinates) or 'none'}; speeds: "
                                 f"{', '.join(self.speeds)})")
        xi = [self.coordinates.index(c) for c in names]
        nu = [self.speeds.index(c) for c in names]
        others_xi = [k for k in range(len(self.coordinates)) if k not in xi]
        others_nu = [k for k in range(len(self.speeds)) if k not in nu]
        rows = self.jacobian[len(self.coordinates) + np.array(nu, dtype=int)] if nu else np.zeros((0, 0))
        scale = max(1.0, float(np.max(np.abs(self.jacobian))))
        coupled = [self.coordinates[k] for k in others_xi if np.max(np.abs(rows[:, k])) > 1e-10 * scale]
        coupled += [f"der({self.speeds[k]})" for k in others_nu
                    if np.max(np.abs(rows[:, len(self.coordinates) + k])) > 1e-10 * scale]
        if coupled:
            raise AnalysisError(f"the equations of {', '.join(names)} involve {', '.join(coupled)} at this steady "
                                "motion: there is no second-order form over these coordinates alone; list those "
                                "too with --independent, or read the first-order matrix A")
        return (self.M[np.ix_(nu, nu)], self.C[np.ix_(nu, nu)], self.K[np.ix_(nu, xi)])


@dataclass(frozen=True)
class _Indices:
    """Positions linearize_steady reads, per split: independent and dependent speeds, kept and eliminated
    coordinates, the shape coordinates' rows and their columns among the kept, the ignorable ones' columns."""

    independent: list[int]
    dependent: list[int]
    keep: list[int]
    eliminated: list[int]
    rows_q: list[int]
    cols_all: list[int]
    cols_ign: list[int]


def _indices(names: list[str], split: Split) -> _Indices:
    """The positions of a split, worked out once (a sweep linearizes thousands of points with one split)."""
    key = (tuple(names), repr(split))
    memo = _INDICES
    if key not in memo:
        keep = [i for i in range(len(names)) if names[i] not in split.eliminated]
        rows_q = [names.index(c) for c in split.shape if c not in split.eliminated]
        memo[key] = _Indices([names.index(c) for c in split.independent],
                             [names.index(c) for c in split.dependent], keep,
                             [names.index(c) for c in split.eliminated], rows_q, [keep.index(i) for i in rows_q],
                             [keep.index(names.index(c)) for c in split.ignorable])
    return memo[key]


_INDICES: dict[tuple, _Indices] = {}


#: The smallest singular value, relative to the largest constraint entry, of the blocks that give the dependent
#: speeds and the eliminated coordinates, below which a steady motion has no linearization. On the bicycle's
#: steady turns as v -> 0 the eigenvalues' error is about 2e-8 of their size at 1e-6, 4e-5 at 2.5e-8.
LINEARIZATION_RTOL = 1e-6


_SINGULAR_SOLVE = ("the constraints or the saddle-point system are singular at this steady motion: choose other "
                   "independent speeds with --independent")
_IGNORABLE_ENTERS = ("the reduced equations depend on an ignorable coordinate at this steady motion (internal check of "
                     "the split failed)")


def _not_linearizable(why: str) -> AnalysisError:
    return AnalysisError(f"{why} to the precision a linearization needs (a singular value below "
                         f"{LINEARIZATION_RTOL:g} of the largest entry), so its linearization is not defined here: "
                         "other independent speeds (--independent) may avoid this")


def linearize_steady(problem: NonholonomicProblem, e: Equilibrium, p: np.ndarray | None = None) -> SteadyLinearization:
    """The linearization about a steady motion on the constraint manifold (module docstring): compiled
    (numeric/newton.c, the same steps) with the compiled pieces, else in numpy."""
    p = parameter_values(problem.model) if p is None else p
    pieces, split = problem.pieces, problem.split
    names = pieces.names
    ix = _indices(names, split)
    v = pieces.evaluate(*problem.point(e), p)
    run = problem.compiled_linearization
    if run is not None:
        status, Jw, Mr, Kf, Cf, deflated, flags = run(v["raw"])
        if status in (1, 2):  # the singular-value test of a block (singular_block's order)
            raise _not_linearizable(problem._split_blocks[0 if status == 1 else -1][3])
        if status:
            raise AnalysisError({10: _SINGULAR_SOLVE, 11: _IGNORABLE_ENTERS}.get(
                status, "the equations are not finite at this steady motion"))
        given = problem.families
        families = [g for g, f in zip(given, flags) if f]
        undeflated = [g for g, f in zip(given, flags) if not f]
    else:
        Jw, Mr, Kf, Cf = _reduced(problem, v)
        families, undeflated, deflated = _deflate(problem, e, p, Jw, [names[i] for i in ix.rows_q],
                                                  split.independent)
    vals = np.linalg.eigvals(deflated) if deflated.size else np.zeros(0, complex)
    vals = vals[np.lexsort((vals.imag, vals.real))]
    nxi = len(ix.rows_q)
    return SteadyLinearization([names[i] for i in ix.rows_q], list(split.independent), Jw, deflated, vals,
                               Mr, Cf, Kf, Jw[:nxi, :nxi], Jw[:nxi, nxi:], list(split.ignorable), families,
                               undeflated)


def _reduced(problem: NonholonomicProblem, v: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Jw, Mr, Kf, Cf of the linearization from a point's evaluated pieces ``v`` (numpy; newton.c's
    mechsys_linearize takes the same steps)."""
    pieces, split = problem.pieces, problem.split
    n, m, mh = pieces.n, pieces.m, pieces.mh
    Eq, Eu, M, A = v["Eq"], v["Eu"], v["M"], v["A"]
    # the test that drops a search's roots as coordinate singularities (drop_singular), with a margin: a branch
    # followed towards such a point (the bicycle's steady turns as v -> 0) reaches blocks singular to round-off,
    # which the solves below do not detect (their eigenvalues were 7e7 at the bicycle's v = 0), and before that,
    # nearly singular ones, whose eigenvalues lose digits about as the square of the block's condition number
    why = problem.singular_block(v, LINEARIZATION_RTOL)
    if why is not None:
        raise _not_linearizable(why)
    ix = _indices(pieces.names, split)
    I, D, keep = ix.independent, ix.dependent, ix.keep
    # accelerations from the differentiated saddle-point system (one factorization for d/dq and d/du)
    K = np.zeros((n + m, n + m))
    K[:n, :n], K[:n, n:], K[n:, :n] = M, -A.T, A
    try:
        P = -np.linalg.solve(K, np.hstack([Eq[:n + m], Eu[:n + m]]))[:n]
        Pq, Pu = P[:, :n], P[:, n:]
        Uq = np.zeros((n, n))
        UI = np.zeros((n, len(I)))
        UI[I, range(len(I))] = 1.0
        if m:
            AD = A[:, D]
            W = -np.linalg.solve(AD, np.hstack([Eq[n + m:n + 2 * m], A[:, I]]))
            Uq[D], UI[D] = W[:, :n], W[:, n:]
        Qm = np.zeros((n, len(keep)))
        Qm[keep, range(len(keep))] = 1.0
        if mh:
            Phi_q = Eq[n + 2 * m:]
            Qm[ix.eliminated] = -np.linalg.solve(Phi_q[:, ix.eliminated], Phi_q[:, keep])
    except np.linalg.LinAlgError:
        raise AnalysisError(_SINGULAR_SOLVE) from None
    dq_dxi = Uq @ Qm  # rates per independent coordinate
    rows_q, cols_all, cols_ign = ix.rows_q, ix.cols_all, ix.cols_ign
    top = np.hstack([dq_dxi[rows_q][:, cols_all], UI[rows_q]])
    acc_q = (Pq @ Qm + Pu @ dq_dxi)[I]
    bottom = np.hstack([acc_q[:, cols_all], (Pu @ UI)[I]])
    Jw = np.vstack([top, bottom])
    # the ignorable coordinates must not enter: their columns vanish (a check of the split)
    ign = np.vstack([dq_dxi[rows_q][:, cols_ign], acc_q[:, cols_ign]]) if cols_ign else np.zeros((0, 0))
    scale = max(1.0, float(np.max(np.abs(Jw)))) if Jw.size else 1.0
    if ign.size and np.max(np.abs(ign)) > 1e-7 * scale:
        raise AnalysisError(_IGNORABLE_ENTERS)
    Mr = UI.T @ M @ UI
    nxi = len(rows_q)
    return Jw, Mr, -Mr @ Jw[nxi:, :nxi], -Mr @ Jw[nxi:, nxi:]


def _deflate(problem: NonholonomicProblem, e: Equilibrium, p: np.ndarray, Jw: np.ndarray, xi: list[str],
             nu: list[str]) -> tuple[list[str], list[str], np.ndarray]:
    """Remove the zero eigenvalue of each family of steady motions exactly: its direction t (the derivative of the
    steady motion along a given rate or a --given coordinate, from the steady-motion equations) satisfies
    Jw t = 0; in the basis [t, complement] the first columns vanish and the rest is the deflated matrix."""
    given = problem.families
    if not given or not Jw.size:
        return [], [], Jw
    z = problem.state(e)
    v = problem._at(z, p)
    Jz = problem._columns(v)
    ix = problem._index
    rhs = np.column_stack([v["Eu"][:, ix[c]] for c in problem.fixed_rates]
                          + [v["Eq"][:, ix[c]] for c in problem.given])
    rows, sizes = problem.deflation_scales
    dz = -sizes[:, None] * np.linalg.lstsq(Jz / rows[:, None] * sizes, rhs / rows[:, None], rcond=None)[0] \
        if Jz.size else np.zeros((0, rhs.shape[1]))
    tangents, families, undeflated = [], [], []
    scale = max(1.0, float(np.max(np.abs(Jw))))
    for j, name in enumerate(given):
        dq, du, _da, _dl = problem.full_state(dz[:, j], values=False)
        if name.startswith("der("):
            du[ix[name[4:-1]]] = 1.0  # along the given rate itself
        else:
            dq[ix[name]] = 1.0  # along the given coordinate itself
        t = np.concatenate([[dq[ix[x]] for x in xi], [du[ix[s]] for s in nu]])
        if np.linalg.norm(Jw @ t) <= 1e-8 * scale * max(1e-300, np.linalg.norm(t)):
            tangents.append(t / np.linalg.norm(t))
            families.append(name)
        else:
            undeflated.append(name)
    if not tangents:
        return [], undeflated, Jw
    # in the basis [T, C], C an orthonormal basis of T's orthogonal complement, the rows of the inverse that belong
    # to C are C^T (C^T T = 0, C^T C = I): the block left once T's columns vanish is C^T Jw C
    C = _complement(np.column_stack(tangents))
    return families, undeflated, C.T @ Jw @ C


def _complement(T: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the orthogonal complement of the columns of T (n x k, independent): the last n - k
    columns of the product of the Householder reflections that make T upper triangular."""
    n, k = T.shape
    Q, A = np.eye(n), np.array(T, dtype=float)
    for j in range(k):
        w = A[j:, j].copy()
        w[0] += np.copysign(np.linalg.norm(w), w[0])
        beta = float(w @ w)
        if beta == 0.0:
            continue
        A[j:, j:] -= np.outer(w, (2.0 / beta) * (w @ A[j:, j:]))
        Q[:, j:] -= np.outer(Q[:, j:] @ w, (2.0 / beta) * w)
    return Q[:, k:]
