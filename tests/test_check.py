"""`mechsys check`: the bundled expectations, failures and the JUnit/Markdown reports, sibling check files,
invalid expectations, discovery. See docs/check.md.

The whole-directory run (`mechsys check systems/`) takes about a minute on two cores and is marked slow; the
other tests use small copies of the bundled models in tmp_path and stay within a few seconds each.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from mechsys.analysis.batch.check import evaluate

ROOT = Path(__file__).resolve().parents[1]
SYSTEMS = ROOT / "systems"


def mechsys_check(*args, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mechsys", "check", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=600)


def model_without_expect(name: str) -> str:
    """The text of systems/<name>.yaml without its `expect:` section (the section is the end of the file)."""
    text = (SYSTEMS / f"{name}.yaml").read_text(encoding="utf-8")
    head, sep, _ = text.partition("\nexpect:\n")
    if not sep:
        return text
    # drop the comment lines that introduce the section as well
    lines = head.rstrip("\n").split("\n")
    while lines and lines[-1].startswith("#"):
        lines.pop()
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------- the bundled models
@pytest.mark.slow
def test_every_bundled_model_has_expectations_and_all_pass(tmp_path):
    proc = mechsys_check(SYSTEMS, "-f", "json", "--junit", tmp_path / "report.xml")
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    data = json.loads(proc.stdout)
    results = data["results"]
    assert data["failed"] == 0 and data["errors"] == 0 and data["passed"] == len(results) > 0
    assert all(r["status"] == "pass" for r in results), [r for r in results if r["status"] != "pass"]
    checked = {Path(r["file"]).name for r in results}
    models = {p.name for p in SYSTEMS.glob("*.yaml") if not p.name.endswith(".check.yaml")}
    assert models - checked == set(), f"model files without expectations: {sorted(models - checked)}"
    # every bundled model carries at least two expectations
    for name in models:
        assert sum(Path(r["file"]).name == name for r in results) >= 2, name
    suites = ET.parse(tmp_path / "report.xml").getroot()
    assert int(suites.get("tests")) == len(results) and suites.get("failures") == "0"


# ------------------------------------------------------------------------ a failing check and the reports
WRONG_CENTRIFUGE = """expect:
  - name: "centrifuge has 2 DOF"
    analysis: info
    output: dof
    value: 2
  - name: "centrifuge βs2 = -1.249420 stable (digest CEN-b)"
    analysis: equilibria
    equilibrium: {beta: -1.249420}
    stability: asymptotically stable
    tolerance: 1.0e-5
  - name: "centrifuge βs4 = 1.399 as misprinted in the book"
    analysis: equilibria
    equilibrium: {beta: 1.399}
    stability: asymptotically stable
    tolerance: 1.0e-5
