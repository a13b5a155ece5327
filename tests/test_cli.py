"""End-to-end CLI behaviour: derive JSON contract, --set, --check, formats, info, schema, atomic output."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import sympy as sp
from typer.testing import CliRunner

import mechsys
from mechsys.cli import app
from mechsys.model.expressions import parse_expression

ROOT = Path(__file__).resolve().parents[1]
CENTRIFUGE = ROOT / "systems" / "centrifuge.yaml"
runner = CliRunner()


def invoke(*args):
    result = runner.invoke(app, [str(a) for a in args])
    return result


def test_derive_json_contract_round_trips_through_the_parser():
    result = invoke("derive", CENTRIFUGE, "--format", "json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert set(data) >= {"name", "coordinates", "mass_matrix", "forcing", "kinetic_energy", "potential_energy",
                         "generalized_forces"}
    assert data["name"] == "centrifuge" and data["coordinates"] == ["alpha", "beta"]
    model = mechsys.load(CENTRIFUGE)
    eq = model.equations("lagrange")
    symbols = {**model.doc.parameters, **model.doc.coords}
    rates = model.doc.rates

    def parse(text):
        return parse_expression(text, symbols, rates)

    for i in range(2):
        assert sp.expand(parse(data["forcing"][i]) - eq.f[i]) == 0
        for j in range(2):
            assert sp.expand(parse(data["mass_matrix"][i][j]) - eq.M[i, j]) == 0
    assert sp.expand(parse(data["kinetic_energy"]) - eq.T) == 0
    assert parse(data["generalized_forces"][0]) == eq.Q[0]


def test_derive_check_reports_agreement_and_exit_0():
    result = invoke("derive", CENTRIFUGE, "--check")
    assert result.exit_code == 0
    assert "lagrange and kane agree" in result.stdout


def test_derive_check_in_json():
    data = json.loads(invoke("derive", CENTRIFUGE, "--check", "-f", "json", "--method", "kane").stdout)
    assert data["method"] == "kane" and data["check"]["agree"] is True
    assert data["check"]["max_relative_difference"] < 1e-12


@pytest.mark.parametrize("fmt, marker", [("text", "equations:"), ("latex", "\\begin{align*}"),
                                         ("markdown", "$$")])
def test_derive_formats(fmt, marker):
    result = invoke("derive", CENTRIFUGE, "-f", fmt)
    assert result.exit_code == 0 and marker in result.stdout
    if fmt != "text":
        assert "\\dot{\\alpha}" in result.stdout


def test_simplify_is_opt_in_and_equivalent():
    plain = json.loads(invoke("derive", CENTRIFUGE, "-f", "json").stdout)
    simple = json.loads(invoke("derive", CENTRIFUGE, "-f", "json", "--simplify").stdout)
    model = mechsys.load(CENTRIFUGE)
    syms = {**model.doc.parameters, **model.doc.coords}
    for a, b in zip(plain["forcing"], simple["forcing"]):
        assert sp.simplify(parse_expression(a, syms, model.doc.rates) - parse_expression(b, syms, model.doc.rates)) == 0


def test_set_overrides_parameter_and_initial_values():
    model = mechsys.load(CENTRIFUGE, {"Mo": "60", "beta": "1.04", "der(beta)": 0})
    assert model.parameters["Mo"] == 60 and model.parameters["dM"] == pytest.approx(60 / 7)
    assert model.doc.initial["beta"] == pytest.approx(1.04) and model.doc.initial_rate["beta"] == 0
    result = invoke("info", CENTRIFUGE, "--set", "m=3", "-f", "json")
    assert result.exit_code == 0


def test_set_errors_exit_2():
    result = invoke("derive", CENTRIFUGE, "--set", "nosuch=1")
    assert result.exit_code == 2


def test_output_is_written_atomically(tmp_path):
    out = tmp_path / "eom.json"
    result = invoke("derive", CENTRIFUGE, "-f", "json", "-o", out)
    assert result.exit_code == 0 and json.loads(out.read_text())["name"] == "centrifuge"
    assert [p.name for p in tmp_path.iterdir()] == ["eom.json"]
    # a failing run leaves the previous output untouched
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nlinks: {a: {joint: {type: revolute, parent: nowhere, coordinate: q}}}\n")
    assert invoke("derive", bad, "-f", "json", "-o", out).exit_code == 2
    assert json.loads(out.read_text())["name"] == "centrifuge"


def test_schema_is_json_schema():
    data = json.loads(invoke("schema").stdout)
    assert data["title"].startswith("mechsys") and "links" in data["properties"]


def test_info_json_centrifuge():
    data = json.loads(invoke("info", CENTRIFUGE, "-f", "json").stdout)
    assert data["dof"] == 2 and data["mobility"] == 2 and data["cyclic"] == ["alpha"]
    assert data["autonomous"] and not data["rheonomic"] and data["holonomic"]
    assert [j["joint_class"] for j in data["joints"]] == [1, 1]


def test_console_script_runs_without_traceback():
    proc = subprocess.run([sys.executable, "-m", "mechsys", "info", str(CENTRIFUGE), "-f", "markdown"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "| mobility" in proc.stdout and not proc.stderr


def test_only_the_executable_freezes_what_the_model_loaded(monkeypatch):
    """`mechsys` (cli.entry) moves what is alive once the model is loaded out of the garbage collector's view
    (gc.freeze: its full collections and the exit then skip sympy and the model); main() called in a long process
    (these tests, an embedding program) must not, or every command would pin its garbage for good."""
    import gc

    from mechsys import cli

    gc.unfreeze()
    try:
        cli.load_model(CENTRIFUGE, None)
        assert gc.get_freeze_count() == 0
        monkeypatch.setattr(cli, "_ONE_SHOT", True)
        cli.load_model(CENTRIFUGE, None)
        assert gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()
    out = subprocess.run([sys.executable, "-c", "import sys, gc; from mechsys import cli; "
                          "sys.argv = ['mechsys', 'info', sys.argv[1]]; cli.entry()", str(CENTRIFUGE)],
                         capture_output=True, text=True)
    assert out.returncode == 0 and "centrifuge" in out.stdout.lower()


def test_the_executable_sizes_sympys_caches_and_derives_the_same_text():
    """`mechsys` asks for larger sympy constructor caches before sympy is imported (cli.size_sympy_cache: equal
    subexpressions built far apart become one object), keeps a size the user chose, and the derived text is the
    same at sympy's default size, at the larger one and with no cache at all."""
    from mechsys import cli

    probe = ("from mechsys import cli; cli.size_sympy_cache(); import sympy.core.cache as c; "
             "print(c.SYMPY_CACHE_SIZE)")
    env = {k: v for k, v in os.environ.items() if k != "SYMPY_CACHE_SIZE"}
    size = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, check=True)
    assert size.stdout.strip() == str(cli.SYMPY_CACHE_SIZE) != "1000"
    chosen = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True,
                            env={**env, "SYMPY_CACHE_SIZE": "500"})
    assert chosen.stdout.strip() == "500"
    for model, method in ((ROOT / "systems" / "bicycle.yaml", "kane"),
                          (ROOT / "tests" / "data" / "beyond" / "furuta_rod_arm.yaml", "lagrange")):
        texts = set()
        for sizing in ({}, {"SYMPY_CACHE_SIZE": "1000"}, {"SYMPY_USE_CACHE": "no"}):
            out = subprocess.run([sys.executable, "-m", "mechsys", "derive", "--method", method, str(model)],
                                 capture_output=True, text=True, env={**env, "MECHSYS_CACHE": "off", **sizing})
            assert out.returncode == 0, out.stderr
            texts.add(out.stdout)
        assert len(texts) == 1
