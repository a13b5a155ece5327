"""mechanics/dag.py: the free symbols of expression DAGs, each shared subexpression visited once, equal sympy's
free_symbols on derived equations, on random expressions with bound variables and conditions, and on trees deeper
than Python's recursion limit; Substitution equals xreplace, rebuilding each shared subexpression once; the
Interner gives equal expressions with one object per value, printed as the originals."""
from __future__ import annotations

import random

import pytest
import sympy as sp

import mechsys
from helpers import DATA_DIR, SYSTEMS_DIR
from mechsys.mechanics.dag import FreeSymbols, Interner, Substitution


@pytest.mark.parametrize("name", ["bicycle", "rolling_disk", "indicator", "four_bar"])
def test_the_free_symbols_of_derived_equations_are_sympys(name):
    model = mechsys.load(SYSTEMS_DIR / f"{name}.yaml")
    symbols = FreeSymbols()
    for method in ("lagrange", "kane"):
        eq = model.equations(method)
        entries = [e for m in (eq.M, eq.f, eq.A, eq.b) for e in m] + [eq.T, eq.V]
        names = sorted(eq.M.free_symbols | eq.f.free_symbols, key=str) + [sp.Symbol("never_seen")]
        for e in entries:
            free = e.free_symbols  # sympy's, computed once per entry
            assert symbols.of(e) == free
            assert [symbols.has(e, s) for s in names] == [s in free for s in names]
        assert symbols.of_all(eq.M) == eq.M.free_symbols


def test_random_expressions_with_bound_variables_and_conditions():
    x, y, a = sp.symbols("x y a")
    rng = random.Random(11)
    leaves = [x, y, a, sp.Integer(2), sp.Float(0.5), sp.pi]

    def grow(depth: int) -> sp.Expr:
        if depth == 0:
            return rng.choice(leaves)
        u, v = grow(depth - 1), grow(depth - 1)
        return rng.choice([u + v, u * v, u**v, sp.sin(u) * v, sp.Abs(u) - v, sp.Min(u, v), sp.Max(u, a),
                           sp.Piecewise((u, v > 0), (v, True)), sp.Integral(u * x, (x, 0, 1)) + v,
                           sp.Derivative(sp.Function("g")(x, a), x) * u,
                           sp.Sum(u * x, (x, 1, 3))])

    symbols = FreeSymbols()
    substitution = Substitution({y: sp.Rational(1, 2), a: 2}, symbols)  # keys that are never bound
    for _ in range(80):
        e = grow(rng.randrange(1, 5))
        assert symbols.of(e) == e.free_symbols, e
        assert [symbols.has(e, s) for s in (x, y, a)] == [s in e.free_symbols for s in (x, y, a)], e
        try:
            expected = e.xreplace(substitution.mapping)
        except (TypeError, ValueError) as exc:  # e.g. Max of arguments that cannot be compared: the same refusal
            with pytest.raises(type(exc)):
                substitution.of(e)
            continue
        assert substitution.of(e) == expected, e


@pytest.mark.parametrize("name", ["indicator", "four_bar", "centrifuge"])
def test_substitution_equals_xreplace_on_derived_equations(name):
    model = mechsys.load(SYSTEMS_DIR / f"{name}.yaml")
    eq = model.equations("kane")
    for mapping in ({model.t: 0}, {u: 0 for u in model.u}, {model.q[0]: sp.Rational(1, 3), model.t: 2}):
        substitution = Substitution(mapping)
        for mat in (eq.M, eq.f, eq.A, eq.b):
            assert substitution.matrix(mat) == mat.xreplace(mapping)


def test_substitution_rebuilds_each_shared_subexpression_once():
    """A DAG with 2**40 paths: xreplace would walk them all; Substitution rebuilds its 40 levels once each."""
    t, x = sp.symbols("t x")
    e = x + t
    for _ in range(40):
        e = sp.sin(e) * sp.cos(e) + e
    substitution = Substitution({t: 0})
    zero = substitution.of(e)
    assert FreeSymbols().of(zero) == {x}  # (sympy's free_symbols would walk the paths too)
    assert len(substitution._memo) < 10 * 40
    small = x + t
    for _ in range(6):
        small = sp.sin(small) * sp.cos(small) + small
    assert Substitution({t: 0}).of(small) == small.xreplace({t: 0})


def test_a_tree_deeper_than_the_recursion_limit():
    x = sp.Symbol("x")
    e = x
    for k in range(5000):
        e = sp.Add(sp.Mul(e, sp.Symbol(f"c{k % 7}"), evaluate=False), sp.Integer(1), evaluate=False)
    assert FreeSymbols().of(e) == {x} | {sp.Symbol(f"c{k}") for k in range(7)}


def _objects_and_values(exprs: list) -> tuple[int, int]:
    """(distinct objects, distinct values) among the nodes of the expressions."""
    seen: dict[int, sp.Basic] = {}
    stack = list(exprs)
    while stack:
        node = stack.pop()
        if id(node) not in seen:
            seen[id(node)] = node
            stack.extend(node.args)
    return len(seen), len(set(seen.values()))


