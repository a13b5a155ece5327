"""`mechsys codegen --target fmu` (issue 15): the FMI 2.0 Model Exchange FMU, checked with FMPy against mechsys.

FMPy validates the modelDescription.xml; the FMU is then run by FMPy: through its own `simulate_fmu` (CVode) and
through its low-level API, stepped by scipy's DOP853 at rtol 1e-12 calling fmi2GetDerivatives (and, for closed
loops, fmi2CompletedIntegratorStep and the event iteration that projects onto the constraints). The reference is
`mechsys simulate`'s Python API (DOP853, rtol 1e-12) with the same `--set` values. Skipped without FMPy or gcc.

FMPy's `simulate_fmu(logger=...)` keeps the custom logger in a process-wide proxy that outlives the call (a later
FMU then calls a freed function): these tests capture FMU messages through their own callbacks instead."""
from __future__ import annotations

import ctypes
import shutil
import subprocess
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from test_cli_hardening import invoke, one_line  # the command-line helpers: exit code, one stderr line

import mechsys
from mechsys.analysis.motion.simulate import simulate
from mechsys.codegen import fmu as fmu_module
from mechsys.codegen.fmu import write_fmu
from mechsys.errors import InputError

try:
    import fmpy
    from fmpy import extract, read_model_description, simulate_fmu
    from fmpy.fmi2 import (FMU2Model, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                           fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
    from fmpy.validation import validate_fmu
except ImportError:  # the tests that run an FMU are skipped
    fmpy = None

ROOT = Path(__file__).resolve().parents[1]
SYSTEMS = ROOT / "systems"
GCC = shutil.which("gcc")
needs_gcc = pytest.mark.skipif(GCC is None, reason="gcc is not installed")
needs_fmpy = pytest.mark.skipif(fmpy is None, reason="FMPy is not installed (pip install 'mechsys[fmu]')")
TIMES = np.linspace(0.0, 2.0, 9)  # the comparison times [s]
MATCH = 1e-8  # the FMU against mechsys simulate, both at rtol 1e-12


# ----------------------------------------------------------------------------------------- helpers
def build(name: str, folder: Path, sets: dict | None = None) -> Path:
    path = folder / f"{name}.fmu"
    write_fmu(mechsys.load(SYSTEMS / f"{name}.yaml", overrides=sets), path)
    return path


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    """The FMUs of the double pendulum, the centrifuge (a calculated parameter) and the slider-crank (a closed
    loop: calculated and approximate start values, projection), built once for the module."""
    if GCC is None or fmpy is None:
        pytest.skip("needs gcc and FMPy")
    folder = tmp_path_factory.mktemp("fmu")
    return {name: build(name, folder) for name in ("double_pendulum", "centrifuge", "slider_crank")}


def reference(name: str, sets: dict | None = None, times: np.ndarray = TIMES) -> np.ndarray:
    """x = [q, u] of `mechsys simulate` at ``times`` (DOP853, rtol 1e-12), with ``sets`` as --set values."""
    model = mechsys.load(SYSTEMS / f"{name}.yaml", overrides=sets)
    result = simulate(model, float(times[-1]), dt=float(times[1] - times[0]), method="DOP853", rtol=1e-12,
                      atol=1e-14)
    assert np.allclose(result.t, times)
    return np.hstack([result.q, result.u])


def _pointer(array: np.ndarray):
    return array.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


class Stepper:
    """An FMU instance run through FMPy's low-level API: start values, initialization, then scipy's DOP853
    calling fmi2GetDerivatives; after each output interval fmi2CompletedIntegratorStep and, if the FMU asks
    for it, the event iteration (where a closed loop is projected back onto its constraints)."""

    def __init__(self, path: Path, start: dict | None = None) -> None:
        self.messages: list[tuple[int, str]] = []
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.nx = len(self.md.derivatives)
        self.events = 0
        # extracted beside the FMU, in pytest's temporary folders (fmpy's own temporary folder was never removed)
        unzipped = extract(str(path), unzipdir=tempfile.mkdtemp(prefix="unzipped-", dir=path.parent))
        self.fmu = FMU2Model(guid=self.md.guid, unzipDirectory=unzipped,
                             modelIdentifier=self.md.modelExchange.modelIdentifier, instanceName="test")
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
        self.fmu.setupExperiment(startTime=0.0)
        for name, value in (start or {}).items():
            self.fmu.setReal([self.vr[name]], [value])
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.event_iteration()
        self.fmu.enterContinuousTimeMode()

    def _log(self, env, instance, status, category, message) -> None:
        self.messages.append((status, message.decode()))

    def event_iteration(self) -> bool:
        changed_any, more = False, True
        while more:
            more, _stop, _nominals, changed, _defined, _time = self.fmu.newDiscreteStates()
            changed_any |= changed
        return changed_any

    def state(self) -> np.ndarray:
        x = np.zeros(self.nx)
        self.fmu.getContinuousStates(_pointer(x), self.nx)
        return x

    def put(self, t: float, x: np.ndarray) -> None:
        x = np.ascontiguousarray(x, dtype=float)
        self.fmu.setTime(t)
        self.fmu.setContinuousStates(_pointer(x), self.nx)

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        self.put(t, x)
        dx = np.zeros(self.nx)
        self.fmu.getDerivatives(_pointer(dx), self.nx)
        return dx

    def get(self, *names: str) -> list[float]:
        return self.fmu.getReal([self.vr[n] for n in names])

    def run(self, times: np.ndarray, rtol: float = 1e-12, atol: float = 1e-14, record: tuple[str, ...] = ()
            ) -> np.ndarray:
        """The states at ``times`` (and the variables ``record`` at each in ``self.recorded``)."""
        from scipy.integrate import solve_ivp

        rows = [self.state()]
        self.recorded = [self.get(*record)] if record else []
        for a, b in zip(times[:-1], times[1:]):
            sol = solve_ivp(self.rhs, (a, b), rows[-1], method="DOP853", rtol=rtol, atol=atol)
            assert sol.success, sol.message
            self.put(float(b), sol.y[:, -1])
            enter, _terminate = self.fmu.completedIntegratorStep()
            if enter:
                self.events += 1
                self.fmu.enterEventMode()
                assert self.event_iteration()
                self.fmu.enterContinuousTimeMode()
            rows.append(self.state())
            if record:
                self.recorded.append(self.get(*record))
        return np.array(rows)


# ----------------------------------------------------------------------------------------- the FMU file
@needs_fmpy
@needs_gcc
@pytest.mark.parametrize("name", ["double_pendulum", "centrifuge", "slider_crank"])
def test_fmpy_validates_the_fmu(fmus, name):
    assert validate_fmu(str(fmus[name])) == []


@needs_fmpy
@needs_gcc
def test_the_archive_holds_the_description_the_sources_and_the_binary(fmus):
    with zipfile.ZipFile(fmus["double_pendulum"]) as zf:
        names = set(zf.namelist())
    assert {"modelDescription.xml", "binaries/linux64/double_pendulum.so", "sources/double_pendulum.c",
            "sources/double_pendulum.h", "sources/fmu_model.h", "sources/fmu_wrapper.c", "sources/fmi2Functions.h",
            "sources/fmi2FunctionTypes.h", "sources/fmi2TypesPlatform.h",
            "documentation/licenses/fmi2-headers.txt"} <= names
    md = read_model_description(str(fmus["double_pendulum"]))
    assert md.fmiVersion == "2.0" and md.modelExchange.modelIdentifier == "double_pendulum"
    assert md.coSimulation is None and md.numberOfEventIndicators == 0
    variables = {v.name: v for v in md.modelVariables}
    assert [v.name for v in md.modelVariables] == [
        "m1", "m2", "l1", "l2", "g", "theta1", "theta2", "der_theta1", "der_theta2", "der(theta1)", "der(theta2)",
        "der(der_theta1)", "der(der_theta2)", "kinetic_energy", "potential_energy", "total_energy"]
    assert [v.valueReference for v in md.modelVariables] == list(range(16))
    m1 = variables["m1"]
    assert (m1.causality, m1.variability, m1.initial, m1.start, m1.unit) == ("parameter", "tunable", "exact", "1.0",
                                                                             "kg")
    assert [(d.variable.name, d.variable.derivative.name) for d in md.derivatives] == [
        ("der(theta1)", "theta1"), ("der(theta2)", "theta2"), ("der(der_theta1)", "der_theta1"),
        ("der(der_theta2)", "der_theta2")]
    assert (variables["theta1"].initial, variables["theta1"].start) == ("exact", "0.5")
    assert [o.variable.name for o in md.outputs] == ["kinetic_energy", "potential_energy", "total_energy"]
    assert not md.modelExchange.needsCompletedIntegratorStep  # no constraints to project onto


@needs_fmpy
@needs_gcc
def test_calculated_parameters_and_start_values_follow_the_file(fmus):
    cf = {v.name: v for v in read_model_description(str(fmus["centrifuge"])).modelVariables}
    assert (cf["dM"].causality, cf["dM"].initial, cf["dM"].start) == ("calculatedParameter", "calculated", None)
    assert cf["Mo"].causality == "parameter"
    md = read_model_description(str(fmus["slider_crank"]))
    sc = {v.name: v for v in md.modelVariables}
    assert (sc["theta2"].initial, float(sc["theta2"].start)) == ("approx", pytest.approx(np.pi / 4, abs=1e-15))
    assert sc["theta3"].initial == sc["x4"].initial == "calculated"  # expressions of l2O and l3A in the file
    assert sc["constraint_residual"].causality == "output"
    assert md.modelExchange.needsCompletedIntegratorStep  # the projection at step events


@needs_gcc
@pytest.mark.parametrize("name", ["double_pendulum", "slider_crank"])
def test_the_sources_compile_cleanly_with_strict_warnings(fmus, name, tmp_path):
    with zipfile.ZipFile(fmus[name]) as zf:
        zf.extractall(tmp_path)
    sources = tmp_path / "sources"
    proc = subprocess.run([GCC, "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-Wshadow", "-fPIC",
                           "-shared", "-o", str(tmp_path / "strict.so"), "fmu_wrapper.c", f"{name}.c", "-lm"],
                          cwd=sources, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    exported = subprocess.run(["nm", "-D", "--defined-only", str(tmp_path / "binaries" / "linux64" / f"{name}.so")],
                              capture_output=True, text=True).stdout if shutil.which("nm") else ""
    symbols = {line.split()[-1] for line in exported.splitlines()}
    if symbols:  # the model's own functions stay hidden: only the FMI functions are exported
        assert "fmi2GetDerivatives" in symbols and "fmi2NewDiscreteStates" in symbols
        assert not [s for s in symbols if s.startswith(name)]


# ----------------------------------------------------------------------------------------- the motion
@needs_fmpy
@needs_gcc
@pytest.mark.parametrize("name, sets, mechsys_sets", [
    ("double_pendulum", {}, {}),
    ("double_pendulum", {"m2": 1.0, "l1": 0.7, "theta2": 0.1, "der_theta1": 0.4},
     {"m2": 1.0, "l1": 0.7, "theta2": 0.1, "der(theta1)": 0.4}),
    ("centrifuge", {}, {}),
    ("centrifuge", {"Mo": 60.0}, {"Mo": 60.0}),  # dM = Mo/7 follows, as with --set Mo=60
])
def test_the_fmu_stepped_by_dop853_matches_mechsys_simulate(fmus, name, sets, mechsys_sets):
    stepper = Stepper(fmus[name], sets)
    got = stepper.run(TIMES)
    want = reference(name, mechsys_sets or None)
    assert np.max(np.abs(got - want)) < MATCH
    if sets:  # the start values changed the motion, so the match above is not the default motion's
        assert np.max(np.abs(want - reference(name))) > 1e-3
    if name == "centrifuge":
        assert stepper.get("dM")[0] == pytest.approx(sets.get("Mo", 50.0) / 7, rel=1e-15)
    T, V, E = stepper.get("kinetic_energy", "potential_energy", "total_energy")
    assert E == pytest.approx(T + V, rel=1e-15)


@needs_fmpy
@needs_gcc
def test_the_files_outputs_are_outputs_of_the_fmu(tmp_path):
    """`outputs:` with a vector (three columns), an acceleration, a generalized momentum and a name the code
    reserves (x becomes x_), against mechsys's own output columns along its simulation."""
    from mechsys.numeric.parameters import parameter_values
    from mechsys.analysis.motion.outputs import output_columns

    path = tmp_path / "pendulum_outputs.yaml"
    path.write_text(PENDULUM.read_text(encoding="utf-8").split("\nexpect:")[0] + "\noutputs:\n"
                    "  elbow: position(rod2)\n  alpha1: der(der(theta1))\n  p1: momentum_of(theta1)\n"
                    "  x: t*der(theta2)\n", encoding="utf-8")
    model = mechsys.load(path)
    write_fmu(model, tmp_path / "outputs.fmu")
    names = ["elbow_x", "elbow_y", "elbow_z", "alpha1", "p1", "x_"]
    md = read_model_description(str(tmp_path / "outputs.fmu"))
    assert [o.variable.name for o in md.outputs] == ["kinetic_energy", "potential_energy", "total_energy", *names]
    stepper = Stepper(tmp_path / "outputs.fmu")
    stepper.run(TIMES, record=tuple(names))
    run = simulate(model, float(TIMES[-1]), dt=float(TIMES[1] - TIMES[0]), method="DOP853", rtol=1e-12, atol=1e-14)
    columns = output_columns(model, run, parameter_values(model))
    want = np.column_stack([columns[c] for c in ("elbow.x", "elbow.y", "elbow.z", "alpha1", "p1", "x")])
    assert np.max(np.abs(np.array(stepper.recorded) - want)) < MATCH
    assert np.ptp(want[:, 3]) > 1.0  # the acceleration varies: the match is not of constants


def test_an_output_of_constraint_forces_is_refused_by_name(tmp_path):
    """reaction() in `outputs:` failed deep in the code generator ('fmu depends on _reaction_0, ... which is not an
    argument', exit 1); it is an input error at the output's line."""
    path = tmp_path / "pendulum_reaction.yaml"
    text = PENDULUM.read_text(encoding="utf-8").split("\nexpect:")[0]
    path.write_text(text + "\noutputs:\n  elbow: position(rod2)\n  pin: reaction(rod1)\n", encoding="utf-8")
    line = one_line(invoke("codegen", str(path), "-t", "fmu", "-o", str(tmp_path / "r.fmu")))
    assert line.startswith(f"{path}:") and "outputs.pin: pin use reaction()" in line
    assert not (tmp_path / "r.fmu").exists()


@needs_fmpy
@needs_gcc
@pytest.mark.slow
def test_names_of_the_fmi_headers_and_the_wrapper_do_not_break_the_fmu(tmp_path):
    """test_codegen's hostile model (keywords, the generated code's own names) with parameters named after the
    FMI headers' macros and types and the wrapper's identifiers, all in a mass: set through FMPy by their code
    names (lambda is lambda_), they move the motion as --set does."""
    from test_codegen import hostile_model

    extra = ["fmi2True", "fmi2OK", "fmi2Component", "MSFMU_NPAR", "MSFMU_NSTATE", "msfmu_log",
             "msfmu_accelerations", "offsetof", "size_t", "time", "status"]
    text = hostile_model().replace("parameters:\n", "parameters:\n" + "".join(
        f"  {name}: 0.0{k + 1}\n" for k, name in enumerate(extra)), 1)
    text = text.replace("mass: ", f"mass: {' + '.join(extra)} + ", 1)
    path = tmp_path / "hostile.yaml"
    path.write_text(text, encoding="utf-8")
    write_fmu(mechsys.load(path), tmp_path / "hostile.fmu")
    assert validate_fmu(str(tmp_path / "hostile.fmu")) == []
    times = np.linspace(0.0, 1.0, 5)
    got = Stepper(tmp_path / "hostile.fmu", {"fmi2True": 0.5, "lambda_": 0.3}).run(times)
    model = mechsys.load(path, overrides={"fmi2True": 0.5, "lambda": 0.3})
    run = simulate(model, 1.0, dt=0.25, method="DOP853", rtol=1e-12, atol=1e-14)
    assert np.max(np.abs(got - np.hstack([run.q, run.u]))) < MATCH
    default = simulate(mechsys.load(path), 1.0, dt=0.25, method="DOP853", rtol=1e-12, atol=1e-14)
    assert np.max(np.abs(run.q - default.q)) > 1e-4


@needs_fmpy
@needs_gcc
def test_fmpy_simulate_fmu_with_cvode_matches_mechsys_simulate(fmus):
    result = simulate_fmu(str(fmus["double_pendulum"]), stop_time=float(TIMES[-1]), relative_tolerance=1e-12,
                          output_interval=float(TIMES[1] - TIMES[0]), start_values={"m2": 1.0},
                          output=["theta1", "theta2", "der_theta1", "der_theta2", "total_energy"])
    got = np.array([[np.interp(t, result["time"], result[n]) for n in ("theta1", "theta2", "der_theta1",
                                                                         "der_theta2")] for t in TIMES])
    assert np.max(np.abs(got - reference("double_pendulum", {"m2": 1.0}))) < MATCH
    assert np.ptp(result["total_energy"]) < 1e-9  # conservative


@needs_fmpy
@needs_gcc
@pytest.mark.parametrize("sets", [{}, {"M2": 3.0, "l2O": 0.12}, {"theta2": 1.0}])
def test_the_closed_loop_matches_mechsys_simulate(fmus, sets):
    """The slider-crank: l2O changes theta3 and x4 through the file's expressions (calculated start values); a
    theta2 start off the file's branch is assembled onto the loop by the same Newton projection as mechsys."""
    stepper = Stepper(fmus["slider_crank"], sets)
    got = stepper.run(TIMES)
    want = reference("slider_crank", sets or None)
    assert np.max(np.abs(got - want)) < MATCH
    assert stepper.get("constraint_residual")[0] < 1e-10
    if "theta2" in sets:  # the crank angle set is held; the others assembled, with a warning naming what moved
        assert abs(got[0, 0] - 1.0) < 1e-12
        assert any(status == 1 and "assembled onto the constraints: theta3" in text
                   for status, text in stepper.messages)


@needs_fmpy
@needs_gcc
@pytest.mark.parametrize("start", [{"th1": 0.6}, {"b": 0.36}, {"th1": 0.6, "der_th1": 3.0}, {"th1": -1.8},
                                   {"th1": -1.5}, {"th3": 2.2}])
def test_a_start_set_on_a_loop_whose_file_guesses_starts_where_mechsys_simulate_starts(tmp_path, start):
    """A four-bar whose file guesses the coupler and rocker angles (off the loop, as users write them). The FMU
    assembled a changed start from its defaults, already assembled at export, and `mechsys simulate --set` from
    the file's values: a crank set to 0.6 started at 0.476 in the FMU and at 0.396 in mechsys (helper audit), both
    moved off the value set. Both now start from the file's values with those set, and hold the values set where
    the others close the loop: th1 = 0.6 exactly, the loop closed, the same motion to 1e-8."""
    path = ROOT / "tests" / "data" / "beyond" / "rough_four_bar.yaml"
    fmu = tmp_path / "rough.fmu"
    write_fmu(mechsys.load(path), fmu)
    stepper = Stepper(fmu, start)
    got = stepper.run(TIMES)
    sets = {("der(th1)" if k == "der_th1" else k): v for k, v in start.items()}
    result = simulate(mechsys.load(path, overrides=sets), float(TIMES[-1]), dt=float(TIMES[1] - TIMES[0]),
                      method="DOP853", rtol=1e-12, atol=1e-14)
    assert np.max(np.abs(got - np.hstack([result.q, result.u]))) < MATCH
    for k, name in enumerate(("th1", "th2", "th3")):
        if name in start:
            assert got[0, k] == start[name] and result.q[0, k] == start[name]
    if "der_th1" in start:
        assert abs(got[0, 3] - 3.0) < 1e-12
    a, b, c, d = 0.1, start.get("b", 0.35), 0.25, 0.3  # the loop: crank tip + coupler = rocker pivot + rocker tip
    th1, th2, th3 = got[0, :3]
    gap = (a * np.cos(th1) + b * np.cos(th1 + th2) - d - c * np.cos(th3),
           a * np.sin(th1) + b * np.sin(th1 + th2) - c * np.sin(th3))
    assert max(map(abs, gap)) < 1e-12


@needs_fmpy
@needs_gcc
def test_the_closed_loop_drifts_and_is_projected_back_at_step_events(fmus):
    stepper = Stepper(fmus["slider_crank"])
    got = stepper.run(np.linspace(0.0, 1.0, 21), rtol=1e-7, atol=1e-9)  # loose: the residual grows past 1e-12
    assert stepper.events > 5
    assert stepper.get("constraint_residual")[0] < 1e-13  # right after a projection
    assert np.max(np.abs(got - reference("slider_crank", times=np.linspace(0.0, 1.0, 21)))) < 1e-4


@needs_fmpy
@needs_gcc
def test_fmpy_simulate_fmu_runs_the_closed_loop_with_its_step_events(fmus):
    times = np.linspace(0.0, 1.0, 101)
    result = simulate_fmu(str(fmus["slider_crank"]), stop_time=1.0, relative_tolerance=1e-12,
                          output_interval=0.01, output=["theta2", "theta3", "x4"])
    got = np.array([[np.interp(t, result["time"], result[n]) for n in ("theta2", "theta3", "x4")] for t in times])
    assert np.max(np.abs(got - reference("slider_crank", times=times)[:, :3])) < MATCH


@needs_fmpy
@needs_gcc
def test_the_fmu_reports_errors_instead_of_wrong_numbers(fmus):
    with pytest.raises(Exception, match="fmi2SetReal failed"):  # dM is computed from Mo
        Stepper(fmus["centrifuge"], {"dM": 7.0})
    with pytest.raises(Exception, match="fmi2SetReal failed"):  # theta3's start is computed from l2O and l3A
        Stepper(fmus["slider_crank"], {"theta3": 0.1})
    with pytest.raises(Exception, match="fmi2ExitInitializationMode failed"):  # M = 0: no accelerations
        Stepper(fmus["double_pendulum"], {"m1": 0.0, "m2": 0.0})
    with pytest.raises(Exception, match="fmi2ExitInitializationMode failed"):  # theta3 = -asin(1.41): not real
        Stepper(fmus["slider_crank"], {"l2O": 0.5})


# ----------------------------------------------------------------------------------------- the command line
PENDULUM = SYSTEMS / "double_pendulum.yaml"


@needs_gcc
def test_cli_writes_the_fmu_atomically(tmp_path):
    out = tmp_path / "model.fmu"
    out.write_bytes(b"old")
    result = invoke("codegen", PENDULUM, "--target", "fmu", "-o", out, "--set", "m1=2")
    assert result.exit_code == 0, result.stderr
    assert result.stdout == (f"wrote {out}: FMI 2.0 Model Exchange FMU double_pendulum (linux64), 4 states, "
                             "5 parameters, 3 outputs\n")
    with zipfile.ZipFile(out) as zf:
        assert '<ScalarVariable name="m1" valueReference="0" description="rod 1 mass" causality="parameter" ' \
               'variability="tunable" initial="exact">\n      <Real unit="kg" start="2.0" />' in \
               zf.read("modelDescription.xml").decode()
    assert [p.name for p in tmp_path.iterdir()] == ["model.fmu"]  # no temporary file left


@needs_gcc
def test_a_failed_build_leaves_the_previous_fmu(tmp_path, monkeypatch):
    out = tmp_path / "model.fmu"
    out.write_bytes(b"old")
    monkeypatch.setattr(fmu_module, "CFLAGS", ("-fno-such-option",))
    assert "gcc could not build the FMU's binary" in one_line(invoke("codegen", PENDULUM, "-t", "fmu", "-o", out), 1)
    assert out.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == ["model.fmu"]


@pytest.mark.parametrize("output, message", [
    ("model.zip", "an FMU file name ends in .fmu"),
    ("missing/model.fmu", "does not exist"),
])
def test_cli_refuses_a_bad_output_before_any_work(output, message, tmp_path):
    assert message in one_line(invoke("codegen", PENDULUM, "-t", "fmu", "-o", tmp_path / output))
    assert not (tmp_path / output).exists()


def test_cli_without_gcc_is_one_line_exit_2(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))  # no gcc on it
    line = one_line(invoke("codegen", PENDULUM, "-t", "fmu", "-o", tmp_path / "model.fmu"))
    assert line == ("mechsys: gcc was not found on PATH: the FMU's binary is compiled with the system C compiler "
                    "gcc; install it (Debian/Ubuntu: apt install gcc), or use --target c for the sources alone")


@needs_gcc  # gcc is checked first
def test_contacts_are_refused_with_one_line(tmp_path):
    line = one_line(invoke("codegen", SYSTEMS / "bouncing_ball.yaml", "-t", "fmu", "-o", tmp_path / "ball.fmu"))
    assert line.startswith("mechsys: contacts (floor) cannot be exported to an FMU: impacts are velocity jumps")
    assert not (tmp_path / "ball.fmu").exists()


def pendulum_with_event(tmp_path: Path, action: str) -> Path:
    text = PENDULUM.read_text(encoding="utf-8").split("\nexpect:")[0]
    path = tmp_path / f"{action}.yaml"
    path.write_text(text + f"\nevents:\n  - {{name: upright, expression: theta1, action: {action}}}\n",
                    encoding="utf-8")
    return path


@needs_gcc  # gcc is checked first
def test_stopping_events_are_refused_and_recorded_ones_warned(tmp_path):
    line = one_line(invoke("codegen", pendulum_with_event(tmp_path, "stop"), "-t", "fmu", "-o", tmp_path / "s.fmu"))
    assert "events that stop the simulation (upright) cannot be exported to an FMU" in line
    with pytest.raises(InputError, match="events that stop"):
        fmu_module.check_exportable(mechsys.load(pendulum_with_event(tmp_path, "stop")))
    assert fmu_module.check_exportable(mechsys.load(pendulum_with_event(tmp_path, "record"))) == [
        "events (upright) are not exported: the FMU has no event indicators (the events only record crossings; "
        "the motion is the same)"]


@needs_gcc
def test_recorded_events_are_exported_with_a_warning(tmp_path):
    result = invoke("codegen", pendulum_with_event(tmp_path, "record"), "-t", "fmu", "-o", tmp_path / "r.fmu")
    assert result.exit_code == 0, result.stderr
    assert result.stderr.startswith("mechsys: warning: events (upright) are not exported")
    assert (tmp_path / "r.fmu").is_file()


@needs_fmpy
@needs_gcc
@pytest.mark.slow
def test_a_nonholonomic_model_matches_mechsys_simulate(tmp_path):
    """The rolling disk (velocity constraints only): about 15 s to derive and build."""
    times = np.linspace(0.0, 1.0, 5)
    stepper = Stepper(build("rolling_disk", tmp_path))
    assert validate_fmu(str(tmp_path / "rolling_disk.fmu")) == []
    assert np.max(np.abs(stepper.run(times) - reference("rolling_disk", times=times))) < MATCH


@needs_fmpy
@needs_gcc
def test_the_fmu_refuses_a_parameter_that_fixes_its_structure(tmp_path):
    """Exported at h = 0, a pin's y row vanishes and is left out (tests/data/beyond/rail_pinned.yaml): the FMU
    takes h = 0 but refuses h = 0.3 with the reason in its log, instead of simulating without the row."""
    path = tmp_path / "rail.fmu"
    write_fmu(mechsys.load(ROOT / "tests" / "data" / "beyond" / "rail_pinned.yaml"), path)
    Stepper(path, {"h": 0.0, "F": 4.0})
    log = []

    class Logged(Stepper):
        def _log(self, env, instance, status, category, message) -> None:
            log.append(message.decode())

    with pytest.raises(Exception, match="fmi2SetReal failed"):
        Logged(path, {"h": 0.3})
    assert any("h fixes the structure of this FMU" in text for text in log)
