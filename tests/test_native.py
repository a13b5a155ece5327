"""The native fast path (numeric/native.py): generated C equations and the compiled DOP853 loop.

The compiled loop follows scipy's DOP853 step by step, so it must reproduce `--method DOP853` to rounding, and
its accelerations must equal the Python path's at any state, for every unconstrained model we ship."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import mechsys
from mechsys.numeric.parameters import parameter_values
from mechsys.analysis.motion.simulate import RightHandSide, compile_model, initial_state, simulate
from mechsys.errors import AnalysisError, InputError
from mechsys.numeric import native
from tests.helpers import DATA_DIR, ROOT, SYSTEMS_DIR, load_data, load_system

pytestmark = pytest.mark.skipif(native.compiler() is None, reason="no C compiler: the native path is optional")

UNCONSTRAINED = [SYSTEMS_DIR / f"{n}.yaml" for n in ("double_pendulum", "cart_pendulum", "centrifuge", "motor_arm",
                                                    "problem57", "spring_chain", "bullet_pendulum", "newton_cradle")]
UNCONSTRAINED += [DATA_DIR / f"{n}.yaml" for n in ("native_functions", "torque_free_body", "two_free_bodies",
                                                  "free_free_chain", "beads_string", "friction_sphere_3d", "p51_racket",
                                                  "stiff_chain")]




@pytest.mark.parametrize("path", UNCONSTRAINED, ids=lambda p: p.stem)
def test_native_accelerations_equal_python_path(path):
    """The C translation of the staged Kane terms (CSE, C printer, assembly, LU) gives the Python path's q''."""
    model = mechsys.load(path)
    nat = native.load(model)
    rhs = RightHandSide(compile_model(model), parameter_values(model))
    rng = np.random.default_rng(7)
    n = len(model.q)
    for _ in range(5):
        y = rng.uniform(-1.5, 1.5, 2 * n)
        t = float(rng.uniform(0, 3))
        expected = rhs(t, y)[n:]
        got = nat.accelerations(t, y, rhs.p)
        assert np.allclose(got, expected, rtol=1e-11, atol=1e-11 * (1 + np.max(np.abs(expected))))


@pytest.mark.parametrize("name,t_end", [("double_pendulum", 10.0), ("centrifuge", 5.0), ("spring_chain", 5.0)])
def test_native_takes_scipys_dop853_steps(name, t_end):
    """Same step-size control, initial step and dense output as scipy's DOP853: same states to rounding."""
    model = load_system(name)
    c, p, y0 = initial_state(model)
    grid = np.linspace(0.0, t_end, 501)
    run = native.load(model).run(p, y0, grid, 1e-10, 1e-12)
    sol = solve_ivp(RightHandSide(c, p), (0.0, t_end), y0, method="DOP853", t_eval=grid, rtol=1e-10, atol=1e-12)
    assert run.status == 0 and len(run.y) == len(grid)
    scale = 1 + np.max(np.abs(sol.y))
    assert np.max(np.abs(run.y - sol.y.T)) < 1e-10 * scale
    # the same steps; native skips the 3 dense-output stages when a step ends exactly on an output time
    assert sol.nfev - 3 * len(grid) <= run.nfev <= sol.nfev


def test_native_3d_body_conserves_energy_and_matches_reference():
    """A torque-free asymmetric body (gyroscopic terms, full inertia): energy drift tiny, state = tight DOP853."""
    model = load_data("torque_free_body")
    r = simulate(model, 20.0, method="native")
    ref = simulate(model, 20.0, method="DOP853", rtol=1e-13, atol=1e-14)
    assert r.method == "native"
    assert r.energy_drift < 1e-9
    assert np.max(np.abs(r.q - ref.q)) < 1e-7


def test_double_pendulum_within_1e_6_of_tight_reference_for_2_s_native():
    """Issue 4's accuracy check, on the compiled path at default settings."""
    model = load_system("double_pendulum")
    r = simulate(model, 2.0, method="native")
    ref = simulate(model, 2.0, method="DOP853", rtol=1e-13, atol=1e-14)
    assert np.max(np.abs(np.hstack([r.q - ref.q, r.u - ref.u]))) < 1e-6


