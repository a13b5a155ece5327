#!/usr/bin/env python
"""Benchmark: n-link planar pendulum through mechsys vs plain sympy.physics.mechanics (KanesMethod).

For each n the same system is taken from nothing to numbers by each pipeline, every run in a fresh Python
process (so sympy's global caches favour no one):

* mechsys:      mechsys.load(YAML) -> model.equations(method) -> compile_matrix(M), compile_matrix(f)
                -> one evaluation of each;
* baseline rel: the chain glued by hand with sympy.physics.mechanics, frames chained by the relative
                angles of the YAML (orient_axis(parent, parent.z, q_k)), Point.v2pt_theory, RigidBody,
                KanesMethod.kanes_equations -> lambdify((q, u, p), [M, f], cse=True) -> one evaluation;
* baseline abs: the same with every frame oriented from N by an absolute angle (the usual n-link pendulum
                script; much cheaper for sympy). State and accelerations are mapped to relative angles.

Imports (sympy, mechsys) happen before the clock starts in every worker and are reported separately.
A baseline run longer than --timeout is abandoned and reported as "> timeout".
The accelerations solve(M, f) of mechsys and every finished baseline are compared at a random state; a
disagreement beyond rtol 1e-9 makes the script exit with status 1 (a fast wrong answer is worthless).
Wall times are reported, never asserted.

    python benchmarks/derive_chain.py                   # n = 5 10 20, kane, both baselines, 1 repeat
    python benchmarks/derive_chain.py --quick           # n = 5 10
    python benchmarks/derive_chain.py --n 20 --repeat 3 --method lagrange --baseline absolute
    python benchmarks/derive_chain.py --profile 20      # cProfile of the mechsys pipeline at n = 20
    python benchmarks/derive_chain.py --commands        # the CLI commands users run, n = 5 10 20 40 80

With --commands the script times what users run instead: whole `mechsys` processes (imports included) on the
chain's YAML file, `derive -o FILE` (its default text form) with the default method (Lagrange) and with `--method kane`, `info`,
`equilibria` and `codegen -t python --method kane` (the generated package), each cold (a fresh private cache folder) and then cached (the same command again), against the
issue's goals (20-link `derive` under 1 s with every method, n = 80 under 20 s) and the absolute-angle baseline.
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
    by_name = dict(zip([f"q{k}" for k in range(1, n + 1)], zip(q_val, u_val)))
    q = [by_name[c][0] for c in model.coordinates]
    u = [by_name[c][1] for c in model.coordinates]
    p = [model.parameters[str(s)] for s in model.parameter_symbols]
    if method == "staged":
        # derive the per-body Kane terms and compile them; M and f are assembled numerically
        from mechsys.numeric.kane import compile_equations

        staged = compile_equations(model)
        t2 = t3 = time.perf_counter()
        M, f = staged.evaluate(0.0, q, u, p)
    else:
        eq = model.equations(method)
        t2 = time.perf_counter()
        fM = compile_matrix(eq.M, model.t, model.q, model.u, model.parameter_symbols)
        fF = compile_matrix(eq.f, model.t, model.q, model.u, model.parameter_symbols)
        t3 = time.perf_counter()
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


def kane_chain(n: int, angles: str):
    """The n-link chain written by hand with sympy.physics.mechanics (pydy style), equations formed:
    (KanesMethod, q, u, [m, l, g]). angles='relative' orients frame k from frame k-1 by q_k (the YAML's
    coordinates); 'absolute' orients every frame from N (the usual script, cheaper for sympy)."""
    import sympy as sp
    from sympy.physics.mechanics import KanesMethod, Point, ReferenceFrame, RigidBody, dynamicsymbols, inertia

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
        if angles == "relative":
            A.orient_axis(parent_frame, parent_frame.z, q[k])  # relative angle, as in the YAML
            A.set_ang_vel(parent_frame, u[k] * parent_frame.z)
        else:
            A.orient_axis(N, N.z, q[k])  # absolute angle
            A.set_ang_vel(N, u[k] * N.z)
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
    return kane, q, u, [m, l, g]


def worker_baseline(n: int, angles: str) -> dict:
    """The chain glued by hand with sympy.physics.mechanics, pydy style.

    angles='relative': frame k is oriented from frame k-1 by q_k (the YAML's coordinates);
    angles='absolute': frame k is oriented from N by theta_k = q_1 + ... + q_k (the usual n-link pendulum
    script; the state is mapped from relative coordinates and the accelerations mapped back).
    """
    t_imp = time.perf_counter()
    import numpy as np
    import sympy as sp
    import sympy.physics.mechanics  # noqa: F401  (imported off the clock; kane_chain uses it)

    t_imp = time.perf_counter() - t_imp
    q_val, u_val = random_state(n)
    if angles == "absolute":
        q_val, u_val = np.cumsum(q_val).tolist(), np.cumsum(u_val).tolist()

    t0 = time.perf_counter()
    kane, q, u, params = kane_chain(n, angles)
    Mb, fb = kane.mass_matrix, kane.forcing
    t1 = time.perf_counter()
    fn = sp.lambdify((q, u, params), [Mb, fb], cse=True)
    t2 = time.perf_counter()
    M, f = fn(q_val, u_val, list(PARAMS.values()))
    t3 = time.perf_counter()

    acc = np.linalg.solve(np.asarray(M, dtype=float), np.asarray(f, dtype=float).reshape(-1))
    if angles == "absolute":
        acc = np.diff(acc, prepend=0.0)  # theta_k'' -> q_k'' = theta_k'' - theta_(k-1)''
    return {
        "total": t3 - t0,
        "stages": {"derive": t1 - t0, "compile": t2 - t1, "eval": t3 - t2},
        "imports": t_imp,
        "acc": acc.tolist(),
    }


def run_worker(kind: str, n: int, method: str, yaml_path: str, timeout: float | None) -> dict | None:
    """One pipeline in a fresh interpreter; the worker's JSON report, or None if it exceeded ``timeout``."""
    cmd = [sys.executable, str(HERE), "--worker", kind, "--n", str(n), "--method", method, "--yaml", yaml_path]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None
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
BASELINES = {"relative": "baseline-rel", "absolute": "baseline-abs"}


def fmt_t(x: float | None, timeout: float | None) -> str:
    return f"{x:7.3f} s" if x is not None else f">{timeout:5.0f} s"


def fmt_ratio(tb: float | None, tm: float, timeout: float | None) -> str:
    if tb is None:
        return f">{(timeout or 0) / tm:7.1f}x"
    return f"{tb / tm:8.2f}x"


def median_total(runs: list[dict | None]) -> float | None:
    """Median over the runs; None (timed out) if any run timed out."""
    if not runs or any(r is None for r in runs):
        return None
    return statistics.median(r["total"] for r in runs)


def rel_diff(a: list[float], b: list[float]) -> float:
    """max_i |a_i - b_i| / max_i |b_i|: the difference relative to the size of the reference vector."""
    import numpy as np

    a_, b_ = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    scale = float(np.max(np.abs(b_))) or 1.0
    return float(np.max(np.abs(a_ - b_))) / scale


COMMANDS = {  # label -> mechsys arguments after the file
    "derive (lagrange)": ["derive", "-o", "{out}"],  # the default text form, as users run it
    "derive --method kane": ["derive", "--method", "kane", "-o", "{out}"],
    "info": ["info"],
    "equilibria": ["equilibria"],
    "codegen --method kane": ["codegen", "-t", "python", "--method", "kane", "-o", "{pkg}"],
}
GOAL_DERIVE_N20, GOAL_DERIVE_N80 = 1.0, 20.0  # seconds, whole process (issue 13)


def time_command(args: list[str], cache: Path, timeout: float) -> tuple[float | None, int | None]:
    """Wall time of one whole `mechsys` process (None past the timeout) and its exit code."""
    env = dict(os.environ, MECHSYS_CACHE=str(cache), COLUMNS="120")
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-m", "mechsys", *args], env=env, capture_output=True, text=True,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, None
    return time.perf_counter() - t0, proc.returncode


def main_commands(ns: list[int], timeout: float, baseline: bool) -> int:
    """The --commands table: every command cold and cached per n, the baseline's derivation beside them."""
    print(f"derive_chain --commands: whole `mechsys` processes on the n-link chain (imports included), cold "
          f"(empty cache) then cached; timeout {timeout:g} s; {os.cpu_count()} CPUs")
    labels = list(COMMANDS)
    cols = [f"{'n':>3}"] + [f"{lab:>22}" for lab in labels] + ([f"{'sympy abs':>10}"] if baseline else [])
    print(" | ".join(cols))
    print("    " + " | ".join(f"{'cold / cached':>22}" for _ in labels))
    failed = False
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in ns:
            model = Path(tmp) / f"chain{n}.yaml"
            model.write_text(chain_yaml(n), encoding="utf-8")
            cells, row = [], {"n": n}
            for label in labels:
                cache = Path(tmp) / f"cache{n}-{labels.index(label)}"
                args = [a.format(out=Path(tmp) / "out.txt", pkg=Path(tmp) / f"package{n}")
                        for a in [COMMANDS[label][0], str(model), *COMMANDS[label][1:]]]
                cold, rc = time_command(args, cache, timeout)
                warm, rc2 = time_command(args, cache, timeout) if cold is not None else (None, None)
                failed |= bool(rc) or bool(rc2)
                row[label] = (cold, warm)
                cells.append(f"{fmt_t(cold, timeout):>10} / {fmt_t(warm, timeout):>9}")
            if baseline:
                base = run_worker("baseline-abs", n, "kane", str(model), timeout)
                row["sympy abs"] = base["total"] if base else None
                cells.append(f"{fmt_t(row['sympy abs'], timeout):>10}")
            rows.append(row)
            print(" | ".join([f"{n:>3}"] + cells), flush=True)
    print()
    for n, goal in ((20, GOAL_DERIVE_N20), (80, GOAL_DERIVE_N80)):
        row = next((r for r in rows if r["n"] == n), None)
        if row is None:
            continue
        for label in ("derive (lagrange)", "derive --method kane"):
            cold = row[label][0]
            verdict = "met" if cold is not None and cold < goal else "NOT met"
            print(f"goal: `mechsys {label}` of the {n}-link chain under {goal:g} s (cold): {verdict} "
                  f"({fmt_t(cold, timeout)})")
    if failed:
        print("a command exited with an error", file=sys.stderr)
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[5, 10, 20], help="chain lengths (default 5 10 20)")
    ap.add_argument("--quick", action="store_true", help="only n = 5 and 10")
    ap.add_argument("--repeat", type=int, default=1, help="fresh-process runs per pipeline; median reported")
    ap.add_argument("--method", choices=["staged", "kane", "lagrange"], default="staged",
                    help="mechsys pipeline: compiled per-body Kane terms (default, what analyses use) or the "
                         "full symbolic M and f of a formulation, compiled whole")
    ap.add_argument("--baseline", choices=["both", "relative", "absolute"], default="both",
                    help="plain-sympy formulation(s): relative angles (as the YAML), absolute angles, or both")
    ap.add_argument("--timeout", type=float, default=120.0,
                    help="seconds before a baseline run is abandoned and reported as '> timeout' (default 120)")
    ap.add_argument("--profile", type=int, metavar="N", help="only cProfile the mechsys pipeline at n = N")
    ap.add_argument("--top", type=int, default=25, help="rows printed by --profile")
    ap.add_argument("--json", metavar="FILE", help="also write the raw results as JSON")
    ap.add_argument("--commands", action="store_true",
                    help="time the CLI commands users run (derive each method, info, equilibria, codegen), cold and "
                         "cached; default n = 5 10 20 40 80")
    ap.add_argument("--worker", choices=["mechsys", *BASELINES.values()], help=argparse.SUPPRESS)
    ap.add_argument("--yaml", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.worker:
        n = args.n[0]
        if args.worker == "mechsys":
            out = worker_mechsys(n, args.method, args.yaml)
        else:
            out = worker_baseline(n, "relative" if args.worker == "baseline-rel" else "absolute")
        print(json.dumps(out))
        return 0
    if args.profile:
        profile_mechsys(args.profile, args.method, args.top)
        return 0
    if args.commands:
        ns = args.n if "--n" in (argv if argv is not None else sys.argv) else [5, 10, 20, 40, 80]
        return main_commands(ns, args.timeout, args.baseline != "relative")

    ns = [5, 10] if args.quick else args.n
    kinds = list(BASELINES) if args.baseline == "both" else [args.baseline]
    import numpy as np
    import sympy

    print(f"derive_chain: n-link planar pendulum, mechsys ({args.method}) vs sympy.physics.mechanics "
          "KanesMethod + lambdify(cse=True)")
    print(f"python {sys.version.split()[0]}, sympy {sympy.__version__}, numpy {np.__version__}, "
          f"{os.cpu_count()} CPUs; repeat {args.repeat} (median), every run in a fresh process, imports not timed;"
          f" baseline timeout {args.timeout:g} s")
    print("baselines: 'rel' = frames chained by relative angles (the YAML's coordinates), "
          "'abs' = frames oriented from N by absolute angles")
    print()
    cols = [f"{'n':>3}", f"{'mechsys':>9}"]
    for k in kinds:
        tag = k[:3]
        cols += [f"{'base ' + tag:>9}", f"{'ratio ' + tag:>9}"]
    cols += [f"{'max rel. diff (acc)':>19}", "agree"]
    header = " | ".join(cols)
    print(header)
    print("-" * len(header))

    results = []
    failed = False
    with tempfile.TemporaryDirectory(prefix="mechsys-bench-") as tmp:
        for n in ns:
            path = Path(tmp) / f"chain{n}.yaml"
            path.write_text(chain_yaml(n))
            runs: dict[str, list[dict | None]] = {"mechsys": [], **{k: [] for k in kinds}}
            for r in range(args.repeat):
                # alternate the order so that no pipeline always runs first
                order = ["mechsys", *kinds]
                if r % 2:
                    order.reverse()
                for kind in order:
                    if kind == "mechsys":
                        res = run_worker("mechsys", n, args.method, str(path), None)
                    elif runs[kind] and runs[kind][-1] is None:
                        res = None  # timed out already at this n: don't burn another timeout
                    else:
                        res = run_worker(BASELINES[kind], n, args.method, str(path), args.timeout)
                    runs[kind].append(res)
            tm = median_total(runs["mechsys"])
            row = {"n": n, "mechsys": tm, "runs": runs}
            diffs = []
            cells = [f"{n:>3}", fmt_t(tm, None)]
            for k in kinds:
                tb = median_total(runs[k])
                row[k] = tb
                row[f"ratio_{k}"] = None if tb is None else tb / tm
                cells += [fmt_t(tb, args.timeout), fmt_ratio(tb, tm, args.timeout)]
                diffs += [rel_diff(x["acc"], y["acc"]) for x in runs["mechsys"] for y in runs[k] if y is not None]
            rel = max(diffs) if diffs else None
            ok = None if rel is None else bool(np.isfinite(rel) and rel <= RTOL)
            failed |= ok is False
            row["rel_diff"], row["agree"] = rel, ok
            cells += [f"{rel:19.2e}" if rel is not None else f"{'(no baseline)':>19}",
                      {True: "yes", False: "NO", None: "n/a"}[ok]]
            print(" | ".join(cells), flush=True)
            results.append(row)

    print()
    print("stages (median seconds; load = YAML + model build, derive = equations of motion, "
          "compile = lambdify, eval = one call):")
    for row in results:
        for kind, runs_k in row["runs"].items():
            done = [x for x in runs_k if x is not None]
            if not done:
                print(f"  n={row['n']:>2} {kind:<8}: timed out (> {args.timeout:g} s)")
                continue
            st = {s_: statistics.median(x["stages"][s_] for x in done) for s_ in done[0]["stages"]}
            imp = statistics.median(x["imports"] for x in done)
            print(f"  n={row['n']:>2} {kind:<8}: " + ", ".join(f"{s_} {v:.3f}" for s_, v in st.items())
                  + f"   (imports {imp:.3f}, not timed)")

    print()
    print("verdict (against the FASTER plain-sympy baseline, so the claim is the conservative one):")
    for row in results:
        times = [row[k] for k in kinds]
        if all(t is None for t in times):
            best, ratio = None, None
        else:
            best = min(t for t in times if t is not None)
            ratio = best / row["mechsys"]
        if ratio is None:
            lower = args.timeout / row["mechsys"]
            status = f"> {lower:.1f}x (every baseline timed out)"
            goals = [("never slower", True)] + ([(f">= {GOAL_RATIO_N20:g}x", lower >= GOAL_RATIO_N20)]
                                                if row["n"] == 20 else [])
        else:
            status = f"{ratio:.2f}x"
            goals = [("never slower", ratio >= 1.0)] + ([(f">= {GOAL_RATIO_N20:g}x faster", ratio >= GOAL_RATIO_N20)]
                                                         if row["n"] == 20 else [])
        text = "; ".join(f"{name}: {'MET' if met else 'MISSED'}" for name, met in goals)
        if row["agree"] is None:
            correct = "accelerations NOT CHECKED (no baseline finished)"
        elif row["agree"]:
            correct = f"accelerations agree (max rel. diff {row['rel_diff']:.1e})"
        else:
            correct = f"accelerations DISAGREE (max rel. diff {row['rel_diff']:.2e} > {RTOL:g})"
        print(f"  n={row['n']:>2}: {status} ({text}); {correct}")
    if any(r["n"] == 20 for r in results):
        print(f"  (the issue's reference baseline at n=20 was ~{BASELINE_REFERENCE_N20} s)")

    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))
    if failed:
        print(f"\nERROR: mechsys and the baseline disagree on the accelerations beyond rtol {RTOL:g}",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
