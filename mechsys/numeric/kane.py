"""Staged numeric equations of motion: compile small per-body Kane terms, assemble M and f with numpy.

Compiling the expanded f of a long chain makes CSE walk O(n^4) terms; compiling the pieces it is made of
(partial velocities, q''-free accelerations, angular velocities) keeps the generated code O(n^2) and gives the
same numbers as the symbolic M and f (tests check this)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np
import sympy as sp

from mechsys.numeric.lambdify import function_from_source, generate_source
from mechsys.numeric.runtime import call_generated

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel


@dataclass
class CompiledEquations:
    """``evaluate(t, q, u, p) -> (M, f)`` for ``M q'' = f`` (constraint rows excluded)."""

    n: int
    bodies: list[tuple[bool, bool]]  # (has mass, has inertia) per body
    _fn: object

    @property
    def size(self) -> int:
        """Number of values the staged function returns."""
        return self.n + sum((3 * self.n + 4) * m + (3 * self.n + 15) * i for m, i in self.bodies)

    def evaluate(self, t: float, q: Sequence[float], u: Sequence[float], p: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        n = self.n
        out = np.asarray(call_generated(self._fn, (t, *q, *u, *p), self.size), dtype=float)
        f = out[:n].copy()  # Q + potential forces (gravity excluded)
        M = np.zeros((n, n))
        k = n
        for has_mass, has_inertia in self.bodies:
            if has_mass:
                Jv = out[k:k + 3 * n].reshape(3, n)
                m = out[k + 3 * n]
                rhs = out[k + 3 * n + 1:k + 3 * n + 4]  # m*g - m*a0
                M += m * Jv.T @ Jv
                f += Jv.T @ rhs
                k += 3 * n + 4
            if has_inertia:
                Jw = out[k:k + 3 * n].reshape(3, n)
                I = out[k + 3 * n:k + 3 * n + 9].reshape(3, 3)
                alpha = out[k + 3 * n + 9:k + 3 * n + 12]
                w = out[k + 3 * n + 12:k + 3 * n + 15]
                M += Jw.T @ I @ Jw
                Iw = I @ w
                gyro = np.array([w[1] * Iw[2] - w[2] * Iw[1], w[2] * Iw[0] - w[0] * Iw[2], w[0] * Iw[1] - w[1] * Iw[0]])
                f -= Jw.T @ (I @ alpha + gyro)  # w x I w written out: np.cross costs 20x more on 3-vectors
                k += 3 * n + 15
        return M, f


def compile_equations(model: MechanicalModel) -> CompiledEquations:
    """Compile the model's Kane terms into one numpy function (parameters stay inputs)."""
    return equations_from_source(equations_source(model))


def equations_from_source(desc: dict) -> CompiledEquations:
    return CompiledEquations(desc["n"], [tuple(b) for b in desc["bodies"]], function_from_source(desc["source"]))


def equation_pieces(model: MechanicalModel) -> tuple[list, list[tuple[bool, bool]]]:
    """The staged Kane terms as one flat list of expressions and the body layout that says how to assemble them
    (the order ``CompiledEquations.evaluate`` and the native integrator read them in)."""
    pieces: list = []
    other = model.generalized_forces.copy()
    for load in model.kin.loads:
        if load.kind != "gravity":
            V = model._elastic_potential(load.kind, load.data)
            if V != 0:
                other -= sp.Matrix([sp.diff(V, q) for q in model.q])
    pieces += list(other)
    gravity = [load.data["g"] for load in model.kin.loads if load.kind == "gravity"]
    layout = []
    for (b, _r, _v, w, frame), (Jv, Jw) in zip(model._body_kinematics, model._body_partials):
        has_mass = b.mass != 0
        has_inertia = not b.particle and b.inertia != sp.zeros(3, 3)
        if has_mass:
            g_home = sum((frame.to_home(g) for g in gravity), sp.zeros(3, 1))
            pieces += [*Jv, b.mass, *(b.mass * (g_home - frame.point_acceleration(b.com_local)))]
        if has_inertia:
            pieces += [*Jw, *b.inertia, *frame.alpha, *w]
        layout.append((has_mass, has_inertia))
    return pieces, layout


def equations_source(model: MechanicalModel) -> dict:
    """Cacheable description of the staged equations: sizes, body layout and generated source."""
    pieces, layout = model_pieces(model)
    source = generate_source(pieces, [model.t, *model.q, *model.u, *model.parameter_symbols])
    return {"n": len(model.q), "bodies": [list(b) for b in layout], "source": source}


def model_pieces(model: MechanicalModel) -> tuple[list, list[tuple[bool, bool]]]:
    """``equation_pieces`` memoised on the model (the Python and the native code generators share them)."""
    cached = getattr(model, "_equation_pieces", None)
    if cached is None:
        cached = model._equation_pieces = equation_pieces(model)
    return cached
