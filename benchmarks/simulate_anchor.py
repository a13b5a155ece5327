#!/usr/bin/env python
"""Benchmark: `mechsys simulate` against the anchor pipeline users glue by hand today, at equal final error.

Anchor: sympy.physics.mechanics KanesMethod -> lambdify([M, f], cse=True) -> np.linalg.solve in the RHS ->
scipy solve_ivp(DOP853). mechsys: the same model from YAML, `simulate(..., method="native")` (the compiled
DOP853 loop). Scenes: a double pendulum (5 s) and a 10-link chain (5 s), uniform rods, the models of
benchmarks/derive_chain.py.

For each pipeline the tolerance is tightened (rtol = atol = 1e-4, 1e-5, ...) until the final state is within
1e-6 of a reference (the anchor itself at rtol = atol = 1e-13); the wall time of that run (best of --repeat)
is compared. One-time costs (derivation, lambdify, C compilation) are reported separately. The two pipelines'
references must agree to a tenth of the target error, or the script exits with status 1: a fast wrong answer is worthless.

The whole-process times of `mechsys simulate systems/double_pendulum.yaml --t-end 10`, cold (empty cache) and
warm (second run), are reported against the issue's targets (2 s and 0.5 s). Times are reported, never asserted.

    python benchmarks/simulate_anchor.py            # both scenes + whole-process timings
    python benchmarks/simulate_anchor.py --quick    # double pendulum only, fewer repeats
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))
from derive_chain import PARAMS, chain_yaml, kane_chain  # noqa: E402  (the models of the derivation benchmark)

TARGET_ERROR = 1e-6
TOLERANCES = [10.0 ** -k for k in range(4, 14)]
GOAL_RATIO = 10.0


def initial_state(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Relative angles: the first link at 0.5 rad, the others bent by 0.1 rad; at rest (large swings, but inside
    the predictability horizon over 5 s, so a 1e-6 final error is a meaningful target)."""
    q = np.full(n, 0.1)
    q[0] = 0.5
    return q, np.zeros(n)


def anchor(n: int):
    """The hand-glued pipeline with absolute angles (the usual script; cheaper for sympy than relative ones).
    Returns (rhs(t, y) in absolute angles, seconds to derive and lambdify)."""
    import sympy as sp

    t0 = time.perf_counter()
    kane, q, u, params = kane_chain(n, "absolute")
    fn = sp.lambdify((q, u, params), [kane.mass_matrix, kane.forcing], cse=True)
    p = list(PARAMS.values())

    def rhs(t, y):
        M, f = fn(y[:n], y[n:], p)
        return np.concatenate([y[n:], np.linalg.solve(np.asarray(M, dtype=float), np.asarray(f, dtype=float)
                                                      .ravel())])
    return rhs, time.perf_counter() - t0


