#!/usr/bin/env python
"""The Whipple bicycle benchmark: eigenvalues of upright running over v = 0..10 m/s through mechsys against the
plain sympy.physics.mechanics pipeline (KanesMethod + linearize, benchmarks/bicycle_sympy.py), in one run.

What is timed, each in a fresh process and with a fresh (empty) mechsys cache unless --warm:
  * mechsys (library): load systems/bicycle.yaml, then at each of the 101 speeds the steady motion (upright,
    polished by Newton) and its linearization on the constraint manifold (analysis/equilibrium/nonholonomic.py);
  * mechsys (CLI, what users run), after the library run (so the model's compiled pieces are in the cache, as
    after any first command on the model): the issue's command `mechsys equilibria systems/bicycle.yaml --sweep
    v=0:10:101` with its defaults, first with no search stored (goal: under 10 s), then in another format (the
    five searches read back from the cache); and the sweep with the search box of lean and steer the docs use
    (--search lean=-0.3:0.3 --search steer=-0.3:0.3);
  * sympy: the baseline.
Prints the times, their ratio and the largest eigenvalue difference (mechsys vs sympy, and both vs the published
matrices); exits 1 when the eigenvalues disagree by more than 1e-9 relative.

    .venv/bin/python benchmarks/bicycle.py            # cold caches (the first command on the model)
    .venv/bin/python benchmarks/bicycle.py --warm     # mechsys with its on-disk cache filled (later commands)
    .venv/bin/python benchmarks/bicycle.py --no-cli   # skip the CLI sweep
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIKE = ROOT / "systems" / "bicycle.yaml"
SPEEDS = [10.0 * k / 100 for k in range(101)]


def mechsys_library() -> dict:
    """Worker: the 101 linearizations through the Python API."""
    import numpy as np

    t0 = time.perf_counter()
    import mechsys
    from mechsys.analysis.equilibrium.bifurcation import swept_parameter
    from mechsys.analysis.equilibrium.equilibria import _polish, make_problem
    from mechsys.analysis.equilibrium.nonholonomic import linearize_steady

    imports = time.perf_counter() - t0
    t0 = time.perf_counter()
    model = mechsys.load(BIKE)
    problem = make_problem(model)
    speed = swept_parameter(problem, "v")  # the parameter vector at v, and the given rates that follow v
    rows = []
    for v in SPEEDS:
        p = speed.at(v)
        z = _polish(problem, problem.start(np.zeros(problem.nq), p), p)
        lin = linearize_steady(problem, problem.equilibrium(z), p)
        rows.append([[float(x.real), float(x.imag)] for x in lin.eigenvalues])
    return {"seconds": time.perf_counter() - t0, "imports": imports, "eigenvalues": rows}


def run_worker(kind: str, env: dict) -> dict:
    out = subprocess.run([sys.executable, __file__, "--worker", kind], capture_output=True, text=True, env=env,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--warm", action="store_true", help="fill the mechsys cache first (later commands)")
    parser.add_argument("--no-cli", action="store_true", help="skip the CLI sweep")
    args = parser.parse_args()
    if args.worker == "library":
        print(json.dumps(mechsys_library()))
        return 0
    if args.worker == "sympy":
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from bicycle_sympy import sympy_bicycle_eigenvalues

        ev, seconds = sympy_bicycle_eigenvalues(SPEEDS)
        print(json.dumps({"seconds": seconds, "eigenvalues": [[[float(x.real), float(x.imag)] for x in row]
                                                              for row in ev]}))
        return 0

    import numpy as np

    sys.path.insert(0, str(ROOT / "tests"))
    import reference_nonholonomic as ref

    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "MECHSYS_CACHE": cache}
        if args.warm:
            run_worker("library", env)
        lib = run_worker("library", env)
        cli = {}
        if not args.no_cli:
            exe = str(Path(sys.executable).parent / "mechsys")
            out = os.path.join(cache, "sweep.out")
            for label, extra in (("first", ["-o", out]), ("stored", ["-f", "json", "-o", out]),
                                 ("boxed", ["--search", "lean=-0.3:0.3", "--search", "steer=-0.3:0.3", "-f", "json",
                                            "-o", out])):
                t0 = time.perf_counter()
                subprocess.run([exe, "equilibria", str(BIKE), "--sweep", "v=0:10:101", *extra], check=True, env=env)
                cli[label] = time.perf_counter() - t0
    base = run_worker("sympy", dict(os.environ))

    def arr(rows):
        return [np.array([complex(a, b) for a, b in row]) for row in rows]

    worst_sympy = max(ref.max_eigenvalue_difference(a, b)[1] for a, b in zip(arr(lib["eigenvalues"]),
                                                                                arr(base["eigenvalues"])))
    worst_paper = max(ref.max_eigenvalue_difference(a, ref.benchmark_eigenvalues(v))[1]
                      for a, v in zip(arr(lib["eigenvalues"]), SPEEDS))
    state = "warm cache" if args.warm else "cold cache"
    print(f"bicycle benchmark, 101 speeds on [0, 10] m/s ({state})")
    print(f"  mechsys library (load + 101 steady motions and linearizations): {lib['seconds']:8.2f} s")
    if cli:
        print(f"  mechsys equilibria systems/bicycle.yaml --sweep v=0:10:101 (CLI, whole process), "
              f"first: {cli['first']:.2f} s (goal under 10 s: {'met' if cli['first'] < 10 else 'NOT met'}); "
              f"searches stored: {cli['stored']:.2f} s; with the docs' search boxes: {cli['boxed']:.2f} s")
    print(f"  sympy KanesMethod + linearize (baseline):                       {base['seconds']:8.2f} s")
    print(f"  ratio baseline / mechsys library: {base['seconds'] / lib['seconds']:.1f}x")
    print(f"  largest eigenvalue difference: mechsys vs sympy {worst_sympy:.2e} (relative), "
          f"mechsys vs published M0, C1, K0, K2 {worst_paper:.2e}")
    return 0 if max(worst_sympy, worst_paper) <= 1e-9 else 1


if __name__ == "__main__":
    sys.exit(main())
