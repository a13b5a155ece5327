"""The constrained equations of motion [[M, A^T], [A, 0]] [q''; -lambda] = [f; b], solved in balanced units."""
from __future__ import annotations

import numpy as np

#: a balanced system whose condition number exceeds this is solved by least squares (redundant constraints)
SINGULAR = 1e14


def _power_of_two(x: np.ndarray) -> np.ndarray:
    """2**round(log2 x): a scaling that multiplies exactly (no rounding of the entries it scales)."""
    return np.exp2(np.round(np.log2(x)))


def balance(M: np.ndarray, A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(dq, dl): diagonal scalings, powers of two, that make D K D = [[M', A'^T], [A', 0]] of unit size: each
    coordinate's row of M (1 / sqrt of its largest entry) and each constraint row of A (1 / its largest entry after
    the coordinates' scaling). A coordinate with no mass takes the matrix's overall size, a zero row 1. The
    scaled system has the solution of the original, scaled back; its condition number does not depend on the
    units (a MEMS four-bar's M ~ 1e-17 beside its A ~ 1e-4 had cond(K) ~ 1e20 and was solved by least squares,
    which returned q'' = 0)."""
    rows = np.max(np.abs(M), axis=1, initial=0.0) if M.size else np.zeros(0)
    overall = float(np.max(rows, initial=0.0))
    rows = np.where(rows > 0, rows, overall if overall > 0 else 1.0)
    dq = _power_of_two(1.0 / np.sqrt(rows))
    scaled = np.abs(A) * dq if A.size else np.zeros(A.shape)
    lengths = np.max(scaled, axis=1, initial=0.0) if A.size else np.zeros(A.shape[0])
    dl = _power_of_two(1.0 / np.where(lengths > 0, lengths, 1.0))
    return dq, dl


def balanced_matrix(M: np.ndarray, A: np.ndarray) -> np.ndarray:
    """D [[M, A^T], [A, 0]] D with balance's scalings."""
    dq, dl = balance(M, A)
    n, m = M.shape[0], A.shape[0]
    K = np.zeros((n + m, n + m))
    K[:n, :n] = dq[:, None] * M * dq
    if m:
        scaled = dl[:, None] * A * dq
        K[n:, :n], K[:n, n:] = scaled, scaled.T
    return K


def condition(M: np.ndarray, A: np.ndarray) -> float:
    """The condition number of the balanced system (inf when it is singular or not finite)."""
    K = balanced_matrix(M, A)
    if not np.all(np.isfinite(K)):
        return float("inf")
    with np.errstate(all="ignore"):
        return float(np.linalg.cond(K))


def solve(M: np.ndarray, A: np.ndarray, f: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q'', lambda) of M q'' = f + A^T lambda, A q'' = b: solved as it is when it is well conditioned (a locked
    linkage's q'' come out exactly 0), else balanced, and by least squares (the minimum-norm multipliers) when even
    the balanced system's condition number exceeds SINGULAR (redundant constraint rows)."""
    n, m = M.shape[0], A.shape[0]
    K = np.zeros((n + m, n + m))
    K[:n, :n], K[:n, n:], K[n:, :n] = M, A.T, A
    if np.linalg.cond(K) <= SINGULAR:
        sol = np.linalg.solve(K, np.concatenate([f, b]))
        return sol[:n], -sol[n:]
    dq, dl = balance(M, A)
    K = balanced_matrix(M, A)
    rhs = np.concatenate([dq * f, dl * b])
    sol = np.linalg.lstsq(K, rhs, rcond=None)[0] if np.linalg.cond(K) > SINGULAR else np.linalg.solve(K, rhs)
    return dq * sol[:n], -dl * sol[n:]
