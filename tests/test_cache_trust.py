"""The cache's trust model (numeric/cache.py, docs/simulate.md "The cache"): keys cover the order of names and the
value-dependent structure, cached results equal uncached ones, and nothing foreign, damaged or unsigned is ever
executed or loaded."""
from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

import mechsys
from mechsys.analysis.motion.simulate import compile_model, simulate
from mechsys.numeric import cache, native
from mechsys.model.yamlpos import load_yaml
from tests.helpers import DATA_DIR, ROOT, SYSTEMS_DIR

DP = SYSTEMS_DIR / "double_pendulum.yaml"
VANISHING = DATA_DIR / "vanishing_row.yaml"
needs_cc = pytest.mark.skipif(native.compiler() is None, reason="needs a C compiler")


@pytest.fixture
def private_cache(tmp_path, monkeypatch):
    """A cache folder and a signing key of this test's own."""
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    return tmp_path / "cache"


def _reordered(tmp_path: Path, source: Path, section: str) -> Path:
    """A copy of ``source`` with the mapping ``section`` in reverse order (the same model for a reader)."""
    data, _ = load_yaml(source.read_text(), str(source))  # keys as written (YAML 1.1 would read `on` as True)
    data[section] = dict(reversed(list(data.get(section, {}).items())))
    out = tmp_path / f"{source.stem}-{section}-reversed.yaml"
    out.write_text(yaml.safe_dump(data, sort_keys=False))
    return out


def _by_name(result) -> dict[str, np.ndarray]:
    return {name: result.q[:, k] for k, name in enumerate(result.coordinates)} | \
        {f"der({name})": result.u[:, k] for k, name in enumerate(result.coordinates)}


def _simulate(path: Path, overrides=None, **kw):
    return _by_name(simulate(mechsys.load(path, overrides), 2.0, 0.1, **kw))


