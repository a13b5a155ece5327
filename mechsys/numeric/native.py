"""Native fast path: the staged equations and a DOP853 loop generated as C, compiled once, cached, run via ctypes.

Why C through the system compiler and ctypes (not numba or symengine): a cached shared library loads in about
a millisecond, so a warm `mechsys simulate` pays neither numba's import (~0.3 s) nor its JIT of the integrator
loop (seconds), and the whole loop (stages, assembly, LU solve, step control, dense output) runs without a
Python call. benchmarks/simulate_anchor.py measures it. The compiler is optional: without one (or with
MECHSYS_NATIVE=off) `auto` falls back to scipy's DOP853, which takes the same steps."""
from __future__ import annotations

import atexit
import ctypes
import math
import os
import platform
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Optional, Sequence

import numpy as np

from mechsys.errors import AnalysisError

if TYPE_CHECKING:  # sympy and the model are imported only where used: a warm run needs neither
    import sympy as sp

    from mechsys.mechanics.model import MechanicalModel
    from mechsys.numeric.lambdify import ForwardProgram

TEMPLATE = Path(__file__).with_name("dop853.c")
BUDGET_SPENT = "the step budget (--max-steps) is spent"
IMPLICIT_METHODS = ("Radau", "BDF", "LSODA", "CVODE")


def budget_spent(method: Optional[str] = None) -> str:
    """BUDGET_SPENT and what may cause it with the method that was integrating: an explicit method is slowed by a
    stiff scene; an implicit one, which takes stiff decay in its stride, by fast oscillations it must follow
    period by period (a stiff undamped spring), where its Python steps cost more than the compiled DOP853's.
    Either may chatter on a discontinuous law."""
    if method in IMPLICIT_METHODS:
        cause = (f"fast undamped oscillations that {method} follows period by period (a stiff spring without "
                 "damping: --method native, the compiled DOP853, follows them far faster; or a looser --rtol)")
    else:
        cause = "a stiff scene (try --method Radau or CVODE)"
    return f"{BUDGET_SPENT}: {cause} or a discontinuous law such as sign() of a rate that the integrator chatters on"


_STATUS = {-1: "the step size became too small",
           -2: "the mass matrix (or, with constraints, [[M, A^T], [A, 0]]: redundant constraints or a singular "
               "configuration) is singular",
           -3: "the state or its derivative is not finite", -4: "an output time lies past the end",
           -5: budget_spent("native")}


_OFF = ("off", "0", "false", "no")  # what MECHSYS_NATIVE and MECHSYS_QUICK_CC accept for "none"


def _on_path(*names: Optional[str]) -> Optional[str]:
    """The path of the first of ``names`` (empty ones skipped) found on PATH, or None."""
    for name in names:
        found = shutil.which(name) if name else None
        if found:
            return found
    return None


def compiler() -> Optional[str]:
    """The C compiler to use (MECHSYS_CC, then CC, then cc/gcc/clang), or None when there is none or
    MECHSYS_NATIVE=off."""
    if os.environ.get("MECHSYS_NATIVE", "").lower() in _OFF:
        return None
    return _on_path(os.environ.get("MECHSYS_CC"), os.environ.get("CC"), "cc", "gcc", "clang")


def quick_compiler() -> Optional[str]:
    """The compiler of code built without optimisation (the straight-line programs of load_program): the Tiny C
    Compiler when there is one (MECHSYS_QUICK_CC, then tcc), else compiler(); MECHSYS_QUICK_CC=off takes
    compiler(). tcc translates the bicycle's constrained pieces (375 kB) in 0.015 s where gcc -O0 takes 0.8 s, and
    its code runs as fast and computes the same (unoptimised code, each operation in the source's order: bit for
    bit gcc -O0's results on the bicycle, tests/test_native.py). Not for the integrator or newton.c (-O2)."""
    cc = compiler()
    choice = os.environ.get("MECHSYS_QUICK_CC", "")
    if cc is None or choice.lower() in _OFF:
        return cc
    return _on_path(choice, "tcc") or cc