"""


def test_a_wrong_expectation_fails_with_exit_1_and_junit_report(tmp_path):
    model = tmp_path / "centrifuge.yaml"
    model.write_text(model_without_expect("centrifuge") + WRONG_CENTRIFUGE, encoding="utf-8")
    junit, markdown = tmp_path / "out" / "check-report.xml", tmp_path / "check-report.md"
    (tmp_path / "out").mkdir()
    proc = mechsys_check(model, "--junit", junit, "--markdown", markdown, "-f", "markdown")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "centrifuge βs4 = 1.399 as misprinted in the book" in proc.stdout
    assert "2 passed, 1 failed, 0 errors" in proc.stdout
    failing = [line for line in proc.stdout.splitlines() if "1.399" in line]
    assert failing and "FAIL" in failing[0] and "no equilibrium within the tolerance" in failing[0]
    # the measured column lists the equilibria that were found, among them the recomputed 1.410445
    assert "1.41044" in failing[0]

    root = ET.parse(junit).getroot()
    suites = [root] if root.tag == "testsuite" else root.findall("testsuite")
    assert len(suites) == 1
    suite = suites[0]
    cases = suite.findall("testcase")
    assert int(suite.get("tests")) == len(cases) == 3
    assert int(suite.get("failures")) == 1 and int(suite.get("errors")) == 0
    failures = [c for c in cases if c.find("failure") is not None]
    assert len(failures) == 1 and failures[0].get("name") == "centrifuge βs4 = 1.399 as misprinted in the book"
    assert all(c.find("error") is None for c in cases)
    assert int(root.get("tests")) == 3 and int(root.get("failures")) == 1
    assert markdown.read_text(encoding="utf-8").count("| FAIL |") == 1


# --------------------------------------------------------------------- sibling files, invalid expectations
def test_sibling_check_file_is_discovered_and_markdown_written(tmp_path):
    (tmp_path / "p57.yaml").write_text(model_without_expect("problem57"), encoding="utf-8")
    (tmp_path / "p57.check.yaml").write_text(
        "expect:\n"
        "  - {name: 'three equilibria (sibling)', analysis: equilibria, output: count, value: 3}\n"
        "  - {name: 'q = pi stable (sibling)', analysis: equilibria, equilibrium: {q: 3.141592653589793},\n"
        "     stability: asymptotically stable, tolerance: 1.0e-9}\n"
        "  - {name: 'saddle root (sibling)', analysis: equilibria, output: eq2.max_real, value: 2.296908,\n"
        "     rel_tolerance: 1.0e-6}\n", encoding="utf-8")
    report = tmp_path / "report.md"
    proc = mechsys_check(tmp_path, "--markdown", report, "-f", "json")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    results = json.loads(proc.stdout)["results"]
    # the .check.yaml file is not itself taken for a model
    assert {Path(r["file"]).name for r in results} == {"p57.yaml"}
    assert [r["status"] for r in results] == ["pass"] * 3
    text = report.read_text(encoding="utf-8")
    assert "three equilibria (sibling)" in text and "saddle root (sibling)" in text
    assert "3 passed, 0 failed, 0 errors" in text


@pytest.mark.parametrize("entry, words", [
    ("{name: bad key, analysis: info, output: dof, value: 1, tolerence: 0.1}", ["tolerence"]),
    ("{name: bad analysis, analysis: eigenvalues, output: dof, value: 1}", ["analysis"]),
    # expectations that could not fail (they passed whatever the analysis gave) or were silently half ignored
    ("{name: no value, analysis: info, output: dof}", ["nothing to compare"]),
    ("{name: tolerance only, analysis: info, output: dof, tolerance: 0.5}", ["nothing to compare"]),
    ("{name: stability alone, analysis: equilibria, output: count, value: 3, stability: unstable}",
     ["'stability' needs 'equilibrium'"]),
    ("{name: empty equilibrium, analysis: equilibria, equilibrium: {}}", ["'equilibrium' is empty"]),
    ("{name: expression on simulate, analysis: simulate, output: final.q, expression: q}",
     ["'expression' belongs to analysis: derive"]),
    ("{name: derive value, analysis: derive, output: 'M[1,1]', value: 99}", ["give 'expression'"]),
    ("{name: derive nothing, analysis: derive, output: 'M[1,1]'}", ["give 'expression'"]),
    ("{name: equilibrium and value, analysis: equilibria, equilibrium: {q: 0}, value: 1}", ["not used"]),
    # options that were ignored (the run used the defaults: a check that should fail passed) or crashed the run
    ("{name: misspelt, analysis: simulate, options: {tend: 0.3}, output: final.q, min: 0}",
     ["simulate has no option 'tend'", "did you mean 't_end'"]),
    ("{name: dt zero, analysis: simulate, options: {t_end: 1, dt: 0}, output: final.q, min: 0}",
     ["dt must be a positive finite number"]),
    ("{name: t_end text, analysis: simulate, options: {t_end: abc}, output: final.q, min: 0}",
     ["t_end must be a positive finite number"]),
    ("{name: rtol, analysis: simulate, options: {rtol: 1e-9}, output: final.q, min: 0}", ["no option 'rtol'"]),
    ("{name: info options, analysis: info, options: {t_end: 1}, output: dof, value: 1}", ["info has no option"]),
    # expectations that can never fail or never pass
    ("{name: inf tolerance, analysis: info, output: dof, value: 5, tolerance: .inf}", ["'tolerance' must be a finite"]),
    ("{name: nan value, analysis: info, output: dof, value: .nan}", ["'value' must be a finite"]),
    ("{name: empty range, analysis: info, output: dof, min: 5, max: 0}", ["nothing can pass"]),
    ("{name: verdict, analysis: equilibria, equilibrium: {q: 0}, stability: wobbly}", ["stability"]),
])
def test_invalid_expectation_in_a_sibling_file_is_an_input_error(tmp_path, entry, words):
    (tmp_path / "p57.yaml").write_text(model_without_expect("problem57"), encoding="utf-8")
    (tmp_path / "p57.check.yaml").write_text(f"expect:\n  - {entry}\n", encoding="utf-8")
    proc = mechsys_check(tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr
    assert "p57.check.yaml" in lines[0] and all(w in lines[0] for w in words)


def test_invalid_expectation_in_the_model_file_is_an_input_error(tmp_path):
    model = tmp_path / "p57.yaml"
    model.write_text(model_without_expect("problem57")
                     + "expect:\n  - {name: x, analysis: equilibria, output: count, value: 3, colour: red}\n",
                     encoding="utf-8")
    proc = mechsys_check(model)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "p57.yaml" in lines[0] and "colour" in lines[0]


def test_a_misspelt_option_in_the_model_file_is_an_input_error_at_its_line(tmp_path):
    """`options: {tend: 0.3}` ran 10 s with the defaults, and the check passed where 0.3 s would fail."""
    model = tmp_path / "p57.yaml"
    text = model_without_expect("problem57")
    model.write_text(text + "expect:\n  - {name: x, analysis: simulate, options: {tend: 0.3}, output: final.q, "
                            "min: 0}\n", encoding="utf-8")
    proc = mechsys_check(model)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    line = len(text.splitlines()) + 2
    assert proc.stderr.strip() == (f"{model}:{line}:45: expect[0].options.tend: simulate has no option 'tend' "
                                   "(did you mean 't_end'?) (options: t_end, dt, method)")


def test_a_missing_path_is_an_input_error(tmp_path):
    proc = mechsys_check(tmp_path / "nowhere")
    assert proc.returncode == 2
    assert "no such file or directory" in proc.stderr


# ----------------------------------------------------------------------------------------------- discovery
def test_directories_are_searched_recursively_and_files_without_expectations_skipped(tmp_path):
    deep = tmp_path / "a" / "b"
    deep.mkdir(parents=True)
    (deep / "p57.yaml").write_text(model_without_expect("problem57")
                                   + "expect:\n  - {name: 'deep check', analysis: info, output: dof, value: 1}\n",
                                   encoding="utf-8")
    (tmp_path / "a" / "plain.yaml").write_text(model_without_expect("problem57"), encoding="utf-8")
    (tmp_path / "top.yaml").write_text(model_without_expect("spring_chain"), encoding="utf-8")
    proc = mechsys_check(tmp_path, "-f", "json")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    results = json.loads(proc.stdout)["results"]
    assert [(Path(r["file"]).name, r["name"], r["status"]) for r in results] == [("p57.yaml", "deep check", "pass")]


def test_no_expectations_at_all_is_reported(tmp_path):
    (tmp_path / "plain.yaml").write_text(model_without_expect("problem57"), encoding="utf-8")
    proc = mechsys_check(tmp_path, "-f", "markdown")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "no expectations found" in proc.stdout


# ------------------------------------------------------------------------------------- comparison rules
def expectation(**kw) -> dict:
    base = {"name": "x", "analysis": "info", "set": {}, "options": {}, "output": None, "equilibrium": None,
            "stability": None, "expression": None, "value": None, "tolerance": 0.0, "rel_tolerance": 0.0,
            "min": None, "max": None}
    return {**base, **kw}


@pytest.mark.parametrize("kw, measured, status", [
    ({"value": 2}, 2, "pass"),
    ({"value": 2}, 2.0000001, "fail"),                                   # no tolerance: exact
    ({"value": 1.0, "tolerance": 1e-3}, 1.0009, "pass"),
    ({"value": 1.0, "tolerance": 1e-3}, 1.0011, "fail"),
    ({"value": 100.0, "rel_tolerance": 1e-3}, 100.09, "pass"),
    ({"value": 100.0, "rel_tolerance": 1e-3}, 100.11, "fail"),
    ({"value": 100.0, "tolerance": 0.5, "rel_tolerance": 1e-3}, 100.4, "pass"),  # the larger one applies
    ({"max": 1e-9}, 5e-10, "pass"),
    ({"max": 1e-9}, 2e-9, "fail"),
    ({"min": 0.0, "max": 1.0}, -0.1, "fail"),
    ({"min": 0.0, "max": 1.0}, 0.5, "pass"),
    ({"value": 1.0, "tolerance": 1.0}, math.nan, "fail"),
    ({"value": False}, False, "pass"),
    ({"value": "unstable"}, "stable", "fail"),
])
def test_value_comparison_rules(kw, measured, status):
    got, _, _ = evaluate(expectation(output="y", **kw), {"y": measured}, "unused.yaml")
    assert got == status


def test_absent_output_fails_and_lists_the_outputs():
    status, measured, message = evaluate(expectation(output="mode9.frequency", value=1), {"mode1.frequency": 2.0},
                                         "unused.yaml")
    assert status == "fail" and measured == "(absent)" and "mode1.frequency" in message


def test_equilibrium_matching_and_verdict():
    outputs = {"count": 2, "eq1.q": -3.141592653589793, "eq1.stability": "asymptotically stable",
               "eq2.q": 0.0, "eq2.stability": "unstable"}
    ok = expectation(analysis="equilibria", equilibrium={"q": 0.0}, stability="unstable")
    assert evaluate(ok, outputs, "unused.yaml")[0] == "pass"
    wrong_verdict = expectation(analysis="equilibria", equilibrium={"q": 0.0}, stability="stable")
    status, _, message = evaluate(wrong_verdict, outputs, "unused.yaml")
    assert status == "fail" and "verdict" in message
    # default tolerance 1e-6 on every listed coordinate
    near = expectation(analysis="equilibria", equilibrium={"q": -3.14159})
    assert evaluate(near, outputs, "unused.yaml")[0] == "fail"
    near["tolerance"] = 1e-5
    assert evaluate(near, outputs, "unused.yaml")[0] == "pass"


def test_the_default_equilibrium_tolerance_follows_the_size_of_the_rests():
    """Rests of a MEMS model at x = 1.0e-6 and 1.5e-6 m: an expected rest at 1.2e-6 matched the one at 1.0e-6
    within the default 1e-6 and passed. The default is 1e-6 times the coordinate's size among the rests found
    (at most 1): 1e-6 at ordinary units, 1.5e-12 here."""
    outputs = {"count": 2, "eq1.x": 1.0e-6, "eq1.stability": "stable", "eq2.x": 1.5e-6, "eq2.stability": "unstable"}
    assert evaluate(expectation(analysis="equilibria", equilibrium={"x": 1.2e-6}), outputs, "u.yaml")[0] == "fail"
    assert evaluate(expectation(analysis="equilibria", equilibrium={"x": 1.0e-6 + 1e-13}, stability="stable"),
                    outputs, "u.yaml")[0] == "pass"
    loose = expectation(analysis="equilibria", equilibrium={"x": 1.2e-6}, tolerance=1e-6)
    assert evaluate(loose, outputs, "u.yaml")[0] == "pass"  # a tolerance given is the tolerance


SPRING_WITH_CLOSED_FORMS = """\
name: mass on a spring, its closed form in the expectations
parameters: {m: 2, k: 18, x0: 0.1}
coordinates:
  x: {initial: x0, rate: 0}
