"""Numeric layer: the staged compiled equations equal the symbolic M and f of both formulations."""
from pathlib import Path

import numpy as np
import pytest

import mechsys
from mechsys.numeric.kane import compile_equations
from mechsys.numeric.lambdify import compile_matrix

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", ["centrifuge", "gyrostabilizer", "indicator", "double_pendulum", "cart_pendulum",
                                  "spring_chain", "wheel_on_axle", "slider_crank", "rolling_disk"])
def test_staged_equations_match_symbolic(name):
    model = mechsys.load(ROOT / "systems" / f"{name}.yaml")
    staged = compile_equations(model)
    params = model.parameter_symbols
    p = [model.parameters[s.name] for s in params]
    rng = np.random.default_rng(11)
    for method in ("kane", "lagrange"):
        eq = model.equations(method)
        M_fn = compile_matrix(eq.M, model.t, model.q, model.u, params)
        f_fn = compile_matrix(eq.f, model.t, model.q, model.u, params)
        for _ in range(3):
            t, q, u = rng.uniform(0, 3), rng.uniform(-2, 2, len(model.q)), rng.uniform(-2, 2, len(model.q))
            M, f = staged.evaluate(t, q, u, p)
            M_ref, f_ref = M_fn(t, q, u, p), f_fn(t, q, u, p).ravel()
            scale = max(1.0, np.abs(M_ref).max(), np.abs(f_ref).max())
            assert np.allclose(M, M_ref, rtol=1e-10, atol=1e-12 * scale)
            assert np.allclose(f, f_ref, rtol=1e-10, atol=1e-12 * scale)


def test_forward_jacobian_of_abs_and_of_an_input_named_like_a_temporary():
    """value_and_jacobian_program: its temporaries are real (d|x|/dx is sign(x), not a Derivative that cannot be
    printed) and never equal an input (a real coordinate named x4 was taken for the fourth temporary, and the
    slider-crank's Jacobian column of x4 came out wrong in `mechsys codegen`)."""
    import sympy as sp

    from mechsys.numeric.lambdify import function_from_source, value_and_jacobian_sources

    q, x4 = sp.symbols("q x4", real=True)
    exprs = [sp.Abs(q) * sp.sin(x4) + sp.cos(q * x4) ** 2, sp.sin(q * x4) + x4 * sp.cos(q * x4) ** 2 + sp.sin(x4)]
    _values, source = value_and_jacobian_sources(exprs, [q, x4], [q, x4])
    fn = function_from_source(source)
    jac = sp.Matrix(exprs).jacobian([q, x4])
    for point in ((0.7, -1.3), (-0.4, 2.2)):
        out = fn(*point)
        want = [float(e.subs({q: point[0], x4: point[1]})) for e in jac]
        assert out[2:] == pytest.approx(want, rel=1e-12, abs=1e-12)


def test_the_chain_rule_sums_a_symbols_partials_before_it_multiplies():
    """differentiate_program differentiates a sum term by term but multiplies each symbol's summed partial once by
    that symbol's tangent: d(x y + x z)/dq = (y + z) dx, not y dx + z dx (the distributed form cost the bicycle's
    generated Jacobian 5 % more operations and gcc 50 % more time at -O2). Numbers and symbols get no temporary."""
    import sympy as sp

    from mechsys.numeric.lambdify import differentiate_program, shared_program

    q, y, z = sp.symbols("q y z", real=True)
    exprs = [sp.sin(q) * y + sp.sin(q) * z + 3 * q, sp.sin(q) * (y - z)]
    program = shared_program(exprs, [q, y, z], [q])
    assert [str(v) for _, v in program.values] == ["sin(q)"]
    jac = differentiate_program(program, [q])
    assert len(jac.derivatives) == 1  # d sin(q)/dq = cos(q); 3 * 1 and the sums are no temporaries
    tangent = jac.symbols[jac.derivatives[0][0]]
    assert jac.jacobian[0] == (y + z) * tangent + 3
    assert jac.jacobian[1] == (y - z) * tangent