def _c_printer(names: dict, fast: bool = True):
    """A C99 printer of straight-line code; ``names`` maps symbols to C names. With ``fast``, sums, products,
    powers, numbers, symbols and the elementary functions are printed directly, in the order of the expression's
    own arguments, sums parenthesized: 30 times faster than sympy's printer, which orders the terms of every sum
    and weighs precedence (the bicycle's pieces: 0.07 s instead of 2.2 s). Any other node goes to sympy's C99
    printer, and an expression with a node C cannot express is refused as before (sympy's strict printer raises,
    or, not strict, sympy prints it all). The sums' order is not sympy's print order, so round-off may differ from
    the Python path's. Code users read (codegen's C target) keeps sympy's layout (not ``fast``)."""
    import sympy as sp
    from sympy.printing.c import C99CodePrinter

    from mechsys.numeric.lambdify import LeanDoprint

    functions = {sp.sin: "sin", sp.cos: "cos", sp.tan: "tan", sp.asin: "asin", sp.acos: "acos", sp.atan: "atan",
                 sp.sinh: "sinh", sp.cosh: "cosh", sp.tanh: "tanh", sp.exp: "exp", sp.log: "log", sp.Abs: "fabs"}
    exact = 2.0 ** 53

    class Printer(LeanDoprint, C99CodePrinter):
        def _print_Symbol(self, expr):
            return names.get(expr) or super()._print_Symbol(expr)

        _print_Dummy = _print_Symbol

        def _print_DiracDelta(self, expr):
            return "0.0"  # derivative of sign(x) in |x|: zero except at the singular point itself

        def _print_Mod(self, expr):
            a, b = (self._print(x) for x in expr.args)  # Python's floored modulo, as the Python path computes
            return f"(({a}) - ({b}) * floor(({a}) / ({b})))"

        def _print_Pow(self, expr):
            if expr.exp.is_Integer and 1 < abs(int(expr.exp)) <= 4:  # exact products, as Python's x**2 is
                base = f"({self._print(expr.base)})"
                prod = "*".join([base] * abs(int(expr.exp)))
                return f"(1.0/({prod}))" if expr.exp < 0 else f"({prod})"
            return super()._print_Pow(expr)

        def doprint(self, expr, assign_to=None):
            if assign_to is not None or not fast:
                return super().doprint(expr, assign_to)
            self._not_supported, self._number_symbols = set(), set()
            text = self._fast(sp.sympify(expr))
            if self._not_supported or self._number_symbols:
                return super().doprint(expr)  # as before: sympy's text with its comments
            return text

        def _fast(self, e) -> str:
            fast = self._fast
            if e.is_Symbol:
                name = names.get(e)
                return name if name is not None else self._print(e)
            if e.is_Add:
                return "(" + " + ".join(fast(a) for a in e.args) + ")"
            if e.is_Mul:
                num, den = [], []
                for a in e.args:
                    if a.is_Pow and a.exp.is_Integer and a.exp < 0:
                        den.append(fast(a.base) if a.exp == -1 else fast(a.base ** -a.exp))
                    elif a.is_Rational and not a.is_Integer and abs(a.p) < exact and a.q < exact:
                        num.append(f"{a.p}.0")
                        den.append(f"{a.q}.0")
                    else:
                        num.append(fast(a))
                top = "*".join(num) if num else "1.0"  # a product needs no parentheses: it is never a factor
                return f"{top}/({'*'.join(den)})" if den else top  # (products are flat), and a base is wrapped
            if e.is_Pow:
                text = c_power(f"({fast(e.base)})", e.exp)
                return text if text is not None else self._print(e)
            if e.is_Integer:
                return f"({int(e)}.0)" if abs(int(e)) < exact else self._print(e)
            if e.is_Rational:
                return f"({e.p}.0/{e.q}.0)" if abs(e.p) < exact and e.q < exact else self._print(e)
            if e.is_Float:
                value = float(e)
                return f"({value!r})" if np.isfinite(value) else self._print(e)
            name = functions.get(type(e))
            if name is not None:
                return f"{name}({fast(e.args[0])})"
            if type(e) is sp.atan2:
                return f"atan2({fast(e.args[0])}, {fast(e.args[1])})"
            return self._print(e)

    return Printer()


def c_power(base: str, x: sp.Expr) -> Optional[str]:
    """C text of ``base`` (a name or a parenthesized operand) to the sympy number ``x`` when x is an integer or
    a half: exact products up to the fourth power (as Python's x**2 is), sqrt for halves; None otherwise."""
    if x.is_Integer:
        n = int(x)
        if n == 1:
            return base
        if 1 < abs(n) <= 4:
            prod = "*".join([base] * abs(n))
            return f"(1.0/({prod}))" if n < 0 else f"({prod})"
        return f"(1.0/{base})" if n == -1 else f"pow({base}, {n}.0)"
    if x.is_Rational and x.q == 2 and abs(x.p) == 1:
        return f"sqrt({base})" if x.p > 0 else f"(1.0/sqrt({base}))"
    return None


#: how a function of the model's translation units is declared for the others: not exported from the library
_SHARED = "__attribute__((visibility(\"hidden\"))) void"


def pieces_source(blocks: Sequence[Sequence], t: sp.Symbol, q: Sequence, u: Sequence, params: Sequence,
                  name: str = "pieces", linkage: str = "static void") -> str:
    """C function ``name(t, q, u, p, out)`` writing the expressions of ``blocks`` one after the other into ``out``.
    Each block's shared subexpressions are computed once, from the same CSE as the block's Python code
    (lambdify.shared_cse: a first `simulate` does not eliminate them twice)."""
    from mechsys.numeric.lambdify import shared_cse

    args = {t: "t", **{s: f"q[{i}]" for i, s in enumerate(q)}, **{s: f"u[{i}]" for i, s in enumerate(u)},
            **{s: f"p[{i}]" for i, s in enumerate(params)}}
    shared, stores, constants, start = [], [], {}, 0
    for b, exprs in enumerate(blocks):
        replacements, reduced = shared_cse(exprs)
        names = {**args, **{sym: f"x{b}_{k}" for k, (sym, _) in enumerate(replacements)}}
        printer = _c_printer(names)
        shared += [f"    const double {names[sym]} = {printer.doprint(value)};" for sym, value in replacements]
        for i, e in enumerate(reduced):
            text = printer.doprint(e)
            value = _number(text)
            if value is None:
                stores.append(f"    out[{start + i}] = {text};")
            else:
                constants[start + i] = value
        start += len(reduced)
    tables, fill = _constant_outputs(name, constants, start)
    # every store after every argument's last read: a store through out, which gcc must assume may alias q, u, p,
    # would make it read the arguments again after it
    return "\n".join(tables + [f"{linkage} {name}(double t, const double *q, const double *u, const double *p, "
                                "double *out) {", "    (void)t; (void)q; (void)u; (void)p;"]
                      + shared + fill + stores + ["}"])


def _number(text: str) -> Optional[float]:
    """The value of an output printed as a plain number, such as (0.0) or (-1.0); None for anything else."""
    literal = text[1:-1] if text.startswith("(") and text.endswith(")") else text
    try:
        return float(literal) if literal.lstrip("-").replace(".", "", 1).isdigit() else None
    except ValueError:
        return None


def _constant_outputs(name: str, constants: dict[int, float], size: int) -> tuple[list[str], list[str]]:
    """Static tables and the statements that write the outputs that are numbers (index -> value) before the
    others: zeros by one memset, the rest by a loop over a table. Not one store each: gcc -O2 walks the aliasing
    of every store against the others (the 40-link chain's 10,400 outputs, 8,520 of them numbers: 8.3 s to compile
    instead of 1.6 s). The same values: a +0.0's bytes are zeros, and the table holds each literal's double."""
    if not constants:
        return [], []
    body = [f"    memset(out, 0, {size} * sizeof(double));"] if any(v == 0 for v in constants.values()) else []
    others = [(i, v) for i, v in constants.items() if v != 0 or math.copysign(1.0, v) < 0]
    head = []
    if others:
        head = [f"static const int {name}_index[{len(others)}] = {{{', '.join(str(i) for i, _ in others)}}};",
                f"static const double {name}_value[{len(others)}] = {{{', '.join(repr(v) for _, v in others)}}};"]
        body.append(f"    for (int k = 0; k < {len(others)}; k++) out[{name}_index[k]] = {name}_value[k];")
    return head, body


