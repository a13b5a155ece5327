"""`mechsys codegen` (issue 15): the generated Python, C and MATLAB/Octave packages reproduce mechsys's own numbers.

Every bundled model is generated for each target and evaluated outside mechsys: the Python module in a clean
interpreter where `import mechsys` fails, the C source compiled with the system compiler and called through ctypes,
the MATLAB files run by GNU Octave (slow; skipped without `octave-cli`). The reference is mechsys's own evaluation
of the same equations (numeric/lambdify.py: M, f, A, b, T, V) and a numpy solve of [[M, -A^T], [A, 0]]; the
linearization is checked against central differences of that reference. A model written here by hand, with names
that are keywords in the targets, is checked against its closed-form M and f."""
from __future__ import annotations

import ctypes
import functools
import json
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from test_cli_hardening import invoke, one_line  # the command-line helpers: exit code, one stderr line

import mechsys
from mechsys.codegen import TARGETS, check_target, derive_package, mangle, write_package
from mechsys.codegen.names import MAX_LENGTH, RESERVED, identifier
from mechsys.codegen.package import MARKER, Package, Program, StepFacts, write_directory
from mechsys.errors import AnalysisError, InputError
from mechsys.numeric.lambdify import compile_matrix

ROOT = Path(__file__).resolve().parents[1]
SYSTEMS = sorted(p.stem for p in (ROOT / "systems").glob("*.yaml"))
HEAVY = "bicycle"  # ~30 s to generate, minutes to compile its C at -O2: a slow test of the Python target only
TOLERANCE = 1e-12
OCTAVE = shutil.which("octave-cli")
CC = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
CFLAGS = ["-O2", "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror"]
needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler")
needs_octave = pytest.mark.skipif(OCTAVE is None, reason="GNU Octave (octave-cli) is not installed")

# A cart with a pendulum, written as a user would, with parameter names that are keywords of the targets
# (lambda: Python, int: C, end and if: MATLAB) and Greek names spelled out.
HAND_MODEL = """\
name: hand cart pendulum
description: cart on a spring with a pendulum (names that are keywords in Python, C and MATLAB)
parameters:
  int: 1.3      # cart mass [kg]
  mu: 0.4       # bob mass [kg]
  ell: 0.7      # pendulum length [m]
  lambda: 25    # spring stiffness [N/m]
  end: 0.2      # spring free length [m]
  if: 0.15      # pivot damping [N m s]
  g: 9.81       # [m/s^2]
coordinates:
  x: {initial: 0.5, rate: 0.1}
  theta: {initial: 0.3, rate: 0}   # from the downward vertical
links:
  cart:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}
    mass: int
  bob:
    joint: {type: revolute, parent: cart, axis: z, coordinate: theta}
    particle: true
    mass: mu
    center_of_mass: [0, -ell, 0]
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
  - {type: spring, between: [ground, cart], stiffness: lambda, free_length: end}
  - {type: torsional_damper, coordinate: theta, coefficient: if}
"""


def hand_closed_form(t: float, q, u, p: dict) -> dict:
    """M, f, T and V of HAND_MODEL derived by hand (bob at (x + l sin theta, -l cos theta))."""
    (x, th), (xd, thd) = q, u
    m_c, mu, ell, k, l0, c, g = (p[n] for n in ("int", "mu", "ell", "lambda", "end", "if", "g"))
    stretch = abs(x) - l0
    return {
        "mass_matrix": [m_c + mu, mu * ell * math.cos(th), mu * ell * math.cos(th), mu * ell ** 2],
        "forcing": [mu * ell * thd ** 2 * math.sin(th) - k * stretch * math.copysign(1.0, x),
                    -mu * g * ell * math.sin(th) - c * thd],
        "kinetic_energy": [0.5 * m_c * xd ** 2 + 0.5 * mu * (xd ** 2 + 2 * xd * ell * thd * math.cos(th)
                                                             + ell ** 2 * thd ** 2)],
        "potential_energy": [-mu * g * ell * math.cos(th) + 0.5 * k * stretch ** 2],
    }


# Names that would break generated code if they were not mangled or reserved: keywords, the generated code's own
# arguments, helpers, macros and temporaries, and a collision (the parameter der_q against the rate der(q)).
HOSTILE_MASS1 = ["lambda", "if", "end", "int", "double", "function", "numpy", "math", "out", "zeros", "pow", "fabs"]
HOSTILE_LENGTH = ["p", "u", "x", "a", "lam", "N", "NC", "K", "M", "s", "solution", "STATE", "PARAMETERS"]
HOSTILE_OTHER = ["M_PI", "NAN", "stdin", "errno", "cse0", "cse12", "_k", "der_q", "memcpy", "solve", "rhs",
                 "mass_matrix", "math__rhs", "MATH__N", "nargin", "Inf"]


TRICKY = 'names that collide with the generated code, a docstring end """, a C comment end */, a backslash \\'


def hostile_model() -> str:
    names = HOSTILE_MASS1 + HOSTILE_LENGTH + HOSTILE_OTHER
    params = "\n".join(f"  {name}: {0.05 + 0.01 * i:.2f}" for i, name in enumerate(names))
    return f"""\
name: math
description: '{TRICKY}'
parameters:
{params}
coordinates:
  q: {{initial: 0.4, rate: 0.2}}
  while: {{initial: -0.3, rate: 0.1}}
links:
  rod1:
    joint: {{type: revolute, parent: ground, axis: z, coordinate: q}}
    mass: {' + '.join(HOSTILE_MASS1)}
    center_of_mass: [0, -({' + '.join(HOSTILE_LENGTH)})/2, 0]
    shape: {{rod: {{length: {' + '.join(HOSTILE_LENGTH)}, axis: y}}}}
  rod2:
    joint: {{type: revolute, parent: rod1, axis: z, coordinate: while, origin: [0, -({' + '.join(HOSTILE_LENGTH)}), 0]}}
    mass: {' + '.join(HOSTILE_OTHER)}
    center_of_mass: [0, -0.3, 0]
    shape: {{rod: {{length: 0.6, axis: y}}}}
forces:
  - {{type: gravity, acceleration: [0, -9.81, 0]}}
"""


