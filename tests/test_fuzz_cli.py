"""Fuzzing the analyses through the real command line (issue 10).

tests/test_fuzz_inputs.py breaks model files and checks that loading fails cleanly; most of its mutants never
reach an analysis. Here the mutants are small edits of VALID bundled models (systems/*.yaml, tests/data/*.yaml):
parameter values scaled, negated, zeroed, made tiny or huge or replaced by another parameter's name (``m1: m2``);
mappings reordered; initial values and rates changed; optional keys dropped or list items duplicated; expressions
perturbed (``+ 0``, ``*1``, one parameter swapped for another); joint axes changed; names renamed consistently.
So most mutants are still valid models, and `info`/`derive`/`codegen`, `simulate` and `equilibria`/`modes`/`collide`
run on them as subprocesses (``python -m mechsys``), with random options (``--set``, ``--rtol``, ``--dt``,
``--method``; sometimes nan, -1, 0), each in a private MECHSYS_CACHE folder: COLD (empty cache), then WARM (same
cache, same command), and for `simulate` also with ``MECHSYS_CACHE=off``.

Every run must end in exactly one of: exit 0; exit 2 or 1 with one non-empty line on stderr that says why. Never
"internal error", a traceback, a signal or a hang; and the warm (and uncached) result must equal the cold one
(`simulate -o` result files numerically, rtol 1e-9/atol 1e-12; the package `codegen` writes byte for byte; the
JSON output of the other commands).

Seeds: fixed by default (reproducible); MECHSYS_FUZZ_SEED=N reproduces a seed; with CI=true or
MECHSYS_FUZZ_ROTATE=1 every run draws a new seed from the clock, printed in the failure message.
MECHSYS_FUZZ_LOG=DIR keeps every mutant and every subprocess output. See tests/fuzzing.py.
"""
from __future__ import annotations

import os
import random
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

import fuzzing as fz

FAST_EXAMPLES = 4     # ~30-60 s on 2 cores (two commands, five subprocesses per example)
SLOW_EXAMPLES = 8     # ~1.5-3 min (three commands, seven subprocesses per example); CI draws a new seed every run
SLOW_OFFSET = 1000    # the slow suite draws other examples than the fast one


def _fuzz(count: int, offset: int, tmp_path: Path, slow: bool, test: str) -> None:
    seed, how, results, seconds = fz.run_examples(count, tmp_path, slow, test, offset)
    outcomes: dict[str, int] = {}
    for r in results:
        for o in r.outcomes:
            outcomes[o] = outcomes.get(o, 0) + 1
    print(f"\n{test}: seed {seed} ({how}), {len(results)} examples in {seconds:.0f} s; outcomes "
          f"{dict(sorted(outcomes.items()))}")
    message = fz.summarize(seed, how, results, seconds, test)
    if message:
        pytest.fail(message, pytrace=False)


def test_fuzz_cli_fast(tmp_path: Path) -> None:
    _fuzz(FAST_EXAMPLES, 0, tmp_path, slow=False, test="test_fuzz_cli_fast")


@pytest.mark.slow
def test_fuzz_cli_slow(tmp_path: Path) -> None:
    _fuzz(SLOW_EXAMPLES, SLOW_OFFSET, tmp_path, slow=True, test="test_fuzz_cli_slow")


# ------------------------------------------------------------------------------------------------- reordering
REORDER_DEFAULT = {"double_pendulum", "four_bar"}  # the reported case and a closed loop; the rest are slow
REORDER_MODELS = [b for b in fz.load_bases([f for f in sorted(fz.SYSTEMS.glob("*.yaml")) if f.stem not in fz.EXPENSIVE])
                  if not b.contacts]
REORDER_ROTATED = 3  # slow models per run, chosen by the fuzz seed (every run in CI draws a new one)


REORDER_TURN_SEED = fz.fuzz_seed()[0] // 10000  # a rotating seed to the hour: the pytest workers agree