def _table(name: str, values: np.ndarray) -> str:
    values = np.atleast_2d(values) if values.ndim == 2 else values
    if values.ndim == 1:
        body = ", ".join(repr(float(v)) for v in values)
        return f"static const double {name}[{len(values)}] = {{{body}}};"
    rows = ", ".join("{" + ", ".join(repr(float(v)) for v in row) + "}" for row in values)
    return f"static const double {name}[{values.shape[0]}][{values.shape[1]}] = {{{rows}}};"


def _dop853_coefficients():
    """scipy's DOP853 tables (Hairer's), read from their module file: importing them through the package would
    import all of scipy.integrate (~0.5 s of a cold run) for a few arrays."""
    import importlib.util

    spec = importlib.util.find_spec("scipy")
    if spec and spec.origin:
        path = Path(spec.origin).parent / "integrate" / "_ivp" / "dop853_coefficients.py"
        if path.exists():
            namespace: dict = {}
            exec(compile(path.read_text(encoding="utf-8"), str(path), "exec"), namespace)  # noqa: S102
            return type("Tables", (), namespace)
    from scipy.integrate._ivp import dop853_coefficients

    return dop853_coefficients


def model_source(model: MechanicalModel) -> str:
    """The complete C translation unit for one model structure."""
    return "\n".join(model_sources(model, split=False))


def model_sources(model: MechanicalModel, split: bool = True) -> list[str]:
    """The C translation units of one model structure: the staged equations, the constraint rows and the
    integrator template, which the compiler then builds at once, one process each (on two cores the bicycle's
    -O2 build takes 0.35 s instead of 0.76 s; the rows alone take 0.32 s); or (``split`` False) one unit."""
    from mechsys.numeric.kane import model_pieces

    co = _dop853_coefficients()
    pieces, layout = model_pieces(model)
    n = len(model.q)
    m = len(model.kin.constraints)
    rows = [list(model.constraint_jacobian), list(model.constraint_rhs)] if m else [[0]]  # A (m x n, row-major), b
    head = ["#include <math.h>", "#include <string.h>", "#ifndef M_PI", "#define M_PI 3.14159265358979323846",
            "#endif"]
    sizes = [f"#define N {n}", f"#define NPAR {len(model.parameter_symbols)}", f"#define NOUT {max(len(pieces), 1)}",
             f"#define NB {max(len(layout), 1)}",
             "static const int LAYOUT[2 * NB] = {" + (", ".join(str(int(x)) for b in layout for x in b) or "0, 0")
             + "};",
             _table("A", co.A), _table("B", co.B), _table("C", co.C), _table("E3", co.E3), _table("E5", co.E5),
             _table("D", co.D),
             f"#define NCON {m}"]
    linkage = _SHARED if split else "static void"
    functions = [pieces_source([pieces], model.t, model.q, model.u, model.parameter_symbols, linkage=linkage),
                 pieces_source(rows, model.t, model.q, model.u, model.parameter_symbols, "constraint_rows", linkage)]
    template = TEMPLATE.read_text(encoding="utf-8")
    if not split:
        return head + sizes + functions + [template]
    declared = [f"{_SHARED} {name}(double t, const double *q, const double *u, const double *p, double *out);"
                for name in ("pieces", "constraint_rows")]
    return ["\n".join(head + [f]) + "\n" for f in functions] + ["\n".join(head + sizes + declared) + "\n" + template]


def build(source: str | Sequence[str], target: Path, opt: str | None = None, cc: str | None = None) -> None:
    """Compile ``source`` (one translation unit, or several) into the shared library ``target`` (atomically: a
    partial file never appears) at the optimisation level ``opt`` (by default -O2, -O1 for very long sources) with
    ``cc`` (by default compiler())."""
    PendingBuild(source, target, opt, cc).finish()


class PendingBuild:
    """The C compiler running on ``source`` in processes of its own (started here): one translation unit is
    compiled and linked by one process; several (on a machine with more than one core) are compiled at once, one
    process each, and linked by ``finish()``. ``finish()`` waits for them and moves the library to ``target``
    (AnalysisError when one failed). Meanwhile the caller's Python work runs: a first `simulate` generates its
    Python code while its integrator compiles."""

    def __init__(self, source: str | Sequence[str], target: Path, opt: str | None = None,
                 cc: str | None = None) -> None:
        cc = cc or compiler()
        if cc is None:
            raise AnalysisError("no C compiler found for the native integrator (set CC or use --method DOP853)")
        from mechsys.numeric.parallel import cores  # (not at import: a warm run loads libraries, builds none)

        units = [source] if isinstance(source, str) else list(source)
        if len(units) > 1 and cores() < 2:
            units = ["\n".join(units)]  # one core: one process (the units declare what they share the same way)
        self.target = target
        self._cc = cc
        self._tmp = tempfile.TemporaryDirectory(dir=target.parent)
        self._so = Path(self._tmp.name) / "model.so"
        opt = opt or ("-O2" if sum(len(u) for u in units) < 2_000_000 else "-O1")
        self._objects: list[Path] = []
        self._procs = []
        for k, unit in enumerate(units):
            c_file = Path(self._tmp.name) / f"model{k}.c"
            c_file.write_text(unit, encoding="utf-8")
            if len(units) == 1:
                out, what = self._so, ["-shared", "-o", str(self._so), str(c_file), "-lm"]
            else:
                out = c_file.with_suffix(".o")
                what = ["-c", "-o", str(out), str(c_file)]
                self._objects.append(out)
            self._procs.append(self._start([cc, opt, "-std=gnu99", "-fPIC", *what]))

    def _start(self, command: list[str]) -> subprocess.Popen:
        # A session of its own, so that cancel() stops the compiler's own processes too (cc1, as: killing the
        # driver alone leaves them running), and TMPDIR in the folder cleaned up (their files go with it).
        env = {**os.environ, "TMPDIR": self._tmp.name}
        return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env,
                                start_new_session=_POSIX)

    def finish(self) -> Path:
        try:
            for proc in self._procs:
                _check(proc, *proc.communicate())
            if self._objects:
                link = self._start([self._cc, "-shared", "-o", str(self._so), *map(str, self._objects), "-lm"])
                self._procs.append(link)
                _check(link, *link.communicate())
            os.replace(self._so, self.target)
        finally:
            self.cancel()
        return self.target

    def cancel(self) -> None:
        """Stop the compilers (each exits without its result) and remove the temporary files."""
        for proc in self._procs:
            if proc.poll() is None:
                if _POSIX:
                    try:
                        os.killpg(proc.pid, signal.SIGKILL)
                    except ProcessLookupError:
                        pass
                proc.kill()
            proc.wait()
            proc.stderr.close()
        self._tmp.cleanup()


