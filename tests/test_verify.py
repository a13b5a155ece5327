"""`mechsys equilibria --verify` (mechsys/analysis/equilibrium/verify.py): perturbed motions about each equilibrium against its
verdict. The bundled centrifuge (four steady motions at omega = 7: unstable, asymptotically stable, unstable,
asymptotically stable; digest §2.2) and problem 57 (§2.1) agree; a conservative pendulum agrees (hanging bounded,
inverted grows); a deliberately wrong verdict is flagged; the CLI's exit status and JSON shape; the documented
example of docs/equilibria.md runs as printed."""
from __future__ import annotations

import copy
import json
import math
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.equilibrium.equilibria import find_equilibria
from mechsys.analysis.equilibrium.verify import (VerifyOptions, agreement, disagreements, horizon, verify_equilibria,
                                     verify_equilibrium)
from mechsys.cli import app

ROOT = Path(__file__).resolve().parents[1]
SYSTEMS = ROOT / "systems"
runner = CliRunner()

PENDULUM = """
name: pendulum
parameters: {m: 1.0, l: 0.8, g: 9.81}
coordinates:
  theta: {initial: 0.1, rate: 0}
links:
  rod:
    joint: {type: revolute, parent: ground, axis: z, coordinate: theta}
    mass: m
    center_of_mass: [0, -l/2, 0]
    shape: {rod: {length: l, axis: y}}
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
"""


def _solved(path: Path):
    model = mechsys.load(path)
    return model, find_equilibria(model)


@pytest.fixture(scope="module")
def problem57():
    return _solved(SYSTEMS / "problem57.yaml")


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory):
    path = tmp_path_factory.mktemp("verify") / "pendulum.yaml"
    path.write_text(PENDULUM)
    return _solved(path)


def _by_coordinate(result, name: str, value: float):
    (e,) = [e for e in result.equilibria if abs(e.coordinates[name] - value) < 1e-6]
    return e


# ------------------------------------------------------------------------------------------ (a) bundled systems
def test_centrifuge_steady_motions_all_agree():
    model, result = _solved(SYSTEMS / "centrifuge.yaml")
    checks = verify_equilibria(model, result)
    assert [e.stability for e in result.equilibria] == ["unstable", "asymptotically stable", "unstable",
                                                        "asymptotically stable"]
    assert [v.observed for v in checks] == ["grows", "decays", "grows", "decays"]
    assert all(v.agrees is True for v in checks)
    assert disagreements(result, checks) == []
    # horizons from the eigenvalues: at the saddles the growth time ln(1e4)/max Re is shorter than the lower
    # bound, 10 time constants of the fastest eigenvalue (here the growing one); 5 time constants of the slow pair
    # at beta_s4
    assert checks[0].horizon == pytest.approx(10 / 7.283931, rel=1e-5)
    assert checks[2].horizon == pytest.approx(10 / 5.171886, rel=1e-5)
    assert checks[3].horizon == pytest.approx(5 / 0.018968, rel=1e-3)
    assert all(len(v.runs) == 4 and not v.clamped for v in checks)


def test_problem57_all_agree(problem57):
    model, result = problem57
    checks = verify_equilibria(model, result)
    assert [(e.stability, v.observed, v.agrees) for e, v in zip(result.equilibria, checks)] == [
        ("asymptotically stable", "decays", True), ("unstable", "grows", True),
        ("asymptotically stable", "decays", True)]
    # linear decay: |x| shrinks like exp(-t) (Re = -1); growth is the largest value over the last window, one
    # period 2 pi / 4.328881 long, so it is about exp(-(horizon - period))
    period = 2 * math.pi / 4.328881
    assert checks[0].horizon == pytest.approx(5 * period, rel=1e-6)
    assert checks[0].growth == pytest.approx(math.exp(-(checks[0].horizon - period)), rel=0.2)
    assert checks[1].horizon == pytest.approx(math.log(1e4) / (-1 + math.sqrt(1 + math.pi**2)), rel=1e-9)


def test_runs_are_deterministic(problem57):
    model, result = problem57
    e = _by_coordinate(result, "q", 0.0)
    a, b = verify_equilibrium(model, e), verify_equilibrium(model, e)
    assert [r.peak for r in a.runs] == [r.peak for r in b.runs]
    c = verify_equilibrium(model, e, VerifyOptions(perturbations=2, seed=5))
    assert len(c.runs) == 2 and c.agrees is True


