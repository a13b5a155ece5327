#!/usr/bin/env python
"""The benchmark bicycle's symbolic stage: what users run through mechsys, cold and with the cache, against plain
sympy.physics.mechanics (KanesMethod + lambdify with CSE) on the same bicycle, in one run (issue 13).

Every mechsys figure is the wall time of a whole `mechsys` process (imports included) on systems/bicycle.yaml,
run twice in a row on one fresh, private cache folder: "cold" is the first command on the model (nothing
cached), "again" the same command repeated (`derive`, `info` and `modes` print their kept output without
sympy, report/warm.py; `simulate` runs its warm plan), and "after" the command run after the ones listed above it
on one shared cache (a different second command on the model). The
baseline is timed in a fresh process too: sympy's own bicycle (test_kane3, benchmarks/bicycle_sympy.py) built,
kanes_equations, then the mass matrix and forcing (full, with the kinematic rows) lambdified with cse=True.
Prints one table with each time and its ratio to the baseline. Goals of the issue: cold derivation at least 2x
faster than sympy; any second command on the model under 1 s.

    .venv/bin/python benchmarks/derive_bicycle.py
    .venv/bin/python benchmarks/derive_bicycle.py --commands derive-kane info   # a subset
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIKE = str(ROOT / "systems" / "bicycle.yaml")
MECHSYS = str(Path(sys.executable).with_name("mechsys"))
#: the commands users run on a model (derive in its default text form: the readable clean-up and the named
#: subexpressions included), the others with the options that keep them about the symbolic stage
COMMANDS = {
    "derive-kane": ["derive", BIKE, "--method", "kane"],
    "derive": ["derive", BIKE],
    "info": ["info", BIKE, "-f", "json"],
    "simulate": ["simulate", BIKE, "--t-end", "0.1", "-f", "json"],
    "modes": ["modes", BIKE, "-f", "json"],
}


def sympy_baseline() -> float:
    """Worker: seconds of build + kanes_equations + lambdify(cse) of M and forcing, after the imports."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import sympy as sp

    from bicycle_sympy import build_and_linearize

    t0 = time.perf_counter()
    km = build_and_linearize(linearize=False)
    states = list(km.q) + list(km.u)
    params = sorted((km.mass_matrix_full.free_symbols | km.forcing_full.free_symbols) - {sp.Symbol("t")},
                    key=str)
    sp.lambdify([states, params], [km.mass_matrix_full, km.forcing_full], cse=True)
    return time.perf_counter() - t0


def mechsys_work() -> float:
    """Worker (cache off): seconds of load + Kane's equations + M and f compiled (CSE), after the imports: the
    same work as the baseline's, without the process around it."""
    os.environ["MECHSYS_CACHE"] = "off"
    import mechsys
    import mechsys.mechanics.model  # noqa: F401  (imported lazily by load; imports are not timed, as for sympy)
    from mechsys.numeric.lambdify import compile_matrix

    t0 = time.perf_counter()
    model = mechsys.load(BIKE)
    eq = model.equations("kane")
    for matrix in (eq.M, eq.f):
        compile_matrix(matrix, model.t, model.q, model.u, model.parameter_symbols)
    return time.perf_counter() - t0


def timed(argv: list[str], env: dict) -> tuple[float, int]:
    t0 = time.perf_counter()
    run = subprocess.run(argv, capture_output=True, text=True, env=env)
    return time.perf_counter() - t0, run.returncode


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--commands", nargs="*", default=list(COMMANDS), choices=list(COMMANDS))
    ap.add_argument("--worker", choices=["sympy", "mechsys"], help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        print(sympy_baseline() if args.worker == "sympy" else mechsys_work())
        return 0
    base_process, _ = timed([sys.executable, __file__, "--worker", "sympy"], dict(os.environ))

    def work(kind: str) -> float:
        return float(subprocess.run([sys.executable, __file__, "--worker", kind], capture_output=True, text=True,
                                    check=True).stdout.strip().splitlines()[-1])

    base = work("sympy")
    own = work("mechsys")
    print(f"sympy KanesMethod + lambdify(cse), the same bicycle: {base:.2f} s of work "
          f"({base_process:.2f} s as a process, imports included)")
    print(f"mechsys load + Kane + M, f compiled (CSE), cache off: {own:.2f} s of work "
          f"({own / base:.2f} of sympy's)\n")
    print(f"{'mechsys command':<16} {'cold [s]':>9} {'/ sympy':>8} {'again [s]':>10} {'/ sympy':>8} "
          f"{'after [s]':>10} {'/ sympy':>8}  exit")
    failed = 0
    with tempfile.TemporaryDirectory() as shared:
        for name in args.commands:
            with tempfile.TemporaryDirectory() as folder:
                env = {**os.environ, "MECHSYS_CACHE": folder}
                cold, rc1 = timed([MECHSYS, *COMMANDS[name]], env)
                warm, rc2 = timed([MECHSYS, *COMMANDS[name]], env)
            # the same command as the first of its kind, after the commands above it ran on one shared cache
            after, rc3 = timed([MECHSYS, *COMMANDS[name]], {**os.environ, "MECHSYS_CACHE": shared})
            failed += bool(rc1 or rc2 or rc3)
            print(f"{name:<16} {cold:9.2f} {cold / base:8.2f} {warm:10.2f} {warm / base:8.2f} {after:10.2f} "
                  f"{after / base:8.2f}  {rc1}/{rc2}/{rc3}")
    print("\nratio < 1: faster than the sympy pipeline's work; each mechsys time is a whole process (about 1 s of "
          "it imports where sympy is needed). again: the same command repeated (derive, info and modes print their "
          "kept output without sympy); after: the command run after those above it on one cache (another second "
          "command on the model)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