def best_time(fn, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def scene(n: int, t_end: float, repeat: int) -> dict:
    from scipy.integrate import solve_ivp

    import mechsys
    from mechsys.analysis.motion.simulate import simulate

    q0, u0 = initial_state(n)
    y0_abs = np.concatenate([np.cumsum(q0), np.cumsum(u0)])  # the anchor's absolute angles
    rhs, anchor_setup = anchor(n)
    ref = solve_ivp(rhs, (0, t_end), y0_abs, method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
    ref_rel = np.concatenate([np.diff(ref[:n], prepend=0.0), np.diff(ref[n:], prepend=0.0)])

    with tempfile.TemporaryDirectory() as tmp:
        os.environ["MECHSYS_CACHE"] = tmp  # a cold cache: the one-time cost is measured, not hidden
        path = Path(tmp) / f"chain{n}.yaml"
        text = chain_yaml(n).replace("  q1: {initial: 0, rate: 0}", "  q1: {initial: 0.5, rate: 0}")
        for k in range(2, n + 1):
            text = text.replace(f"  q{k}: {{initial: 0, rate: 0}}", f"  q{k}: {{initial: 0.1, rate: 0}}")
        path.write_text(text)
        t0 = time.perf_counter()
        model = mechsys.load(path)
        simulate(model, 1e-3, method="native")  # derive, generate, compile (C) once
        mechsys_setup = time.perf_counter() - t0
        order = [model.coordinates.index(f"q{k}") for k in range(1, n + 1)]

        def mechsys_final(rtol):
            r = simulate(model, t_end, t_end, "native", rtol, rtol)
            return np.concatenate([r.q[-1][order], r.u[-1][order]])

        mine_ref = mechsys_final(1e-13)
        agree = float(np.max(np.abs(mine_ref - ref_rel)))
        rows = {}
        for name, run in (("anchor", lambda tol: (lambda y: np.concatenate(
                              [np.diff(y[:n], prepend=0.0), np.diff(y[n:], prepend=0.0)]))(
                              solve_ivp(rhs, (0, t_end), y0_abs, method="DOP853", rtol=tol, atol=tol).y[:, -1])),
                          ("mechsys", mechsys_final)):
            for tol in TOLERANCES:
                err = float(np.max(np.abs(run(tol) - ref_rel)))
                if err <= TARGET_ERROR:
                    seconds, _ = best_time(lambda: run(tol), repeat)
                    rows[name] = {"tol": tol, "error": err, "seconds": seconds}
                    break
    return {"n": n, "agree": agree, "rows": rows, "setup": {"anchor": anchor_setup, "mechsys": mechsys_setup}}


def whole_process(repeat: int) -> dict:
    cmd = [sys.executable, "-m", "mechsys", "simulate", str(REPO / "systems" / "double_pendulum.yaml"),
           "--t-end", "10"]
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "MECHSYS_CACHE": tmp}
        t0 = time.perf_counter()
        subprocess.run(cmd, env=env, capture_output=True, check=True)
        cold = time.perf_counter() - t0
        warm = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            subprocess.run(cmd, env=env, capture_output=True, check=True)
            warm.append(time.perf_counter() - t0)
    return {"cold": cold, "warm": statistics.median(warm)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="double pendulum only, 2 repeats")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    repeat = 2 if args.quick else args.repeat
    scenes = [(2, 5.0)] if args.quick else [(2, 5.0), (10, 5.0)]
    status = 0
    print(f"equal final error <= {TARGET_ERROR:g} (reference: the anchor at rtol = atol = 1e-13); best of {repeat}")
    print(f"{'scene':>10} | {'anchor tol':>10} | {'anchor [s]':>10} | {'mechsys tol':>11} | {'mechsys [s]':>11} | "
          f"{'ratio':>7} | {'refs agree':>10} | one-time: anchor / mechsys [s]")
    for n, t_end in scenes:
        r = scene(n, t_end, repeat)
        a, m = r["rows"].get("anchor"), r["rows"].get("mechsys")
        ok = r["agree"] <= 0.1 * TARGET_ERROR  # the references agree well inside the error target
        status |= 0 if ok else 1
        ratio = a["seconds"] / m["seconds"] if a and m else float("nan")
        label = "double" if n == 2 else f"chain {n}"
        print(f"{label:>10} | {a['tol']:10.0e} | {a['seconds']:10.4f} | {m['tol']:11.0e} | {m['seconds']:11.5f} | "
              f"{ratio:6.0f}x | {r['agree']:10.1e} | {r['setup']['anchor']:.2f} / {r['setup']['mechsys']:.2f}"
              f"{'' if ratio >= GOAL_RATIO else '  (below the 10x goal)'}")
    w = whole_process(3 if args.quick else 5)
    print(f"\nwhole process `mechsys simulate systems/double_pendulum.yaml --t-end 10`: cold {w['cold']:.2f} s "
          f"(target 2 s), warm {w['warm']:.2f} s (target 0.5 s; median)")
    if status:
        print("DISAGREEMENT: the two pipelines' reference solutions differ by more than a tenth of the target error", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