@pytest.mark.parametrize("section", ["parameters", "coordinates"])
@pytest.mark.parametrize("method", ["auto", "DOP853"])
def test_reordered_names_never_reuse_code_compiled_for_another_order(private_cache, tmp_path, monkeypatch,
                                                                     section, method):
    """Issue 10.1: generated code reads parameters and states by position. Swapping two parameter (or coordinate)
    lines used to reuse the cached code: theta1(2 s) = 0.362363 instead of 0.287344."""
    original = _simulate(DP, method=method)
    swapped = _simulate(_reordered(tmp_path, DP, section), method=method)
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    uncached = _simulate(_reordered(tmp_path, DP, section), method=method)
    assert original["theta1"][-1] == pytest.approx(0.287344, abs=1e-6)
    for name, values in original.items():
        np.testing.assert_allclose(swapped[name], values, rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(swapped[name], uncached[name])


def test_a_value_that_changes_the_structure_changes_the_key(private_cache):
    """Issue 10.2: the pin's y row vanishes identically at h = 0 and is dropped. With --set h=1 the row exists;
    the code cached for h = 0 (one row) must not be reused. Checked against the closed forms in the model file."""
    free = simulate(mechsys.load(VANISHING), 1.0, 0.05)  # h = 0, cached first
    t = free.t
    np.testing.assert_allclose(free.q[:, 0], 0.1 * np.cos(math.sqrt(5.0) * t), atol=1e-7)
    np.testing.assert_allclose(free.q[:, 1], free.q[:, 0], atol=1e-9)
    locked_model = mechsys.load(VANISHING, {"h": "1"})
    assert len(locked_model.kin.constraints) == 2
    assert cache.model_key(locked_model, "simulate") != cache.model_key(mechsys.load(VANISHING), "simulate")
    locked = simulate(locked_model, 1.0, 0.05)
    assert np.max(np.abs(locked.q[:, :2])) < 1e-9  # cart and slider locked at 0
    np.testing.assert_allclose(locked.q[:, 2], 0.2 * np.cos(math.sqrt(10.0) * t), atol=1e-7)
    assert np.max(locked.residual) < 1e-9


def test_sweep_clones_rebuild_when_values_change_the_structure():
    """with_overrides (what sweep workers reuse) must not keep rows dropped under other values."""
    base = mechsys.load(VANISHING)
    same = base.with_overrides({"k": 20.0})
    assert same.kin is base.kin  # structure shared: nothing rebuilt
    changed = base.with_overrides({"h": 1.0})
    assert changed.kin is not base.kin and len(changed.kin.constraints) == 2
    assert len(base.kin.constraints) == 1


@needs_cc
@pytest.mark.slow
# the bicycle (a minute here) is left out: its steady-motion pieces have their own cached = uncached test
# (tests/test_nonholonomic.py) and its simulation takes the rolling disk's code path, which is in this list
@pytest.mark.parametrize("name", sorted(p.stem for p in SYSTEMS_DIR.glob("*.yaml") if p.stem != "bicycle"))
def test_cached_equals_uncached_for_every_bundled_model(name, private_cache, tmp_path, monkeypatch):
    """Cold (compiles and stores), warm (reads the cache) and uncached runs give identical numbers, also with the
    parameters listed in reverse order and a changed parameter value."""
    path = SYSTEMS_DIR / f"{name}.yaml"
    model = mechsys.load(path)
    variants = [(path, None), (_reordered(tmp_path, path, "parameters"), None)]
    variants += [(path, {name_: str(1.1 * value)}) for name_, value in list(model.parameters.items())[:1]]
    for source, overrides in variants:
        runs = []
        for setting in (str(private_cache), str(private_cache), "off"):
            monkeypatch.setenv("MECHSYS_CACHE", setting)
            runs.append(_by_name(simulate(mechsys.load(source, overrides), 0.5, 0.05)))
        for name_, values in runs[2].items():
            np.testing.assert_array_equal(runs[0][name_], values, err_msg=f"{source.name} {overrides} cold")
            np.testing.assert_array_equal(runs[1][name_], values, err_msg=f"{source.name} {overrides} warm")


# --------------------------------------------------------------------------------------------- safety
def _entries(folder: Path) -> list[Path]:
    return sorted(folder.glob("*.json"))


def test_a_tampered_entry_is_never_executed(private_cache, tmp_path):
    """Cached source is code once compiled: an entry whose bytes changed after signing is ignored and rebuilt."""
    marker = tmp_path / "PWNED"
    first = simulate(mechsys.load(DP), 0.5, 0.1, method="DOP853")
    for entry in _entries(private_cache):
        entry.write_bytes(entry.read_bytes().replace(b"math.sin(", f"__import__('os').system('touch {marker}') or math.sin(".encode()))
    model = mechsys.load(DP)
    again = simulate(model, 0.5, 0.1, method="DOP853")
    assert not marker.exists()
    assert compile_model(model).cache_hit is False
    np.testing.assert_array_equal(first.q, again.q)


def test_correctly_signed_code_is_still_refused_unless_it_is_arithmetic(private_cache, tmp_path):
    """Defence in depth: even an entry signed with the user's key is compiled only if it is plain arithmetic."""
    from mechsys.numeric.runtime import check_source

    marker = tmp_path / "PWNED"
    model = mechsys.load(DP)
    compile_model(model)
    key = cache.model_key(model, "simulate")
    entry = cache.load(key)
    entry["eqs"]["source"] = entry["eqs"]["source"].replace(
        "math.sin(", f"__import__('os').system('touch {marker}') or math.sin(", 1)
    cache.store(key, entry)
    fresh = mechsys.load(DP)
    assert compile_model(fresh).cache_hit is False
    assert not marker.exists()
    with pytest.raises(ValueError):
        check_source(entry["eqs"]["source"])


def test_entries_signed_with_another_key_are_ignored(private_cache, tmp_path, monkeypatch):
    """A cache folder restored from elsewhere (another branch's CI cache, another user) carries no valid
    signature for this user's key: everything is rebuilt."""
    compile_model(mechsys.load(DP))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "other-config"))
    assert compile_model(mechsys.load(DP)).cache_hit is False


def test_group_writable_entries_and_folders_are_not_trusted(private_cache, monkeypatch):
    compile_model(mechsys.load(DP))
    for entry in _entries(private_cache):
        entry.chmod(0o666)
    assert compile_model(mechsys.load(DP)).cache_hit is False
    private_cache.chmod(0o777)
    assert cache.usable_dir() is None
    model = mechsys.load(DP)
    assert compile_model(model).cache_hit is False and simulate(model, 0.2, 0.1).q.shape == (3, 2)


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="chown to another user needs root")
def test_entries_owned_by_another_user_are_ignored(private_cache):
    compile_model(mechsys.load(DP))
    for entry in _entries(private_cache):
        os.chown(entry, 12345, 12345)
    assert compile_model(mechsys.load(DP)).cache_hit is False