def _reorder_turn() -> set[str]:
    """The slow models this run checks: REORDER_ROTATED of them, chosen by the fuzz seed, so that rotating seeds
    cover all of them over a few runs (each costs 10-25 s of subprocesses); MECHSYS_REORDER_ALL=1 runs every one."""
    slow = sorted(b.stem for b in REORDER_MODELS if b.stem not in REORDER_DEFAULT)
    if os.environ.get("MECHSYS_REORDER_ALL", "").strip() in ("1", "true", "yes"):
        return set(slow)
    return set(random.Random(REORDER_TURN_SEED).sample(slow, min(REORDER_ROTATED, len(slow))))


@pytest.mark.parametrize("base", [pytest.param(b, id=b.stem,
                                               marks=() if b.stem in REORDER_DEFAULT else pytest.mark.slow)
                                  for b in REORDER_MODELS])
def test_cached_equals_uncached_under_reordering_and_set(base: fz.BaseModel, tmp_path: Path) -> None:
    """The same model with its parameters and its coordinates mappings reversed, simulated after the original in
    ONE cache folder (and both again with one parameter --set to 1.1x its value), must give what the same runs
    give with MECHSYS_CACHE=off: parameter and coordinate order are part of what the compiled code reads."""
    if base.stem not in REORDER_DEFAULT and base.stem not in _reorder_turn():
        pytest.skip(f"not in this run's turn of {REORDER_ROTATED} slow models (seed {REORDER_TURN_SEED}: "
                    f"{', '.join(sorted(_reorder_turn()))}); MECHSYS_REORDER_ALL=1 runs every model")
    copy = tmp_path / f"{base.stem}_reversed.yaml"
    copy.write_text(fz.dump(fz.reversed_copy(base.data)), encoding="utf-8")
    assignment, what = fz.scaled_set(base.data)
    set_args = ["--set", assignment]
    cases = [("original", base.path, []), ("reversed", copy, []),
             (f"original {what}", base.path, set_args), (f"reversed {what}", copy, set_args)]
    shared = tmp_path / "cache"
    logs = fz.log_dir()

    def run(k: int, mode: str) -> fz.Run:
        label, path, extra = cases[k]
        out = tmp_path / f"case{k}-{mode}.csv"
        argv = [sys.executable, "-m", "mechsys", "simulate", str(path), "--t-end", "0.5", "-o", str(out), *extra]
        r = fz.run_cli(argv, str(shared) if mode == "cached" else "off", fz.TIMEOUTS["simulate"], tmp_path,
                       f"{label} ({mode})", out)
        fz.log_run(logs, f"reorder-{base.stem}-case{k}-{mode}", r)
        return r

    # the cached runs in order, in one folder; the uncached ones alongside
    with ThreadPoolExecutor(max_workers=2) as pool:
        off_future = pool.submit(lambda: [run(k, "off") for k in range(len(cases))])
        cached = [run(k, "cached") for k in range(len(cases))]
        off = off_future.result()

    problems = []
    for k, (c, o) in enumerate(zip(cached, off)):
        for r in (c, o):
            if r.rc != 0 or r.timed_out:
                problems.append(f"{r.label}: exit {r.rc}: {fz.first_error_line(r)}")
        if c.rc == 0 and o.rc == 0:
            diff = fz.compare_tables(fz.read_csv(c.output), fz.read_csv(o.output), by_name=True)
            if diff:
                problems.append(f"{cases[k][0]}: cached run differs from MECHSYS_CACHE=off: {diff}")
    # the physics does not depend on the order of the mappings (looser: the arithmetic order differs)
    for a, b in ((0, 1), (2, 3)):
        if off[a].rc == 0 and off[b].rc == 0:
            diff = fz.compare_tables(fz.read_csv(off[a].output), fz.read_csv(off[b].output), rtol=1e-6, atol=1e-9,
                                     by_name=True)
            if diff:
                problems.append(f"{cases[b][0]} differs from {cases[a][0]} (both MECHSYS_CACHE=off): {diff}")
    assert not problems, (f"{base.path.name} (reversed copy: {copy}):\n  " + "\n  ".join(problems))