_POSIX = os.name == "posix"


def _check(proc: subprocess.Popen, _out, err: str) -> None:
    if proc.returncode != 0:
        first = (err.strip().splitlines() or ["unknown error"])[0]
        raise AnalysisError(f"compiling the native integrator failed: {first}")


@dataclass
class NativeRun:
    y: np.ndarray  # (len(t_out), 2n)
    nfev: int
    nsteps: int
    nrejected: int
    status: int
    t_reached: float
    h_next: float = 0.0  # the step size the loop would take next (to continue after a projection)

    @property
    def message(self) -> str:
        return _STATUS.get(self.status, f"status {self.status}")


class NativeIntegrator:
    """A loaded model library: ``run(p, y0, t_out, rtol, atol)`` integrates with the compiled DOP853 loop."""

    def __init__(self, path: Path) -> None:
        lib = ctypes.CDLL(str(path))
        self._lib = lib
        self.path = Path(path)
        dp = ctypes.POINTER(ctypes.c_double)
        lib.mechsys_state_bytes.restype = ctypes.c_int
        lib.mechsys_size.restype = ctypes.c_int
        lib.mechsys_parameters.restype = ctypes.c_int
        lib.mechsys_start.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, dp, dp, ctypes.c_double,
                                      ctypes.c_double, ctypes.c_double, ctypes.c_double]
        lib.mechsys_advance.argtypes = [ctypes.c_void_p, dp, ctypes.c_int, dp, dp, ctypes.POINTER(ctypes.c_int)]
        lib.mechsys_counters.argtypes = [ctypes.c_void_p, dp]
        lib.mechsys_accelerations.argtypes = [ctypes.c_double, dp, dp, dp]
        self.n = lib.mechsys_size()
        self.n_parameters = lib.mechsys_parameters()
        self.from_cache = False
        self.key: Optional[str] = None  # the cache key when the library is kept in the cache
        self._state_bytes = lib.mechsys_state_bytes()

    @staticmethod
    def _ptr(a: np.ndarray):
        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    def check_sizes(self, p: np.ndarray, y: np.ndarray) -> None:
        """The C code reads p and y by position without bounds: refuse arrays of another length."""
        if p.shape != (self.n_parameters,) or y.shape != (2 * self.n,):
            raise AnalysisError(f"native integrator: {len(p)} parameters and {len(y)} states given, "
                                f"the library takes {self.n_parameters} and {2 * self.n}")

    def accelerations(self, t: float, y: np.ndarray, p: np.ndarray) -> np.ndarray:
        y = np.ascontiguousarray(y, dtype=float)
        p = np.ascontiguousarray(p, dtype=float)
        self.check_sizes(p, y)
        a = np.zeros(self.n)
        status = self._lib.mechsys_accelerations(float(t), self._ptr(y), self._ptr(p), self._ptr(a))
        if status:
            raise AnalysisError(f"native equations at t = {t:g}: {_STATUS.get(status, status)}")
        return a

    def run(self, p: np.ndarray, y0: np.ndarray, t_out: np.ndarray, rtol: float, atol: float,
            progress: Optional[Callable[[float], None]] = None, chunk: int = 50,
            max_steps: float = 1e6, h0: float = 0.0) -> NativeRun:
        """Integrate from t_out[0] to t_out[-1]; outputs at every t_out. ``progress(t)`` is called every ``chunk``
        outputs (the loop itself never returns to Python between steps). At most ``max_steps`` steps (accepted
        and rejected) are taken. ``h0`` > 0 starts with that step size instead of selecting one."""
        p = np.ascontiguousarray(p, dtype=float)
        y0 = np.ascontiguousarray(y0, dtype=float)
        t_out = np.ascontiguousarray(t_out, dtype=float)
        self.check_sizes(p, y0)
        state = ctypes.create_string_buffer(self._state_bytes)
        Y = np.zeros((len(t_out), 2 * self.n))
        status = self._lib.mechsys_start(state, float(t_out[0]), float(t_out[-1]), self._ptr(y0), self._ptr(p),
                                         float(rtol), float(atol), float(max_steps), float(h0))
        written = 0
        done = ctypes.c_int(0)
        while status == 0 and written < len(t_out):
            count = min(chunk if progress else len(t_out), len(t_out) - written)
            status = self._lib.mechsys_advance(state, self._ptr(p), count, self._ptr(t_out[written:]),
                                               self._ptr(Y[written:]), ctypes.byref(done))
            written += done.value
            if progress is not None:
                progress(float(t_out[written - 1]) if written else float(t_out[0]))
        counters = np.zeros(5)
        self._lib.mechsys_counters(state, self._ptr(counters))
        return NativeRun(Y[:written], int(counters[0]), int(counters[1]), int(counters[2]), int(status),
                         float(counters[3]), float(counters[4]))