def test_the_cache_folder_and_key_are_private(private_cache, tmp_path):
    compile_model(mechsys.load(DP))
    assert private_cache.stat().st_mode & 0o777 == 0o700
    key = tmp_path / "config" / "mechsys" / "cache.key"
    assert key.stat().st_mode & 0o777 == 0o600 and len(key.read_bytes()) == 32
    assert all(e.stat().st_mode & 0o077 == 0 for e in private_cache.iterdir())


def _cli(args, tmp_path, **env):
    full = {**os.environ, "MECHSYS_CACHE": str(tmp_path / "cache"), "XDG_CONFIG_HOME": str(tmp_path / "config"),
            **env}
    return subprocess.run([sys.executable, "-m", "mechsys", *map(str, args)], capture_output=True, text=True,
                          env=full, cwd=ROOT, timeout=300)


@needs_cc
@pytest.mark.parametrize("damage", ["truncate", "empty", "garbage"])
def test_a_damaged_library_is_rebuilt_not_loaded(tmp_path, damage):
    """A truncated .so used to kill every later run with SIGBUS; an empty one gave a permanent internal error."""
    args = ["simulate", DP, "--t-end", "2", "-o", tmp_path / "a.csv"]
    assert _cli(args, tmp_path).returncode == 0
    for lib in (tmp_path / "cache").glob("*.so"):
        data = lib.read_bytes()
        lib.write_bytes({"truncate": data[: len(data) // 2], "empty": b"", "garbage": os.urandom(len(data))}[damage])
    for plan_run in range(2):  # the warm plan names the library: it must not load it either
        proc = _cli(["simulate", DP, "--t-end", "2", "-o", tmp_path / "b.csv"], tmp_path)
        assert proc.returncode == 0, proc.stderr
        assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()


@needs_cc
def test_an_inconsistent_plan_falls_back_to_the_full_path(private_cache, tmp_path):
    """A plan whose arrays do not fit its library (a short initial state) is not run: the C code would read past
    the end. The full path gives the right answer."""
    ok = _cli(["simulate", DP, "--t-end", "2", "-o", tmp_path / "a.csv"], tmp_path)  # same cache and key
    assert ok.returncode == 0, ok.stderr
    plans = [key for key in (p.stem for p in _entries(private_cache)) if "initial" in (cache.load(key) or {})]
    assert len(plans) == 1
    entry = cache.load(plans[0])
    entry["initial"] = entry["initial"][:1]
    cache.store(plans[0], entry)
    proc = _cli(["simulate", DP, "--t-end", "2", "-o", tmp_path / "b.csv"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "warm plan" not in proc.stdout
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()


@needs_cc
def test_native_off_also_bypasses_a_warm_plan(tmp_path):
    for _ in range(2):
        assert _cli(["simulate", DP, "--t-end", "1"], tmp_path).returncode == 0
    proc = _cli(["simulate", DP, "--t-end", "1"], tmp_path, MECHSYS_NATIVE="off")
    assert proc.returncode == 0, proc.stderr
    assert "warm plan" not in proc.stdout and "DOP853" in proc.stdout


@needs_cc
@pytest.mark.parametrize("setting", ["off", "below-a-file"])
def test_temporary_build_folders_are_removed(tmp_path, setting):
    """Without a usable cache the library is built in a temporary folder, which used to stay behind."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    (tmp_path / "a-file").write_text("x")
    cache_setting = "off" if setting == "off" else str(tmp_path / "a-file" / "cache")
    proc = _cli(["simulate", DP, "--t-end", "1"], tmp_path, MECHSYS_CACHE=cache_setting, TMPDIR=str(tmp))
    assert proc.returncode == 0, proc.stderr
    assert "native" in proc.stdout
    assert list(tmp.iterdir()) == []


def test_sweep_model_copies_live_in_a_private_folder(tmp_path):
    """The sweep's copies of a model file used a predictable /tmp/mechsys-sweep-<uid> that was reused if it
    existed (anyone could plant a model there); now each process has its own mkdtemp folder."""
    from mechsys.analysis.batch import sweep

    text = DP.read_text()
    spec = {"path": str(tmp_path / "gone.yaml"), "text": text, "digest": "abc"}
    copy = Path(sweep._model_file(spec))
    assert copy.read_text() == text
    assert copy.parent.stat().st_mode & 0o777 == 0o700
    assert copy.parent.name != f"mechsys-sweep-{os.getuid()}"


def test_the_arithmetic_check_allows_what_sympy_prints_and_nothing_else():
    import sympy as sp

    from mechsys.numeric.lambdify import generate_source
    from mechsys.numeric.runtime import check_source, function_from_source

    x = sp.Symbol("x")
    printed = generate_source([sp.nan, -sp.oo, sp.oo, sp.Piecewise((x, x > 0), (-x, True)), sp.Max(x, 1) + sp.Abs(x),
                               sp.sign(x) * sp.sqrt(x**2 + 1) / sp.pi, sp.atan2(x, 2) ** sp.Rational(3, 2),
                               sp.Float(2.5) * x - 3], [x])
    out = function_from_source(printed)(-2.0)
    assert math.isnan(out[0]) and out[1] == -math.inf and out[2] == math.inf and out[3] == 2.0
    assert out[4] == 3.0 and out[5] == pytest.approx(-math.sqrt(5) / math.pi) and out[7] == -8.0
    fn = function_from_source("def _f(a0):\n    return [1.0 if a0 > 0 and a0 < 3 or not a0 else -a0, (1, 2.0)]")
    assert fn(2.0) == [1.0, (1, 2.0)] and fn(4.0) == [-4.0, (1, 2.0)]
    for bad in ["def _f(a0):\n    return [float('1e5')]", "def _f(a0):\n    return [abs('x')]",
                "def _f(a0):\n    return [float('nan')]", "def _f(a0):\n    return [b'x']",
                "def _f(a0):\n    return [getattr(a0, 'real')]", "def _f(a0):\n    return [math.__loader__]",
                "def _f(a0):\n    return [a0.real]", "def _f(a0):\n    return [a0[0]]", "def _f(a0):\n    return [1j]",
                "def _f(a0):\n    return [f(a0)]", "def _f(a0):\n    return [abs(a0, key=1)]",
                "def _f(a0):\n    global g\n    g = 1\n    return [a0]", "def _f(a0):\n    a0.x = 1\n    return [a0]",
                "def _f(a0):\n    import os\n    return [a0]", "def _f(a0):\n    from math import sin\n    return [a0]",
                "def _f(a0):\n    while a0:\n        pass\n    return [a0]",
                "def _f(a0):\n    return [x for x in (1, 2)]", "def _f(a0):\n    return [lambda: 1]",
                "def _f(a0):\n    return [a0 in (1, 2)]", "def _f(a0):\n    return [a0 is None]",
                "def _f(a0):\n    yield a0", "def _f(*a):\n    return [1]", "def _f(a0, *, k):\n    return [1]",
                "def _f(a0=math):\n    return [a0]", "def _f(a0: int):\n    return [a0]",
                "@abs\ndef _f(a0):\n    return [a0]", "def _g(a0):\n    return [a0]",
                "def _f(a0):\n    return [a0]\nx = 1", "import os\ndef _f(a0):\n    return [a0]",
                "def _f(a0):\n    def h():\n        return a0\n    return [h]", "def _f(a0):\n    del a0\n    return [1]",
                "def _f(a0):\n    return [{a0: 1}]", "def _f(a0):\n    return [{a0}]",
                "def _f(a0):\n    return [__import__('os')]", "def _f(a0):\n    return [math.sin.__self__]"]:
        with pytest.raises(ValueError):
            check_source(bad)


def test_the_stored_steady_motion_pieces_do_not_decide_autonomy_for_other_values(private_cache, tmp_path):
    """The rolling disk with a lean torque A sin(w t): at A = 0 it is autonomous (steady motions), at A = 1 it is
    not (f has sin(w t): no steady motion). The nonholonomic pieces' cache entry (keyed without parameter values)
    stored 'autonomous' from the first run, so `equilibria --set A=1` after an A = 0 run listed two 'stable'
    steady motions, and A = 0 after A = 1 refused. Each order now gives what an uncached run gives."""
    from typer.testing import CliRunner

    from mechsys.cli import app

    text = (SYSTEMS_DIR / "rolling_disk.yaml").read_text().split("\nexpect:")[0]
    data, _ = load_yaml(text, "rolling_disk.yaml")
    data["parameters"].update({"A": 0, "w": 3})
    data["forces"].append({"type": "generalized_force", "coordinate": "lean", "value": "A*sin(w*t)"})
    path = tmp_path / "disk_pushed.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    runner = CliRunner()
    for order in (("0", "1"), ("1", "0")):
        for value in order:
            result = runner.invoke(app, ["equilibria", str(path), "--set", f"A={value}", "-f", "json"])
            if value == "0":
                assert result.exit_code == 0, result.output
            else:
                assert result.exit_code == 1 and "non-autonomous" in result.output, result.output
