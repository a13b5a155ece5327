"""Cross-check of two formulations: the same M and f numerically at random states, symbolically if cheap."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp

from mechsys.mechanics.model import MechanicalModel
from mechsys.numeric.lambdify import compile_matrix

_SYMBOLIC_OPS_LIMIT = 3000


@dataclass
class CrossCheck:
    methods: tuple[str, str]
    agree: bool
    states: int
    max_rel_diff: float
    symbolic: str  # "identical", "inconclusive" or "skipped (large)"

    def summary(self) -> str:
        a, b = self.methods
        if not self.agree:
            return (f"{a} and {b} DISAGREE: max relative difference {self.max_rel_diff:.3g} "
                    f"over {self.states} random states")
        sym = {"identical": "symbolically identical",
               "inconclusive": "symbolic check inconclusive (trigonometric forms differ)",
               "skipped (large)": "symbolic check skipped (large expressions)"}[self.symbolic]
        return (f"{a} and {b} agree: M and f equal at {self.states} random states "
                f"(max relative difference {self.max_rel_diff:.2g}); {sym}")


def random_states(model: MechanicalModel, count: int, seed: int = 0) -> list[tuple[float, np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    n = len(model.q)
    return [(float(rng.uniform(0, 2)), rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n)) for _ in range(count)]


def _rel_diff(x: np.ndarray, y: np.ndarray) -> float:
    if x.size == 0:
        return 0.0
    scale = max(float(np.max(np.abs(x))), float(np.max(np.abs(y))), 1e-300)
    return float(np.max(np.abs(x - y))) / scale


def cross_check(model: MechanicalModel, methods: tuple[str, str] = ("lagrange", "kane"), states: int = 8,
                tol: float = 1e-9, seed: int = 0) -> CrossCheck:
    """Compare two derivations of the same model; ``agree`` when all relative differences are below tol."""
    e1, e2 = (model.equations(m) for m in methods)
    params = model.parameter_symbols
    p = [model.parameters[s.name] for s in params]
    worst = 0.0
    fns = [(compile_matrix(x.M, model.t, model.q, model.u, params), compile_matrix(x.f, model.t, model.q, model.u,
                                                                                  params)) for x in (e1, e2)]
    for t, q, u in random_states(model, states, seed):
        for k in range(2):
            worst = max(worst, _rel_diff(fns[0][k](t, q, u, p), fns[1][k](t, q, u, p)))
    agree = worst <= tol
    symbolic = "skipped (large)"
    diffs = [e1.M - e2.M, e1.f - e2.f]
    if agree and all(sp.count_ops(d) < _SYMBOLIC_OPS_LIMIT for d in diffs):
        symbolic = "identical" if all(sp.expand(d) == sp.zeros(*d.shape) for d in diffs) else "inconclusive"
    return CrossCheck(methods, agree, states, worst, symbolic)
