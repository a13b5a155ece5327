"""Products of symbolic matrices built entry by entry: one Mul per term and one Add per entry, no finiteness checks.

sympy's matrix product (DomainMatrix over EXRAW) asks of every entry whether 0*x == 0, which makes sympy ask whether
x is finite: a walk of the entry's whole tree through the assumptions system. On Kane's terms for a long chain
(partial velocities whose entries are long sums) those checks were most of the time: the 40-link chain's mass
matrix 6.8 s -> 3.2 s, its gravity forces 1.7 s -> 0.13 s. The entries are the ones sympy's product builds (the
same Mul of the same factors and Add of the same terms), for the finite expressions a model is made of."""
from __future__ import annotations

from operator import itemgetter

import sympy as sp

from mechsys.mechanics.construct import Constructors
from mechsys.mechanics.order import canonical_key

__all__ = ["product", "gram", "nonzero", "sums"]


def nonzero(e: sp.Expr) -> bool:
    """``e != 0`` without sympy's comparison for anything but a number (only a number equals 0 structurally;
    the comparison of every term of a long chain's Kane sums cost as much as adding them)."""
    return e is not sp.S.Zero and not (e.is_Number and e == 0)


def _nonzero_rows(A: sp.MatrixBase) -> list[dict[int, sp.Expr]]:
    return [{k: a for k, a in enumerate(row) if nonzero(a)} for row in A.tolist()]


def product(A: sp.MatrixBase, B: sp.MatrixBase) -> sp.Matrix:
    """A * B, each entry the Add of the products A[i, k] * B[k, j] over the nonzero pairs."""
    if A.shape[1] != B.shape[0]:
        raise ValueError(f"cannot multiply {A.shape} by {B.shape}")
    m, o = A.shape[0], B.shape[1]
    b_rows = _nonzero_rows(B)
    build = Constructors()
    out = [[sp.S.Zero] * o for _ in range(m)]
    for i, a_row in enumerate(_nonzero_rows(A)):
        terms: dict[int, list] = {}
        for k, a in a_row.items():
            for j, b in b_rows[k].items():
                terms.setdefault(j, []).append(build.times(a, b))
        for j, t in terms.items():
            out[i][j] = build.add(t)
    return sp.Matrix(m, o, [e for row in out for e in row])


def gram(J: sp.MatrixBase, scale: sp.Expr = sp.S.One) -> sp.Matrix:
    """(scale * J).T * J (a mass matrix's m Jv^T Jv): the upper triangle built, the lower one mirrored."""
    rows, n = J.shape
    entries = J.T.tolist()  # column by column
    scaled = entries if scale == 1 else (scale * J).T.tolist()
    cols = [{x: scaled[i][x] for x in range(rows) if nonzero(entries[i][x])} for i in range(n)]
    plain = [{x: entries[i][x] for x in cols[i]} for i in range(n)]
    times = _Products([a for c in cols for a in c.values()] + [b for c in plain for b in c.values()])
    build = Constructors()
    out = [[sp.S.Zero] * n for _ in range(n)]
    for i in range(n):
        for j in range(i, n):
            t = [times(a, plain[j][x]) for x, a in cols[i].items() if x in plain[j]]
            if t:
                out[i][j] = out[j][i] = build.add(t)
    return sp.Matrix(n, n, [e for row in out for e in row])


class _Products:
    """a * b for the entries of one product, as sympy's Mul builds it, without its sorting where that is safe.

    Mul sorts its factors with Basic.compare, which walks two long sums until they differ: on Kane's mass matrix
    of a long chain (products of sums of 40 terms) most of gram's time. When the two factors' own factors are
    distinct sums, symbols and functions (nothing Mul combines: no numbers, powers, exponentials or repeats),
    the product is those factors in Mul's order, and that order is read from one sort of every factor of the
    entries (a total order: Basic.compare is lexicographic). Otherwise Mul builds it. The result is the same
    expression, args in the same order (tests/test_products.py compares every bundled and test-data model)."""

    def __init__(self, entries: list[sp.Expr]) -> None:
        factors: dict[sp.Expr, None] = {}
        for e in entries:
            for f in sp.Mul.make_args(e):
                factors.setdefault(f, None)
        plain = [f for f in factors if _plain(f)]
        self.rank = {f: k for k, f in enumerate(sorted(plain, key=canonical_key))}

    def __call__(self, a: sp.Expr, b: sp.Expr) -> sp.Expr:
        rank = self.rank
        try:
            merged = sorted([(rank[f], f) for f in sp.Mul.make_args(a) + sp.Mul.make_args(b)], key=itemgetter(0))
        except KeyError:  # a factor that is not plain
            return a * b
        if all(merged[k][0] < merged[k + 1][0] for k in range(len(merged) - 1)):  # distinct (equal ones: one rank)
            return sp.Mul._from_args([f for _, f in merged], True)
        return a * b


def _plain(f: sp.Expr) -> bool:
    """A factor that Mul keeps as it is next to other such factors (no coefficient, power or exp to merge)."""
    return (f.is_Add or f.is_Symbol or f.is_Function and not isinstance(f, sp.exp)) and f.is_commutative


def sums(groups: list[list[sp.Expr]]) -> list[sp.Expr]:
    """sp.Add(*group) for each group, with one sort for all of them where that is safe.

    Add sorts its terms with Basic.compare. Groups drawn from one pool of terms (the coefficients of each rate in
    a chain's velocity: the same n terms, a suffix of them per rate) sort the same terms again and again. When
    a group's terms are commutative products, symbols or functions (no numbers, sums or powers of numbers,
    nothing Add rebuilds) whose parts without a numeric coefficient are distinct (nothing Add collects), its
    sum is those terms in Add's order, and that order is read from one sort of all the groups' terms (a total
    order). Otherwise Add builds it. The result is the same expression, args in the same order."""
    pool: dict[sp.Expr, None] = {}
    for group in groups:
        for t in group:
            pool.setdefault(t, None)
    if sum(len(g) for g in groups) <= len(pool) + 1:  # nothing shared: Add's own sort costs no more
        return [sp.Add(*g) for g in groups]
    plain = [t for t in pool if _plain_term(t)]
    rank = {t: k for k, t in enumerate(sorted(plain, key=canonical_key))}
    return [_ranked_sum(g, rank) for g in groups]


def _ranked_sum(group: list[sp.Expr], rank: dict[sp.Expr, int]) -> sp.Expr:
    if len(group) < 2 or any(t not in rank for t in group):
        return sp.Add(*group)
    rests = {t.as_coeff_Mul()[1] for t in group}
    if len(rests) < len(group):  # two terms Add would collect
        return sp.Add(*group)
    return sp.Add._from_args(sorted(group, key=rank.__getitem__), True)


def _plain_term(t: sp.Expr) -> bool:
    """A term that Add keeps as it is next to other such terms (given their parts without a coefficient are
    distinct): a commutative product, symbol, function or power of something but a number."""
    if not (t.is_Mul or t.is_Symbol or t.is_Function or t.is_Pow and not t.base.is_Number):
        return False
    return t.is_commutative is True