def _same_srepr(a: sp.Basic, b: sp.Basic, pairs: set) -> bool:
    """sp.srepr(a) == sp.srepr(b), node by node: the same classes with their arguments in the same order, and atoms
    with the same srepr (a Float's precision, a Symbol's assumptions); each pair of shared nodes compared once
    (srepr writes shared subtrees out each time: the bicycle's equations took 24 s)."""
    stack = [(a, b)]
    while stack:
        x, y = stack.pop()
        if (id(x), id(y)) in pairs:
            continue
        pairs.add((id(x), id(y)))
        if type(x) is not type(y) or len(x.args) != len(y.args):
            return False
        if not x.args:
            if sp.srepr(x) != sp.srepr(y):
                return False
        else:
            stack.extend(zip(x.args, y.args))
    return True


@pytest.mark.parametrize("path", [SYSTEMS_DIR / "bicycle.yaml", SYSTEMS_DIR / "double_pendulum.yaml",
                                  SYSTEMS_DIR / "indicator.yaml", DATA_DIR / "beyond" / "top_zxz.yaml",
                                  DATA_DIR / "beyond" / "furuta_rod_arm.yaml"])
def test_interned_equations_are_the_same_with_one_object_per_value(path):
    from mechsys.report.printing import to_text

    model = mechsys.load(path)
    for method in ("lagrange", "kane"):
        eq = model.equations(method)
        one = eq.interned()
        before = [e for m in (eq.M, eq.f, eq.Q, eq.A, eq.b) for e in m] + [eq.T, eq.V]
        after = [e for m in (one.M, one.f, one.Q, one.A, one.b) for e in m] + [one.T, one.V]
        assert len(before) == len(after)
        pairs: set = set()
        for b, a in zip(before, after):
            assert a == b and _same_srepr(a, b, pairs) and to_text(a) == to_text(b)
        objects, values = _objects_and_values(after)
        assert objects == values


def test_equal_expressions_built_apart_become_one_object():
    from sympy.core.cache import clear_cache

    x, y, l = sp.symbols("x y l")
    rows = []
    for _ in range(2):
        clear_cache()  # else sympy's cache gives back the first row's objects
        rows.append([l * sp.cos(x + y) + sp.Max(x, l) * sp.Abs(y), sp.Piecewise((x, y > 0), (l, True)) + x**2])
    assert rows[0][0] is not rows[1][0] and rows[0][0].args[0] is not rows[1][0].args[0]
    one = Interner()
    got = [[one.of(e) for e in r] for r in rows]
    assert got[0][0] is got[1][0] and got[0][1] is got[1][1]
    assert got[0] == rows[0]
    objects, values = _objects_and_values([e for r in got for e in r])
    assert objects == values


def test_sympys_constructor_cache_does_not_hand_back_other_argument_objects():
    """A function rebuilt over an interned argument is not taken from sympy's cache, where an equal function may be
    kept over another object of the same value (built by an earlier Interner: a CI run's test order)."""
    x, y = sp.symbols("x y")
    a, b, c = (sp.Add._from_args((x, y)) for _ in range(3))  # three objects of one value
    kept = sp.cos(c, evaluate=False)  # sympy's cache now holds cos over c
    own = sp.Basic.__new__(sp.cos, b)
    own.nargs = kept.nargs
    expr = sp.Mul._from_args((own, a))  # cos(x + y)*(x + y), built apart: a is interned first, then cos over it
    got = Interner().of(expr)
    assert got == expr and sp.srepr(got) == sp.srepr(expr)
    objects, values = _objects_and_values([got])
    assert objects == values and got.args[0] is not kept and got.args[0].args[0] is got.args[1]


def test_random_expressions_intern_to_themselves():
    from sympy.core.cache import clear_cache

    rng = random.Random(11)
    syms = sp.symbols("a b c d")
    makers = [lambda u, v: u + v, lambda u, v: u * v, lambda u, v: u ** 2 - v, lambda u, v: sp.sin(u) * sp.cos(v),
              lambda u, v: sp.sqrt(u ** 2 + v ** 2), lambda u, v: sp.atan2(u, v) + sp.exp(-u),
              lambda u, v: sp.Rational(3, 7) * u - sp.Float(0.25) * v, lambda u, v: sp.Max(u, v) + sp.Abs(u - v)]
    for _ in range(40):
        pool = list(syms)
        for _ in range(30):
            pool.append(rng.choice(makers)(rng.choice(pool), rng.choice(pool)))
        clear_cache()  # equal expressions, other objects
        copies = [sp.sympify(sp.srepr(e)) for e in pool[-10:]]
        assert any(c is not e for c, e in zip(copies, pool[-10:]))
        one = Interner()
        got = [one.of(e) for e in pool[-10:] + copies]
        assert got[:10] == pool[-10:] and all(a is b for a, b in zip(got[:10], got[10:]))
        pairs: set = set()
        assert all(_same_srepr(a, b, pairs) for a, b in zip(got, pool[-10:] + copies))


def test_interning_a_tree_deeper_than_the_recursion_limit():
    x = sp.Symbol("x")
    e = x
    for k in range(5000):
        e = sp.Add(sp.Mul(e, sp.Symbol(f"c{k % 7}"), evaluate=False), sp.Integer(1), evaluate=False)
    assert Interner().of(e) == e