# ------------------------------------------------------------------------------------------ (b) conservative
def test_conservative_pendulum_hanging_bounded_inverted_grows(pendulum):
    model, result = pendulum
    checks = verify_equilibria(model, result)
    hanging, inverted = (_by_coordinate(result, "theta", 0.0), _by_coordinate(result, "theta", math.pi))
    by_eq = {id(e): v for e, v in zip(result.equilibria, checks)}
    assert hanging.stability == "stable" and by_eq[id(hanging)].observed == "bounded"
    assert inverted.stability == "unstable" and by_eq[id(inverted)].observed == "grows"
    assert all(v.agrees is True for v in checks)
    # undamped: the deviation neither grows nor decays (a few periods of the only oscillation)
    assert 0.5 < by_eq[id(hanging)].growth < 3


# ------------------------------------------------------------------------------------------ (c) wrong verdicts
def _relabelled(e, stability: str):
    wrong = copy.copy(e)
    wrong.stability = stability
    return wrong


def test_unstable_labelled_stable_is_flagged(problem57):
    model, result = problem57
    saddle = _relabelled(_by_coordinate(result, "q", 0.0), "stable")
    v = verify_equilibrium(model, saddle)
    assert v.agrees is False and v.observed == "grows" and v.stability == "stable"
    fake = copy.copy(result)
    fake.equilibria = [saddle]
    (line,) = disagreements(fake, [v])
    assert "equilibrium 1 (q = 0)" in line and "'stable'" in line and "grows" in line


def test_asymptotically_stable_labelled_unstable_is_flagged(problem57):
    model, result = problem57
    v = verify_equilibrium(model, _relabelled(_by_coordinate(result, "q", math.pi), "unstable"))
    assert v.agrees is False and v.observed == "decays"


def test_conservative_stable_labelled_asymptotically_stable_is_flagged(pendulum):
    model, result = pendulum
    v = verify_equilibrium(model, _relabelled(_by_coordinate(result, "theta", 0.0), "asymptotically stable"))
    assert v.agrees is False and v.observed == "bounded"


def test_critical_unstable_without_growth_and_undecided_are_not_judged(pendulum):
    """A critical case called unstable (the instability may come from nonlinear terms, far too slow to show)
    and an undecided verdict: the motion is reported, agrees is None, never False."""
    model, result = pendulum
    hanging = _by_coordinate(result, "theta", 0.0)
    v = verify_equilibrium(model, _relabelled(hanging, "unstable"))
    assert v.agrees is None and v.observed == "bounded" and "nonlinear" in v.note
    u = verify_equilibrium(model, _relabelled(hanging, "undecided"))
    assert u.agrees is None and u.observed == "bounded"


def test_agreement_rules():
    grow, decay, centre = np.array([2.0, -2.0]), np.array([-1 + 3j, -1 - 3j]), np.array([3j, -3j])
    assert agreement("unstable", "grows", grow, False, True) == (True, "")
    assert agreement("unstable", "bounded", grow, False, True)[0] is False
    assert agreement("unstable", "bounded", grow, False, False)[0] is None  # horizon cut short
    assert agreement("unstable", "bounded", centre, True, True)[0] is None
    assert agreement("asymptotically stable", "decays", decay, False, True)[0] is True
    assert agreement("asymptotically stable", "bounded", decay, False, True)[0] is False
    assert agreement("asymptotically stable", "grows", decay, False, False)[0] is False
    assert agreement("stable", "decays", centre, True, True)[0] is True
    assert agreement("stable", "grows", centre, True, False)[0] is False
    assert agreement("undecided", "grows", centre, True, True)[0] is None


def test_horizon_rules():
    h = horizon(np.array([-1 + 2j, -1 - 2j]))  # 5 periods (15.7 s) beat 5 time constants (5 s)
    assert h.seconds == pytest.approx(5 * 2 * math.pi / 2) and not h.clamped
    assert horizon(np.array([0.5, -3.0])).seconds == pytest.approx(math.log(1e4) / 0.5)
    tiny = horizon(np.array([1e-5, -1e3]))  # growth far slower than the fastest scale: bounded, and said so
    assert tiny.clamped and tiny.seconds == pytest.approx(1e7 / 1e3)
    assert horizon(np.zeros(0)).seconds == 10.0
    assert horizon(np.array([-1 + 2j, -1 - 2j]), factor=2).seconds == pytest.approx(2 * 5 * math.pi)


def test_options_are_checked():
    from mechsys.errors import InputError

    for bad in ({"perturbations": 0}, {"size": 0.0}, {"size": 2.0}, {"horizon_factor": -1.0}):
        with pytest.raises(InputError):
            VerifyOptions(**bad)


