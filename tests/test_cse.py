"""numeric/cse.py: sympy's cse with the common-argument search on sets gives sympy's result, term for term."""
from __future__ import annotations

import random

import pytest
import sympy as sp
from sympy.simplify import cse_main

import mechsys
from helpers import chain_file, load_system
from mechsys.numeric import cse as fast


def _same(exprs: list, symbols=lambda: None) -> None:
    """``symbols``: makes the temporaries' names (a fresh generator for each call)."""
    want = sp.cse(exprs, symbols=symbols(), order="none")
    got = fast.cse(exprs, symbols=symbols(), order="none")
    assert got == want
    assert [sp.srepr(e) for e in got[1]] == [sp.srepr(e) for e in want[1]]
    assert [(sp.srepr(s), sp.srepr(v)) for s, v in got[0]] == [(sp.srepr(s), sp.srepr(v)) for s, v in want[0]]


@pytest.mark.parametrize("name", ["rolling_disk", "four_bar", "gyrostabilizer", "slider_crank", "chain"])
@pytest.mark.parametrize("method", ["kane", "lagrange"])
def test_the_equations_cse_is_sympys(name, method, tmp_path):
    """M, f, A, b of bundled models and of a 10-link chain (sums and products sharing many arguments: where the
    sets matter), with numbered real temporaries as lambdify.shared_program names them."""
    model = mechsys.load(chain_file(10, tmp_path)) if name == "chain" else load_system(name)
    eq = model.equations(method)
    exprs = [sp.sympify(e) for e in [*eq.M, *eq.f, *eq.A, *eq.b]]
    _same(exprs)
    taken = set().union(*(e.free_symbols for e in exprs))
    _same(exprs, lambda: sp.numbered_symbols("x", real=True, exclude=taken))


def test_random_sums_and_products_give_sympys_cse():
    """Sums of products over a few symbols and functions, many sharing two or more arguments, some sharing all of
    them (a whole sum is then the common subexpression), with rational and float coefficients."""
    rng = random.Random(5)
    atoms = [*sp.symbols("a b c d e f", real=True), sp.sin(sp.Symbol("x")), sp.cos(sp.Symbol("y"))]
    numbers = [sp.Integer(2), sp.Rational(1, 3), sp.Float(0.25), sp.Integer(-1)]
    for _ in range(40):
        def product():
            return sp.Mul(rng.choice(numbers), *rng.sample(atoms, rng.randint(2, 5)))

        def total():
            return sp.Add(*(product() for _ in range(rng.randint(2, 6))), *rng.sample(atoms, rng.randint(0, 3)))

        exprs = [total() for _ in range(rng.randint(3, 12))]
        exprs += [e * total() for e in rng.sample(exprs, 2)] + [sp.sqrt(total())]
        _same(exprs)


def test_sympys_own_match_is_back_after_the_call_and_after_an_error(monkeypatch):
    original = cse_main.match_common_args
    x, y, z = sp.symbols("x y z")
    fast.cse([x + y + z, sp.sin(x + y)])
    assert cse_main.match_common_args is original

    def broken(funcs):
        raise RuntimeError("broken")

    monkeypatch.setattr(fast, "_Tracker", broken)
    with pytest.raises(RuntimeError, match="broken"):
        fast.cse([x + y + z, sp.sin(x + y)])
    assert cse_main.match_common_args is original


def test_a_search_that_walks_sets_in_another_order_is_caught(tmp_path, monkeypatch):
    """The comparison can fail: matching the candidates largest first (sympy tries the smallest matches first)
    gives other temporaries on the 10-link chain's equations."""
    eq = mechsys.load(chain_file(10, tmp_path)).equations("kane")
    exprs = [sp.sympify(e) for e in [*eq.M, *eq.f]]
    real_sorted = sorted

    def largest_first(items, key=None, **kwargs):
        out = real_sorted(items, key=key, **kwargs)
        return out[::-1] if key is not None and kwargs == {} and out and isinstance(out[0], int) else out

    monkeypatch.setattr(fast, "sorted", largest_first, raising=False)
    with pytest.raises(AssertionError):
        _same(exprs)


SPHERICAL_CHAIN = """\
name: boxes on spherical joints
parameters: {{m: 0.7, l: 0.5, a: 0.06, b: 0.1, g: 9.81}}
coordinates:
{coordinates}
links:
{links}
forces:
  - {{type: gravity, acceleration: [0, 0, -g]}}
"""


def test_a_spherical_chains_staged_pieces_give_sympys_cse(tmp_path):
    """The expressions a first `simulate` compiles for a chain of boxes on spherical joints: equal subtrees built
    apart, which cse now meets interned (one object per value) with sympy's cache cleared; the temporaries are
    sympy's own, term for term."""
    from mechsys.numeric.kane import model_pieces

    n = 4
    coordinates = "\n".join(f"  {a}{i}: {{initial: {0.1 * i:.1f}, rate: 0.2}}" for i in range(1, n + 1) for a in "zyx")
    links = "\n".join(
        f"  b{i}:\n    joint: {{type: spherical, parent: {'ground' if i == 1 else f'b{i - 1}'}, sequence: zyx, "
        f"coordinates: [z{i}, y{i}, x{i}]{'' if i == 1 else ', origin: [0, 0, -l]'}}}\n"
        f"    mass: m\n    center_of_mass: [0, 0, -l/2]\n    shape: {{box: {{size: [a, b, l]}}}}"
        for i in range(1, n + 1))
    path = tmp_path / "boxes.yaml"
    path.write_text(SPHERICAL_CHAIN.format(coordinates=coordinates, links=links), encoding="utf-8")
    pieces, _layout = model_pieces(mechsys.load(path))
    _same([sp.sympify(e) for e in pieces])