# ----------------------------------------------------------------------------------------- mechsys's own numbers
def expressions(model) -> dict[str, sp.Matrix]:
    """The expressions behind each generated model function (the package's function names)."""
    eq = model.equations("lagrange")
    out = {"mass_matrix": eq.M, "forcing": eq.f, "kinetic_energy": sp.Matrix([eq.T]),
           "potential_energy": sp.Matrix([eq.V])}
    if eq.A.shape[0]:
        out.update(constraint_matrix=eq.A, constraint_rhs=eq.b, constraint_velocity=model.constraint_velocity)
        if model.holonomic_constraints.shape[0]:
            out["constraint_position"] = model.holonomic_constraints
    return out


class Reference:
    """mechsys's evaluation: its compiled expressions (numeric/lambdify.py) and numpy's solve of the KKT system."""

    def __init__(self, model) -> None:
        args = (model.t, model.q, model.u, model.parameter_symbols)
        self.functions = {name: compile_matrix(expr, *args) for name, expr in expressions(model).items()}
        self.p = [model.parameters[s.name] for s in model.parameter_symbols]
        self.n = len(model.q)

    def values(self, t: float, q, u) -> dict[str, np.ndarray]:
        return {name: np.asarray(fn(t, q, u, self.p), dtype=float).ravel() for name, fn in self.functions.items()}

    def system(self, t: float, q, u) -> tuple[np.ndarray, np.ndarray]:
        v = self.values(t, q, u)
        n = self.n
        M, s = v["mass_matrix"].reshape(n, n), v["forcing"]
        if "constraint_matrix" not in v:
            return M, s
        A = v["constraint_matrix"].reshape(-1, n)
        m = A.shape[0]
        return np.block([[M, -A.T], [A, np.zeros((m, m))]]), np.concatenate([s, v["constraint_rhs"]])

    def accelerations(self, t: float, q, u) -> np.ndarray:
        K, s = self.system(t, q, u)
        return np.linalg.solve(K, s)

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        return np.concatenate([x[self.n:], self.accelerations(t, x[:self.n], x[self.n:])[:self.n]])

    def linearization(self, t: float, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A by central differences of rhs, B from the KKT matrix (d q''/d tau = first n rows of K^-1 [I; 0])."""
        n = self.n
        A = np.zeros((2 * n, 2 * n))
        for j in range(2 * n):
            h = 1e-6 * max(1.0, abs(x[j]))
            e = np.zeros(2 * n)
            e[j] = h
            A[:, j] = (self.rhs(t, x + e) - self.rhs(t, x - e)) / (2 * h)
        K, _ = self.system(t, x[:n], x[n:])
        unit = np.zeros((K.shape[0], n))
        unit[:n] = np.eye(n)
        B = np.vstack([np.zeros((n, n)), np.linalg.solve(K, unit)[:n]])
        return A, B


def states(n: int, count: int = 4, seed: int = 15) -> list[tuple[float, list[float], list[float]]]:
    rng = np.random.default_rng(seed)
    return [(float(rng.uniform(0, 2)), rng.uniform(-1.2, 1.2, n).tolist(), rng.uniform(-1.2, 1.2, n).tolist())
            for _ in range(count)]


def relative(got, want) -> float:
    got, want = np.asarray(got, dtype=float).ravel(), np.asarray(want, dtype=float).ravel()
    assert got.shape == want.shape, (got.shape, want.shape)
    return float(np.max(np.abs(got - want), initial=0.0) / max(float(np.max(np.abs(want), initial=0.0)), 1e-300))


def check_against_reference(results: list[dict], reference: Reference, samples, tol: float,
                            linear_tol: float = 1e-6) -> None:
    """Every function, the accelerations, the multipliers, rhs and the linearization of a target's results."""
    n = reference.n
    for (t, q, u), got in zip(samples, results):
        want = reference.values(t, q, u)
        assert set(want) <= set(got), sorted(set(want) - set(got))
        for name, value in want.items():
            assert relative(got[name], value) <= tol, (name, t, q, u, got[name], value.tolist())
        solution = reference.accelerations(t, q, u)
        assert relative(got["accelerations"], solution[:n]) <= tol, ("accelerations", got["accelerations"], solution)
        if len(solution) > n:
            assert relative(got["multipliers"], solution[n:]) <= tol, ("multipliers", got["multipliers"], solution)
        x = np.array(q + u)
        assert relative(got["rhs"], reference.rhs(t, x)) <= tol
        A, B = reference.linearization(t, x)
        assert relative(got["linear_A"], A) <= linear_tol, ("linear A", np.array(got["linear_A"]), A)
        assert relative(got["linear_B"], B) <= tol * 100, ("linear B", np.array(got["linear_B"]), B)


# ----------------------------------------------------------------------------------------- packages
@functools.lru_cache(maxsize=None)
def bundled(name: str) -> tuple[object, Package]:
    model = mechsys.load(ROOT / "systems" / f"{name}.yaml")
    return model, derive_package(model)


def write(pkg: Package, target: str, folder: Path) -> Path:
    write_directory(folder, TARGETS[target](pkg))
    return folder


def function_names(pkg: Package) -> list[str]:
    return [name for name in pkg.functions if name != "residual_jacobian"]


PYTHON_RUNNER = r"""
import json, sys
package, site, module, names = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4].split(",")
sys.path[:0] = [package, site]  # the package, then numpy's folder: -S processed no .pth file (no editable mechsys)
try:
    import mechsys  # noqa: F401
except ImportError:
    pass
else:
    sys.exit("mechsys is importable in the clean interpreter")
model = __import__(module)
if "sympy" in sys.modules or "mechsys" in sys.modules:
    sys.exit("the generated module imported sympy or mechsys")
changes = json.loads(sys.argv[5]) if len(sys.argv) > 5 else {}
p = model.params(**changes)
out = []
for t, q, u in json.load(sys.stdin):
    entry = {name: getattr(model, name)(t, q, u, p) for name in names}
    entry["accelerations"], entry["multipliers"] = model.accelerations(t, q, u, p)
    entry["rhs"] = model.rhs(t, q + u, p)
    entry["linear_A"], entry["linear_B"] = model.linearize(t, q + u, p)
    out.append({k: (v.ravel().tolist() if hasattr(v, "ravel") else [v]) for k, v in entry.items()})
print(json.dumps(out))
"""


def run_python(pkg: Package, folder: Path, samples, changes: dict | None = None) -> list[dict]:
    """Evaluate the generated Python module in `python -I -S` (no site: the editable mechsys is not importable)."""
    site = str(Path(np.__file__).resolve().parents[1])
    names = ",".join(function_names(pkg))
    args = [sys.executable, "-I", "-S", "-c", PYTHON_RUNNER, str(folder), site, pkg.prefix, names]
    if changes:
        args.append(json.dumps(changes))
    proc = subprocess.run(args, input=json.dumps(samples), capture_output=True, text=True, cwd=folder, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


class CPackage:
    """The generated C compiled into a shared library (warnings are errors) and called through ctypes."""

    def __init__(self, pkg: Package, folder: Path) -> None:
        library = folder / f"lib{pkg.prefix}.so"
        proc = subprocess.run([CC, *CFLAGS, "-shared", "-fPIC", "-o", str(library), str(folder / f"{pkg.prefix}.c"),
                               "-lm"], capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr
        self.lib = ctypes.CDLL(str(library))
        self.pkg = pkg
        self.n, self.m = pkg.n, pkg.m
        self.params((p.value for p in pkg.parameters))

    def params(self, values) -> None:
        values = list(values)
        self.p = (ctypes.c_double * max(len(values), 1))(*values)

    @staticmethod
    def array(values) -> ctypes.Array:
        values = list(values)
        return (ctypes.c_double * max(len(values), 1))(*values)

    def call(self, name: str, *args, size: int, status: bool = False) -> list[float]:
        out = (ctypes.c_double * max(size, 1))()
        fn = getattr(self.lib, f"{self.pkg.prefix}_{name}")
        fn.restype = ctypes.c_int if status else None
        converted = [ctypes.c_double(a) if isinstance(a, float) else a for a in args]
        result = fn(*converted, ctypes.byref(self.p), out)
        assert not status or result == 0, f"{name} returned {result}"
        return list(out)[:size]

    def evaluate(self, samples) -> list[dict]:
        n, m, out = self.n, self.m, []
        for t, q, u in samples:
            cq, cu = self.array(q), self.array(u)
            entry = {name: self.call(name, float(t), cq, cu, size=int(np.prod(fn.shape, dtype=int)))
                     for name, fn in self.pkg.functions.items() if name != "residual_jacobian"}
            a, lam = (ctypes.c_double * n)(), (ctypes.c_double * max(m, 1))()
            fn = self.lib[f"{self.pkg.prefix}_accelerations"]
            assert fn(ctypes.c_double(t), cq, cu, ctypes.byref(self.p), a, lam) == 0
            entry["accelerations"], entry["multipliers"] = list(a), list(lam)[:m]
            x = self.array(q + u)
            entry["rhs"] = self.call_state("rhs", t, x, 2 * n)
            A, B = (ctypes.c_double * (4 * n * n))(), (ctypes.c_double * (2 * n * n))()
            assert self.lib[f"{self.pkg.prefix}_linearize"](ctypes.c_double(t), x, ctypes.byref(self.p), A, B) == 0
            entry["linear_A"], entry["linear_B"] = list(A), list(B)
            out.append(entry)
        return out

    def call_state(self, name: str, t: float, x, size: int) -> list[float]:
        out = (ctypes.c_double * size)()
        assert self.lib[f"{self.pkg.prefix}_{name}"](ctypes.c_double(t), x, ctypes.byref(self.p), out) == 0
        return list(out)


def run_octave(pkg: Package, folder: Path, samples, changes: dict | None = None) -> list[dict]:
    """Evaluate the MATLAB files with GNU Octave; every result printed with 17 digits, row by row."""
    P = pkg.prefix
    lines = [f"addpath('{folder}');", f"p = {P}_params();"]
    lines += [f"p.{k} = {v!r};" for k, v in (changes or {}).items()]
    names = function_names(pkg)
    for k, (t, q, u) in enumerate(samples):
        lines += [f"t = {t!r}; q = [{'; '.join(map(repr, q))}]; u = [{'; '.join(map(repr, u))}];"]
        for name in names:
            lines.append(f"v = {P}_{name}(t, q, u, p); fprintf('{k} {name}'); fprintf(' %.17g', v.'); fprintf('\\n');")
        lines += [f"[a, lam] = {P}_accelerations(t, q, u, p);",
                  f"fprintf('{k} accelerations'); fprintf(' %.17g', a); fprintf('\\n');",
                  f"fprintf('{k} multipliers'); fprintf(' %.17g', lam); fprintf('\\n');",
                  f"v = {P}_rhs(t, [q; u], p); fprintf('{k} rhs'); fprintf(' %.17g', v); fprintf('\\n');",
                  f"[A, B] = {P}_linearize(t, [q; u], p);",
                  f"fprintf('{k} linear_A'); fprintf(' %.17g', A.'); fprintf('\\n');",
                  f"fprintf('{k} linear_B'); fprintf(' %.17g', B.'); fprintf('\\n');"]
    script = folder / "evaluate_states.m"
    script.write_text("\n".join(lines) + "\n", encoding="utf-8")
    proc = subprocess.run([OCTAVE, "--no-gui", "--no-init-file", "--quiet", str(script)], capture_output=True,
                          text=True, timeout=300, cwd=folder)
    assert proc.returncode == 0, proc.stderr + proc.stdout
    out: list[dict] = [{} for _ in samples]
    for line in proc.stdout.splitlines():
        k, name, *values = line.split()
        out[int(k)][name] = [float(v) for v in values]
    return out


# ----------------------------------------------------------------------------------------- bundled models
LIGHT = [name for name in SYSTEMS if name != HEAVY]


@pytest.mark.parametrize("name", LIGHT)
def test_generated_python_agrees_with_mechsys(name, tmp_path):
    model, pkg = bundled(name)
    samples = states(pkg.n)
    results = run_python(pkg, write(pkg, "python", tmp_path / "pkg"), samples)
    check_against_reference(results, Reference(model), samples, TOLERANCE)


@needs_cc
@pytest.mark.parametrize("name", LIGHT)
def test_generated_c_agrees_with_mechsys(name, tmp_path):
    model, pkg = bundled(name)
    samples = states(pkg.n)
    results = CPackage(pkg, write(pkg, "c", tmp_path / "pkg")).evaluate(samples)
    check_against_reference(results, Reference(model), samples, TOLERANCE)


@needs_cc
def test_only_the_jacobian_is_built_unoptimised_and_opting_out_gives_the_same_linearization(tmp_path, monkeypatch):
    """residual_jacobian (run once per linearization) carries gcc's optimize("O0") through a macro, no other
    function does; built with -D<P>_OPTIMIZE_JACOBIAN (every function at -O2) the linearization is the same."""
    model, pkg = bundled("slider_crank")
    folder = write(pkg, "c", tmp_path / "pkg")
    source = (folder / f"{pkg.prefix}.c").read_text()
    P = pkg.prefix.upper()
    marked = re.findall(rf"^{P}_ONCE_PER_LINEARIZATION void (\w+)\(", source, re.M)
    assert marked == [f"{pkg.prefix}_residual_jacobian"]
    assert f'#define {P}_ONCE_PER_LINEARIZATION __attribute__((optimize("O0")))' in source
    samples = states(pkg.n)
    unoptimised = CPackage(pkg, folder).evaluate(samples)
    monkeypatch.setattr(sys.modules[__name__], "CFLAGS", CFLAGS + [f"-D{P}_OPTIMIZE_JACOBIAN"])
    copy = tmp_path / "optimised"
    shutil.copytree(folder, copy)
    optimised = CPackage(pkg, copy).evaluate(samples)
    for a, b in zip(unoptimised, optimised):
        for key in ("linear_A", "linear_B"):
            assert np.allclose(a[key], b[key], rtol=1e-13, atol=1e-13)


@pytest.mark.slow
@needs_octave
@pytest.mark.parametrize("name", LIGHT)
def test_generated_matlab_agrees_with_mechsys_in_octave(name, tmp_path):
    model, pkg = bundled(name)
    samples = states(pkg.n, count=2)
    results = run_octave(pkg, write(pkg, "matlab", tmp_path / "pkg"), samples)
    check_against_reference(results, Reference(model), samples, 1e-10)


@pytest.mark.slow
def test_the_bicycle_generates_and_agrees_in_python(tmp_path):
    """Nonholonomic, 9 coordinates, 6 constraint rows, equations of ~300 000 operations."""
    model, pkg = bundled(HEAVY)
    samples = states(pkg.n, count=2)
    results = run_python(pkg, write(pkg, "python", tmp_path / "pkg"), samples)
    check_against_reference(results, Reference(model), samples, 1e-10, linear_tol=1e-5)


def test_constraint_functions_vanish_on_the_files_consistent_initial_state(tmp_path):
    """The closed loops' position and velocity rows are zero where the file assembles the mechanism."""
    for name in ("four_bar", "slider_crank"):
        _, pkg = bundled(name)
        folder = write(pkg, "python", tmp_path / name)
        x0 = pkg.initial_state()
        results = run_python(pkg, folder, [(0.0, x0[:pkg.n], x0[pkg.n:])])[0]
        assert max(map(abs, results["constraint_position"] + results["constraint_velocity"])) < 1e-12
        assert "holonomic" in (folder / "README.md").read_text()


def test_a_guessed_initial_state_is_assembled_onto_the_loop(tmp_path):
    """A user's guess of the coupler angle (theta3 = 0.2) leaves the four-bar's loop open by 0.2 m. The package's
    initial state was that guess: its example integrated the open loop (theta2(1 s) = -0.0707, simulate's 0.6973),
    exit 0. It is now the state simulate starts from, on the loop, and the README says which values moved."""
    model = mechsys.load(ROOT / "systems" / "four_bar.yaml", overrides={"theta3": "0.2"})
    pkg = derive_package(model)
    folder = write(pkg, "python", tmp_path / "four_bar")
    x0 = pkg.initial_state()
    results = run_python(pkg, folder, [(0.0, x0[:pkg.n], x0[pkg.n:])])[0]
    assert max(map(abs, results["constraint_position"] + results["constraint_velocity"])) < 1e-12
    from mechsys.analysis.motion.simulate import initial_state, simulate

    assert x0 == pytest.approx(list(initial_state(model)[2]), abs=1e-15)
    assert "assembled onto the constraints" in (folder / "README.md").read_text()
    run = subprocess.run([sys.executable, "example.py", "1.0"], cwd=folder, capture_output=True, text=True, timeout=120)
    final = dict(line.split(" = ") for line in run.stdout.splitlines() if " = " in line)
    assert float(final["theta2"]) == pytest.approx(float(simulate(model, t_end=1.0).q[-1][0]), abs=1e-6)


def test_method_kane_gives_the_same_accelerations(tmp_path):
    model, _ = bundled("centrifuge")
    pkg = derive_package(model, "kane")
    samples = states(pkg.n)
    results = run_python(pkg, write(pkg, "python", tmp_path / "pkg"), samples)
    reference = Reference(model)
    for (t, q, u), got in zip(samples, results):
        assert relative(got["accelerations"], reference.accelerations(t, q, u)) <= TOLERANCE
    assert "(kane)" in (tmp_path / "pkg" / "centrifuge.py").read_text()


# ----------------------------------------------------------------------------------------- a model by hand
@pytest.fixture(scope="module")
def hand(tmp_path_factory):
    path = tmp_path_factory.mktemp("hand") / "cart.yaml"
    path.write_text(HAND_MODEL, encoding="utf-8")
    model = mechsys.load(path)
    return model, derive_package(model)


def hand_check(results, samples, params: dict, tol: float) -> None:
    for (t, q, u), got in zip(samples, results):
        for name, want in hand_closed_form(t, q, u, params).items():
            assert relative(got[name], want) <= tol, (name, got[name], want)


def test_hand_model_names_are_mangled_and_documented(hand, tmp_path):
    model, pkg = hand
    codes = {p.name: p.code for p in pkg.parameters}
    assert codes == {"int": "int_", "mu": "mu", "ell": "ell", "lambda": "lambda_", "end": "end_", "if": "if_",
                     "g": "g"}
    assert [(c.code, c.rate_code) for c in pkg.coordinates] == [("x_", "der_x"), ("theta", "der_theta")]
    assert pkg.prefix == "hand_cart_pendulum"
    readme = write(pkg, "python", tmp_path / "pkg").joinpath("README.md").read_text()
    assert readme.startswith(MARKER)
    assert "| `lambda_` | `lambda` | 25.0 | N/m | spring stiffness |" in readme
    assert "| 0 | `x` | `x_` | `der_x` (index 2) |  | 0.5 | 0.1 |" in readme
    assert "| 1 | `theta` | `theta` | `der_theta` (index 3) | rad |" in readme


def test_hand_model_python_matches_the_closed_form(hand, tmp_path):
    _, pkg = hand
    samples = states(pkg.n, count=5, seed=3)
    folder = write(pkg, "python", tmp_path / "pkg")
    defaults = {"int": 1.3, "mu": 0.4, "ell": 0.7, "lambda": 25.0, "end": 0.2, "if": 0.15, "g": 9.81}
    hand_check(run_python(pkg, folder, samples), samples, defaults, TOLERANCE)
    changed = dict(defaults, **{"lambda": 31.0, "if": 0.5})
    hand_check(run_python(pkg, folder, samples, {"lambda_": 31.0, "if_": 0.5}), samples, changed, TOLERANCE)


@needs_cc
def test_hand_model_c_matches_the_closed_form(hand, tmp_path):
    _, pkg = hand
    samples = states(pkg.n, count=5, seed=3)
    c = CPackage(pkg, write(pkg, "c", tmp_path / "pkg"))
    defaults = {"int": 1.3, "mu": 0.4, "ell": 0.7, "lambda": 25.0, "end": 0.2, "if": 0.15, "g": 9.81}
    hand_check(c.evaluate(samples), samples, defaults, TOLERANCE)
    c.params([{"lambda": 31.0}.get(p.name, p.value) for p in pkg.parameters])
    hand_check(c.evaluate(samples), samples, dict(defaults, **{"lambda": 31.0}), TOLERANCE)


@pytest.mark.slow
@needs_octave
def test_hand_model_matlab_matches_the_closed_form(hand, tmp_path):
    _, pkg = hand
    samples = states(pkg.n, count=3, seed=3)
    defaults = {"int": 1.3, "mu": 0.4, "ell": 0.7, "lambda": 25.0, "end": 0.2, "if": 0.15, "g": 9.81}
    results = run_octave(pkg, write(pkg, "matlab", tmp_path / "pkg"), samples, {"end_": 0.25})
    hand_check(results, samples, dict(defaults, end=0.25), 1e-10)


# ----------------------------------------------------------------------------------------- names
def test_der_names_become_identifiers():
    assert mangle(["der(q)", "der(der(q))", "q"]) == {"der(q)": "der_q", "der(der(q))": "der_der_q", "q": "q_"}


def test_reserved_words_of_every_target_get_an_underscore():
    names = ["lambda", "if", "end", "int", "function", "double", "None", "elseif", "x", "out", "NAN", "M_PI", "math"]
    assert mangle(names) == {name: name + "_" for name in names}
    assert mangle(["mass", "theta1", "k12"]) == {"mass": "mass", "theta1": "theta1", "k12": "k12"}


def test_greek_and_other_characters_are_transliterated():
    assert identifier("α") == "alpha" and identifier("Ω") == "Omega"
    assert identifier("θ_1") == "theta_1" and identifier("ω²") == "omega2"
    assert identifier("é") == "e" and identifier("λ") == "lambda_"  # a Greek name can be a reserved word too
    assert identifier("_k") == "v_k" and identifier("2x") == "v2x" and identifier("()") == "v"
    assert identifier("a b-c") == "a_b_c" and identifier("cse3") == "cse3_"


def test_collisions_are_resolved_deterministically():
    # an already valid name keeps its identifier wherever it stands; the mangled one takes a suffix
    assert mangle(["der(q)", "der_q"]) == {"der(q)": "der_q_2", "der_q": "der_q"}
    assert mangle(["der_q", "der(q)"]) == {"der_q": "der_q", "der(q)": "der_q_2"}
    assert mangle(["a-b", "a b", "a_b"]) == {"a-b": "a_b_2", "a b": "a_b_3", "a_b": "a_b"}
    assert mangle(["lambda", "lambda_"]) == {"lambda": "lambda__2", "lambda_": "lambda_"}
    assert mangle(["rhs"], reserved={"rhs"}) == {"rhs": "rhs_"}


def test_identifiers_are_valid_in_every_target_and_distinct():
    names = ["α", "der(α)", "x" * 100, "x" * 99 + "y", "lambda", "lambda_", "_", "__", "end", "π", "a.b", "a(b)"]
    out = mangle(names)
    assert len(set(out.values())) == len(names)
    for ident in out.values():
        assert re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", ident) and len(ident) <= MAX_LENGTH, ident
        assert ident not in RESERVED and ident.isidentifier(), ident
    assert mangle(names) == out  # deterministic


def test_hostile_names_do_not_break_any_target(tmp_path):
    """Parameters named after the generated code's own words, a collision and a model named like a standard
    module: the Python and C packages still reproduce mechsys's numbers."""
    path = tmp_path / "hostile.yaml"
    path.write_text(hostile_model(), encoding="utf-8")
    model = mechsys.load(path)
    pkg = derive_package(model)
    assert pkg.prefix == "math_"  # a module named math would shadow the standard one
    codes = {p.name: p.code for p in pkg.parameters}
    assert codes["der_q"] == "der_q" and pkg.coordinates[0].rate_code == "der_q_2"
    assert codes["_k"] == "v_k" and codes["cse0"] == "cse0_" and codes["math__rhs"] == "math__rhs_"
    check_every_target(model, pkg, tmp_path)


def check_every_target(model, pkg: Package, folder: Path) -> None:
    """Python always, C with a compiler, MATLAB with Octave (both fast enough for one model)."""
    samples = states(pkg.n, count=2)
    reference = Reference(model)
    check_against_reference(run_python(pkg, write(pkg, "python", folder / "py"), samples), reference, samples,
                            TOLERANCE)
    if CC:
        check_against_reference(CPackage(pkg, write(pkg, "c", folder / "c")).evaluate(samples), reference,
                                samples, TOLERANCE)
    if OCTAVE:
        check_against_reference(run_octave(pkg, write(pkg, "matlab", folder / "m"), samples), reference, samples,
                                1e-10)


def test_every_function_of_the_language_prints_in_every_target(tmp_path):
    """abs, sign, min, max, atan2, the hyperbolic and inverse functions, and in the Jacobian their derivatives
    (Heaviside, DiracDelta), with explicit time."""
    model = mechsys.load(ROOT / "tests" / "data" / "native_functions.yaml")
    pkg = derive_package(model)
    assert any(fn.program.outputs and any(e.has(sp.Heaviside) for e in fn.program.outputs + [
        v for _, v in fn.program.assignments]) for fn in pkg.functions.values())
    check_every_target(model, pkg, tmp_path)


def test_a_program_knows_which_functions_its_steps_apply():
    """Program.applies, which lets the printers skip looking through every statement for re(...) and Heaviside:
    true for a function any step or output applies (however deep), false otherwise; each expression looked at
    once for all the functions cut from one CSE (StepFacts)."""
    x, y, c0, c1 = sp.symbols("x y c0 c1")
    facts = StepFacts()
    deep = sp.Add(*(sp.Mul(x, sp.Heaviside(y - k)) for k in range(3))) * sp.cos(x) + 1
    program = Program([(c0, sp.sin(x) * y), (c1, deep)], [c0 + c1], facts)
    assert program.applies(sp.Heaviside) and program.applies(sp.sin) and program.applies(sp.cos)
    assert not program.applies(sp.re) and not program.applies(sp.tan)
    plain = Program([(c0, sp.sin(x) * y)], [c0 * sp.re(y)], facts)
    assert plain.applies(sp.re) and not plain.applies(sp.Heaviside)
    assert len(facts.kinds) == 4  # sin(x)*y looked at once for both programs
    model, pkg = bundled("double_pendulum")
    fn = pkg.functions["residual_jacobian"]
    assert not fn.program.applies(sp.Heaviside) and not fn.program.applies(sp.re)


# ----------------------------------------------------------------------------------------- example drivers
def reference_final_state(model, t_end: float) -> np.ndarray:
    from scipy.integrate import solve_ivp

    reference = Reference(model)
    x0 = [model.doc.initial[c] for c in model.coordinates] + [model.doc.initial_rate[c] for c in model.coordinates]
    sol = solve_ivp(reference.rhs, (0.0, t_end), x0, method="DOP853", rtol=1e-12, atol=1e-13)
    return sol.y[:, -1]


def final_state(text: str, pkg: Package) -> np.ndarray:
    values = dict(line.split(" = ") for line in text.strip().splitlines())
    names = [c.code for c in pkg.coordinates] + [c.rate_code for c in pkg.coordinates]
    return np.array([float(values[n]) for n in names])


def test_example_drivers_reach_the_reference_final_state(tmp_path):
    """python example.py (solve_ivp in a clean interpreter) and the C RK4 driver end where mechsys's rhs does."""
    model, pkg = bundled("double_pendulum")
    want = reference_final_state(model, 1.0)
    folder = write(pkg, "python", tmp_path / "py")
    site = str(Path(np.__file__).resolve().parents[1])
    script = f"import sys; sys.path[:0] = [{str(folder)!r}, {site!r}]; sys.argv = ['example.py', '1.0']; " \
             "exec(open('example.py').read())"
    proc = subprocess.run([sys.executable, "-I", "-S", "-c", script], capture_output=True, text=True, cwd=folder,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert np.max(np.abs(final_state(proc.stdout, pkg) - want)) < 1e-8
    if CC:
        folder = write(pkg, "c", tmp_path / "c")
        build = subprocess.run(["make", f"CC={CC}", "CFLAGS=" + " ".join(CFLAGS)], capture_output=True, text=True,
                               cwd=folder, timeout=120)
        assert build.returncode == 0, build.stderr
        proc = subprocess.run(["./example", "1.0", "4000"], capture_output=True, text=True, cwd=folder, timeout=60)
        assert proc.returncode == 0, proc.stderr
        assert np.max(np.abs(final_state(proc.stdout, pkg) - want)) < 1e-9


@pytest.mark.slow
@needs_octave
def test_octave_example_reaches_the_reference_final_state(tmp_path):
    model, pkg = bundled("double_pendulum")
    folder = write(pkg, "matlab", tmp_path / "m")
    proc = subprocess.run([OCTAVE, "--no-gui", "--no-init-file", "--quiet", "--eval",
                           f"t_end = 1; {pkg.prefix}_example"], capture_output=True, text=True, cwd=folder, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert np.max(np.abs(final_state(proc.stdout, pkg) - reference_final_state(model, 1.0))) < 1e-7


# ----------------------------------------------------------------------------------------- refusals
def test_a_singular_mass_matrix_is_refused():
    model = mechsys.load(ROOT / "tests" / "data" / "zero_mass_second_pendulum.yaml")
    with pytest.raises(AnalysisError, match="mass matrix is singular"):
        derive_package(model)


def test_a_model_without_free_coordinates_is_refused(tmp_path):
    path = tmp_path / "driven.yaml"
    path.write_text("name: driven\nparameters: {w: 2}\ncoordinates:\n  phi: {prescribed: w*t}\nlinks:\n"
                    "  arm:\n    joint: {type: revolute, parent: ground, axis: z, coordinate: phi}\n"
                    "    mass: 1\n    center_of_mass: [1, 0, 0]\n", encoding="utf-8")
    with pytest.raises(InputError, match="no free coordinates"):
        derive_package(mechsys.load(path))


def test_unknown_target_and_method_are_input_errors():
    with pytest.raises(InputError, match="unknown target 'fortran'; use one of python, c, matlab"):
        check_target("fortran")
    with pytest.raises(InputError, match="unknown method"):
        derive_package(bundled("problem57")[0], "hamilton")


# ----------------------------------------------------------------------------------------- the command line
PENDULUM = ROOT / "systems" / "double_pendulum.yaml"


@pytest.mark.parametrize("target, files", [
    ("python", ["README.md", "double_pendulum.py", "example.py"]),
    ("c", ["Makefile", "README.md", "double_pendulum.c", "double_pendulum.h", "example.c"]),
    ("matlab", ["README.md", "double_pendulum_example.m", "double_pendulum_mass_matrix.m",
                "double_pendulum_params.m", "double_pendulum_rhs.m", "double_pendulum_linearize.m"]),
])
def test_cli_writes_the_package(target, files, tmp_path):
    out = tmp_path / "pkg"
    result = invoke("codegen", PENDULUM, "--target", target, "-o", out, "--set", "m1=2")
    assert result.exit_code == 0, result.stderr
    assert set(files) <= {p.name for p in out.iterdir()}
    assert result.stdout.startswith(f"wrote {out}: ")
    assert "| `m1` | `m1` | 2.0 | kg | rod 1 mass |" in (out / "README.md").read_text()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary folder left


def test_cli_replaces_a_previous_package_but_no_other_folder(tmp_path):
    out = tmp_path / "pkg"
    assert invoke("codegen", PENDULUM, "-t", "python", "-o", out).exit_code == 0
    (out / "stale.txt").write_text("old")
    assert invoke("codegen", PENDULUM, "-t", "c", "-o", out).exit_code == 0
    assert not (out / "stale.txt").exists() and (out / "double_pendulum.c").exists()
    assert not [p for p in tmp_path.iterdir() if p.name != "pkg"]
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("keep")
    assert "not empty" in one_line(invoke("codegen", PENDULUM, "-t", "c", "-o", other))
    assert [p.name for p in other.iterdir()] == ["notes.txt"]


@pytest.mark.parametrize("args, message", [
    (["--target", "fortran"], "unknown target 'fortran'; use one of python, c, matlab"),
    (["--target", "c", "--method", "hamilton"], "Invalid value for '--method'"),
    (["--target", "c", "--set", "nope=1"], "unknown parameter or coordinate"),
])
def test_cli_bad_input_is_one_line_exit_2(args, message, tmp_path):
    out = tmp_path / "pkg"
    result = invoke("codegen", PENDULUM, "-o", out, *args)
    if "--method" in args:  # a usage error: click's message through main(), exit 2
        proc = subprocess.run([sys.executable, "-m", "mechsys", "codegen", str(PENDULUM), "-o", str(out), *args],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2 and message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    else:
        assert message in one_line(result)
    assert not out.exists()


def test_cli_refuses_a_file_and_a_missing_folder(tmp_path):
    afile = tmp_path / "taken"
    afile.write_text("x")
    assert "it is a file" in one_line(invoke("codegen", PENDULUM, "-t", "python", "-o", afile))
    assert afile.read_text() == "x"
    assert "does not exist" in one_line(invoke("codegen", PENDULUM, "-t", "python", "-o", tmp_path / "no" / "pkg"))


def test_cli_singular_model_is_one_line_exit_1(tmp_path):
    result = invoke("codegen", ROOT / "tests" / "data" / "zero_mass_second_pendulum.yaml", "-t", "c", "-o",
                    tmp_path / "pkg")
    assert "mass matrix is singular" in one_line(result, 1)
    assert not (tmp_path / "pkg").exists()


def test_cli_constrained_and_nonholonomic_models_are_exported(tmp_path):
    for name in ("slider_crank", "rolling_disk"):
        result = invoke("codegen", ROOT / "systems" / f"{name}.yaml", "-t", "c", "-o", tmp_path / name)
        assert result.exit_code == 0, result.stderr
        readme = (tmp_path / name / "README.md").read_text()
        assert "## Constraint rows" in readme and "[[M, -A^T], [A, 0]]" in readme
    assert "nonholonomic" in (tmp_path / "rolling_disk" / "README.md").read_text()


def test_contacts_are_named_as_not_exported(tmp_path):
    result = invoke("codegen", ROOT / "systems" / "bouncing_ball.yaml", "-t", "python", "-o", tmp_path / "pkg")
    assert result.exit_code == 0, result.stderr
    readme = (tmp_path / "pkg" / "README.md").read_text()
    assert "## Not exported" in readme and "impacts are not exported" in readme


def test_write_package_returns_the_files(tmp_path):
    model, _ = bundled("problem57")
    files = write_package(model, "matlab", tmp_path / "pkg")
    assert sorted(p.name for p in (tmp_path / "pkg").iterdir()) == files


def test_constants_that_c99_lacks_are_defined(tmp_path):
    """sqrt(2) in the equations: sympy's C printer writes M_SQRT2, which math.h defines only outside strict C99;
    the package defines it (and the other POSIX constants) itself, so it compiles with -std=c99 -pedantic and
    agrees with mechsys."""
    text = (ROOT / "systems" / "double_pendulum.yaml").read_text()
    text = text.replace("acceleration: [0, -g, 0]", "acceleration: [0, -g*sqrt(2)/2, 0]")
    assert "sqrt(2)" in text
    path = tmp_path / "roots.yaml"
    path.write_text(text)
    model = mechsys.load(path)
    pkg = derive_package(model)
    source = write(pkg, "c", tmp_path / "c")
    assert "M_SQRT2" in "".join(p.read_text() for p in Path(source).glob("*.c"))  # what the printer writes
    check_every_target(model, pkg, tmp_path)


def _module_of(folder: Path, name: str):
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"{name}_{folder.name}", folder / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_parameters_that_fix_the_exported_structure_are_refused(tmp_path):
    """A cart on a rail along [1, h, 0] pinned to a cart on x (a user's model): exported at h = 0, the pin's y row
    vanishes and is left out, so the package at h = 0.3 would let the carts move where the pin locks them
    (closed form: s1 h / |(1, h)| = 0, so both stand still). `params(h=0.3)` refuses it and the README says why;
    exported with --set h=0.3, both rows are there and the carts do not accelerate under the push."""
    from tests.helpers import DATA_DIR

    path = DATA_DIR / "beyond" / "rail_pinned.yaml"
    flat = _module_of(write(derive_package(mechsys.load(path)), "python", tmp_path / "flat"), "rail")
    assert flat.CONSTRAINTS == ("pin.x",) and set(flat.FIXED) == {"h"}
    assert flat.params(h=0.0, F=5.0)["F"] == 5.0
    with pytest.raises(ValueError, match="h fixes the structure of this export"):
        flat.params(h=0.3)
    assert "### Fixed by this export" in (tmp_path / "flat" / "README.md").read_text()
    sloped = _module_of(write(derive_package(mechsys.load(path, {"h": "0.3"})), "python", tmp_path / "sloped"),
                        "rail")
    assert sloped.CONSTRAINTS == ("pin.x", "pin.y") and sloped.FIXED == {}
    acc, _lam = sloped.accelerations(0.0, [0.0, 0.0], [0.0, 0.0])
    assert np.allclose(acc, 0.0, atol=1e-12)
    assert _module_of(write(bundled("double_pendulum")[1], "python", tmp_path / "dp"), "double_pendulum").FIXED == {}