# ------------------------------------------------------------------------------------------ closed loop
@pytest.mark.slow
def test_four_bar_closed_loop_agrees():
    """Perturbations along the constraint manifold's tangent space; simulate projects them onto the loop."""
    model, result = _solved(SYSTEMS / "four_bar.yaml")
    checks = verify_equilibria(model, result)
    assert [(e.stability, v.observed) for e, v in zip(result.equilibria, checks)] == [
        ("stable", "bounded"), ("stable", "bounded"), ("unstable", "grows"), ("unstable", "grows")]
    assert all(v.agrees is True for v in checks)


# ------------------------------------------------------------------------------------------ (d) CLI
def test_cli_verify_json_shape_and_exit_zero():
    out = runner.invoke(app, ["equilibria", str(SYSTEMS / "problem57.yaml"), "--verify", "-f", "json"])
    assert out.exit_code == 0, out.output
    data = json.loads(out.stdout)
    for e in data["equilibria"]:
        v = e["verification"]
        assert set(v) == {"agrees", "stability", "observed", "growth", "peak", "horizon", "clamped", "size",
                          "perturbations", "method", "note", "runs"}
        assert v["agrees"] is True and v["stability"] == e["stability"] and v["perturbations"] == 4
        assert len(v["runs"]) == 4 and all(set(r) == {"observed", "growth", "peak"} for r in v["runs"])
    assert [e["verification"]["observed"] for e in data["equilibria"]] == ["decays", "grows", "decays"]


def test_cli_without_verify_has_no_verification():
    out = runner.invoke(app, ["equilibria", str(SYSTEMS / "problem57.yaml"), "-f", "json"])
    assert out.exit_code == 0 and all("verification" not in e for e in json.loads(out.stdout)["equilibria"])


def test_cli_disagreement_is_printed_and_exits_one(monkeypatch):
    """A wrong verdict (injected) is named in the table, on stderr, and makes the exit status 1; the output is
    complete."""
    import mechsys.analysis.equilibrium.equilibria as eq

    real = eq.find_equilibria

    def wrong(model, *args, **kwargs):
        result = real(model, *args, **kwargs)
        for e in result.equilibria:
            if e.stability == "unstable":
                e.stability = "asymptotically stable"
        return result

    monkeypatch.setattr(eq, "find_equilibria", wrong)
    out = runner.invoke(app, ["equilibria", str(SYSTEMS / "problem57.yaml"), "--verify", "-f", "markdown"])
    assert out.exit_code == 1
    assert "| 2 | asymptotically stable | grows (peak x" in out.stdout and "| NO |" in out.stdout
    assert "DISAGREEMENT: equilibrium 2 (q = 0): the verdict is 'asymptotically stable', but the perturbed " \
           "motion grows" in out.stdout
    assert "mechsys: verification disagrees: equilibrium 2 (q = 0)" in out.stderr
    assert "### verdicts" in out.stdout  # everything is still printed


def test_cli_verify_with_sweep_is_an_input_error():
    out = runner.invoke(app, ["equilibria", str(SYSTEMS / "centrifuge.yaml"), "--verify", "--sweep", "Mo=10:20:3"])
    assert out.exit_code == 2
    assert out.stderr.strip() == "mechsys: --verify cannot be combined with --sweep (verify the equilibria at one " \
                                 "parameter value)"


# ------------------------------------------------------------------------------------------ documented example
NUMBER = r"-?\d+(?:\.\d+)?(?:e[+-]?\d+)?"


def _numbers(text: str) -> list[float]:
    return [float(x) for x in re.findall(NUMBER, text)]


def test_documented_verify_example_runs_as_printed():
    """docs/equilibria.md §5.3: the command and its verification table (numbers to 2%: the runs' peaks depend on
    the integrator's last digits)."""
    doc = (ROOT / "docs" / "equilibria.md").read_text()
    section = doc[doc.index("### 5.3 Verification by simulation"):]
    section = section[:section.index("\n## ")]
    (command,) = re.findall(r"^\$ (mechsys equilibria [^\n(]*?)\s*(?:\(.*)?$", section, flags=re.M)
    argv = shlex.split(command)[1:]
    out = runner.invoke(app, argv)
    assert out.exit_code == 0, out.output
    documented = [line for line in section.splitlines() if re.match(r"\| \d+ \|", line)]
    printed = [line for line in out.stdout.splitlines() if re.match(r"\| \d+ \|", line)]
    printed = printed[-len(documented):]  # the verification table is the last one
    assert len(documented) == 4
    for doc_line, run_line in zip(documented, printed):
        assert re.sub(NUMBER, "N", doc_line) == re.sub(NUMBER, "N", run_line)
        assert _numbers(run_line) == pytest.approx(_numbers(doc_line), rel=0.02)