def test_a_remembered_cse_is_the_cse_computed_afresh_for_the_same_expressions():
    """shared_cse remembers its latest results (one command compiles M for the cyclic test and for info; a first
    simulate prints the same expressions as Python and as C): the key is the expressions in order and the kind of
    CSE, a hit is what sympy's cse gives, and the sources printed from it depend on the arguments' order."""
    import sympy as sp

    from mechsys.numeric import lambdify as L

    x, y, a = sp.symbols("x y a")
    exprs = [sp.sin(x) * a + y**2, sp.cos(x - y) * sp.sin(x) * a]
    first = L.shared_cse(exprs)
    assert L.shared_cse(list(exprs)) is first and first == sp.cse(exprs, order="none")
    assert L.shared_cse(exprs, light=True) == L.light_cse(exprs)
    assert L.shared_cse(exprs[::-1]) == sp.cse(exprs[::-1], order="none")
    source = L.generate_source(exprs, [x, y, a])
    swapped = L.generate_source(exprs, [y, x, a])
    assert swapped != source
    assert L.function_from_source(swapped)(2.0, 1.0, 3.0) == L.function_from_source(source)(1.0, 2.0, 3.0)
    for k in range(L._RECENT_SIZE + 1):  # bounded: the oldest is forgotten
        L.shared_cse([x + k])
    assert len(L._RECENT) == L._RECENT_SIZE and (tuple(exprs), False) not in L._RECENT


