"""The generated packages' residual Jacobian d[M q'' - f]/d[q, q'] against an independent derivation.

The package builds it by forward differentiation of one CSE of M and f (numeric/lambdify.differentiate_program:
sums term by term, products left unsorted, derivatives that are numbers or symbols used in place). Here the
reference is sympy's own `jacobian` of M a - f from tests/reference_mechanics.py (plain sympy from T and V,
nothing of mechsys) on models written as a user would: the Furuta pendulum and a heavy top (tests/data/beyond/),
and a four-link chain of rods with relative angles written below, with its Lagrangian built here by hand. And
the generated code is the same in every process."""
from __future__ import annotations

import functools
import importlib.util
import os
import subprocess
import sys

import numpy as np
import pytest
import sympy as sp

import mechsys
import reference_mechanics as ref
from mechsys.codegen import TARGETS, derive_package
from mechsys.codegen.package import write_directory
from test_lagrange_reference import _reference

LINKS = 4
CHAIN = "\n".join([
    "name: rods",
    "parameters: {m: 0.7, l: 0.9, g: 9.81}",
    "coordinates:",
    *[f"  q{k}: {{initial: 0.1, rate: 0}}" for k in range(1, LINKS + 1)],
    "links:",
    *[line for k in range(1, LINKS + 1) for line in (
        f"  rod{k}:",
        f"    joint: {{type: revolute, parent: {'ground' if k == 1 else f'rod{k - 1}'}, axis: z, coordinate: q{k}"
        + ("}" if k == 1 else ", origin: [l, 0, 0]}"),
        "    mass: m",
        "    center_of_mass: [l/2, 0, 0]",
        "    shape: {rod: {length: l, axis: x}}")],
    "forces:",
    "  - {type: gravity, acceleration: [0, -g, 0]}",
]) + "\n"


@functools.lru_cache(maxsize=None)
def _chain_reference() -> tuple[list[str], sp.Matrix, sp.Matrix, tuple, tuple]:
    """M and f of the chain from its Lagrangian: rods of mass m, length l (I = m l^2 / 12 about the centre)."""
    m, l, g = 0.7, 0.9, 9.81
    names = [f"q{k}" for k in range(1, LINKS + 1)]
    q, u = sp.symbols(" ".join(f"x{k}" for k in range(LINKS)), real=True), \
        sp.symbols(" ".join(f"v{k}" for k in range(LINKS)), real=True)
    T = V = sp.Integer(0)
    joint = sp.Matrix([0, 0])
    for k in range(LINKS):
        angle, rate = sum(q[:k + 1]), sum(u[:k + 1])
        axis = sp.Matrix([sp.cos(angle), sp.sin(angle)])
        centre = joint + axis * l / 2
        v = centre.jacobian(q) * sp.Matrix(u)
        T += sp.Rational(1, 2) * m * (v.T * v)[0] + sp.Rational(1, 2) * m * l ** 2 / 12 * rate ** 2
        V += m * g * centre[1]
        joint = joint + axis * l
    p = sp.Matrix([T]).jacobian(u).T
    M = p.jacobian(u)
    f = -sp.Matrix([V]).jacobian(q).T + sp.Matrix([T]).jacobian(q).T - p.jacobian(q) * sp.Matrix(u)
    return names, M, f, q, u


def reference_case(case: str, tmp_path) -> tuple:
    """(model file, coordinate names, M, f, q symbols, u symbols) of an independent reference: "chain" (the rods
    above, its file written to tmp_path) or a case of tests/test_lagrange_reference.py ("furuta", "zxz")."""
    if case == "chain":
        path = tmp_path / "rods.yaml"
        path.write_text(CHAIN)
        names, M, f, q, u = _chain_reference()
        return path, names, M, f, q, u
    path, system = _reference(case)
    return path, list(system.names), system.M, system.f, system.q, system.u


_REFERENCES: dict = {}  # case -> its reference Jacobian (one per model for both methods)


def _reference_jacobian(M: sp.Matrix, f: sp.Matrix, q: tuple, u: tuple):
    """d(M a - f)/d(q, u) as a numpy function of (q, u, a): sympy's jacobian."""
    a = sp.symbols(f"a0:{len(q)}", real=True)
    return sp.lambdify((*q, *u, *a), (M * sp.Matrix(a) - f).jacobian([*q, *u]), "numpy")


def _generated_module(pkg, folder):
    write_directory(folder, TARGETS["python"](pkg))
    spec = importlib.util.spec_from_file_location(f"generated_{pkg.prefix}", folder / f"{pkg.prefix}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("method", ["lagrange", "kane"])
@pytest.mark.parametrize("case", ["furuta", "zxz", "chain"])
def test_residual_jacobian_equals_sympys_jacobian_of_the_reference(case, method, tmp_path):
    path, names, M, f, q, u = reference_case(case, tmp_path)
    reference = _REFERENCES.get(case) or _REFERENCES.setdefault(case, _reference_jacobian(M, f, q, u))

    model = mechsys.load(path)
    assert sorted(model.coordinates) == sorted(names)
    order = [model.coordinates.index(name) for name in names]  # reference index -> model index
    n = len(names)
    generated = _generated_module(derive_package(model, method), tmp_path / "package")
    p = generated.params()
    rng = np.random.default_rng(23)
    for _ in range(5):
        qv, uv, av = (rng.uniform(-2, 2, n), rng.uniform(-3, 3, n), rng.uniform(-4, 4, n))
        J = np.asarray(generated.residual_jacobian(0.0, qv, uv, av, np.zeros(0), p), dtype=float)
        want = np.asarray(reference(*qv[order], *uv[order], *av[order]), dtype=float)
        columns = [*order, *(n + i for i in order)]
        got = J[np.ix_(order, columns)]
        scale = max(1.0, float(np.abs(want).max()))
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-10 * scale)


@pytest.mark.parametrize("method", ["lagrange", "kane"])
def test_the_generated_code_does_not_change_with_the_process(method, tmp_path):
    """Two `codegen` runs whose string hashing differs (PYTHONHASHSEED: the order of every set of symbols) write
    the same files: the derivatives are formed in program order, not in a set's order."""
    path = tmp_path / "rods.yaml"
    path.write_text(CHAIN)
    written = []
    for seed in ("1", "2"):
        out = tmp_path / f"package{seed}"
        env = dict(os.environ, PYTHONHASHSEED=seed, MECHSYS_CACHE="off")
        subprocess.run([sys.executable, "-m", "mechsys", "codegen", str(path), "-t", "python", "--method", method,
                        "-o", str(out)], env=env, check=True, capture_output=True)
        written.append({f.name: f.read_text() for f in sorted(out.iterdir())})
    assert written[0] == written[1]
