"""Roots at singular configurations of closed loops, where the constraint Jacobian loses its generic rank."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mechsys.analysis.equilibrium.equilibria import EquilibriumProblem

#: why a root near a singular configuration of the constraints is not a rest (unbalanced)
UNBALANCED = ("the closed loops are at or near a singular configuration (a change point, where their constraints lose "
              "rank) and the forces have a part along the motion they lose there")
#: why a root at a regular configuration of redundant loop rows is not a rest (unbalanced)
ROUNDING = ("the forces have a part along the motion the closed loops allow, held only by the rounding of their "
            "redundant constraint rows")
#: why a rest at a singular configuration gets no verdict (branch_point)
BRANCHES = ("at a singular configuration of the closed loops (their constraint Jacobian has rank {here} here, "
            "{generic} elsewhere: assembly branches meet): the linearization does not decide")
#: a singular value of the constraint Jacobian below this fraction of its largest counts as lost: the root is within
#: about 1e-4 of a configuration where the rank drops, closer than Newton's 1e-6 to 1e-5 accuracy there
NEAR = 1e-4
#: the part of the forces along a lost direction a rest may have, relative to the force scale (_scale)
BALANCE = 1e-6


def _rank(A: np.ndarray, tol: float) -> int:
    sv = np.linalg.svd(A, compute_uv=False)
    return int(np.count_nonzero(sv > tol * sv[0])) if sv.size and sv[0] > 0 else 0


def _pieces(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """f (the generalized force at rest, multipliers 0), df/dq and the constraint Jacobian A at z's configuration."""
    nq, k = problem.nq, len(problem.rate_unknowns)
    at = np.concatenate([z[: nq + k], np.zeros(len(z) - nq - k)])
    J = problem.J(at, p)
    return problem.F(at, p)[:nq], J[:nq, :nq], J[-problem.m:, :nq]


def onto_constraints(problem: EquilibriumProblem, start: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The start moved onto the constraint manifold Phi(q) = 0 by minimum-norm Gauss-Newton (the start itself
    without constraints, or when that fails). A random point of the box lies far from every assembly branch of a
    closed loop, and the full Newton from there mostly stagnates (Andrews' squeezer: 92% of the starts); from
    its projection it reaches an equilibrium, and the projections visit every assembly mode."""
    if not problem.m:
        return start
    nq, m = problem.nq, problem.m
    q = start.copy()
    for _ in range(30):
        z = np.concatenate([q, np.zeros(m)])
        phi = problem.F(z, p)[-m:]
        A = problem.J(z, p)[-m:, :nq]
        if not (np.all(np.isfinite(phi)) and np.all(np.isfinite(A))):
            return start
        if np.max(np.abs(phi)) <= 1e-12 * float(np.max(np.abs(A))):  # A: a length per radian (no floor: any units)
            return q
        q[:nq] = q[:nq] + np.linalg.lstsq(A, -phi, rcond=None)[0]
    return start


def generic_rank(problem: EquilibriumProblem, p: np.ndarray) -> int:
    """The rank of A on the mechanism's branch: its largest at configurations near the file's initial one moved onto
    the constraints (as `info` ranks it), at any configuration tried when none gets there. A parallelogram with a
    redundant third bar has 4 rows of rank 3."""
    store = problem.__dict__.setdefault("_generic_rank", {})
    key = tuple(float(v) for v in p)
    if key not in store:
        store[key] = _generic_rank(problem, np.asarray(p, dtype=float))
    return store[key]


def _generic_rank(problem: EquilibriumProblem, p: np.ndarray) -> int:
    model = problem.model
    q0 = np.array([model.doc.initial.get(c, 0.0) for c in problem.free], dtype=float)
    rng = np.random.default_rng(11)
    ranks, fallback = [], []
    for k in range(4):
        q = q0 + (0.0 if k == 0 else 1e-3 * (1 + np.abs(q0)) * rng.uniform(-1, 1, len(q0)))
        start = np.concatenate([q, np.zeros(len(problem.rate_unknowns))])
        moved = onto_constraints(problem, start, p)
        z = np.concatenate([moved, np.zeros(problem.m)])
        _, _, A = _pieces(problem, z, p)
        if not np.all(np.isfinite(A)):
            continue
        (ranks if moved is not start else fallback).append(_rank(A, 1e-9))
    return max(ranks or fallback or [problem.m])


def _scale(f: np.ndarray, dfdq: np.ndarray) -> float:
    """A force scale that does not vanish with f: f itself, or its change per unit of the coordinates."""
    return max(float(np.max(np.abs(f), initial=0.0)), float(np.max(np.abs(dfdq), initial=0.0)), 1e-300)


def _imbalance(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray) -> tuple[int, int, float] | None:
    """(A's rank at z counting singular values above NEAR, its generic_rank, the largest part of the forces along
    the directions beyond the smaller of the two, relative to _scale); None for problems without holonomic loops
    and where a value is not finite. At a rest the forces have no part along the motions the constraints allow."""
    if not problem.m or not problem.model.is_holonomic:
        return None
    f, dfdq, A = _pieces(problem, z, p)
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(dfdq)) and np.all(np.isfinite(A))):
        return None
    _, sv, Vt = np.linalg.svd(A)
    here = int(np.count_nonzero(sv > NEAR * sv[0])) if sv.size and sv[0] > 0 else 0
    generic = generic_rank(problem, p)
    return here, generic, float(np.max(np.abs(Vt[min(here, generic):] @ f), initial=0.0)) / _scale(f, dfdq)


def unbalanced(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray) -> str | None:
    """Why z is not a rest although F(z) vanishes to rounding, else None: the forces have a part along a
    direction the constraints do not see (to BALANCE). UNBALANCED where A has (nearly) lost rank at its
    configuration: near such a configuration (a parallelogram's change point) f + A^T lambda = 0 is met only as
    lambda grows without bound: Newton creeps towards it and stops where the multipliers' terms (1e4 to 1e15) leave
    F at their rounding (a parallelogram with a third bar: 48 such roots at its change points, listed as 'locked'
    rests). ROUNDING at a regular configuration of redundant rows: the rounding of their dependent row is a direction
    the multipliers can grow along (the same parallelogram at MEMS scale, 1e-4 m and 1e-9 kg, had a 'locked' rest
    at theta2 = -0.84 held by multipliers of 3e5 N)."""
    out = _imbalance(problem, z, p)
    if out is None or out[2] <= BALANCE:
        return None
    return UNBALANCED if out[0] < out[1] else ROUNDING


def branch_point(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray) -> str | None:
    """Why a rest (unbalanced is None) gets no verdict: A has lost rank at it (BRANCHES), or None. The tangent
    space there is not the mechanism's: the linearization sees two crossing branches, or none."""
    out = _imbalance(problem, z, p)
    return None if out is None or out[0] >= out[1] else BRANCHES.format(here=out[0], generic=out[1])


def merge_branch_points(problem: EquilibriumProblem, roots: list[np.ndarray], p: np.ndarray) -> list[np.ndarray]:
    """The roots with those at branch points that lie within 1e-5 (1 + |z|) of one already kept dropped: Newton
    converges only linearly to a root where A is singular and stops 1e-8 to 1e-6 from it, one copy per start."""
    kept: list[np.ndarray] = []
    for z in roots:
        size = float(np.linalg.norm(z[: problem.nq + len(problem.rate_unknowns)]))
        if kept and branch_point(problem, z, p) and np.min(problem.distances(z, np.asarray(kept))) < 1e-5 * (1 + size):
            continue
        kept.append(z)
    return kept