def test_the_direct_python_printer_computes_what_sympys_printer_computes():
    """lambdify._Printer prints sums, products, powers and numbers itself (sympy's printer sorts every sum):
    random expressions of those nodes, of the elementary functions around them and of some nodes it leaves to
    sympy (Piecewise, Mod, sign, atan2), printed both ways, give the same numbers."""
    import math

    import sympy as sp
    from sympy.printing.pycode import PythonCodePrinter

    from mechsys.numeric import lambdify as L
    from mechsys.numeric.runtime import function_from_source

    x, y, z = sp.symbols("x y z", real=True)
    rng = np.random.default_rng(21)
    atoms = [x, y, z, sp.Integer(3), sp.Integer(-2), sp.Rational(-2, 7), sp.Float(0.3), sp.Float(1 / 3),
             sp.Float(-1.25e-3), sp.pi]
    unary = [sp.sin, sp.cos, sp.atan, sp.exp, sp.Abs, sp.tanh, sp.sign, lambda e: sp.sqrt(e ** 2 + 1),
             lambda e: 1 / sp.sqrt(e ** 2 + 2), lambda e: sp.log(e ** 2 + 2)]

    def draw(depth):
        if depth == 0 or rng.random() < 0.2:
            return atoms[rng.integers(len(atoms))]
        a, b = draw(depth - 1), draw(depth - 1)
        return [a + b, a * b - x, a / (b ** 2 + 1), a ** int(rng.integers(-3, 6)), -a * b / 7,
                unary[rng.integers(len(unary))](a) + b, sp.atan2(a, b ** 2 + 1) * y,
                (a ** 2 + 1) ** sp.Rational(3, 2), (a ** 2 + 1) ** (b ** 2 / 3),
                sp.Mod(a, 3) + sp.Piecewise((a, b > 0), (-b, True))][rng.integers(10)]

    exprs = [draw(4) for _ in range(80)]
    names = {x: "a0", y: "a1", z: "a2"}
    fast = L._Printer(names)

    class Sympys(PythonCodePrinter):
        def _print_Symbol(self, e):
            return names[e]

    plain = Sympys({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": False})
    texts = {which: [printer.doprint(e) for e in exprs] for which, printer in (("fast", fast), ("sympy", plain))}
    assert texts["fast"] != texts["sympy"]
    fns = {which: [function_from_source(f"def _f(a0, a1, a2):\n    return [{text}]") for text in t]
           for which, t in texts.items()}
    compared = 0
    for point in np.random.default_rng(22).uniform(-2, 2, (20, 3)):
        for k in range(len(exprs)):
            got = []
            for which in ("fast", "sympy"):
                try:
                    got.append(complex(fns[which][k](*map(float, point))[0]))
                except (ValueError, ZeroDivisionError, OverflowError):
                    got.append(None)
            if got[1] is None or not math.isfinite(abs(got[1])):
                continue
            # (sympy prints a Float's 15 digits, mechsys its double exactly: round-off apart after cancellations)
            assert got[0] is not None and abs(got[0] - got[1]) <= 1e-9 * max(1.0, abs(got[1])), (exprs[k], got)
            compared += 1
    assert compared > 1000


@pytest.mark.parametrize("target", ["python", "c", "matlab"])
def test_the_lean_doprint_prints_what_sympys_doprint_prints(target, monkeypatch):
    """LeanDoprint skips sympy's re(...) rewrite where an expression has no re: the same text with and without it,
    for an expression with re(UnevaluatedExpr(x)) (rewritten to x) and expressions without re."""
    import sympy as sp
    from sympy.printing.codeprinter import CodePrinter

    from mechsys.codegen import matlab, python
    from mechsys.numeric import native

    x, y = sp.symbols("x y", real=True)
    names = {x: "x", y: "y"}
    printer = {"python": lambda: python._Printer(names), "c": lambda: native._c_printer(names, fast=False),
               "matlab": lambda: matlab._Printer(names)}[target]()
    exprs = [sp.re(sp.UnevaluatedExpr(x)) * y + sp.sin(x), sp.sin(x) ** 2 * y + sp.sqrt(y ** 2 + 1),
             sp.Piecewise((x, y > 0), (-y, True))]
    lean = [printer.doprint(e) for e in exprs]
    monkeypatch.setattr(type(printer), "_handle_UnevaluatedExpr", CodePrinter._handle_UnevaluatedExpr)
    assert [printer.doprint(e) for e in exprs] == lean
    assert "re(" not in lean[0] and "x" in lean[0]


def test_ordered_terms_is_sympys_print_order():
    """lambdify.ordered_terms (the C and MATLAB targets' order of a sum's terms, numbers' complex values
    remembered) equals Expr.as_ordered_terms on every sum of the rolling disk's CSE'd equations and on random sums
    of rational, float, irrational and imaginary coefficients, powers, functions, a non-commutative factor, the
    special case of a number and a negative product, and a sum with an O() term."""
    import random

    import sympy as sp

    from mechsys.numeric.cse import cse
    from mechsys.numeric.lambdify import ordered_terms

    eq = mechsys.load(Path(__file__).parents[1] / "systems" / "rolling_disk.yaml").equations("kane")
    replacements, reduced = cse([sp.sympify(e) for e in [*eq.M, *eq.f, *eq.A, *eq.b]])
    sums = [n for e in [v for _, v in replacements] + reduced for n in sp.preorder_traversal(e) if n.is_Add]
    x, y, z = sp.symbols("x y z", real=True)
    A = sp.Symbol("A", commutative=False)
    rng = random.Random(9)
    numbers = [sp.Integer(-3), sp.Rational(1, 3), sp.Float(0.7), sp.Float(-2.5), sp.sqrt(2), sp.pi, sp.I, 2 - sp.I]
    parts = [x, y ** 2, x * y, sp.sin(z), sp.cos(x) ** 3, z ** -2, sp.exp(y), x * z ** 2, A * x]
    for _ in range(300):
        sums.append(sp.Add(*(rng.choice(numbers) * rng.choice(parts) for _ in range(rng.randint(2, 6))),
                           *([rng.choice(numbers)] if rng.random() < 0.4 else [])))
    sums += [1 - 2 * x, sp.pi - 3 * y, x + sp.O(x ** 2)]
    assert len(sums) > 350
    for s in sums:
        if s.is_Add:
            assert ordered_terms(s) == s.as_ordered_terms(), s