def test_auto_picks_native_for_a_non_stiff_open_chain_and_cvode_for_the_stiff_chain():
    assert simulate(load_system("double_pendulum"), 1.0).method == "native"
    assert simulate(load_data("stiff_chain"), 10.0).method == "CVODE"  # SUNDIALS is in the dev extra


def test_auto_keeps_the_compiled_loop_where_lasting_oscillations_must_be_followed_anyway():
    """A chain of six masses with springs of 1 to 1e8 (tests/data/beyond/stiff_chain.yaml): a decay rate of 2.2e5
    1/s makes it stiff, but modes of up to 60 rad/s ring through the 10 s, and CVODE at rtol 1e-12 followed them in
    1.6 million Python evaluations (105 s; Radau 385 s) where the compiled loop takes 2.4 s (agreeing with Radau to
    3e-12). auto now takes the compiled loop there, and still CVODE for the overdamped chain above."""
    model = mechsys.load(DATA_DIR / "beyond" / "stiff_chain.yaml")
    auto = simulate(model, 10.0, dt=0.01)
    assert auto.method == "native"
    assert any("oscillations up to 60 rad/s last through the run" in w for w in auto.warnings)
    native = simulate(model, 10.0, dt=0.01, method="native")
    assert np.array_equal(auto.q, native.q)


def test_native_refuses_contacts_and_events_with_a_reason():
    """An option that does not fit the model: an input error (exit 2), not a failed analysis."""
    with pytest.raises(InputError, match="contacts"):
        simulate(load_system("bouncing_ball"), 1.0, method="native")
    with pytest.raises(InputError, match="events"):
        simulate(load_data("falling_events"), 1.0, method="native")


@pytest.mark.parametrize("name", ["four_bar", "rolling_disk", "indicator"])
def test_native_closed_loops_and_rolling_agree_with_the_scipy_path(name):
    """Constraints on the compiled loop: [[M, A^T], [A, 0]] solved in C, projected about every 20 steps (dense
    output in between: the step is set by the tolerance, 109 steps for the indicator over 3 s); the scipy path
    projects about every 20 steps too. Both agree with a run at rtol 1e-13 to what rtol 1e-10 gives over that many
    steps (1e-8 on the indicator, 2e-7 of rates up to 12 rad/s on the four-bar for scipy's DOP853; the output grid
    used to force a step per output, which hid it)."""
    model = mechsys.load(SYSTEMS_DIR / f"{name}.yaml", release_prescribed=True)
    a = simulate(model, 3.0, method="native")
    b = simulate(model, 3.0, method="DOP853")
    ref = simulate(model, 3.0, method="native", rtol=1e-13, atol=1e-15)
    assert a.method == "native"
    R = np.hstack([ref.q, ref.u])
    for run in (a, b):  # global errors, relative to each coordinate's or rate's largest value
        assert np.all(np.abs(np.hstack([run.q, run.u]) - R) <= 1e-7 * (1.0 + np.max(np.abs(R), axis=0)))
    assert np.max(a.residual) <= 1e-10
    for k in a.driving:
        for run in (a, b):
            scale = 1.0 + float(np.max(np.abs(ref.driving[k])))  # small forces that cancel large terms
            assert np.max(np.abs(run.driving[k] - ref.driving[k])) <= 1e-7 * scale


def test_slider_crank_runs_through_its_dead_centres_native():
    """A flywheel-driven slider-crank turns ten times through both dead centres (theta2 = 0, pi): the augmented
    formulation stays regular there (the crank pin's Jacobian keeps full rank), energy and residual hold."""
    model = mechsys.load(SYSTEMS_DIR / "slider_crank.yaml", {"der(theta2)": "20"})
    r = simulate(model, 3.0, method="native")
    assert r.q[-1, model.coordinates.index("theta2")] > 2 * np.pi * 9
    assert np.max(r.residual) <= 1e-10
    assert r.energy_drift < 1e-8