def start(model: MechanicalModel) -> None:
    """Start compiling the model's native integrator (when a compiler is there and the library is not cached), so
    that the compiler runs while the caller generates its Python code; load() takes the result."""
    from mechsys.numeric import cache

    if compiler() is None or getattr(model, "_native_integrator", False) is not False \
            or getattr(model, "_native_pending", None) is not None:
        return
    key = _native_key(model)
    path = cache.library(key)
    if path is not None:  # built before: taken now (load() then computes no key again)
        model._native_integrator = NativeIntegrator(path)
        model._native_integrator.from_cache, model._native_integrator.key = True, key
        return
    tmp = tempfile.TemporaryDirectory(prefix="mechsys-native-")
    pending = PendingBuild(model_sources(model), Path(tmp.name) / f"{key}.so")
    model._native_pending = (key, tmp, pending)
    if not _UNFINISHED:
        atexit.register(_abandon)
    _UNFINISHED[id(pending)] = (tmp, pending)


#: builds start() began that load() has not finished, by id: stopped at exit (no compiler left behind, no files)
_UNFINISHED: dict[int, tuple] = {}


def _abandon() -> None:
    for tmp, pending in list(_UNFINISHED.values()):
        pending.cancel()
        tmp.cleanup()
    _UNFINISHED.clear()


def abandon(model: MechanicalModel) -> None:
    """Stop the build start() began for this model and remove its files, if load() has not taken it: a run that
    fails before integrating (a start the constraints cannot assemble, at a gimbal lock) leaves none behind, in
    this process either (tests run many commands in one)."""
    held = model.__dict__.pop("_native_pending", None)
    if held is not None:
        _key, tmp, pending = held
        _UNFINISHED.pop(id(pending), None)
        pending.cancel()
        tmp.cleanup()


def _native_key(model) -> str:
    from mechsys.numeric import cache

    # the library is machine code: the key names the platform as well as the model structure
    return cache.model_key(model, f"native-{sys.platform}-{platform.machine()}")


def load(model: MechanicalModel) -> Optional[NativeIntegrator]:
    """The model's native integrator, from the cache (only when its signature verifies), from start()'s build, or
    compiled now; None when no compiler is available. Without a usable cache the library is built in a temporary
    folder that is removed once it is loaded. With constraints the accelerations solve
    [[M, A^T], [A, 0]] [q''; -lambda] = [f; b]; the caller projects."""
    from mechsys.numeric import cache

    cached = getattr(model, "_native_integrator", False)
    if cached is not False:
        return cached
    result = None
    if compiler() is not None:
        held = model.__dict__.pop("_native_pending", None)
        key = _native_key(model) if held is None else held[0]
        path = cache.library(key) if held is None else None
        if path is not None:
            result = NativeIntegrator(path)
            result.from_cache = True
        else:
            tmp, pending = held[1:] if held is not None else (
                tempfile.TemporaryDirectory(prefix="mechsys-native-"), None)
            with tmp:
                built = Path(tmp.name) / f"{key}.so"
                if pending is None:
                    build(model_sources(model), built)
                else:
                    _UNFINISHED.pop(id(pending), None)
                    pending.finish()
                path = cache.store_library(key, built)
                result = NativeIntegrator(path or built)  # loaded before the temporary folder goes
        result.key = key if path is not None else None
    model._native_integrator = result
    return result


# ----------------------------------------------------------------------------------------- straight-line programs
def program_source(program: ForwardProgram, functions: dict[str, tuple[int, bool]]) -> Optional[str]:
    """C translation unit of a ForwardProgram (numeric/lambdify.py): for each ``name: (count, with_jacobian)`` of
    ``functions`` a function ``name(const double *a, double *out)`` writing the first ``count`` outputs (and then
    the Jacobian rows); every function computes all shared subexpressions (at -O0 none is dropped; the bicycle's
    residual alone still takes 20 us). None when an expression has no C form (the caller keeps the Python code)."""
    import sympy as sp

    names = {a: f"a[{i}]" for i, a in enumerate(program.args)}
    names.update({sym: name for name, sym in program.symbols.items()})
    printer = _c_printer(names)
    values = [f"    const double {name} = {printer.doprint(e)};" for name, e in program.values]
    derivatives = [f"    const double {name} = {printer.doprint(e)};" for name, e in program.derivatives]
    outputs = [printer.doprint(sp.sympify(e)) for e in program.outputs]
    jacobian = [printer.doprint(e) if e != 0 else "0.0" for e in program.jacobian]
    if getattr(printer, "_not_supported", None):
        return None
    parts = ["#include <math.h>", "#ifndef M_PI", "#define M_PI 3.14159265358979323846", "#endif"]
    for name, (count, with_jacobian) in functions.items():
        body = values + (derivatives if with_jacobian else [])
        results = outputs[:count] + (jacobian if with_jacobian else [])
        parts.append(f"void {name}(const double *a, double *out) {{")
        parts += body + [f"    out[{i}] = {e};" for i, e in enumerate(results)] + ["}"]
    return "\n".join(parts) + "\n"


class Program:
    """Compiled straight-line functions of one argument vector (program_source), called through ctypes."""

    def __init__(self, path: Path, functions: dict[str, int], n_args: int) -> None:
        self._lib = ctypes.CDLL(str(path))
        self.n_args = n_args
        self._functions = {}
        for name, size in functions.items():
            fn = getattr(self._lib, name)
            fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p]  # raw addresses: data_as() costs more than the call
            fn.restype = None
            self._functions[name] = (fn, size)

    def address(self, name: str) -> int:
        """The machine address of function ``name`` (for compiled code that calls it: newton.c)."""
        return ctypes.cast(self._functions[name][0], ctypes.c_void_p).value

    def __call__(self, name: str, args: np.ndarray) -> np.ndarray:
        fn, size = self._functions[name]
        a = np.ascontiguousarray(args, dtype=float)
        if a.shape != (self.n_args,):  # the C code reads by position without bounds
            raise AnalysisError(f"compiled function {name}: {a.size} arguments given, it takes {self.n_args}")
        out = np.empty(size)
        fn(a.ctypes.data, out.ctypes.data)  # a and out stay referenced for the call's duration
        return out


