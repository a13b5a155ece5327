"""Linearization about an equilibrium: M q'' + (C + G) q' + (K + N) q = B u, from exact symbolic derivatives."""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Iterator

import numpy as np
import sympy as sp

from mechsys.mechanics.dag import Substitution
from mechsys.mechanics.model import INTERNAL_METHOD, MechanicalModel
from mechsys.numeric import cache
from mechsys.numeric.runtime import check_source, function_from_code, rows_function_from_code

if TYPE_CHECKING:
    from mechsys.analysis.equilibrium.equilibria import Equilibrium


class LinearPieces:
    """Compiled M, df/dq, df/du, the constraint Jacobian and d(A^T lambda)/dq of a model (t = 0), evaluated at
    a state (q, u, lambda) for a parameter vector. The generated code is cached on disk, keyed by the model's
    structure (parameters stay symbols), so a second command on the model derives no Jacobian and runs no CSE."""

    KEYS = ("M", "dfdq", "dfdu", "A")

    def __init__(self, model: MechanicalModel) -> None:
        self.model = model
        self.n = len(model.q)
        self.m = len(model.kin.constraints)
        self.lam = list(sp.symbols(f"lambda1:{self.m + 1}", real=True)) if self.m else []
        args = [*model.q, *model.u, *self.lam, *model.parameter_symbols]
        key = cache.model_key(model, "linear-pieces")
        entry = cache.load(key)
        if not self._usable(entry):
            source = self._forward(args)
            layout, start = {}, 0
            for name, shape in self._shapes().items():
                layout[name] = [start, shape]
                start += shape[0] * shape[1]
            entry = {"layout": layout, "source": source}
            cache.store(key, entry)
        self.layout = {name: (int(start), tuple(shape)) for name, (start, shape) in entry["layout"].items()}
        self._code = check_source(entry["source"])
        self._fn = function_from_code(self._code)
        self._evaluated: dict[tuple, np.ndarray] = {}  # outputs evaluated ahead (evaluated_ahead), by exact inputs

    def _shapes(self) -> dict[str, list[int]]:
        n, m = self.n, self.m
        return {"M": [n, n], "dfdq": [n, n], "dfdu": [n, n], "A": [m, n]}

    def _forward(self, args: list) -> str:
        """Python source returning M, df/dq, df/du and A (KEYS order, row by row) at t = 0 from Kane's equations
        (INTERNAL_METHOD): one light CSE of f + A^T lambda, M and A, and the Jacobian by forward-mode
        differentiation of its shared subexpressions (lambdify.differentiate_program), not sympy's derivatives of
        whole entries CSE'd afterwards (the 40-link chain's blocks: 18.6 s instead of 39.5 s). df/du is the
        force's: A, the coefficients of the rates in velocity constraints linear in them, does not contain them."""
        from mechsys.numeric.lambdify import differentiate_program, shared_program, value_and_jacobian_sources

        model, n = self.model, self.n
        eq = model.equations(INTERNAL_METHOD)
        at_t0 = Substitution({model.t: 0}, model.diff.symbols).matrix
        force = at_t0(eq.f + (eq.A.T * sp.Matrix(self.lam) if self.m else sp.zeros(n, 1)))
        M, A = at_t0(eq.M), at_t0(eq.A)
        wrt = [*model.q, *model.u]
        program = differentiate_program(shared_program(list(force) + list(M) + list(A), args, wrt, light=True),
                                        wrt, n)
        J, w = program.jacobian, 2 * n
        dfdq = [J[i * w + j] for i in range(n) for j in range(n)]
        dfdu = [J[i * w + n + j] for i in range(n) for j in range(n)]
        outputs = program.outputs[n:]
        program.outputs = outputs[:n * n] + dfdq + dfdu + outputs[n * n:]
        program.jacobian = []
        return value_and_jacobian_sources((), args, (), program=program)[1]

    def _usable(self, entry: dict | None) -> bool:
        """A stored entry whose layout is this model's (every block in order, with its shape)."""
        shapes = self._shapes()
        try:
            layout, start = entry["layout"], 0
            for name in self.KEYS:
                if layout[name] != [start, shapes[name]]:
                    return False
                start += shapes[name][0] * shapes[name][1]
            return list(layout) == list(self.KEYS) and isinstance(entry["source"], str)
        except (TypeError, KeyError):
            return False

    @cached_property
    def symbolic(self) -> dict[str, sp.Matrix]:
        """The symbolic blocks at t = 0 from Lagrange's equations (as `--linearize` prints them)."""
        return self.blocks("lagrange")

    def blocks(self, method: str) -> dict[str, sp.Matrix]:
        """The symbolic blocks at t = 0 from one formulation's equations (Jacobians by the model's memoized
        differentiation: sympy's expressions). The compiled blocks come from Kane's (INTERNAL_METHOD): the same
        equations, whose f is built from accelerations and stays compact where Lagrange's, differentiated from T,
        swells (the 10-link chain: 2.9 s instead of 16 s, and a fifth of the time per evaluation)."""
        model = self.model
        eq = model.equations(method)
        at_t0 = Substitution({model.t: 0}, model.diff.symbols).matrix  # once per shared subexpression
        force = eq.f + (eq.A.T * sp.Matrix(self.lam) if self.m else sp.zeros(self.n, 1))

        def jacobian(rows: sp.Matrix, wrt: list) -> sp.Matrix:
            return sp.Matrix(rows.shape[0], len(wrt), lambda i, j: model.diff(rows[i], wrt[j]))

        return {"M": at_t0(eq.M), "dfdq": at_t0(jacobian(force, model.q)), "dfdu": at_t0(jacobian(eq.f, model.u)),
                "A": at_t0(eq.A)}

    def evaluate(self, q: np.ndarray, u: np.ndarray, lam: np.ndarray, p: np.ndarray) -> dict[str, np.ndarray]:
        inputs = _exact_key(q, u, lam, p)
        ahead = self._evaluated.get(inputs) if inputs is not None else None
        out = ahead.copy() if ahead is not None else np.asarray(self._fn(*q, *u, *lam, *p), dtype=float)
        result = {}
        for key, (start, shape) in self.layout.items():
            size = shape[0] * shape[1]
            result[key] = out[start:start + size].reshape(shape)
        return result

    @contextmanager
    def evaluated_ahead(self, states: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]) -> Iterator[None]:
        """Within the block, `evaluate` at any of ``states`` (q, u, lambda, p) reads outputs computed for all of
        them in one pass (runtime.rows_function_from_code: bit for bit the one-by-one values; a find of a
        40-link chain's 984 equilibria spent a third of its time evaluating them one by one). States the pass
        cannot evaluate exactly, or whose outputs are not finite, are evaluated one by one as before."""
        keys = [_exact_key(*state) for state in states]
        rows = [np.concatenate(state) for state, key in zip(states, keys) if key is not None]
        if len(rows) > 1:
            values = rows_function_from_code(self._code)(np.array(rows))
            if values is not None:
                finite = np.all(np.isfinite(values), axis=1)
                for key, row, ok in zip([k for k in keys if k is not None], values, finite):
                    if ok:
                        self._evaluated[key] = row
        try:
            yield
        finally:
            self._evaluated.clear()