@pytest.mark.parametrize("method", ["native", "DOP853"])
def test_singular_mass_matrix_is_reported(tmp_path, method):
    """A coordinate that carries no mass: the compiled loop stops with the reason, not garbage."""
    f = tmp_path / "massless.yaml"
    f.write_text("""
name: massless
parameters: {m: 1.0}
coordinates: {x: {initial: 0.0, rate: 1.0}, y: {initial: 0.0}}
links:
  a: {particle: true, joint: {type: prismatic, parent: ground, axis: x, coordinate: x}, mass: m}
  b: {particle: true, joint: {type: prismatic, parent: a, axis: y, coordinate: y}, mass: 0}
""")
    model = mechsys.load(f)
    with pytest.raises(AnalysisError, match="singular"):
        simulate(model, 1.0, method=method)


def test_progress_callback_reports_increasing_times():
    seen = []
    simulate(load_system("double_pendulum"), 5.0, method="native", progress=seen.append)
    assert len(seen) >= 5 and seen == sorted(seen) and seen[-1] == pytest.approx(5.0)


def test_without_a_compiler_auto_falls_back_to_scipy(tmp_path):
    env = {**os.environ, "MECHSYS_NATIVE": "off", "MECHSYS_CACHE": str(tmp_path)}
    out = tmp_path / "r.json"
    proc = subprocess.run([sys.executable, "-m", "mechsys", "simulate", str(SYSTEMS_DIR / "double_pendulum.yaml"),
                           "--t-end", "1", "-o", str(out), "-f", "json"], capture_output=True, text=True, env=env,
                          cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert "DOP853" in proc.stdout
    assert json.loads(out.read_text())["columns"][0] == "t"


def test_native_library_is_cached_between_processes(tmp_path):
    env = {**os.environ, "MECHSYS_CACHE": str(tmp_path)}
    cmd = [sys.executable, "-m", "mechsys", "simulate", str(SYSTEMS_DIR / "double_pendulum.yaml"), "--t-end", "1"]
    first = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    second = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    assert first.returncode == 0 and second.returncode == 0
    assert "compile native" in first.stdout and "compile native" not in second.stdout
    assert list(tmp_path.glob("*.so"))


def test_a_build_started_early_gives_the_library_built_late(monkeypatch, tmp_path):
    """native.start compiles in the background while simulate generates its Python code; load() takes that
    library: stored in the cache, computing what the Python path computes. A build nobody takes is stopped and its
    files removed (at exit)."""
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    native._abandon()  # builds other tests of this worker left (the assertions below are about this test's own)

    def fresh(name):  # not the session's shared models: this test sets their compiled code
        return mechsys.load(SYSTEMS_DIR / f"{name}.yaml")

    model = fresh("double_pendulum")
    native.start(model)
    assert model._native_pending is not None
    early = native.load(model)
    assert early is not None and not getattr(early, "from_cache", False) and early.key is not None
    assert not hasattr(model, "_native_pending") and not native._UNFINISHED
    c = compile_model(model)
    p = parameter_values(model)
    y = np.array([0.3, -0.2, 0.5, 0.1])
    rhs = RightHandSide(c, p)
    np.testing.assert_allclose(early.accelerations(0.0, y, p), rhs(0.0, y)[2:], rtol=1e-12, atol=1e-12)
    again = fresh("double_pendulum")
    native.start(again)  # cached now: nothing to start
    assert getattr(again, "_native_pending", None) is None and native.load(again).from_cache
    other = fresh("cart_pendulum")
    native.start(other)
    assert native._UNFINISHED
    native._abandon()
    assert not native._UNFINISHED and not list(tmp_path.glob("mechsys-native-*"))


def test_redundant_constraints_fall_back_to_least_squares_with_a_warning(tmp_path):
    """Two proportional constraint rows make [[M, A^T], [A, 0]] singular: the compiled LU stops, auto says so and
    finishes with the least-squares (SVD) solve of the scipy path; --method native reports the reason."""
    text = (SYSTEMS_DIR / "centrifuge.yaml").read_text()
    text += "constraints:\n  - {type: holonomic, expression: beta - 0.1}\n  - {type: holonomic, expression: 2*beta - 0.2}\n"
    path = tmp_path / "redundant.yaml"
    path.write_text(text)
    model = mechsys.load(path, {"beta": "0.1", "der(beta)": "0"})
    r = simulate(model, 1.0)
    assert r.method == "DOP853" and any("redundant" in w for w in r.warnings)
    assert np.max(np.abs(r.q[:, model.coordinates.index("beta")] - 0.1)) < 1e-10
    with pytest.raises(AnalysisError, match="redundant"):
        simulate(model, 1.0, method="native")


def test_assembly_from_rough_guesses_reports_the_branch(tmp_path):
    """Closed loops start from Newton assembly of the file's guesses; the summary says what moved and where to."""
    model = mechsys.load(SYSTEMS_DIR / "four_bar.yaml", {"theta3": "0.3", "theta4": "1.9"})
    r = simulate(model, 0.1)
    note = [w for w in r.warnings if w.startswith("initial state assembled")]
    assert note and "theta3 = " in note[0] and "(guess 0.3)" in note[0]
    assert np.max(r.residual) <= 1e-10
    quiet = simulate(load_system("four_bar"), 0.1)
    assert not [w for w in quiet.warnings if w.startswith("initial state assembled")]


def test_a_chattering_discontinuous_law_spends_the_step_budget_and_says_why(tmp_path):
    """sign(der(x)) friction sticks at x' = 0, where the ODE has no classical solution: an explicit integrator
    chatters with steps near the rounding limit. The run stops at the budget with the reason (exit 1), instead of
    running for hours."""
    proc = subprocess.run([sys.executable, "-m", "mechsys", "simulate", str(DATA_DIR / "native_functions.yaml"),
                           "--t-end", "3", "--max-steps", "20000"], capture_output=True, text=True, cwd=ROOT,
                          env={**os.environ, "MECHSYS_CACHE": str(tmp_path)})
    assert proc.returncode == 1
    assert "step budget (--max-steps)" in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_an_unwritable_cache_folder_still_runs_native(tmp_path):
    """MECHSYS_CACHE below a plain file cannot be created (even by root): the library is built in a temporary
    folder instead, and the run succeeds."""
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    proc = subprocess.run([sys.executable, "-m", "mechsys", "simulate", str(SYSTEMS_DIR / "double_pendulum.yaml"),
                           "--t-end", "1"], capture_output=True, text=True, cwd=ROOT,
                          env={**os.environ, "MECHSYS_CACHE": str(blocker / "cache")})
    assert proc.returncode == 0, proc.stderr
    assert "native" in proc.stdout


@pytest.mark.parametrize("method", ["native", "DOP853"])
def test_the_output_grid_does_not_set_the_step_of_a_driven_model(method):
    """Issue 13: a prescribed coordinate (a drive row) went through one solve per output interval, so the
    indicator took 2,502 steps over 25 s at --dt 0.01 and 775 at --dt 0.1, on the native loop and on scipy alike.
    Solves now span about 20 steps with dense output in between: the step count no longer follows the outputs,
    the outputs agree, and the drive constraints still hold to round-off."""
    model = mechsys.load(SYSTEMS_DIR / "indicator.yaml", release_prescribed=True)  # drive rows, as `simulate`
    coarse = simulate(model, 25.0, dt=0.1, method=method)
    fine = simulate(model, 25.0, dt=0.01, method=method)
    assert coarse.method == fine.method == method and set(fine.driving) == {"psi", "gamma"}
    assert fine.steps < 1.1 * coarse.steps and fine.steps < len(fine.t) / 3
    common = np.rint(coarse.t / 0.01).astype(int)
    assert np.allclose(fine.t[common], coarse.t)
    assert np.allclose(fine.q[common], coarse.q, rtol=1e-7, atol=1e-7)
    assert max(np.max(coarse.residual), np.max(fine.residual)) <= 1e-10


def test_a_prescribed_coordinate_costs_no_more_steps_than_its_generalized_force():
    """Issue 13's goal: the indicator with its prescribed platform and rotor angles (drive rows) takes at most 1.5x
    the steps of the same equation (7.8) written by hand as one coordinate with a generalized force
    (tests/data/indicator_generalized_force.yaml), and both give the same tilt."""
    driven = simulate(mechsys.load(SYSTEMS_DIR / "indicator.yaml", release_prescribed=True), 25.0, dt=0.01)
    reduced = simulate(mechsys.load(DATA_DIR / "indicator_generalized_force.yaml"), 25.0, dt=0.01)
    assert driven.method == reduced.method == "native"
    assert driven.steps <= 1.5 * reduced.steps, (driven.steps, reduced.steps)
    beta = driven.q[:, driven.coordinates.index("beta")]
    assert np.max(np.abs(beta - reduced.q[:, 0])) <= 1e-6


def test_the_fast_c_printer_computes_what_sympys_printer_computes(tmp_path):
    """numeric/native.py prints internal C directly (30x faster than sympy's printer on the bicycle): random
    expressions of every node it prints itself (sums, products with divisions and rationals, integer and half
    powers, floats, the elementary functions, atan2, abs) and some it hands to sympy (Mod, Piecewise), compiled
    from both printers, give the same numbers; an expression C cannot express is refused by both alike."""
    import sympy as sp

    x, y, z = sp.symbols("x y z", real=True)
    names = {x: "a[0]", y: "a[1]", z: "a[2]"}
    rng = np.random.default_rng(5)
    atoms = [x, y, z, sp.Integer(3), sp.Rational(-2, 7), sp.Float(0.3), sp.Float(-1.25e-3), sp.pi]
    unary = [sp.sin, sp.cos, sp.tan, sp.atan, sp.exp, sp.Abs, sp.tanh, lambda e: sp.sqrt(e ** 2 + 1),
             lambda e: sp.log(e ** 2 + 2), lambda e: sp.asin(sp.tanh(e) / 2)]

    def draw(depth):
        if depth == 0 or rng.random() < 0.2:
            return atoms[rng.integers(len(atoms))]
        kind = rng.integers(8)
        a, b = draw(depth - 1), draw(depth - 1)
        return [a + b, a * b - x, a / (b ** 2 + 1), (a ** 2 + 1) ** sp.Rational(-1, 2) * b,
                a ** int(rng.integers(2, 7)),
                unary[rng.integers(len(unary))](a) + b, sp.atan2(a, b ** 2 + 1) * y,
                sp.Mod(a, 3) + sp.Piecewise((a, b > 0), (-b, True))][kind]

    exprs = [draw(4) for _ in range(60)]
    sources = {}
    for fast in (True, False):
        printer = native._c_printer(names, fast)
        body = "\n".join(f"    out[{i}] = {printer.doprint(e)};" for i, e in enumerate(exprs))
        head = "#include <math.h>\n#include <stdbool.h>\nvoid f(const double *a, double *out) {"
        sources[fast] = f"{head}\n{body}\n}}\n"
    assert sources[True] != sources[False]
    values = {}
    for fast, source in sources.items():
        lib = tmp_path / f"f{int(fast)}.so"
        native.build(source, lib, "-O0")
        program = native.Program(lib, {"f": len(exprs)}, 3)
        values[fast] = np.array([program("f", rng2) for rng2 in np.random.default_rng(9).uniform(-2, 2, (25, 3))])
    both = np.isfinite(values[False])
    assert np.array_equal(both, np.isfinite(values[True]))
    assert np.allclose(values[True][both], values[False][both], rtol=1e-12, atol=1e-12)
    unknown = sp.Function("g")(x) + x  # no C form: both printers refuse it alike
    for fast in (True, False):
        with pytest.raises(Exception, match="Unsupported"):
            native._c_printer(names, fast).doprint(unknown)


def test_c_source_reuses_the_python_codes_cse(monkeypatch):
    """A first `simulate` prints the staged equations and the constraint rows as Python and as C: one CSE each
    (lambdify.shared_cse), not one per language. The C source from the memo equals the one computed afresh."""
    from mechsys.numeric import lambdify

    model = mechsys.load(SYSTEMS_DIR / "rolling_disk.yaml")
    monkeypatch.setattr(lambdify, "_RECENT", lambdify.OrderedDict())
    calls = []
    real = lambdify.cse
    monkeypatch.setattr(lambdify, "cse", lambda exprs, **kw: calls.append(len(exprs)) or real(exprs, **kw))
    first = native.model_source(model)
    assert len(calls) == 3  # the staged pieces, A, b
    args = (model.t, model.q, model.u, model.parameter_symbols)
    for matrix in (model.constraint_jacobian, model.constraint_rhs):
        lambdify.matrix_source(matrix, *args)
    assert len(calls) == 3  # the Python code of A and b took the C code's CSE
    monkeypatch.setattr(lambdify, "_RECENT", lambdify.OrderedDict())
    assert native.model_source(model) == first and len(calls) == 6


@pytest.mark.parametrize("name", ["double_pendulum", "four_bar", "rolling_disk", "bicycle"])
def test_the_units_compiled_at_once_build_the_library_of_the_one_unit(name, tmp_path, monkeypatch):
    """model_sources splits the integrator's C into the staged equations, the constraint rows and the template,
    compiled at once (one process each) and linked: the library computes what the one-unit build computes, bit for
    bit, and exports only the integrator's entry points (the shared functions are hidden: two models' libraries in
    one process cannot mix). On one core the units go to one process."""
    import ctypes

    from mechsys.numeric import parallel

    model = mechsys.load(SYSTEMS_DIR / f"{name}.yaml")
    units = native.model_sources(model)
    assert len(units) == 3 and "\n".join(native.model_sources(model, split=False)) == native.model_source(model)
    started = []
    real = native.subprocess.Popen
    monkeypatch.setattr(native.subprocess, "Popen", lambda cmd, **kw: started.append(cmd) or real(cmd, **kw))
    libraries = {}
    for how, cores in (("one unit", 2), ("split", 2), ("split, one core", 1)):
        monkeypatch.setattr(parallel, "cores", lambda: cores)
        started.clear()
        path = tmp_path / f"{how}.so"
        native.build(native.model_source(model) if how == "one unit" else units, path)
        assert len(started) == {"one unit": 1, "split": 4, "split, one core": 1}[how]  # 3 compilers + the linker
        libraries[how] = native.NativeIntegrator(path)
    assert not hasattr(ctypes.CDLL(str(tmp_path / "split.so")), "pieces")
    assert not hasattr(ctypes.CDLL(str(tmp_path / "split.so")), "constraint_rows")
    p = parameter_values(model)
    rng = np.random.default_rng(2)
    n = len(model.q)
    for _ in range(5):
        y = rng.uniform(-1, 1, 2 * n)
        one = libraries["one unit"].accelerations(0.0, y, p)
        assert all(np.array_equal(one, lib.accelerations(0.0, y, p), equal_nan=True) for lib in libraries.values())


def test_a_unit_that_does_not_compile_fails_the_build_and_leaves_no_files(tmp_path):
    folder = tmp_path / "build"
    folder.mkdir()
    with pytest.raises(AnalysisError, match="compiling the native integrator failed"):
        native.build(["int f(void) { return 1; }\n", "int g(void) { return x; }\n"], folder / "lib.so")
    assert not list(folder.iterdir())


def test_a_cancelled_build_stops_the_compilers_processes_and_leaves_no_temporary_files(tmp_path, monkeypatch):
    """cancel() stops the C compiler while it compiles: its own processes (cc1, as) too, and the temporary files
    they write (cc*.s, formerly in the system's temporary folder, left there by each suite run) go with the build."""
    system_tmp = tmp_path / "system-tmp"
    system_tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(system_tmp))
    lines = "\n".join(f"  s += sin(a[{k % 7}] * {k + 1}.0) * cos(s + {k}.5);" for k in range(20_000))
    source = f"#include <math.h>\ndouble f(const double *a) {{\n  double s = 0.0;\n{lines}\n  return s;\n}}\n"
    folder = tmp_path / "build"
    folder.mkdir()
    pending = native.PendingBuild(source, folder / "lib.so", "-O2")
    deadline = time.monotonic() + 30.0
    while not list(Path(pending._tmp.name).glob("cc*")) and not list(system_tmp.glob("cc*")):
        assert time.monotonic() < deadline, "the compiler wrote no temporary file"
        time.sleep(0.01)
    group = pending._procs[0].pid
    pending.cancel()
    time.sleep(0.2)
    assert not list(system_tmp.iterdir()) and not list(folder.iterdir())
    alive = [p for p in Path("/proc").glob("[0-9]*") if _in_group(p, group)]
    assert not alive