def load_program(key: str, source: Optional[str], functions: dict[str, int], n_args: int) -> Optional[Program]:
    """The compiled program ``key`` from the cache (signature verified) or built from ``source`` now by the quick
    compiler (compiler() when that fails); None without a compiler, without source, or when compiling fails (the
    caller keeps its Python code)."""
    from mechsys.numeric import cache

    quick = quick_compiler()
    if quick is None or source is None:
        return None
    import hashlib

    # machine code: the key names the platform, the compiler, and the source itself (so it always matches the
    # Python code)
    digest = hashlib.sha256(source.encode()).hexdigest()[:16]
    key = f"{key}-{sys.platform}-{platform.machine()}-{Path(quick).name}-{digest}"
    path = cache.library(key)
    if path is not None:
        return Program(path, functions, n_args)
    with tempfile.TemporaryDirectory(prefix="mechsys-program-") as tmp:
        built = Path(tmp) / f"{key}.so"
        # straight-line code: -O0 compiles the bicycle's pieces in a second (tcc: 0.015 s), -O2 in half a minute,
        # and runs them as fast (the time goes to the call and the memory traffic)
        for cc in dict.fromkeys((quick, compiler())):
            try:
                build(source, built, "-O0", cc)
                path = cache.store_library(key, built)
                return Program(path or built, functions, n_args)  # loaded before the temporary folder goes
            except (AnalysisError, OSError):
                continue
    return None


# ----------------------------------------------------------------------------------------- the compiled Newton
NEWTON = Path(__file__).with_name("newton.c")
_LONG = np.dtype(ctypes.c_long)
_newton_lib: dict[str, Optional[ctypes.CDLL]] = {}
_NEWTON_LOCK = threading.Lock()


def _fresh_lock_after_fork() -> None:
    """A process forked while prepare_newton's thread held the lock would wait for that thread forever (it does
    not exist there): the child takes a lock of its own (and loads or builds the library itself)."""
    global _NEWTON_LOCK
    _NEWTON_LOCK = threading.Lock()


os.register_at_fork(after_in_child=_fresh_lock_after_fork)


def prepare_newton() -> None:
    """Start building newton.c's library in a thread, when it is not built yet: its compiler then runs beside the
    model's own (two processes; a first steady-motion command saves the second). newton_library waits for it."""
    cc = compiler()
    if cc is None or cc in _newton_lib or _NEWTON_LOCK.locked():
        return
    threading.Thread(target=newton_library, name="mechsys-newton-build").start()  # not a daemon: exit waits


def newton_library() -> Optional[ctypes.CDLL]:
    """newton.c's deflated Newton, built once per machine and source (-O2) and kept in the cache like the models'
    libraries; None without a C compiler or when it does not build (the caller keeps its Python loop)."""
    cc = compiler()
    if cc is None:
        return None
    with _NEWTON_LOCK:  # one build, however many threads ask (prepare_newton's and the caller's)
        if cc not in _newton_lib:
            _newton_lib[cc] = _load_newton()
    return _newton_lib[cc]


def _load_newton() -> Optional[ctypes.CDLL]:
    """newton.c's library from the cache, or built now and stored; its functions' signatures declared."""
    import hashlib

    from mechsys.numeric import cache

    source = NEWTON.read_text(encoding="utf-8")
    digest = hashlib.sha256(source.encode()).hexdigest()[:16]
    key = f"newton-{sys.platform}-{platform.machine()}-{digest}"
    path = cache.library(key)
    lib = None
    try:
        if path is None:
            with tempfile.TemporaryDirectory(prefix="mechsys-newton-") as tmp:
                built = Path(tmp) / f"{key}.so"
                build(source, built)
                path = cache.store_library(key, built)
                lib = ctypes.CDLL(str(path or built))  # loaded before the temporary folder goes
        else:
            lib = ctypes.CDLL(str(path))
    except (AnalysisError, OSError):
        lib = None
    if lib is not None:
        fn = lib.mechsys_deflated_newton
        fn.argtypes = ([ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p]
                       + [ctypes.c_int] * 4 + [ctypes.c_void_p] * 3 + [ctypes.c_int, ctypes.c_void_p, ctypes.c_int]
                       + [ctypes.c_void_p] * 2)
        fn.restype = ctypes.c_int
        lib.mechsys_newton_work.argtypes = [ctypes.c_int] * 5
        lib.mechsys_newton_work.restype = ctypes.c_int
        fn = lib.mechsys_corrector
        fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int, ctypes.c_int,
                       ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        fn.restype = ctypes.c_int
        lib.mechsys_corrector_work.argtypes = [ctypes.c_int] * 5
        lib.mechsys_corrector_work.restype = ctypes.c_int
        fn = lib.mechsys_linearize
        fn.argtypes = [ctypes.c_void_p] * 10
        fn.restype = ctypes.c_int
        lib.mechsys_linearize_work.argtypes = [ctypes.c_int] * 5
        lib.mechsys_linearize_work.restype = ctypes.c_int
    return lib


