#!/usr/bin/env python
"""Benchmark: which compiled backend for `simulate` — generated Python, numba, or generated C (the native path).

The same staged Kane terms (mechsys/numeric/kane.py) are evaluated three ways on one scene, each driving DOP853
at rtol 1e-10 (atol 1e-12) to the same final state:

* python  — the generated Python source (math) + numpy assembly, called by scipy's solve_ivp (`--method DOP853`);
* numba   — the same generated source compiled with numba.njit, assembly and solve in an njit function, called
            by scipy's solve_ivp: what a numba backend gives without rewriting the integrator in numba;
* native  — mechsys's C translation of the same terms with the DOP853 loop itself compiled (`--method native`).

Reported per backend: the integration time (best of --repeat, in-process, after warm-up), and the one-time costs
every new process pays: importing the backend, compiling (numba's JIT; the C compiler, once per model thanks to
the disk cache) and loading a cached artefact. Final states must agree to 1e-8 or the script exits with status 1.
numba is optional (`pip install numba`, in the `bench` extra that `make bench` installs); without it that row is
skipped. Times are reported, never asserted.

    python benchmarks/backends.py                 # double pendulum, 10 s
    python benchmarks/backends.py --chain 10      # a 10-link chain instead
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))
from derive_chain import chain_yaml  # noqa: E402


def best(fn, repeat: int) -> tuple[float, object]:
    out, times = None, []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def numba_rhs(model, p: np.ndarray):
    """The generated pieces source under numba.njit, the assembly of kane.CompiledEquations.evaluate in njit.
    Returns (rhs(t, y), seconds of JIT compilation)."""
    import numba

    from mechsys.numeric.kane import equations_source

    desc = equations_source(model)
    n, layout = desc["n"], np.array(desc["bodies"], dtype=np.int64).reshape(-1, 2)
    names = {"math": __import__("math"), "np": np}
    exec(compile(desc["source"], "<pieces>", "exec"), names)  # noqa: S102 (mechsys's own generated source)
    pieces = numba.njit(names["_f"])
    nargs = 1 + 2 * n + len(p)
    call_src = (f"def call(t, y, p):\n    return np.array(pieces(t, "
                + ", ".join([f"y[{i}]" for i in range(2 * n)] + [f"p[{i}]" for i in range(nargs - 1 - 2 * n)])
                + "))\n")
    scope = {"np": np, "pieces": pieces}
    exec(compile(call_src, "<call>", "exec"), scope)  # noqa: S102
    call = numba.njit(scope["call"])

    @numba.njit
    def accelerations(t, y, p):
        out = call(t, y, p)
        f = out[:n].copy()
        M = np.zeros((n, n))
        k = n
        for b in range(layout.shape[0]):
            if layout[b, 0]:
                Jv = out[k:k + 3 * n].reshape(3, n)
                m = out[k + 3 * n]
                r = out[k + 3 * n + 1:k + 3 * n + 4]
                M += m * (Jv.T @ Jv)
                f += Jv.T @ r
                k += 3 * n + 4
            if layout[b, 1]:
                Jw = out[k:k + 3 * n].reshape(3, n)
                inertia = out[k + 3 * n:k + 3 * n + 9].reshape(3, 3)
                al = out[k + 3 * n + 9:k + 3 * n + 12]
                w = out[k + 3 * n + 12:k + 3 * n + 15]
                M += Jw.T @ (inertia @ Jw)
                f -= Jw.T @ (inertia @ al + np.cross(w, inertia @ w))
                k += 3 * n + 15
        return np.linalg.solve(M, f)

    @numba.njit
    def rhs_nb(t, y, p):
        dy = np.empty(2 * n)
        dy[:n] = y[n:]
        dy[n:] = accelerations(t, y, p)
        return dy

    t0 = time.perf_counter()
    rhs_nb(0.0, np.zeros(2 * n) + 0.1, p)  # triggers the JIT
    jit = time.perf_counter() - t0
    return (lambda t, y: rhs_nb(t, y, p)), jit


def import_seconds(module: str) -> float:
    code = f"import time; t = time.perf_counter(); import {module}; print(time.perf_counter() - t)"
    return float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                check=True).stdout)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--chain", type=int, default=0, help="an n-link chain instead of the double pendulum")
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    from scipy.integrate import solve_ivp

    import mechsys
    from mechsys.analysis.motion.simulate import RightHandSide, initial_state
    from mechsys.numeric import native

    with tempfile.TemporaryDirectory() as tmp:
        os.environ["MECHSYS_CACHE"] = tmp
        if args.chain:
            path = Path(tmp) / "chain.yaml"
            path.write_text(chain_yaml(args.chain).replace("q1: {initial: 0, rate: 0}", "q1: {initial: 0.5, rate: 0}"))
        else:
            path = REPO / "systems" / "double_pendulum.yaml"
        model = mechsys.load(path)
        c, p, y0 = initial_state(model)
        span, tol = (0.0, args.t_end), dict(rtol=1e-10, atol=1e-12)
        rows, finals = [], {}

        rhs = RightHandSide(c, p)
        secs, sol = best(lambda: solve_ivp(rhs, span, y0, method="DOP853", **tol), args.repeat)
        rows.append(("python + scipy DOP853", secs, sol.nfev, "-", "-"))
        finals["python"] = sol.y[:, -1]

        try:
            fn, jit = numba_rhs(model, p)
            secs, sol = best(lambda: solve_ivp(fn, span, y0, method="DOP853", **tol), args.repeat)
            rows.append(("numba RHS + scipy DOP853", secs, sol.nfev, f"import {import_seconds('numba'):.2f}",
                         f"JIT {jit:.2f} (every process)"))
            finals["numba"] = sol.y[:, -1]
        except ImportError:
            rows.append(("numba RHS + scipy DOP853", float("nan"), 0, "not installed", "pip install numba"))

        t0 = time.perf_counter()
        nat = native.load(model)
        build = time.perf_counter() - t0
        t0 = time.perf_counter()
        native.NativeIntegrator(nat.path)
        load = time.perf_counter() - t0
        secs, run = best(lambda: nat.run(p, y0, np.array(span), **tol), args.repeat)
        rows.append(("native (C loop)", secs, run.nfev, "ctypes (stdlib)",
                     f"cc {build:.2f} once per model; load {load * 1e3:.1f} ms"))
        finals["native"] = run.y[-1]

    scene = f"{args.chain}-link chain" if args.chain else "double pendulum"
    print(f"{scene}, {args.t_end:g} s, DOP853 rtol 1e-10: integration time (best of {args.repeat}) and one-time costs")
    print(f"{'backend':<26} | {'integrate [s]':>13} | {'RHS evals':>9} | {'vs python':>9} | {'import [s]':<16} | "
          "compile / load [s]")
    base = rows[0][1]
    for name, secs, nfev, imp, comp in rows:
        ratio = f"{base / secs:8.0f}x" if secs == secs else "      n/a"
        print(f"{name:<26} | {secs:13.4f} | {nfev:9d} | {ratio} | {imp:<16} | {comp}")
    ref = finals["python"]
    worst = max(float(np.max(np.abs(v - ref))) for v in finals.values())
    print(f"\nfinal states agree to {worst:.1e}")
    if worst > 1e-8:
        print("DISAGREEMENT between backends", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
