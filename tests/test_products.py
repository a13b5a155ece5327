"""The entry-by-entry matrix products (mechanics/products.py) and the one-walk rate coefficients
(kinematics.rate_coefficients) against sympy's own product, differentiation and substitution."""
from __future__ import annotations

import random

import pytest
import sympy as sp

from mechsys.mechanics.kinematics import rate_coefficients
from mechsys.mechanics.products import gram, product, sums

q1, q2, q3, a, b, c, m = sp.symbols("q1 q2 q3 a b c m")
u1, u2, u3 = sp.symbols("u1 u2 u3")


def _random_entry(rng: random.Random) -> sp.Expr:
    """Zero, a number, a symbol, a trigonometric product or a sum of them (as a chain's partial velocities)."""
    atoms = [sp.Integer(0), sp.Integer(0), sp.Rational(1, 2), sp.Integer(-3), a, b, -c, sp.sin(q1), sp.cos(q1 + q2)]
    kind = rng.randrange(4)
    if kind == 0:
        return rng.choice(atoms)
    if kind == 1:
        return rng.choice(atoms) * rng.choice(atoms)
    return sp.Add(*(rng.choice(atoms) * rng.choice(atoms[4:]) for _ in range(rng.randrange(2, 5))))


def _random_matrix(rng: random.Random, rows: int, cols: int) -> sp.Matrix:
    return sp.Matrix(rows, cols, [_random_entry(rng) for _ in range(rows * cols)])


@pytest.mark.parametrize("seed", range(8))
def test_product_builds_sympys_entries(seed):
    rng = random.Random(seed)
    A, B = _random_matrix(rng, 3, 4), _random_matrix(rng, 4, 2)
    got = product(A, B)
    assert got.shape == (3, 2)
    assert list(got) == list(A * B)  # the same expressions, not only the same values


@pytest.mark.parametrize("seed", range(8))
def test_gram_is_symmetric_and_equals_sympys(seed):
    rng = random.Random(seed)
    J = _random_matrix(rng, 3, 5)
    for scale in (sp.Integer(1), m, 2 * m):
        got = gram(J, scale)
        assert got == got.T
        reference = (scale * J).T * J
        # the upper triangle is sympy's own entry; the lower one mirrors it (the same value)
        for i in range(5):
            for j in range(i, 5):
                assert got[i, j] == reference[i, j]
                assert sp.expand(got[j, i] - reference[j, i]) == 0
    # a numeric scale can distribute over a sum (sympy's 2*(x + y) -> 2*x + 2*y): same values
    got = gram(J, sp.Integer(2))
    assert sp.expand(got - (2 * J).T * J) == sp.zeros(5, 5)


def test_product_rejects_mismatched_shapes():
    with pytest.raises(ValueError, match="cannot multiply"):
        product(sp.zeros(2, 3), sp.zeros(2, 3))


def test_rate_coefficients_equal_the_jacobian():
    """A velocity linear in the rates, with a rheonomic part inside a product: the walk's coefficients are the
    Jacobian (by differentiation), and the nested time term does not leave a k*(c + a) - k*c behind."""
    v = sp.Matrix([
        -a * sp.sin(q1) * u1 - b * (u1 + u2) * sp.sin(q1 + q2),
        m * (c * sp.cos(q3) + a * u3) + u2 / 2,
        sp.Integer(0),
        (a * u1 + b * (c + u2)) * (sp.sin(q1) + 2) - c,
    ])
    rates = [u1, u2, u3]
    got = rate_coefficients(v, rates)
    assert got.shape == (4, 3)
    assert sp.expand(got - v.jacobian(rates)) == sp.zeros(4, 3)
    assert got[1, 2] == m * a
    assert got[3, 1] == b * (sp.sin(q1) + 2)
    assert got[2, :] == sp.zeros(1, 3)


def test_rate_coefficients_of_a_nonlinear_entry_keep_the_secant():
    """An entry that is not linear in the rates (a caller's mistake, not a velocity): the substitution's secant,
    entry(u_j = 1, others 0) - entry(0), as before the one-walk reading; the linear entries are read as usual."""
    v = sp.Matrix([u1 * u2 + a * u1, sp.sin(u1) + b * u2, a * u3])
    got = rate_coefficients(v, [u1, u2, u3])
    assert list(got[0, :]) == [a, 0, 0]
    assert list(got[1, :]) == [sp.sin(1), b, 0]
    assert list(got[2, :]) == [0, 0, a]


def _models():
    from helpers import DATA_DIR, SYSTEMS_DIR

    return sorted(SYSTEMS_DIR.glob("*.yaml")) + sorted(DATA_DIR.glob("*.yaml"))


@pytest.mark.parametrize("path", _models(), ids=lambda p: p.stem)
def test_gram_of_every_models_partial_velocities_is_sympys_product(path):
    """gram's products skip Mul's sorting where that is safe (products._Products): each entry must be the very
    expression sympy's matrix product builds (== compares args in order), on the partial velocities of every
    bundled and test-data model."""
    import mechsys
    from mechsys.errors import MechsysError

    try:
        model = mechsys.load(path)
        pairs = list(zip(model._body_kinematics, model._body_partials))
    except MechsysError:
        pytest.skip("not a loadable model")
    for (body, *_), (Jv, _Jw) in pairs:
        if body.mass == 0:
            continue
        got = gram(Jv, body.mass)
        want = (body.mass * Jv).T * Jv
        n = Jv.shape[1]
        for i in range(n):
            for j in range(i, n):
                assert got[i, j] == want[i, j] and got[i, j].args == want[i, j].args, (i, j)


