"""The multistart's deflated Newton as compiled code (numeric/newton.c): its least-squares step against numpy's
lstsq, and its roots against the Python loop's (analysis/equilibrium/equilibria.py, _newton) on nonholonomic
models: the same steady motions from the same starts."""
from __future__ import annotations

import ctypes
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import mechsys
from mechsys.analysis.equilibrium import equilibria as eqm
from mechsys.analysis.equilibrium.bifurcation import swept_parameter
from mechsys.analysis.equilibrium.nonholonomic import NonholonomicProblem
from mechsys.errors import AnalysisError
from mechsys.numeric import native

sys.path.insert(0, str(Path(__file__).parent))
from helpers import SYSTEMS_DIR  # noqa: E402

LIB = native.newton_library()
pytestmark = pytest.mark.skipif(LIB is None, reason="no C compiler")


def c_lstsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    m, n = A.shape
    a = np.ascontiguousarray(A, dtype=float).copy()
    b = np.ascontiguousarray(b, dtype=float)
    x = np.zeros(n)
    work = np.empty(LIB.mechsys_newton_work(m, n, 0, 0, 0))
    fn = LIB.mechsys_lstsq
    fn.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
    fn.restype = None
    fn(a.ctypes.data, m, n, b.ctypes.data, x.ctypes.data, work.ctypes.data)
    return x


@pytest.mark.parametrize("case", ["full rank", "rank deficient", "underdetermined", "zero column", "graded"])
def test_the_least_squares_step_is_numpys_minimum_norm_solution(case):
    rng = np.random.default_rng(7)
    if case == "full rank":
        A = rng.normal(size=(23, 18))
    elif case == "rank deficient":  # rank 10: numpy's gelsd gives the minimum-norm solution
        A = rng.normal(size=(23, 10)) @ rng.normal(size=(10, 18))
    elif case == "underdetermined":
        A = rng.normal(size=(6, 10))
    elif case == "zero column":
        A = rng.normal(size=(12, 8))
        A[:, 3] = 0.0
    else:  # columns scaled over 12 decades: QR's diagonal trips the SVD fallback, the rank is still full
        A = rng.normal(size=(15, 9)) * np.logspace(0, -12, 9)[None, :]
    b = rng.normal(size=A.shape[0])
    want = np.linalg.lstsq(A, b, rcond=None)[0]
    got = c_lstsq(A, b)
    if case == "graded":  # ill-conditioned: compare residuals, both least-squares to round-off
        assert np.linalg.norm(A @ got - b) == pytest.approx(np.linalg.norm(A @ want - b), rel=1e-8)
    else:
        assert np.allclose(got, want, rtol=1e-10, atol=1e-12 * np.max(np.abs(want)))


def _roots(problem, p, compiled: bool) -> list[np.ndarray]:
    if not compiled:
        problem.compiled_newton = lambda p: None  # the Python loop
    else:
        problem.__dict__.pop("compiled_newton", None)
    plan = eqm.search_plan(problem, None, None)
    roots = eqm._search(problem, p, plan, 0)
    # lying flat the bicycle's front contact is a continuum (every chi touches the ground): not comparable roots,
    # the search names them as coordinate singularities and drops them
    return [z for z in roots if problem.split_singularity(z, p) is None]


def _same_roots(problem, a: list[np.ndarray], b: list[np.ndarray]) -> bool:
    ang = problem.is_angle()

    def close(x, y):
        d = x - y
        d[ang] = np.remainder(d[ang] + np.pi, 2 * np.pi) - np.pi  # steer = pi and -pi are one angle
        return np.max(np.abs(d[:problem.nq])) < 1e-7

    return len(a) == len(b) and all(any(close(x, y) for y in b) for x in a)


@pytest.mark.parametrize("model, speed", [("bicycle", 5.0), ("rolling_disk", None)])
def test_the_compiled_loop_finds_the_python_loops_roots(model, speed):
    """Same starts, same deflation, same acceptance: the same steady motions (round-off differs, so a start may
    converge elsewhere in principle; on these models it does not), several times faster."""
    problem = NonholonomicProblem(mechsys.load(SYSTEMS_DIR / f"{model}.yaml"))
    p = swept_parameter(problem, "v").at(speed) if speed is not None else eqm.parameter_values(problem.model)
    assert problem.compiled_newton(p) is not None
    compiled, python = _roots(problem, p, True), _roots(problem, p, False)
    assert compiled and _same_roots(problem, compiled, python)
    for z in compiled:
        assert np.max(np.abs(problem.F(z, p))) < 1e-10 * max(1.0, np.max(np.abs(problem.J(z, p))))


