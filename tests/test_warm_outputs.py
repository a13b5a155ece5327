"""Warm outputs of `derive`, `info`, `equilibria` and `modes` (report/warm.py): a repeated command prints what
the full path printed, byte for byte, without importing sympy; the key follows the file, the options, the code
and the numeric path; damaged entries, `derive --check`, `--verify` and `--plot` take the full path."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from mechsys.cli import app
from mechsys.numeric import cache
from mechsys.report import warm
from tests.helpers import ROOT, SYSTEMS_DIR

PROBE = """
import sys
from mechsys.cli import main
try:
    main()
except SystemExit as exc:
    code = exc.code
print("SYMPY", "sympy" in sys.modules, file=sys.stderr)
sys.exit(code)
"""

MODELS = sorted(p.name for p in SYSTEMS_DIR.glob("*.yaml"))


def _probe(cache_dir, *args) -> tuple[str, bool]:
    env = {**os.environ, "MECHSYS_CACHE": str(cache_dir)}
    proc = subprocess.run([sys.executable, "-c", PROBE, *map(str, args)], capture_output=True, text=True, env=env,
                          cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    line = [x for x in proc.stderr.splitlines() if x.startswith("SYMPY")][-1]
    return proc.stdout, line.split()[1] == "True"


def _cli(monkeypatch, cache_dir, *args) -> str:
    monkeypatch.setenv("MECHSYS_CACHE", str(cache_dir))
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.stdout


def test_a_second_derive_and_info_print_the_same_without_sympy(tmp_path):
    model = tmp_path / "centrifuge.yaml"
    shutil.copy(SYSTEMS_DIR / "centrifuge.yaml", model)
    full = []
    for args in (["derive", model], ["info", model], ["derive", model, "-m", "kane", "-f", "latex"],
                 ["info", model, "-f", "json"]):
        first, sympy1 = _probe(tmp_path / "cache", *args)
        second, sympy2 = _probe(tmp_path / "cache", *args)
        assert first == second and first.strip()
        assert sympy2 is False
        full.append(sympy1)
    assert full == [True, True, True, False]  # info's facts serve every format: `info -f json` was warm at once
    # written to a file: the same text as printed
    out = tmp_path / "eq.txt"
    printed, _ = _probe(tmp_path / "cache", "derive", model)
    _probe(tmp_path / "cache", "derive", model, "-o", out)
    assert out.read_text() == printed


@pytest.mark.slow
@pytest.mark.parametrize("name", MODELS)
def test_warm_outputs_equal_the_full_paths_for_every_bundled_model(name, tmp_path, monkeypatch):
    """The first run (full path, kept) and the second (warm) print the same bytes, in every format kept."""
    for args in (["derive", SYSTEMS_DIR / name], ["derive", SYSTEMS_DIR / name, "-m", "kane", "-f", "json"],
                 ["info", SYSTEMS_DIR / name], ["info", SYSTEMS_DIR / name, "-f", "markdown"]):
        first = _cli(monkeypatch, tmp_path / "cache", *args)
        key = warm.output_key(args[0], args[1], _options(args))
        assert cache.load(key) is not None  # kept by the first run
        assert _cli(monkeypatch, tmp_path / "cache", *args) == first


def _options(args: list) -> dict:
    if args[0] == "info":
        return {"set": []}
    method = args[args.index("-m") + 1] if "-m" in args else "lagrange"
    fmt = args[args.index("-f") + 1] if "-f" in args else "text"
    return {"set": [], "method": method, "format": fmt, "raw": False, "simplify": False, "subexpressions": "auto"}


def test_the_key_follows_the_file_the_options_and_the_code(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    model = tmp_path / "m.yaml"
    shutil.copy(SYSTEMS_DIR / "double_pendulum.yaml", model)
    base = {"set": [], "method": "lagrange", "format": "text", "raw": False, "simplify": False,
            "subexpressions": "auto"}
    key = warm.output_key("derive", model, base)
    assert key == warm.output_key("derive", model, dict(base))
    others = [warm.output_key("info", model, base)]
    others += [warm.output_key("derive", model, {**base, k: v}) for k, v in
               [("set", ["m1=2"]), ("method", "kane"), ("format", "json"), ("raw", True), ("simplify", True),
                ("subexpressions", "named"), ("subexpressions", "inline")]]
    others.append(warm.output_key("derive", model, {**base, "set": ["a=1", "b=2"]}))
    others.append(warm.output_key("derive", model, {**base, "set": ["b=2", "a=1"]}))
    model.write_text(model.read_text() + "\n# a comment changes the bytes\n")
    others.append(warm.output_key("derive", model, base))
    monkeypatch.setattr(warm, "_SOURCE", ["another version of the code"])
    shutil.copy(SYSTEMS_DIR / "double_pendulum.yaml", model)
    others.append(warm.output_key("derive", model, base))
    assert key not in others and len(set(others)) == len(others)
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    assert warm.output_key("derive", model, base) is None
    assert warm.output_key("derive", tmp_path / "missing.yaml", base) is None


def test_an_edited_file_prints_its_own_equations(tmp_path, monkeypatch):
    model = tmp_path / "m.yaml"
    shutil.copy(SYSTEMS_DIR / "double_pendulum.yaml", model)
    first = _cli(monkeypatch, tmp_path / "cache", "derive", model, "-f", "json")
    text = model.read_text()
    assert "name: double_pendulum" in text
    model.write_text(text.replace("name: double_pendulum", "name: renamed_pendulum"))
    second = _cli(monkeypatch, tmp_path / "cache", "derive", model, "-f", "json")
    assert '"renamed_pendulum"' in second and '"renamed_pendulum"' not in first


def test_damaged_entries_are_ignored_and_check_always_runs(tmp_path, monkeypatch):
    model = SYSTEMS_DIR / "double_pendulum.yaml"
    fresh = _cli(monkeypatch, tmp_path / "fresh", "derive", model)
    info_fresh = _cli(monkeypatch, tmp_path / "fresh", "info", model, "-f", "json")
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    key = warm.output_key("derive", model, _options(["derive", model]))
    cache.store(key, {"text": ["not", "text"]})
    assert warm.load_text(key) is None
    assert _cli(monkeypatch, tmp_path / "cache", "derive", model) == fresh
    info_key = warm.output_key("info", model, {"set": []})
    cache.store(info_key, {"info": {"name": "x", "moving_links": "many"}})
    assert warm.load_info(info_key) is None
    assert _cli(monkeypatch, tmp_path / "cache", "info", model, "-f", "json") == info_fresh
    # a kept output with another check line is never read by --check: the check runs
    checked = _cli(monkeypatch, tmp_path / "cache", "derive", model, "--check")
    assert "check:" in checked and "check:" not in fresh


def test_facts_that_are_not_plain_data_are_not_kept(tmp_path, monkeypatch):
    import numpy as np

    from mechsys.analysis.facts import Info

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    model = SYSTEMS_DIR / "double_pendulum.yaml"
    _cli(monkeypatch, tmp_path / "cache", "info", model, "-f", "json")
    key = warm.output_key("info", model, {"set": []})
    facts = warm.load_info(key)
    assert isinstance(facts, Info) and Info.from_dict(facts.to_dict()) == facts
    other = warm.output_key("info", model, {"set": ["m1=2"]})
    facts.mobility = np.int64(facts.mobility)  # not JSON: not kept (no error either)
    warm.store_info(other, facts)
    assert cache.load(other) is None


#: models whose equilibria and modes are compared (holonomic, cyclic, prescribed, closed loop, rolling)
NUMERIC_MODELS = ["double_pendulum.yaml", "centrifuge.yaml", "indicator.yaml", "four_bar.yaml", "rolling_disk.yaml"]


@pytest.mark.slow
@pytest.mark.parametrize("name", NUMERIC_MODELS)
def test_warm_equilibria_and_modes_equal_the_full_paths(name, tmp_path, monkeypatch):
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    for args in (["equilibria", SYSTEMS_DIR / name], ["equilibria", SYSTEMS_DIR / name, "-f", "json"],
                 ["modes", SYSTEMS_DIR / name, "-f", "json"], ["modes", SYSTEMS_DIR / name, "-f", "markdown"]):
        first = CliRunner().invoke(app, [str(a) for a in args])
        second = CliRunner().invoke(app, [str(a) for a in args])
        assert (second.exit_code, second.stdout) == (first.exit_code, first.stdout)
        assert first.exit_code in (0, 1)  # modes without a stable equilibrium ends with a reason (and nothing kept)


def test_a_second_sweep_and_modes_print_the_same_without_sympy(tmp_path):
    model = tmp_path / "centrifuge.yaml"
    shutil.copy(SYSTEMS_DIR / "centrifuge.yaml", model)
    for args in (["equilibria", model, "--set", "dM=7.142857142857143", "--sweep", "Mo=10:70:61", "-f", "csv"],
                 ["modes", model], ["equilibria", model, "--linearize", "-f", "json"]):
        first, sympy1 = _probe(tmp_path / "cache", *args)
        second, sympy2 = _probe(tmp_path / "cache", *args)
        assert first == second and first.strip()
        assert sympy1 is True and sympy2 is False


def test_the_numeric_commands_key_follows_the_options_and_the_numeric_path(tmp_path, monkeypatch):
    model = tmp_path / "c.yaml"
    shutil.copy(SYSTEMS_DIR / "centrifuge.yaml", model)
    first = _cli(monkeypatch, tmp_path / "cache", "equilibria", model, "-f", "markdown")
    for extra in (["--set", "Mo=30"], ["--search", "beta=-1:1"], ["--linearize"], ["--hurwitz"], ["-f", "csv"]):
        assert _cli(monkeypatch, tmp_path / "cache", "equilibria", model, "-f", "markdown", *extra) != first
    monkeypatch.setenv("MECHSYS_NATIVE", "off")  # the Python path: another key (its last digits may differ)
    assert warm.numeric_path() == {"compiler": None, "quick": None}
    base = {"set": [], "format": "json"}
    keys = {warm.output_key("modes", model, {**base, **warm.numeric_path()})}
    monkeypatch.delenv("MECHSYS_NATIVE")
    keys.add(warm.output_key("modes", model, {**base, **warm.numeric_path()}))
    monkeypatch.setenv("MECHSYS_QUICK_CC", "off")  # the steady-motion pieces built by the C compiler, not tcc
    keys.add(warm.output_key("modes", model, {**base, **warm.numeric_path()}))
    monkeypatch.delenv("MECHSYS_QUICK_CC")
    from mechsys.numeric import native

    cc = native.compiler()
    assert len(keys) == (1 if cc is None else 2 if native.quick_compiler() == cc else 3)


def test_kept_tables_read_back_as_printed_and_damaged_ones_are_ignored(tmp_path, monkeypatch):
    from mechsys.report.tables import Table, render_tables

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    t = Table("t", ["a", "b"], [[1, 2.5], [complex(1.0, -2.0), "x"], [True, None], [float("nan"), 1e300]], ["note"])
    payload = {"x": [1.0, 2.0], "z": complex(0.5, 1.5)}
    warm.store_tables("k" * 32, [t], payload)
    tables, back = warm.load_tables("k" * 32)
    for fmt in ("json", "csv", "markdown", "latex"):
        assert render_tables(tables, fmt, back) == render_tables([t], fmt, payload)
    cache.store("d" * 32, {"tables": [{"title": 1, "columns": [], "notes": [], "rows": []}], "payload": None})
    assert warm.load_tables("d" * 32) is None
    cache.store("e" * 32, {"tables": [{"title": "t", "columns": ["a"], "notes": [], "rows": [[{"x": 1}]]}]})
    assert warm.load_tables("e" * 32) is None
    import numpy as np

    warm.store_tables("f" * 32, [Table("t", ["a"], [[np.int64(3)]])], None)  # not a plain cell: not kept
    assert cache.load("f" * 32) is None


def test_a_second_codegen_writes_the_same_files_without_sympy(tmp_path, monkeypatch):
    """codegen keeps the package's files: the repeat writes them byte for byte without sympy; an edited file, a
    file of another name (printed in the package), another method and a damaged entry take the full path."""
    model = tmp_path / "four_bar.yaml"
    shutil.copy(SYSTEMS_DIR / "four_bar.yaml", model)

    def files(folder):
        return {f.name: f.read_bytes() for f in sorted(folder.iterdir())}

    first, sympy1 = _probe(tmp_path / "cache", "codegen", model, "-t", "c", "-o", tmp_path / "a")
    second, sympy2 = _probe(tmp_path / "cache", "codegen", model, "-t", "c", "-o", tmp_path / "b")
    assert sympy1 is True and sympy2 is False
    assert first.replace(str(tmp_path / "a"), "") == second.replace(str(tmp_path / "b"), "")
    assert files(tmp_path / "a") == files(tmp_path / "b")
    fresh = tmp_path / "fresh"
    _cli(monkeypatch, tmp_path / "off", "codegen", model, "-t", "c", "-o", fresh)  # another cache: the full path
    assert files(fresh) == files(tmp_path / "a")

    renamed = tmp_path / "linkage.yaml"
    shutil.copy(model, renamed)
    _, sympy3 = _probe(tmp_path / "cache", "codegen", renamed, "-t", "c", "-o", tmp_path / "c")
    assert sympy3 is True and "linkage.yaml" in (tmp_path / "c" / "README.md").read_text()
    _, sympy4 = _probe(tmp_path / "cache", "codegen", model, "-t", "c", "-m", "kane", "-o", tmp_path / "d")
    assert sympy4 is True
    model.write_text(model.read_text().replace("name: four_bar", "name: edited_bar"))
    _, sympy5 = _probe(tmp_path / "cache", "codegen", model, "-t", "c", "-o", tmp_path / "e")
    assert sympy5 is True and "edited_bar" in (tmp_path / "e" / "README.md").read_text()

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    key = warm.output_key("codegen", model, {"set": [], "method": "lagrange", "target": "c", "name": model.name})
    assert warm.load_files(key) is not None  # the key the command uses
    for damaged in ({"files": {"../escape.c": "x"}}, {"files": {"a.c": 1}}, {"files": {}}, {"text": "x"}):
        cache.store(key, damaged)
        assert warm.load_files(key) is None


def test_a_file_saved_between_the_key_and_the_load_keeps_no_output(tmp_path, monkeypatch):
    """`derive` hashed the file once for its key and read it again to load the model: a file saved in between (m2
    0.8 -> 3.0) stored m2 = 3.0's equations under m2 = 0.8's key, and every later `derive` of the m2 = 0.8 content
    printed m2 = 3.0. Such an output is now not kept; an unchanged file's is."""
    from mechsys.cli import load_model

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    old = (SYSTEMS_DIR / "double_pendulum.yaml").read_text().split("\nexpect:")[0] + "\n"
    path = tmp_path / "dp.yaml"
    path.write_text(old)
    key = warm.output_key("derive", path, {"format": "json"})
    path.write_text(old.replace("m2: 0.8", "m2: 3.0"))  # saved while the command imports
    model = load_model(path, None)
    assert model.parameters["m2"] == 3.0
    warm.store_text(key, "m2 = 3.0's equations")
    assert warm.load_text(key) is None
    path.write_text(old)
    key = warm.output_key("derive", path, {"format": "json", "other": 1})
    load_model(path, None)
    warm.store_text(key, "m2 = 0.8's equations")
    assert warm.load_text(key) == "m2 = 0.8's equations"