links:
  block: {joint: {type: prismatic, parent: ground, axis: x, coordinate: x}, mass: m}
forces:
  - {type: torsional_spring, coordinate: x, stiffness: k, free_angle: 0}
expect:
  - name: x(1) = x0 cos(sqrt(k/m))
    analysis: simulate
    options: {t_end: 1, dt: 0.01}
    output: final.x
    value: x0*cos(sqrt(k/m)*1)
    tolerance: 1.0e-8
  - name: with k = 8 set, x(1) = x0 cos(2)
    analysis: simulate
    set: {k: 8}
    options: {t_end: 1, dt: 0.01}
    output: final.x
    value: x0*cos(sqrt(k/m))
    tolerance: 1.0e-8
  - name: a wrong closed form fails
    analysis: simulate
    options: {t_end: 1, dt: 0.01}
    output: final.x
    value: x0*sin(sqrt(k/m))
    tolerance: 1.0e-8
  - name: an unknown name is an error
    analysis: simulate
    options: {t_end: 1, dt: 0.01}
    output: final.x
    value: x0*cos(omega)
    tolerance: 1.0e-8
"""


def test_a_value_written_as_a_closed_form_in_the_parameters_is_evaluated(tmp_path):
    """`value: 5/14*g*sin(alpha)` was compared as text with the measured number (a FAIL without a message, under an
    'expected' column showing its tolerance); it is now an expression of the parameters, with `set` applied."""
    path = tmp_path / "spring.yaml"
    path.write_text(SPRING_WITH_CLOSED_FORMS, encoding="utf-8")
    r = mechsys_check(path, "-f", "json")
    assert r.returncode == 1, r.stdout + r.stderr
    results = {x["name"]: x for x in json.loads(r.stdout)["results"]}
    assert [results[name]["status"] for name in ("x(1) = x0 cos(sqrt(k/m))", "with k = 8 set, x(1) = x0 cos(2)",
                                                   "a wrong closed form fails", "an unknown name is an error")] == [
        "pass", "pass", "fail", "error"]
    assert float(results["x(1) = x0 cos(sqrt(k/m))"]["measured"]) == pytest.approx(0.1 * math.cos(3), abs=1e-8)
    assert "= -0.09899924966" in results["x(1) = x0 cos(sqrt(k/m))"]["message"]
    assert float(results["with k = 8 set, x(1) = x0 cos(2)"]["measured"]) == pytest.approx(0.1 * math.cos(2), abs=1e-8)
    assert "unknown name 'omega'" in results["an unknown name is an error"]["message"]


@pytest.mark.parametrize("kw, text", [
    ({"tolerance": 1e-3}, "y = 1.0 ± 0.001"),
    ({"rel_tolerance": 1e-3}, "y = 1.0 ± 0.001 (relative)"),
    ({"tolerance": 1e-12, "rel_tolerance": 1e-3}, "y = 1.0 ± max(1e-12, 0.001 relative)"),  # the larger applies
])
def test_the_expected_text_shows_the_tolerance_that_applies(kw, text):
    """With both tolerances the text showed only the absolute one (± 1e-12) beside a pass by 3e-4."""
    from mechsys.analysis.batch.check import _expected_text

    assert _expected_text(expectation(output="y", value=1.0, **kw)) == text


MEMS_ROD = """\
name: mems_rod
parameters: {m: 1.0e-9, L: 1.0e-4, g: 9.81}
coordinates:
  theta: {initial: 0.1}
