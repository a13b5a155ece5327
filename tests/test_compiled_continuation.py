"""A sweep's per-point work as compiled code (numeric/newton.c): the continuation's corrector (mechsys_corrector:
the same Newton steps as the Python loop, analysis/equilibrium/continuation.py _Tracer.newton, on a sweep's
bordered system, the same Jacobian at the result, the same sweeps; used only where the swept value moves the
arguments affinely) and the linearization about a steady motion (mechsys_linearize: the numpy steps of
analysis/equilibrium/nonholonomic.py, the same matrices, eigenvalues, families and refusals)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import mechsys
from mechsys.analysis.equilibrium import bifurcation as bf
from mechsys.analysis.equilibrium.continuation import ContinuationOptions, _Tracer
from mechsys.analysis.equilibrium.equilibria import is_isolated, solve_equilibria
from mechsys.analysis.equilibrium import nonholonomic as nh
from mechsys.analysis.equilibrium.nonholonomic import NonholonomicProblem
from mechsys.errors import AnalysisError
from mechsys.numeric import native

sys.path.insert(0, str(Path(__file__).parent))
from helpers import SYSTEMS_DIR  # noqa: E402

pytestmark = pytest.mark.skipif(native.newton_library() is None, reason="no C compiler")

DATA = Path(__file__).parent / "data"
DISK = SYSTEMS_DIR / "rolling_disk.yaml"


def _tracers(path: Path, name: str, at: float):
    """The sweep's scaled system F(x, p) = E(D x)[rows] at a steady motion found at ``name`` = ``at``, as sweep()
    builds it (auxiliary unknowns scaled and weighted down), traced by the Python loop and by the compiled one."""
    problem = NonholonomicProblem(mechsys.load(path))
    par = bf.swept_parameter(problem, name)
    P = par.at(at)
    roots = [z for z in solve_equilibria(problem, P) if is_isolated(problem, z, P)]
    assert roots
    z0 = roots[0]
    system = bf.SweptSystem(problem, par, problem.auxiliary_scale(roots), bf._independent_rows(problem.J(z0, P)))
    n = len(z0)
    F, Fx, Fp = system.F, system.Fx, system.Fp
    s = np.where(np.arange(n) >= problem.nq + len(problem.rate_unknowns), bf.AUX_ARC_WEIGHT, 1.0)
    factory = system.compiled([(z0 / system.D, at)])
    assert factory is not None
    options = ContinuationOptions(tol=1e-10, tol_re=1e-8, x_scale=s, tol_scale=np.ones(n))
    python = _Tracer(F, Fx, Fp, None, n, options)
    compiled = _Tracer(F, Fx, Fp, None, n, options, compiled=factory)
    return python, compiled, python.z_of(z0 / system.D, at)


@pytest.mark.parametrize("path, name, at", [
    (SYSTEMS_DIR / "bicycle.yaml", "v", 5.0),  # the speed sets a given rate: dF/dp from dE/du
    (DISK, "g", 9.81),                          # E reads g: dF/dp by the central difference of Fp_along
    (DISK, "der(spin)", 4.0),                   # the given rate itself
])
def test_the_compiled_corrector_takes_the_python_loops_steps(path, name, at):
    python, compiled, z0 = _tracers(path, name, at)
    rng = np.random.default_rng(11)
    n = python.n
    agreed = converged = 0
    for trial in range(12):
        size = 10.0 ** rng.uniform(-6, 0.5)  # from easy corrections to guesses where Newton fails
        guess = z0 + size * rng.normal(size=n + 1) * np.abs(z0).clip(0.1)
        border = rng.normal(size=n + 1)
        border /= np.linalg.norm(border)
        monotone = trial % 3 != 0
        iters = 2 if trial % 4 == 1 else 10  # few iterations: the far guesses fail
        a = python.newton(guess, border, iters, monotone)
        b = compiled.newton(guess, border, iters, monotone)
        assert (a is None) == (b is None), (trial, size)
        agreed += 1
        if a is None:
            continue
        converged += 1
        scale = 1.0 + np.max(np.abs(a[0]))
        assert np.max(np.abs(a[0] - b[0])) <= 1e-9 * scale
        assert abs(a[1] - b[1]) <= 1  # round-off may move the last test across the tolerance
        # the Jacobian the compiled corrector leaves for the point's tangent is the Python one at its point
        kept = compiled.jac(b[0])
        python.__dict__.pop("_last_jac", None)
        fresh = python.jac(b[0])
        assert np.allclose(kept, fresh, rtol=1e-6, atol=1e-8 * np.max(np.abs(fresh)))
    assert agreed == 12 and 3 <= converged < 12  # both outcomes were exercised


def test_a_swept_value_that_moves_the_arguments_nonlinearly_keeps_the_python_loop():
    """The rolling disk's spin rate is 1/r: sweeping r moves a given rate as 1/r, which the compiled corrector's
    affine arguments cannot follow: sweep() keeps the Python loop there, and uses the compiled one for g."""
    problem = NonholonomicProblem(mechsys.load(DISK))
    radius, gravity = bf.swept_parameter(problem, "r"), bf.swept_parameter(problem, "g")
    assert not radius.affine and gravity.affine and bf.swept_parameter(problem, "der(spin)").affine
    z = np.zeros(len(problem.unknowns))
    rows = list(range(len(z)))
    assert bf.SweptSystem(problem, radius, np.ones(len(z)), rows).compiled([(z, 0.3)]) is None
    assert bf.SweptSystem(problem, gravity, np.ones(len(z)), rows).compiled([(z, 9.81)]) is not None


@pytest.mark.parametrize("name, lo, hi", [("g", 5.0, 15.0), ("r", 0.2, 0.4)])
def test_a_sweep_with_the_compiled_corrector_is_the_python_loops_sweep(monkeypatch, name, lo, hi):
    """The rolling disk's steady turns swept in g (compiled) and r (Python either way): the same branches, the
    same events to 1e-8 and the same verdicts as with the Python loop."""
    def run(compiled: bool):
        if not compiled:
            monkeypatch.setattr(bf.SweptSystem, "compiled", lambda self, starts: None)
        return bf.sweep(mechsys.load(DISK), name, lo, hi, 21)

    a, b = run(True), run(False)
    assert len(a.branches) == len(b.branches) > 0
    assert [e["kind"] for e in a.bifurcations] == [e["kind"] for e in b.bifurcations]
    for x, y in zip(a.bifurcations, b.bifurcations):
        assert x["value"] == pytest.approx(y["value"], rel=1e-8, abs=1e-10)
    for p, q in zip(a.branches, b.branches):
        assert [pt.verdict for pt in p.points] == [pt.verdict for pt in q.points]
        assert np.allclose([pt.p for pt in p.points], [pt.p for pt in q.points], rtol=1e-9, atol=1e-12)


def test_arguments_out_of_range_are_refused():
    """The compiled code reads and writes by position without bounds: the wrapper checks them first."""
    problem = NonholonomicProblem(mechsys.load(DISK))
    par = bf.swept_parameter(problem, "g")
    nz = len(problem.unknowns)
    make = bf.SweptSystem(problem, par, np.ones(nz), list(range(nz))).compiled([(np.zeros(nz), 9.81)])
    assert make(np.ones(nz), np.ones(nz + 1), 1e-10) is not None
    with pytest.raises(AnalysisError, match="out of range"):
        make(np.ones(nz + 1), np.ones(nz + 1), 1e-10)  # s of the wrong length


def _both(problem, e, p):
    """linearize_steady compiled and in numpy (the outcome: a SteadyLinearization or the AnalysisError's text)."""
    out = []
    for compiled in (True, False):
        run = problem.compiled_linearization
        if not compiled:
            problem.__dict__["compiled_linearization"] = None
        try:
            out.append(nh.linearize_steady(problem, e, p))
        except AnalysisError as exc:
            out.append(str(exc))
        finally:
            problem.__dict__["compiled_linearization"] = run
    return out


def _same_spectrum(a: np.ndarray, b: np.ndarray, atol: float) -> bool:
    """The same eigenvalues up to atol, matched one to one by distance (sort_complex orders by the real part first,
    and round-off signs of a zero real part, -1e-31 against 2e-65, reorder the imaginary pairs)."""
    from scipy.optimize import linear_sum_assignment

    if a.shape != b.shape:
        return False
    rows, cols = linear_sum_assignment(np.abs(a[:, None] - b[None, :]))
    return bool(np.all(np.abs(a[rows] - b[cols]) <= atol))


@pytest.mark.parametrize("path, options, name, values", [
    (SYSTEMS_DIR / "bicycle.yaml", {}, "v", [0.0, 0.5, 4.3, 8.0]),  # holonomic + nonholonomic, a given rate
    (SYSTEMS_DIR / "bicycle.yaml", {"given": ["lean"]}, "v", [4.0]),  # a family that is not deflated (lean)
    (DISK, {}, "g", [9.81]),
    (DISK, {"given": ["lean"], "solve": ["der(yaw)"]}, "g", [9.81]),  # a --given coordinate's family
    (DATA / "chaplygin_sleigh.yaml", {"given": ["psi"]}, "v", [-1.0, 1.5]),
])
def test_the_compiled_linearization_is_the_numpy_one(path, options, name, values):
    problem = NonholonomicProblem(mechsys.load(path), **options)
    assert problem.compiled_linearization is not None
    par = bf.swept_parameter(problem, name)
    compared = refused = 0
    for value in values:
        p = par.at(value)
        for z in solve_equilibria(problem, p)[:8]:
            a, b = _both(problem, problem.equilibrium(z), p)
            if isinstance(b, str):  # the same refusal (a singular split: the bicycle's pivot at v = 0)
                assert a == b
                refused += 1
                continue
            compared += 1
            scale = 1.0 + np.max(np.abs(b.jacobian))
            for key in ("jacobian", "M", "C", "K", "W", "V"):
                assert np.allclose(getattr(a, key), getattr(b, key), rtol=1e-9, atol=1e-9 * scale), key
            assert (a.families, a.undeflated, a.coordinates, a.speeds) == \
                (b.families, b.undeflated, b.coordinates, b.speeds)
            # the deflated matrices differ by an orthogonal change of basis: their eigenvalues agree
            assert a.deflated.shape == b.deflated.shape
            size = 1.0 + np.max(np.abs(b.eigenvalues), initial=0.0)
            assert _same_spectrum(a.eigenvalues, b.eigenvalues, 1e-8 * size)
    assert compared >= len(values)
    if 0.0 in values and path.stem == "bicycle":
        assert refused >= 1  # the refusal path was exercised (the pivot at v = 0)