def _in_group(proc: Path, group: int) -> bool:
    """Whether the process /proc/<pid> lives (not a zombie) in the process group ``group``."""
    try:
        fields = (proc / "stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return False
    return fields[0] != "Z" and int(fields[2]) == group


def _program_sources(path, monkeypatch, tmp_path) -> tuple[str, dict[str, int], int]:
    """The C program of a model's constrained steady-motion pieces (what load_program builds, from the cache entry
    ConstrainedPieces stores), its functions and its argument count."""
    from mechsys.analysis.equilibrium.nonholonomic import ConstrainedPieces
    from mechsys.numeric import cache

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    model = mechsys.load(path)
    pieces = ConstrainedPieces(model, "kane")
    source = cache.load(cache.model_key(model, "constrained-pieces-kane"))["c"]
    return source, {"mechsys_values": pieces.size, "mechsys_full": pieces._full_size}, pieces.n_args


@pytest.mark.skipif(native.shutil.which("tcc") is None, reason="the Tiny C Compiler is not installed (make install)")
@pytest.mark.parametrize("path", [SYSTEMS_DIR / "bicycle.yaml", SYSTEMS_DIR / "rolling_disk.yaml",
                                  DATA_DIR / "chaplygin_sleigh.yaml", DATA_DIR / "andrews_squeezer.yaml"],
                         ids=lambda p: p.stem)
def test_the_quick_compiler_builds_programs_that_compute_what_gccs_compute(path, tmp_path, monkeypatch):
    """tcc (quick_compiler) and the C compiler at -O0 build the same steady-motion program: the same numbers, bit
    for bit, at random arguments (unoptimised code does each operation in the source's order)."""
    source, functions, n_args = _program_sources(path, monkeypatch, tmp_path)
    programs = []
    for cc in (native.shutil.which("tcc"), native.compiler()):
        built = tmp_path / f"{Path(cc).name}.so"
        native.build(source, built, "-O0", cc)
        programs.append(native.Program(built, functions, n_args))
    rng = np.random.default_rng(4)
    for _ in range(50):
        a = rng.uniform(-2.0, 2.0, n_args)
        for name in functions:
            x, y = (program(name, a) for program in programs)
            assert np.array_equal(x.view(np.int64), y.view(np.int64))


def test_programs_are_built_by_the_quick_compiler_else_by_the_c_compiler(tmp_path, monkeypatch):
    """load_program builds with quick_compiler() (tcc when there is one), keys the library by that compiler, and
    when it fails builds with compiler() instead; MECHSYS_QUICK_CC=off takes compiler()."""
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    source = "#include <math.h>\nvoid f(const double *a, double *out) { out[0] = a[0] * a[1] + sin(a[0]); }\n"
    monkeypatch.setenv("MECHSYS_QUICK_CC", "off")
    assert native.quick_compiler() == native.compiler()
    failing = tmp_path / "failing-cc"
    failing.write_text("#!/bin/sh\nexit 1\n")
    failing.chmod(0o755)
    monkeypatch.setenv("MECHSYS_QUICK_CC", str(failing))
    assert native.quick_compiler() == str(failing)
    started = []
    real = native.subprocess.Popen
    monkeypatch.setattr(native.subprocess, "Popen", lambda cmd, **kw: started.append(cmd[0]) or real(cmd, **kw))
    program = native.load_program("quick-test", source, {"f": 1}, 2)
    assert started == [str(failing), native.compiler()]
    assert program("f", np.array([0.5, 3.0]))[0] == 0.5 * 3.0 + np.sin(0.5)
    libraries = sorted(p.name for p in (tmp_path / "cache").glob("*.so"))
    assert len(libraries) == 1 and "-failing-cc-" in libraries[0]
    monkeypatch.setenv("MECHSYS_QUICK_CC", "off")
    started.clear()
    native.load_program("quick-test", source, {"f": 1}, 2)  # another compiler: another library
    assert started == [native.compiler()] and len(list((tmp_path / "cache").glob("*.so"))) == 2
    started.clear()
    native.load_program("quick-test", source, {"f": 1}, 2)
    assert started == []  # from the cache


def test_outputs_that_are_numbers_are_filled_in_not_stored_one_by_one(tmp_path):
    """pieces_source writes the outputs that are numbers by one memset (zeros) and a loop over a table (the
    others), before the other outputs' stores and after every shared subexpression (gcc -O2 spent 8.3 of 8.3 s on
    the 40-link chain's 8,520 number stores); every output gets its value, numbers and expressions alike."""
    import ctypes
    import math

    import sympy as sp

    t, q0, u0, p0 = sp.symbols("t q0 u0 p0")
    block = [sp.Integer(0), sp.Integer(1), sp.Integer(-1), u0 * q0, sp.Integer(0), sp.Float(2.5),
             sp.Rational(1, 2), sp.sin(q0) + p0, sp.Integer(0), sp.sin(q0) * u0]
    source = native.pieces_source([block, [sp.Integer(0), q0 + u0]], t, [q0], [u0], [p0], name="f", linkage="void")
    body = source[source.index("void f("):]
    assert body.count("out[") == 6 and "memset(out, 0, 12 * sizeof(double));" in body
    assert body.index("memset") > body.rindex("const double") and body.index("memset") < body.index("out[3] =")
    path = tmp_path / "f.so"
    native.build("#include <math.h>\n#include <string.h>\n" + source, path, "-O2")
    f = ctypes.CDLL(str(path)).f
    f.argtypes = [ctypes.c_double] + [ctypes.c_void_p] * 4
    q, u, p = np.array([0.3]), np.array([-1.7]), np.array([2.0])
    out = np.full(12, np.nan)
    f(0.0, q.ctypes.data, u.ctypes.data, p.ctypes.data, out.ctypes.data)
    x, v, c = 0.3, -1.7, 2.0
    expected = [0.0, 1.0, -1.0, v * x, 0.0, 2.5, 0.5, math.sin(x) + c, 0.0, math.sin(x) * v, 0.0, x + v]
    assert out.tolist() == expected


def test_a_run_that_fails_before_integrating_leaves_no_build(monkeypatch, tmp_path):
    """simulate starts the native build before it assembles the start; a start it refuses (a closed loop that
    cannot be assembled) stops the build and removes its files instead of leaving them to the process's exit."""
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    native._abandon()
    from mechsys.errors import AnalysisError

    broken = mechsys.load(SYSTEMS_DIR / "four_bar.yaml", {"l1": 5.0, "theta2": 0.1, "theta3": 0.1, "theta4": 0.1})
    with pytest.raises(AnalysisError):  # a ground link of 5 m: the loop cannot close
        simulate(broken, 0.1)
    assert not native._UNFINISHED and not hasattr(broken, "_native_pending")