class CompiledNewton:
    """newton.c's loop over a Program's ``values`` and ``full`` functions for unknowns z placed in the argument
    vector by position (args = base, args[pos] = z); the Jacobian is gathered from ``full``'s output followed by a
    zero (index, sign: size x nz)."""

    def __init__(self, lib: ctypes.CDLL, program: Program, values: str, full: str, base: np.ndarray,
                 pos: np.ndarray, index: np.ndarray, sign: np.ndarray, is_angle: np.ndarray) -> None:
        self._fn = lib.mechsys_deflated_newton
        self._values, self._full = program.address(values), program.address(full)
        self._out_size = program._functions[values][1]
        self._full_size = program._functions[full][1]
        self.base = np.ascontiguousarray(base, dtype=float)
        if self.base.shape != (program.n_args,):
            raise AnalysisError(f"compiled Newton: {self.base.size} arguments given, the program takes "
                                f"{program.n_args}")
        self.pos = np.ascontiguousarray(pos, dtype=_LONG)
        self.size, self.nz = index.shape
        if not (self.pos.shape == (self.nz,) and np.all((self.pos >= 0) & (self.pos < program.n_args))
                and np.all((index >= 0) & (index <= self._full_size)) and self._out_size >= self.size):
            raise AnalysisError("compiled Newton: positions or Jacobian indices out of range")
        self.index = np.ascontiguousarray(index, dtype=_LONG)
        self.sign = np.ascontiguousarray(sign, dtype=float)
        self.is_angle = np.ascontiguousarray(is_angle, dtype=np.uint8)
        self.work = np.empty(lib.mechsys_newton_work(self.size, self.nz, program.n_args, self._full_size,
                                                     self._out_size))
        self._program = program  # keeps the library loaded while the addresses are used

    def __call__(self, z: np.ndarray, known: np.ndarray, max_iter: int) -> Optional[np.ndarray]:
        """The iterate where the loop ended (converged or max_iter: to be polished), or None when it failed."""
        z = np.array(z, dtype=float).reshape(self.nz)
        known = np.ascontiguousarray(known, dtype=float).reshape(-1, self.nz)
        ok = self._fn(self._values, self._full, self.base.size, self.base.ctypes.data, self.pos.ctypes.data,
                      self.nz, self.size, self._full_size, self._out_size, self.index.ctypes.data,
                      self.sign.ctypes.data, known.ctypes.data, known.shape[0], self.is_angle.ctypes.data,
                      int(max_iter), z.ctypes.data, self.work.ctypes.data)
        return z if ok else None


class _CorrectorSetup(ctypes.Structure):
    """newton.c's corrector_t, field by field."""
    _fields_ = ([("values", ctypes.c_void_p), ("full", ctypes.c_void_p)]
                + [(name, ctypes.c_int) for name in ("nargs", "nz", "size", "full_size", "out_size", "n",
                                                     "jac_offset", "pfirst", "fp_params")]
                + [("p_ref", ctypes.c_double), ("tol", ctypes.c_double)]
                + [(name, ctypes.c_void_p) for name in ("base", "slope", "pos", "D", "s", "r", "rows", "jindex",
                                                        "jsign")])


class CompiledCorrector:
    """newton.c's continuation corrector (mechsys_corrector) over a Program's ``values`` and ``full``: the sweep's
    unknowns x = z_problem / D enter the arguments at ``pos`` scaled by D and the tracer's s; the arguments follow
    the swept p affinely (args = base + (p - p_ref) slope); F is the rows ``rows`` of the first outputs; dE/dz is
    gathered from ``full``'s output followed by a zero (index, sign: size x nz), dE/d(q, u) is the size x 2n block
    of ``full``'s output at ``jac_offset``; ``fp_params``: E reads a parameter (from ``pfirst`` on) that follows p.
    Called as _Tracer.newton: (z, iterations, the Jacobian [dF/dx s | dF/dp] at z) or None."""

    def __init__(self, lib: ctypes.CDLL, program: Program, values: str, full: str, *, base: np.ndarray,
                 slope: np.ndarray, p_ref: float, pos: np.ndarray, D: np.ndarray, s: np.ndarray, r: np.ndarray,
                 rows: np.ndarray, index: np.ndarray, sign: np.ndarray, n: int, jac_offset: int, pfirst: int,
                 fp_params: bool, tol: float) -> None:
        self._fn = lib.mechsys_corrector
        out_size, full_size = program._functions[values][1], program._functions[full][1]
        size, nz = index.shape
        arrays = {"base": base, "slope": slope, "D": D, "s": s, "r": r, "jsign": sign}
        self._keep = {k: np.ascontiguousarray(v, dtype=float) for k, v in arrays.items()}
        self._keep.update(pos=np.ascontiguousarray(pos, dtype=_LONG), rows=np.ascontiguousarray(rows, dtype=_LONG),
                          jindex=np.ascontiguousarray(index, dtype=_LONG))
        k = self._keep
        nargs = program.n_args
        shapes_ok = (k["base"].shape == k["slope"].shape == (nargs,) and k["pos"].shape == k["D"].shape
                     == k["s"].shape == k["rows"].shape == (nz,) and k["r"].shape == (nz + 1,))
        if not (shapes_ok and np.all((k["pos"] >= 0) & (k["pos"] < nargs)) and np.all((k["rows"] >= 0)
                & (k["rows"] < size)) and np.all((k["jindex"] >= 0) & (k["jindex"] <= full_size))
                and size <= out_size and 0 <= pfirst <= nargs and 2 * n <= nargs
                and jac_offset + size * 2 * n <= full_size):
            raise AnalysisError("compiled corrector: arguments, positions or indices out of range")
        self.nz = nz
        self._setup = _CorrectorSetup(program.address(values), program.address(full), nargs, nz, size, full_size,
                                      out_size, n, jac_offset, pfirst, int(bool(fp_params)), float(p_ref),
                                      float(tol), *(k[name].ctypes.data for name in
                                                    ("base", "slope", "pos", "D", "s", "r", "rows", "jindex",
                                                     "jsign")))
        self._work = np.empty(lib.mechsys_corrector_work(nz, nargs, full_size, out_size, size))
        self._iters = ctypes.c_int(0)
        self._program = program  # keeps the library loaded while the addresses are used

    def __call__(self, z_guess: np.ndarray, border: np.ndarray, max_iter: int,
                 monotone: bool) -> Optional[tuple[np.ndarray, int, np.ndarray]]:
        z = np.array(z_guess, dtype=float).reshape(self.nz + 1)
        border = np.ascontiguousarray(border, dtype=float).reshape(self.nz + 1)
        jac = np.empty((self.nz, self.nz + 1))
        ok = self._fn(ctypes.addressof(self._setup), z.ctypes.data, border.ctypes.data, int(max_iter),
                      int(bool(monotone)), jac.ctypes.data, ctypes.addressof(self._iters), self._work.ctypes.data)
        return (z, self._iters.value, jac) if ok else None


