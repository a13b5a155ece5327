"""Warm start of `mechsys simulate` (analysis/motion/warm.py): a repeated run reuses a plan keyed by the file's bytes and
options, gives byte-identical results, and never imports sympy, pydantic's model or scipy.integrate."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

from mechsys.numeric import native
from tests.helpers import ROOT, SYSTEMS_DIR

pytestmark = pytest.mark.skipif(native.compiler() is None, reason="the warm plan needs the native path")

PROBE = """
import sys
from mechsys.cli import main
try:
    main()
except SystemExit as exc:
    code = exc.code
print("MODULES", "sympy" in sys.modules, "scipy.integrate" in sys.modules, "mechsys.model.schema" in sys.modules,
      file=sys.stderr)
sys.exit(code)
"""


def _run(tmp_path, *args, cache=None):
    env = {**os.environ, "MECHSYS_CACHE": str(cache or tmp_path / "cache")}
    proc = subprocess.run([sys.executable, "-c", PROBE, "simulate", *map(str, args)], capture_output=True,
                          text=True, env=env, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    line = [x for x in proc.stderr.splitlines() if x.startswith("MODULES")][-1]
    return proc.stdout, line.split()[1:] == ["False", "False", "False"]


def test_second_run_is_warm_identical_and_imports_no_sympy(tmp_path):
    model = tmp_path / "dp.yaml"
    shutil.copy(SYSTEMS_DIR / "double_pendulum.yaml", model)
    out1, out2 = tmp_path / "a.csv", tmp_path / "b.csv"
    first, light1 = _run(tmp_path, model, "--t-end", "3", "-o", out1)
    second, light2 = _run(tmp_path, model, "--t-end", "3", "-o", out2)
    assert not light1 and "warm plan" not in first
    assert light2 and "warm plan" in second
    assert out1.read_bytes() == out2.read_bytes()
    # a different horizon and output grid reuse the same plan
    third, light3 = _run(tmp_path, model, "--t-end", "1", "--dt", "0.01")
    assert light3 and "warm plan" in third


def test_plan_follows_the_file_and_the_options(tmp_path):
    model = tmp_path / "dp.yaml"
    shutil.copy(SYSTEMS_DIR / "double_pendulum.yaml", model)
    a, b, c = tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "c.csv"
    _run(tmp_path, model, "--t-end", "1", "-o", a)
    _, warm_set = _run(tmp_path, model, "--t-end", "1", "--set", "g=1.62", "-o", b)
    assert not warm_set  # new options: a new plan, built by the full path
    assert a.read_bytes() != b.read_bytes()
    _, warm_again = _run(tmp_path, model, "--t-end", "1", "--set", "g=1.62", "-o", c)
    assert warm_again and b.read_bytes() == c.read_bytes()
    model.write_text(model.read_text().replace("\n", "\n# edited\n", 1))
    _, warm_edit = _run(tmp_path, model, "--t-end", "1")
    assert not warm_edit  # any change to the file's bytes invalidates the plan


def test_options_that_need_the_model_take_the_full_path(tmp_path):
    model = SYSTEMS_DIR / "double_pendulum.yaml"
    _run(tmp_path, model, "--t-end", "1")
    _, light = _run(tmp_path, model, "--t-end", "1", "--method", "DOP853")
    assert not light
    _, light = _run(tmp_path, model, "--t-end", "1", "--reactions", "-o", tmp_path / "r.csv")
    assert not light


def test_stiff_horizon_is_not_run_from_the_plan(tmp_path):
    """auto's stiffness decision depends on t_end: the plan keeps the decay rate and redoes it."""
    model = ROOT / "tests" / "data" / "stiff_chain.yaml"
    first, _ = _run(tmp_path, model, "--t-end", "0.01")
    assert "native" in first
    _, light_short = _run(tmp_path, model, "--t-end", "0.01")
    assert light_short
    long_run, light_long = _run(tmp_path, model, "--t-end", "10", "--dt", "0.1")
    assert not light_long and ("CVODE" in long_run or "Radau" in long_run)


@pytest.mark.parametrize("name", ["four_bar", "rolling_disk"])
def test_closed_loops_and_rolling_start_warm_with_identical_results(tmp_path, name):
    """Projection needs only the constraint rows' generated source, so closed loops start warm too."""
    model = SYSTEMS_DIR / f"{name}.yaml"
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    _, light1 = _run(tmp_path, model, "--t-end", "1", "-o", a)
    second, light2 = _run(tmp_path, model, "--t-end", "1", "-o", b)
    assert not light1 and light2 and "warm plan" in second
    assert a.read_bytes() == b.read_bytes()


def test_drives_take_the_full_path(tmp_path):
    """Driving forces are multipliers of the Python equations: a model with prescribed coordinates never starts
    from a plan."""
    model = ROOT / "tests" / "data" / "slider_crank_driven.yaml"
    _run(tmp_path, model, "--t-end", "0.2")
    out, light = _run(tmp_path, model, "--t-end", "0.2")
    assert not light and "driving force" in out


def test_a_file_saved_during_a_run_does_not_get_the_old_plan(tmp_path, monkeypatch):
    """The plan was keyed by the file as it was after the run: a double pendulum saved with m2 = 3 while its m2 =
    0.8 run integrated stored the m2 = 0.8 plan under the new content's key, and every later run of that content
    integrated the old model. The key is now the loaded text's: the saved content runs its own model (as with the
    cache off), and the old content still finds its plan."""
    import mechsys.analysis.motion.charted as charted
    from mechsys.analysis.motion.simulate import SimulationOptions
    from mechsys.analysis.motion.warm import plan_key, simulate_file

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    old = (SYSTEMS_DIR / "double_pendulum.yaml").read_text().split("\nexpect:")[0] + "\n"
    new = old.replace("m2: 0.8", "m2: 3.0")
    assert new != old
    path = tmp_path / "dp.yaml"
    path.write_text(old)
    run = charted.simulate_charted

    def saved_meanwhile(*args, **kwargs):
        path.write_text(new)  # the user saves the file while the run integrates
        return run(*args, **kwargs)

    monkeypatch.setattr(charted, "simulate_charted", saved_meanwhile)
    options = SimulationOptions(t_end=1.0, dt=0.01)
    simulate_file(path, [], options)
    monkeypatch.setattr(charted, "simulate_charted", run)
    from mechsys.numeric import cache

    assert cache.load(plan_key(path, [], old)) is not None and cache.load(plan_key(path, [], new)) is None
    warm, _ = simulate_file(path, [], options)  # the new content: its own model
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    cold, _ = simulate_file(path, [], options)
    assert warm.q[-1].tolist() == cold.q[-1].tolist()
