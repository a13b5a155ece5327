"""numeric/tangents.py: forward-mode derivatives printed straight to C, checked against sympy's own jacobian of
the same expressions (an independent derivation: no CSE, no chain rule of ours)."""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from mechsys.numeric import native, tangents
from mechsys.numeric.lambdify import shared_program

if native.compiler() is None:  # pragma: no cover - every CI machine has cc
    pytest.skip("no C compiler", allow_module_level=True)

x, y, z = sp.symbols("x y z", real=True)


def _draw(rng, depth):
    """A random expression of every node the tangents have a rule for, sharing subtrees (so CSE makes a graph)."""
    atoms = [x, y, z, sp.Integer(3), sp.Rational(-2, 7), sp.Float(0.3), sp.pi]
    unary = [sp.sin, sp.cos, sp.tan, sp.atan, sp.exp, sp.Abs, sp.tanh, sp.sinh, sp.cosh,
             lambda e: sp.sqrt(e ** 2 + 1), lambda e: sp.log(e ** 2 + 2), lambda e: sp.asin(sp.tanh(e) / 2),
             lambda e: sp.acos(sp.tanh(e) / 3)]
    if depth == 0 or rng.random() < 0.15:
        return atoms[rng.integers(len(atoms))]
    a, b = _draw(rng, depth - 1), _draw(rng, depth - 1)
    kind = rng.integers(9)
    return [a + b, a * b * x - y, a / (b ** 2 + 1), (a ** 2 + 1) ** sp.Rational(-1, 2) * b,
            a ** int(rng.integers(-3, 7)), unary[rng.integers(len(unary))](a) + b,
            sp.atan2(a, b ** 2 + 1) * y, (a ** 2 + 1) ** (sp.sin(b) / 2), (a ** 2 + 2) ** sp.Float(1.5) * z][kind]


def _compile(tmp_path, source, functions, n_args):
    lib = tmp_path / "p.so"
    native.build(source, lib, "-O0")
    return native.Program(lib, functions, n_args)


def test_tangents_equal_sympys_jacobian_on_random_expressions(tmp_path):
    rng = np.random.default_rng(3)
    exprs = [_draw(rng, 4) for _ in range(40)]
    exprs += [e * exprs[k + 1] for k, e in enumerate(exprs[:10])]  # shared subtrees across outputs
    inner = x * y / 3 + x / 5  # every rule at least once, on an argument that varies with both x and y
    exprs += [f(inner) for f in (sp.sin, sp.cos, sp.tan, sp.exp, sp.log, sp.asin, sp.acos, sp.atan, sp.sinh,
                                 sp.cosh, sp.tanh, sp.Abs)]
    exprs += [sp.atan2(inner, y + 2), sp.atan2(y, inner), inner ** 3, inner ** -2, sp.sqrt(inner ** 2 + 1),
              1 / sp.sqrt(x ** 2 + 1), (y ** 2 + 1) ** sp.Rational(3, 7), (x ** 2 + 1) ** sp.Float(1.5),
              (x ** 2 + 1) ** y, 2 ** inner, (x ** 2 + 1) ** z]
    wrt, rows = [x, y], len(exprs) - 5  # the last five are values only; z is an argument, not differentiated
    program = shared_program(exprs, [x, y, z], wrt)
    assert len(program.values) > 20
    source = tangents.program_source(program, wrt, rows, {"full": (len(exprs), True), "values": (rows, False)})
    assert source is not None
    full = len(exprs) + rows * len(wrt)
    compiled = _compile(tmp_path, source, {"full": full, "values": rows}, 3)
    jacobian = sp.lambdify([x, y, z], sp.Matrix(exprs[:rows]).jacobian(wrt), "numpy")
    values = sp.lambdify([x, y, z], exprs, "numpy")
    def reference(point):
        with np.errstate(all="ignore"):
            return np.concatenate([np.asarray(values(*point), dtype=float),
                                   np.asarray(jacobian(*point), dtype=float).ravel()])

    checked = 0
    for point in np.random.default_rng(4).uniform(-1.5, 1.5, (30, 3)):
        want = reference(point)
        got = compiled("full", point)
        ok = np.isfinite(want)
        assert np.array_equal(ok, np.isfinite(got))
        # an entry that a change of the point in its last bits moves beyond the tolerance (sin(exp(36 z)) at z = 1.3:
        # the sine of 1e20, whose double depends on the libm's rounding of exp) has no answer to compare with
        nudged = reference(point * (1 + 4 * np.finfo(float).eps))
        with np.errstate(all="ignore"):
            ok &= np.isclose(nudged, want, rtol=1e-11, atol=1e-11)
        assert np.allclose(got[ok], want[ok], rtol=1e-10, atol=1e-10)
        np.testing.assert_array_equal(compiled("values", point), got[:rows])
        checked += int(ok.sum())
    assert checked > 0.9 * 30 * full


def test_the_tangent_of_a_power_at_zero_is_finite(tmp_path):
    """x**2 and x**3 differentiate at x = 0 as c*x**(c - 1), not as c*x**c/x (0/0)."""
    exprs = [x ** 2 + y, x ** 3 * y, sp.sqrt(x ** 2 + 1)]
    program = shared_program(exprs, [x, y], [x, y])
    source = tangents.program_source(program, [x, y], 3, {"f": (3, True)})
    got = _compile(tmp_path, source, {"f": 9}, 2)("f", np.array([0.0, 2.0]))
    np.testing.assert_allclose(got, [2.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("node", [sp.sign(x) * y, sp.Heaviside(x) + y, sp.Max(x, y), sp.Function("g")(x)])
def test_a_node_without_a_rule_is_refused(node):
    """None: the caller differentiates symbolically (nonholonomic.ConstrainedPieces) instead."""
    program = shared_program([node, x * y], [x, y], [x, y])
    assert tangents.program_source(program, [x, y], 2, {"f": (2, True)}) is None