class _LinearizationSetup(ctypes.Structure):
    """newton.c's lin_t, field by field."""
    _fields_ = ([(name, ctypes.c_int) for name in ("n", "m", "mh", "size", "jac", "nI", "nkeep", "nxi", "nign", "nz",
                                                   "nfam", "nt", "hfirst")]
                + [("rtol", ctypes.c_double)]
                + [(name, ctypes.c_void_p) for name in ("I", "D", "keep", "elim", "rows_q", "cols_all", "cols_ign",
                                                        "jindex", "jsign", "rhs", "tsrc", "tone", "rinv",
                                                        "zsize")])


class CompiledLinearization:
    """newton.c's linearization about a steady motion (mechsys_linearize: analysis/equilibrium/nonholonomic.py's
    linearize_steady and _deflate, the same steps) from a point's evaluated pieces. ``sizes``: n, m, mh, size,
    jac (where dE/d(q, u) starts in the output), hfirst (the holonomic rows' first row); ``lists``: the index lists
    I, D, keep, elim, rows_q, cols_all, cols_ign; ``index``, ``sign``: dE/dz gathered from the output (size x nz);
    ``rhs``: the families' columns (nfam x size, indices into the output); ``tsrc`` (nt: how a family's direction
    is read from its dz, the same for all) and ``tone`` (nfam: its entry set to 1); ``scales``: (rows, sizes) of
    equation_scales, in which a family's direction is solved (None: ones). Called with the output followed by a
    zero: (status, Jw, Mr, Kf, Cf, deflated, which families were deflated); status 0 ok, else newton.c's code and
    the arrays None."""

    _LISTS = ("I", "D", "keep", "elim", "rows_q", "cols_all", "cols_ign")

    def __init__(self, lib: ctypes.CDLL, *, sizes: dict, lists: dict, index: np.ndarray, sign: np.ndarray,
                 rhs: np.ndarray, tsrc: np.ndarray, tone: np.ndarray, rtol: float, full_size: int,
                 scales: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        self._fn = lib.mechsys_linearize
        n, m, size = sizes["n"], sizes["m"], sizes["size"]
        k = {name: np.ascontiguousarray(lists[name], dtype=np.intc) for name in self._LISTS}
        k.update(jindex=np.ascontiguousarray(index, dtype=_LONG), jsign=np.ascontiguousarray(sign, dtype=float),
                 rhs=np.ascontiguousarray(rhs, dtype=_LONG).reshape(-1, size),
                 tsrc=np.ascontiguousarray(tsrc, dtype=np.intc), tone=np.ascontiguousarray(tone, dtype=np.intc))
        nz = k["jindex"].shape[1] if k["jindex"].ndim == 2 else 0
        rows, zsize = scales if scales is not None else (np.ones(1), np.ones(1))
        k.update(rinv=np.ascontiguousarray(np.broadcast_to(1.0 / np.asarray(rows, dtype=float), (size,))),
                 zsize=np.ascontiguousarray(np.broadcast_to(np.asarray(zsize, dtype=float), (max(nz, 1),))))
        nfam, nxi, nI = len(k["tone"]), len(k["rows_q"]), len(k["I"])
        nt = nxi + nI
        ok = (k["jindex"].shape == (size, nz) and k["rhs"].shape == (nfam, size) and k["tsrc"].shape == (nt,)
              and len(k["D"]) == m and len(k["elim"]) == sizes["mh"] and len(k["cols_all"]) == nxi
              and all(np.all((k[name] >= 0) & (k[name] < n)) for name in ("I", "D", "keep", "elim", "rows_q"))
              and all(np.all((k[name] >= 0) & (k[name] < len(k["keep"]))) for name in ("cols_all", "cols_ign"))
              and np.all((k["jindex"] >= 0) & (k["jindex"] <= full_size))
              and np.all((k["rhs"] >= 0) & (k["rhs"] <= full_size))
              and np.all((k["tsrc"] >= -1) & (k["tsrc"] < nz)) and np.all((k["tone"] >= -1) & (k["tone"] < nt))
              and sizes["jac"] + size * 2 * n <= full_size and sizes["hfirst"] + sizes["mh"] <= size)
        if not ok:
            raise AnalysisError("compiled linearization: index lists out of range")
        self._keep = k
        self.nt, self.nxi, self.nI, self.nfam = nt, nxi, nI, nfam
        self._full_size = full_size
        self._setup = _LinearizationSetup(n, m, sizes["mh"], size, sizes["jac"], nI, len(k["keep"]), nxi,
                                          len(k["cols_ign"]), nz, nfam, nt, sizes["hfirst"], float(rtol),
                                          *(k[name].ctypes.data for name in (*self._LISTS, "jindex", "jsign", "rhs",
                                                                             "tsrc", "tone", "rinv", "zsize")))
        self._work = np.empty(lib.mechsys_linearize_work(n, m, size, nz, nt))
        self._k = ctypes.c_int(0)

    def __call__(self, raw: np.ndarray):
        raw = np.ascontiguousarray(raw, dtype=float)
        if raw.shape != (self._full_size + 1,):
            raise AnalysisError(f"compiled linearization: {raw.size} numbers given, it reads {self._full_size + 1}")
        nt, nxi, nI = self.nt, self.nxi, self.nI
        Jw, Mr, Kf, Cf = np.empty((nt, nt)), np.empty((nI, nI)), np.empty((nI, nxi)), np.empty((nI, nI))
        deflated = np.empty(nt * nt)
        flags = np.zeros(max(self.nfam, 1), dtype=np.intc)
        status = self._fn(ctypes.addressof(self._setup), raw.ctypes.data, Jw.ctypes.data, Mr.ctypes.data,
                          Kf.ctypes.data, Cf.ctypes.data, deflated.ctypes.data, flags.ctypes.data,
                          ctypes.addressof(self._k), self._work.ctypes.data)
        if status:
            return status, None, None, None, None, None, None
        nd = nt - self._k.value
        return 0, Jw, Mr, Kf, Cf, deflated[:nd * nd].reshape(nd, nd), flags[:self.nfam].astype(bool)
