"""Products of symbolic matrices built entry by entry: one Mul per term and one Add per entry, no finiteness checks.

sympy's matrix product (DomainMatrix over EXRAW) asks of every entry whether 0*x == 0, which makes sympy ask whether
x is finite: a walk of the entry's whole tree through the assumptions system. On Kane's terms for a long chain
(partial velocities whose entries are long sums) those checks were most of the time: the 40-link chain's mass
matrix 6.8 s -> 3.2 s, its gravity forces 1.7 s -> 0.13 s. The entries are the ones sympy's product builds (the
same Mul of the same factors and Add of the same terms), for the finite expressions a model is made of."""
from __future__ import annotations

import sympy as sp

__all__ = ["product", "gram"]


def _nonzero_rows(A: sp.MatrixBase) -> list[dict[int, sp.Expr]]:
    rows, cols = A.shape
    return [{k: A[i, k] for k in range(cols) if A[i, k] != 0} for i in range(rows)]


def product(A: sp.MatrixBase, B: sp.MatrixBase) -> sp.Matrix:
    """A * B, each entry the Add of the products A[i, k] * B[k, j] over the nonzero pairs."""
    if A.shape[1] != B.shape[0]:
        raise ValueError(f"cannot multiply {A.shape} by {B.shape}")
    m, o = A.shape[0], B.shape[1]
    b_rows = _nonzero_rows(B)
    out = sp.zeros(m, o)
    for i, a_row in enumerate(_nonzero_rows(A)):
        terms: dict[int, list] = {}
        for k, a in a_row.items():
            for j, b in b_rows[k].items():
                terms.setdefault(j, []).append(a * b)
        for j, t in terms.items():
            out[i, j] = sp.Add(*t)
    return out


def gram(J: sp.MatrixBase, scale: sp.Expr = sp.S.One) -> sp.Matrix:
    """(scale * J).T * J (a mass matrix's m Jv^T Jv): the upper triangle built, the lower one mirrored."""
    rows, n = J.shape
    scaled = J if scale == 1 else scale * J
    cols = [{x: scaled[x, i] for x in range(rows) if J[x, i] != 0} for i in range(n)]
    plain = [{x: J[x, i] for x in cols[i]} for i in range(n)]
    out = sp.zeros(n, n)
    for i in range(n):
        for j in range(i, n):
            t = [a * plain[j][x] for x, a in cols[i].items() if x in plain[j]]
            if t:
                out[i, j] = out[j, i] = sp.Add(*t)
    return out
