#!/usr/bin/env python
"""Benchmark: n-link planar pendulum through mechsys vs plain sympy.physics.mechanics (KanesMethod).

For each n the same system is taken from nothing to numbers twice, each time in a fresh Python process
(so sympy's global caches favour neither side):

* mechsys:  mechsys.load(YAML) -> model.equations(method) -> compile_matrix(M), compile_matrix(f)
            -> one evaluation of each;
* baseline: the same chain glued by hand with sympy.physics.mechanics (ReferenceFrame.orient_axis,
            Point.v2pt_theory, RigidBody, KanesMethod.kanes_equations) -> lambdify((q, u, p), [M, f],
            cse=True) -> one evaluation.

Imports (sympy, mechsys) happen before the clock starts in both workers and are reported separately.
The accelerations solve(M, f) of both pipelines are compared at a random state; a disagreement beyond
rtol makes the script exit with status 1 (a fast wrong answer is worthless). Wall times are reported,
never asserted.

    python benchmarks/derive_chain.py                 # n = 5 10 20, kane, 1 repeat
    python benchmarks/derive_chain.py --quick         # n = 5 10
    python benchmarks/derive_chain.py --n 20 --repeat 3 --method lagrange
    python benchmarks/derive_chain.py --profile 20    # cProfile of the mechsys pipeline at n = 20
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve()
REPO = HERE.parent.parent

# Parameter values shared by the YAML model and the hand-built baseline (order = symbol order in both).
PARAMS = {"m": 0.7, "l": 0.9, "g": 9.81}
SEED = 20240611
RTOL = 1e-9
GOAL_RATIO_N20 = 5.0
BASELINE_REFERENCE_N20 = 5.6  # seconds, measured when the issue was opened


# ------------------------------------------------------------------------------------------------ model
def chain_yaml(n: int) -> str:
    """The mechsys model file of an n-link planar pendulum of uniform rods with relative angles."""
    lines = [
        f"# {n}-link planar pendulum of uniform rods (benchmarks/derive_chain.py); relative angles q1..q{n}.",
        f"name: chain{n}",
        f"description: {n}-link planar pendulum of uniform rods",
        "parameters:",
        *(f"  {k}: {v}" for k, v in PARAMS.items()),
        "coordinates:",
        *(f"  q{k}: {{initial: 0, rate: 0}}" for k in range(1, n + 1)),
        "links:",
    ]
    for k in range(1, n + 1):
        if k == 1:
            joint = "{type: revolute, parent: ground, axis: z, coordinate: q1}"
        else:
            joint = f"{{type: revolute, parent: link{k - 1}, axis: z, coordinate: q{k}, origin: [l, 0, 0]}}"
        lines += [
            f"  link{k}:",
            f"    joint: {joint}",
            "    mass: m",
            "    center_of_mass: [l/2, 0, 0]",
            "    shape: {rod: {length: l, axis: x}}",
        ]
    lines += ["forces:", "  - {type: gravity, acceleration: [0, -g, 0]}"]
    return "\n".join(lines) + "\n"


def random_state(n: int) -> tuple[list[float], list[float]]:
    import numpy as np

    rng = np.random.default_rng(SEED + n)
    return rng.uniform(-3.0, 3.0, n).tolist(), rng.uniform(-1.5, 1.5, n).tolist()


# ------------------------------------------------------------------------------------------------ workers
def worker_mechsys(n: int, method: str, yaml_path: str) -> dict:
    t_imp = time.perf_counter()
    import numpy as np

    import mechsys
    import mechsys.mechanics.model  # noqa: F401  (mechsys.load imports it lazily; keep it off the clock)
    import mechsys.model.load  # noqa: F401
    from mechsys.numeric.lambdify import compile_matrix

    t_imp = time.perf_counter() - t_imp
    q_val, u_val = random_state(n)

    t0 = time.perf_counter()
    model = mechsys.load(yaml_path)
    t1 = time.perf_counter()
    eq = model.equations(method)
    t2 = time.perf_counter()
    fM = compile_matrix(eq.M, model.t, model.q, model.u, model.parameter_symbols)
    fF = compile_matrix(eq.f, model.t, model.q, model.u, model.parameter_symbols)
    t3 = time.perf_counter()
    by_name = dict(zip([f"q{k}" for k in range(1, n + 1)], zip(q_val, u_val)))
    q = [by_name[c][0] for c in model.coordinates]
    u = [by_name[c][1] for c in model.coordinates]
    p = [model.parameters[str(s)] for s in model.parameter_symbols]
    M = fM(0.0, q, u, p)
    f = fF(0.0, q, u, p)
    t4 = time.perf_counter()

    acc = np.linalg.solve(M, np.asarray(f, dtype=float).reshape(-1))
    acc_by_name = dict(zip(model.coordinates, acc.tolist()))
    return {
        "total": t4 - t0,
        "stages": {"load": t1 - t0, "derive": t2 - t1, "compile": t3 - t2, "eval": t4 - t3},
        "imports": t_imp,
        "acc": [acc_by_name[f"q{k}"] for k in range(1, n + 1)],
    }


def worker_baseline(n: int) -> dict:
    t_imp = time.perf_counter()
    import numpy as np
    import sympy as sp
    from sympy.physics.mechanics import (KanesMethod, Point, ReferenceFrame, RigidBody, dynamicsymbols,
                                         inertia)

    t_imp = time.perf_counter() - t_imp
    q_val, u_val = random_state(n)

    t0 = time.perf_counter()
    q = dynamicsymbols(f"q1:{n + 1}")
    u = dynamicsymbols(f"u1:{n + 1}")
    m, l, g = sp.symbols("m l g")
    N = ReferenceFrame("N")
    O = Point("O")
    O.set_vel(N, 0)
    parent_frame, joint = N, O
    bodies, loads = [], []
    for k in range(n):
        A = ReferenceFrame(f"A{k + 1}")
        A.orient_axis(parent_frame, parent_frame.z, q[k])  # relative angle, as in the YAML
        A.set_ang_vel(parent_frame, u[k] * parent_frame.z)
        if k > 0:
            P = Point(f"P{k + 1}")
            P.set_pos(joint, l * parent_frame.x)
            P.v2pt_theory(joint, N, parent_frame)
            joint = P
        G = Point(f"G{k + 1}")
        G.set_pos(joint, l / 2 * A.x)
        G.v2pt_theory(joint, N, A)
        Izz = m * l**2 / 12
        bodies.append(RigidBody(f"link{k + 1}", G, A, m, (inertia(A, 0, Izz, Izz), G)))
        loads.append((G, -m * g * N.y))
        parent_frame = A
    kd = [qk.diff() - uk for qk, uk in zip(q, u)]
    kane = KanesMethod(N, q_ind=q, u_ind=u, kd_eqs=kd)
    kane.kanes_equations(bodies, loads)
    Mb, fb = kane.mass_matrix, kane.forcing
    t1 = time.perf_counter()
    fn = sp.lambdify((q, u, [m, l, g]), [Mb, fb], cse=True)
    t2 = time.perf_counter()
    M, f = fn(q_val, u_val, list(PARAMS.values()))
    t3 = time.perf_counter()

    acc = np.linalg.solve(np.asarray(M, dtype=float), np.asarray(f, dtype=float).reshape(-1))
    return {
        "total": t3 - t0,
        "stages": {"derive": t1 - t0, "compile": t2 - t1, "eval": t3 - t2},
        "imports": t_imp,
        "acc": acc.tolist(),
    }


def run_worker(kind: str, n: int, method: str, yaml_path: str) -> dict:
    """One pipeline in a fresh interpreter; returns the worker's JSON report."""
    cmd = [sys.executable, str(HERE), "--worker", kind, "--n", str(n), "--method", method, "--yaml", yaml_path]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise SystemExit(f"{kind} worker failed for n={n} (exit {proc.returncode}):\n{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


# ------------------------------------------------------------------------------------------------ profiling
def profile_mechsys(n: int, method: str, top: int) -> None:
    """cProfile of the mechsys pipeline (load + derive + compile + eval) in this process."""
    import cProfile
    import pstats

    import mechsys  # noqa: F401
    import mechsys.mechanics.model  # noqa: F401
    import mechsys.numeric.lambdify  # noqa: F401

    with tempfile.TemporaryDirectory(prefix="mechsys-bench-") as tmp:
        path = Path(tmp) / f"chain{n}.yaml"
        path.write_text(chain_yaml(n))
        prof = cProfile.Profile()
        prof.enable()
        worker_mechsys(n, method, str(path))
        prof.disable()
    print(f"cProfile of the mechsys pipeline, n = {n}, method = {method} (top {top} by cumulative time):")
    pstats.Stats(prof, stream=sys.stdout).strip_dirs().sort_stats("cumulative").print_stats(top)


# ------------------------------------------------------------------------------------------------ driver
def fmt_s(x: float) -> str:
    return f"{x:8.3f} s"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[5, 10, 20], help="chain lengths (default 5 10 20)")
    ap.add_argument("--quick", action="store_true", help="only n = 5 and 10")
    ap.add_argument("--repeat", type=int, default=1, help="fresh-process runs per pipeline; median reported")
    ap.add_argument("--method", choices=["kane", "lagrange"], default="kane", help="mechsys derivation method")
    ap.add_argument("--profile", type=int, metavar="N", help="only cProfile the mechsys pipeline at n = N")
    ap.add_argument("--top", type=int, default=25, help="rows printed by --profile")
    ap.add_argument("--json", metavar="FILE", help="also write the raw results as JSON")
    ap.add_argument("--worker", choices=["mechsys", "baseline"], help=argparse.SUPPRESS)
    ap.add_argument("--yaml", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.worker:
        n = args.n[0]
        out = worker_mechsys(n, args.method, args.yaml) if args.worker == "mechsys" else worker_baseline(n)
        print(json.dumps(out))
        return 0
    if args.profile:
        profile_mechsys(args.profile, args.method, args.top)
        return 0

    ns = [5, 10] if args.quick else args.n
    import numpy as np
    import sympy

    print(f"derive_chain: n-link planar pendulum, mechsys ({args.method}) vs sympy.physics.mechanics "
          f"KanesMethod + lambdify(cse=True)")
    print(f"python {sys.version.split()[0]}, sympy {sympy.__version__}, numpy {np.__version__}; "
          f"repeat {args.repeat} (median), each run in a fresh process; times exclude imports")
    print()
    header = f"{'n':>3} | {'mechsys':>10} | {'baseline':>10} | {'ratio b/m':>9} | {'max rel. diff (acc)':>19} | agree"
    print(header)
    print("-" * len(header))

    results = []
    failed = False
    with tempfile.TemporaryDirectory(prefix="mechsys-bench-") as tmp:
        for n in ns:
            path = Path(tmp) / f"chain{n}.yaml"
            path.write_text(chain_yaml(n))
            mech, base = [], []
            for r in range(args.repeat):
                # alternate the order so neither pipeline always runs on a warmer machine
                order = ("mechsys", "baseline") if r % 2 == 0 else ("baseline", "mechsys")
                for kind in order:
                    (mech if kind == "mechsys" else base).append(run_worker(kind, n, args.method, str(path)))
            tm = statistics.median(x["total"] for x in mech)
            tb = statistics.median(x["total"] for x in base)
            a_b = np.asarray(base[0]["acc"])
            diffs = [float(np.max(np.abs(np.asarray(x["acc"]) - np.asarray(y["acc"]))) / np.max(np.abs(a_b)))
                     for x in mech for y in base]
            rel = max(diffs)
            ok = bool(np.isfinite(rel) and rel <= RTOL)
            failed |= not ok
            print(f"{n:>3} | {fmt_s(tm)} | {fmt_s(tb)} | {tb / tm:8.2f}x | {rel:19.2e} | {'yes' if ok else 'NO'}")
            results.append({"n": n, "mechsys": tm, "baseline": tb, "ratio": tb / tm, "rel_diff": rel, "agree": ok,
                            "mechsys_runs": mech, "baseline_runs": base})

    print()
    print("stages (median seconds):")
    for r in results:
        ms = {k: statistics.median(x["stages"][k] for x in r["mechsys_runs"]) for k in r["mechsys_runs"][0]["stages"]}
        bs = {k: statistics.median(x["stages"][k] for x in r["baseline_runs"]) for k in r["baseline_runs"][0]["stages"]}
        mi = statistics.median(x["imports"] for x in r["mechsys_runs"])
        bi = statistics.median(x["imports"] for x in r["baseline_runs"])
        print(f"  n={r['n']:>2} mechsys : " + ", ".join(f"{k} {v:.3f}" for k, v in ms.items())
              + f"  (imports {mi:.3f}, not timed)")
        print(f"  n={r['n']:>2} baseline: " + ", ".join(f"{k} {v:.3f}" for k, v in bs.items())
              + f"  (imports {bi:.3f}, not timed)")

    print()
    print("verdict:")
    for r in results:
        goals = [("never slower", r["ratio"] >= 1.0)]
        if r["n"] == 20:
            goals.append((f">= {GOAL_RATIO_N20:g}x faster", r["ratio"] >= GOAL_RATIO_N20))
        text = "; ".join(f"{name}: {'MET' if met else 'MISSED'}" for name, met in goals)
        correct = "accelerations agree" if r["agree"] else f"accelerations DISAGREE (rel. diff {r['rel_diff']:.2e})"
        print(f"  n={r['n']:>2}: {r['ratio']:.2f}x ({text}); {correct}")
    if any(r["n"] == 20 for r in results):
        print(f"  (issue's reference baseline at n=20: ~{BASELINE_REFERENCE_N20} s)")

    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))
    if failed:
        print(f"\nERROR: mechsys and the baseline disagree on the accelerations beyond rtol {RTOL:g}",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