links:
  rod:
    joint: {type: revolute, parent: ground, axis: z, coordinate: theta}
    mass: m
    center_of_mass: [0, -L/2, 0]
    shape: {rod: {length: L, axis: y}}
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
expect:
  - {name: right M, analysis: derive, output: "M[1,1]", expression: m*L**2/3}
  - {name: right f, analysis: derive, output: "f[1]", expression: -m*g*L/2*sin(theta)}
  - {name: M a quarter, analysis: derive, output: "M[1,1]", expression: m*L**2/12}
  - {name: M zero, analysis: derive, output: "M[1,1]", expression: "0"}
  - {name: f sign, analysis: derive, output: "f[1]", expression: m*g*L/2*sin(theta)}
"""


def test_expression_checks_are_relative_to_the_entry_at_any_scale(tmp_path):
    """A MEMS rod (1e-9 kg, 100 um): M = m L^2/3 = 3.3e-18 about its end (closed form), f = -m g L/2 sin(theta).
    Against |a - b| / max(1, |a|, |b|) every wrong expectation passed, 0 included. Now the scale is the entry's
    own size: the right ones pass, a quarter of M, zero and the wrong sign fail with their true relative
    differences (3/4, 1, 2)."""
    model = tmp_path / "mems_rod.yaml"
    model.write_text(MEMS_ROD, encoding="utf-8")
    proc = mechsys_check(model, "-f", "json")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    rows = {r["name"]: r for r in json.loads(proc.stdout)["results"]}
    assert [rows[k]["status"] for k in ("right M", "right f", "M a quarter", "M zero", "f sign")] == \
        ["pass", "pass", "fail", "fail", "fail"]
    assert [rows[k]["message"] for k in ("M a quarter", "M zero", "f sign")] == \
        ["max relative difference 7.50e-01", "max relative difference 1.00e+00", "max relative difference 2.00e+00"]