def test_positions_out_of_range_are_refused():
    """The compiled code writes and reads by position without bounds: the wrapper checks them first."""
    problem = NonholonomicProblem(mechsys.load(SYSTEMS_DIR / "rolling_disk.yaml"))
    p = eqm.parameter_values(problem.model)
    run = problem.compiled_newton(p)
    program = problem.pieces._native
    with pytest.raises(AnalysisError, match="out of range"):
        native.CompiledNewton(LIB, program, "mechsys_values", "mechsys_full", run.base, run.pos + 10_000, run.index,
                              run.sign, problem.is_angle())
    with pytest.raises(AnalysisError, match="arguments"):
        native.CompiledNewton(LIB, program, "mechsys_values", "mechsys_full", run.base[:-1], run.pos, run.index,
                              run.sign, problem.is_angle())


def test_a_stored_search_is_kept_per_numeric_path(tmp_path, monkeypatch):
    """The compiled loop and the Python loop differ in round-off, so their searches are stored apart: a search
    made with a C compiler is not read back under MECHSYS_NATIVE=off (the cache rule: the key covers the code),
    nor one whose pieces another compiler built (MECHSYS_QUICK_CC=off: gcc instead of tcc)."""
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path))
    keys = {}
    for path in ("compiled", "compiled by the C compiler", "python"):
        if path == "compiled by the C compiler":
            monkeypatch.setenv("MECHSYS_QUICK_CC", "off")
        if path == "python":
            monkeypatch.setenv("MECHSYS_NATIVE", "off")
        problem = NonholonomicProblem(mechsys.load(SYSTEMS_DIR / "rolling_disk.yaml"))
        assert problem.newton_path == ("python" if path == "python"
                                       else f"compiled-{Path(native.quick_compiler()).name}")
        p = eqm.parameter_values(problem.model)
        keys[path] = eqm._disk_key(problem, (np.asarray(p).tobytes(), (), (), "[]", 40, "{}", 0))
    assert None not in keys.values() and keys["compiled"] != keys["python"]
    quick_differs = native.shutil.which("tcc") is not None
    assert len(set(keys.values())) == (3 if quick_differs else 2)


def test_the_library_built_beside_other_work_is_built_once(monkeypatch, tmp_path):
    """prepare_newton builds newton.c in a thread (beside a model's own compilation); newton_library waits for
    that build instead of starting another: one library in the cache, the same object for every caller."""
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path))
    monkeypatch.setattr(native, "_newton_lib", {})
    native.prepare_newton()
    lib = native.newton_library()
    assert lib is not None and native.newton_library() is lib
    for thread in threading.enumerate():  # the first thread may still be finishing (it found the library built)
        if thread.name == "mechsys-newton-build":
            thread.join(timeout=60)
    native.prepare_newton()  # built already: no second thread
    assert [t.name for t in threading.enumerate()].count("mechsys-newton-build") == 0
    assert len(list(tmp_path.glob("newton-*.so"))) == 1
    assert lib.mechsys_newton_work(3, 3, 0, 0, 0) > 0


def test_a_process_forked_during_the_build_does_not_wait_for_it(monkeypatch, tmp_path):
    """A sweep forks its workers: one forked while prepare_newton's thread holds the lock gets a lock of its own
    (the thread does not exist in the child) and still gets the library."""
    import os

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path))
    monkeypatch.setattr(native, "_newton_lib", {})
    with native._NEWTON_LOCK:  # as if the build thread were inside newton_library
        pid = os.fork()
        if pid == 0:  # the child: exit 0 when it got the library; killed by the alarm if it waits for the lock
            import signal

            signal.alarm(60)
            os._exit(0 if native.newton_library() is not None else 1)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0


def test_the_deflations_angle_wrapping_is_numpys_remainder_bit_for_bit():
    """equilibria._wrap (fmod, then the divisor added where negative) gives remainder(d + pi, 2 pi) - pi bit for
    bit: random distances, multiples of pi and 2 pi and their neighbours, zeros of both signs, subnormals, huge
    values, infinities and nan; in place, on a whole array and on a gathered part."""
    from mechsys.analysis.equilibrium.equilibria import _wrap

    rng = np.random.default_rng(11)
    base = np.concatenate([rng.uniform(-50, 50, 20_000), np.arange(-20, 21) * np.pi, np.arange(-20, 21) * 2 * np.pi,
                           [0.0, -0.0, 1e-300, -1e-300, 5e-324, -5e-324, 1e300, -1e300, np.inf, -np.inf, np.nan]])
    values = np.concatenate([base, base + np.pi, base - np.pi, np.nextafter(base, np.inf),
                             np.nextafter(base, -np.inf)]).reshape(-1, 5)
    with np.errstate(all="ignore"):
        expected = np.remainder(values + np.pi, 2 * np.pi) - np.pi
        wrapped = values.copy()
        assert _wrap(wrapped) is wrapped
        assert np.array_equal(wrapped.view(np.int64), expected.view(np.int64))
        part = values.copy()
        part[:, [0, 3]] = _wrap(part[:, [0, 3]])
        assert np.array_equal(part[:, [0, 3]].view(np.int64), expected[:, [0, 3]].view(np.int64))
        assert np.array_equal(part[:, [1, 2, 4]].view(np.int64), values[:, [1, 2, 4]].view(np.int64))