def _exact_key(*arrays: np.ndarray) -> tuple | None:
    """The inputs' lengths and bytes when all are float64 vectors (what evaluated_ahead computes with), else None."""
    if not all(isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == 1 for a in arrays):
        return None
    return tuple(len(a) for a in arrays), b"".join(a.tobytes() for a in arrays)


def pieces(model: MechanicalModel) -> LinearPieces:
    """The model's LinearPieces, built once per model object."""
    cached = getattr(model, "_linear_pieces", None)
    if cached is None:
        cached = LinearPieces(model)
        model._linear_pieces = cached
    return cached


@dataclass
class Linearization:
    """Linear equations about an equilibrium over all free coordinates (constraint directions included)."""

    coordinates: list[str]
    M: np.ndarray
    C: np.ndarray
    G: np.ndarray
    K: np.ndarray
    N: np.ndarray
    constraint_jacobian: np.ndarray

    @cached_property
    def A(self) -> np.ndarray:
        """State matrix for the state (q, q'); requires a nonsingular M."""
        n = len(self.coordinates)
        Minv = np.linalg.inv(self.M)
        return np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ (self.K + self.N), -Minv @ (self.C + self.G)]])

    @cached_property
    def B(self) -> np.ndarray:
        """Input matrix for generalized forces on every coordinate."""
        n = len(self.coordinates)
        return np.vstack([np.zeros((n, n)), np.linalg.inv(self.M)])

    def characteristic_polynomial(self) -> np.ndarray:
        """Coefficients (highest power first) of det(M s^2 + (C+G) s + K + N), exactly as the book writes them."""
        s = sp.Symbol("s")
        mat = sp.Matrix(self.M) * s**2 + sp.Matrix(self.C + self.G) * s + sp.Matrix(self.K + self.N)
        poly = sp.Poly(sp.expand(mat.det(method="berkowitz")), s)
        return np.array([float(c) for c in poly.all_coeffs()], dtype=float)

    def hurwitz_determinants(self) -> list[float]:
        return hurwitz_determinants(self.characteristic_polynomial())