def test_gram_of_a_chains_sums_is_sympys_product():
    """Sums of trigonometric products, as a relative-angle chain's partial velocities: the fast path taken."""
    qs = sp.symbols("x1:9")
    l = sp.Symbol("l")
    rows = []
    for trig in (sp.cos, sp.sin):
        rows.append([sp.Add(*(l * trig(sum(qs[:k + 1])) for k in range(i, 8))) for i in range(8)])
    J = sp.Matrix(rows)
    got = gram(J, m)
    want = (m * J).T * J
    for i in range(8):
        for j in range(i, 8):
            assert got[i, j] == want[i, j] and got[i, j].args == want[i, j].args


def _same(got: sp.Expr, want: sp.Expr) -> bool:
    return got == want and got.args == want.args


def test_sums_are_adds_with_their_args_in_order():
    """Groups drawn from one pool (a chain's rate coefficients: suffixes of one sum), and groups the one-sort path
    must leave to Add: terms Add collects (x and 2*x), numbers, sums, powers of numbers, a noncommutative term,
    an infinity, a single term, an empty group."""
    qs = sp.symbols("x1:9")
    l = sp.Symbol("l")
    pool = [l * sp.cos(sum(qs[:k + 1])) for k in range(8)] + [sp.sin(qs[0]), qs[1] ** 2, -qs[2] / 2]
    groups = [pool[k:] for k in range(len(pool))] + [pool[::-1], pool[::2]]
    A = sp.Symbol("A", commutative=False)
    odd = [[a, 2 * a, b], [a, sp.Integer(3), b], [a, b + c, c], [sp.sqrt(2), a, b], [A, a, b], [sp.zoo, a, b],
           [a * b, -a * b / 2, c], [a], [], [a, sp.sin(a), sp.cos(a) * b, b]]
    rng = random.Random(3)
    mixed = [[rng.choice(pool + [a, b, 2 * a]) for _ in range(rng.randrange(1, 8))] for _ in range(40)]
    for batch in (groups, odd, groups + odd, mixed):
        got = sums([list(g) for g in batch])
        for g, e in zip(batch, got):
            assert _same(e, sp.Add(*g)), g


@pytest.mark.parametrize("path", [p for p in _models() if p.stem in ("bicycle", "double_pendulum", "four_bar",
                                                                     "rolling_disk", "gyrostabilizer")],
                         ids=lambda p: p.stem)
def test_rate_coefficients_of_models_take_adds_in_sympys_order(path, monkeypatch):
    """Every sum the rate-coefficient walk builds through the one-sort path is the very Add sympy builds."""
    import mechsys
    from mechsys.mechanics import kinematics

    calls = []

    def checked(groups):
        got = sums(groups)
        for g, e in zip(groups, got):
            assert _same(e, sp.Add(*g))
        calls.append(len(groups))
        return got

    monkeypatch.setattr(kinematics, "sums", checked)
    model = mechsys.load(path)
    assert model._body_partials and calls


def test_rate_coefficients_of_a_spatial_chain_equal_sympys_jacobian(tmp_path):
    """A 10-link spatial chain written as a user would (joints about z and y in turn, rods along x): the walk's
    coefficients, one sort per shared sum, are the Jacobian of the velocities by sympy's differentiation, and
    every sum they hold is in Add's order."""
    import mechsys

    lines = ["name: spatial_chain", "parameters: {m: 1.0, l: 0.5, g: 9.81}", "coordinates:"]
    lines += [f"  q{k}: {{initial: 0.1, rate: 0}}" for k in range(1, 11)]
    lines += ["links:"]
    for k in range(1, 11):
        parent, origin = ("ground", "[0, 0, 0]") if k == 1 else (f"rod{k - 1}", "[l, 0, 0]")
        lines += [f"  rod{k}:",
                  f"    joint: {{type: revolute, parent: {parent}, axis: {'zy'[k % 2]}, coordinate: q{k}, "
                  f"origin: {origin}}}",
                  "    mass: m", "    center_of_mass: [l/2, 0, 0]", "    shape: {rod: {length: l, axis: x}}"]
    lines += ["forces:", "  - {type: gravity, acceleration: [0, 0, -g]}"]
    path = tmp_path / "spatial_chain.yaml"
    path.write_text("\n".join(lines) + "\n")
    model = mechsys.load(path)
    for (body, _r, v, w, _frame), (Jv, Jw) in zip(model._body_kinematics, model._body_partials):
        for got, want in ((Jv, v.jacobian(model.u)), (Jw, w.jacobian(model.u))):
            assert sp.expand(got - want) == sp.zeros(*got.shape), body.name
            for e in got:
                if e.is_Add:
                    assert _same(e, sp.Add(*e.args))