def hurwitz_determinants(coeffs: np.ndarray) -> list[float]:
    """Delta_1..Delta_n of the Hurwitz matrix of a0 s^n + a1 s^(n-1) + ... + an (a0 > 0 assumed)."""
    a = list(coeffs)
    n = len(a) - 1

    def coef(k: int) -> float:
        return a[k] if 0 <= k <= n else 0.0

    H = np.array([[coef(2 * (j + 1) - (i + 1)) for j in range(n)] for i in range(n)], dtype=float)
    return [float(np.linalg.det(H[:k, :k])) for k in range(1, n + 1)]


def state_at(model: MechanicalModel, coordinates: dict[str, float], rates: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    q = np.array([coordinates.get(c, 0.0) for c in model.coordinates], dtype=float)
    u = np.array([rates.get(c, 0.0) for c in model.coordinates], dtype=float)
    return q, u


def linearize(model: MechanicalModel, equilibrium: Equilibrium, p: np.ndarray | None = None) -> Linearization:
    """Linearize about an equilibrium (or steady motion): K + N = -d(f + A^T lambda)/dq, C + G = -df/du,
    split into symmetric and skew-symmetric parts."""
    from mechsys.numeric.parameters import parameter_values

    p = parameter_values(model) if p is None else p
    q, u = state_at(model, equilibrium.coordinates, equilibrium.rates)
    lam = np.array(equilibrium.multipliers, dtype=float)
    v = pieces(model).evaluate(q, u, lam, p)
    stiff, damp = -v["dfdq"], -v["dfdu"]
    return Linearization(list(model.coordinates), v["M"], (damp + damp.T) / 2, (damp - damp.T) / 2,
                         (stiff + stiff.T) / 2, (stiff - stiff.T) / 2, v["A"])


def symbolic_matrices(model: MechanicalModel) -> dict[str, sp.Matrix]:
    """M, C + G and K + N as expressions of the coordinates (rates at zero): valid about any state of rest where
    no spring or damper has zero length. The derivatives of a length |d| leave DiracDelta(d) (0 there) and
    sign(d)**2 (1 there); they are dropped, so a spring prints as k, not k*sign(L + x1)**2 + 2*k*(...)*DiracDelta(L
    + x1)."""
    lp = pieces(model)
    rest = {u: 0 for u in model.u}
    mats = {"M": lp.symbolic["M"], "C+G": (-lp.symbolic["dfdu"]).xreplace(rest),
            "K+N": (-lp.symbolic["dfdq"]).xreplace(rest)}
    return {key: _away_from_zero_length(m) for key, m in mats.items()}


def _away_from_zero_length(m: sp.Matrix) -> sp.Matrix:
    if not m.has(sp.DiracDelta, sp.sign):
        return m
    m = m.replace(lambda e: isinstance(e, sp.DiracDelta), lambda e: sp.Integer(0))
    return m.replace(lambda e: e.is_Pow and isinstance(e.base, sp.sign) and e.exp.is_even, lambda e: sp.Integer(1))
