"""CLI smoke tests for `mechsys equilibria` and `mechsys modes`: JSON contract, --sweep CSV/plot output, FRF CSV,
exit codes (2 for bad input such as a malformed --sweep, 1 when the analysis cannot be done, e.g. equilibria of a
non-autonomous system). Reference numbers: seed000_part2_digest.md §2.1 (Problem 57), §2.2 (centrifuge);
seeds001_004_digest.md E001-8 (beads on a string)."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mechsys.cli import app

ROOT = Path(__file__).resolve().parents[1]
SYSTEMS = ROOT / "systems"
DATA = ROOT / "tests" / "data"
CENTRIFUGE = SYSTEMS / "centrifuge.yaml"
runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def ok_json(*args):
    result = invoke(*args)
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def test_equilibria_json_contract_problem57():
    """§2.1: three equilibria q = -pi, 0, pi; eigenvalues as [re, im] pairs; verdicts as strings."""
    data = ok_json("equilibria", SYSTEMS / "problem57.yaml", "-f", "json")
    assert {"equilibria", "bifurcations"} <= set(data)
    assert data["bifurcations"] == []
    eqs = data["equilibria"]
    assert len(eqs) == 3
    for e in eqs:
        assert {"coordinates", "rates", "eigenvalues", "stability"} <= set(e)
        assert set(e["coordinates"]) == {"q"} and e["rates"] == {}
        assert e["stability"] in {"asymptotically stable", "stable", "unstable", "undecided"}
        assert all(isinstance(p, list) and len(p) == 2 and all(isinstance(x, (int, float)) for x in p)
                   for p in e["eigenvalues"])
    assert [e["coordinates"]["q"] for e in eqs] == pytest.approx([-math.pi, 0.0, math.pi], abs=1e-9)
    assert [e["stability"] for e in eqs] == ["asymptotically stable", "unstable", "asymptotically stable"]
    saddle = sorted(re for re, im in eqs[1]["eigenvalues"])
    assert saddle == pytest.approx([-1 - math.sqrt(1 + math.pi**2), -1 + math.sqrt(1 + math.pi**2)], rel=1e-9)
    focus = sorted((re, im) for re, im in eqs[2]["eigenvalues"])
    root = math.sqrt(2 * math.pi**2 - 1)
    assert focus[0] == pytest.approx((-1.0, -root), rel=1e-9)
    assert focus[1] == pytest.approx((-1.0, root), rel=1e-9)


def test_equilibria_json_reports_steady_rates_of_cyclic_coordinates():
    """§2.2: the centrifuge's steady motions carry the cyclic rate alpha' = Mo/dM = 7 and only beta as coordinate."""
    data = ok_json("equilibria", SYSTEMS / "centrifuge.yaml", "-f", "json")
    eqs = data["equilibria"]
    assert [e["coordinates"]["beta"] for e in eqs] == pytest.approx([-2.879372, -1.249420, -0.423246, 1.410445],
                                                                    abs=1e-5)
    for e in eqs:
        assert e["rates"]["alpha"] == pytest.approx(7.0, rel=1e-9)
        assert len(e["eigenvalues"]) == 3


def test_set_is_applied_before_the_analysis():
    """--set Mo=35 (dM = Mo/7 follows) keeps omega_s = 7: the same four beta_s."""
    data = ok_json("equilibria", SYSTEMS / "centrifuge.yaml", "--set", "Mo=35", "-f", "json")
    assert len(data["equilibria"]) == 4
    data = ok_json("equilibria", SYSTEMS / "centrifuge.yaml", "--set", "dM=10", "-f", "json")
    # omega_s = 50/10 = 5 < omega_c = 5.127846: only two steady motions (§2.2 table, fold at 5.127846)
    assert len(data["equilibria"]) == 2
    assert [e["rates"]["alpha"] for e in data["equilibria"]] == pytest.approx([5.0, 5.0], rel=1e-9)


def test_sweep_writes_csv_and_plot(tmp_path):
    """--sweep with -f csv --output writes the branch table; --plot writes a bifurcation diagram."""
    out = tmp_path / "branches.csv"
    png = tmp_path / "diagram.png"
    result = invoke("equilibria", SYSTEMS / "indicator.yaml", "--set", "Iz=0.8", "--sweep", "omega1=-20:20:21",
                    "-f", "csv", "--output", out, "--plot", png)
    assert result.exit_code == 0, result.output
    assert out.is_file() and out.stat().st_size > 0
    rows = list(csv.reader(out.read_text().splitlines()))
    assert len(rows) >= 1 + 21, rows[:3]   # header + at least one row per sweep value
    assert any("omega1" in cell for cell in rows[0]), rows[0]
    assert png.is_file() and png.stat().st_size > 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_sweep_json_lists_bifurcations():
    """Iz = 0.8, Omega = 150: pitchforks at omega1 = -2.5 and 10 (digest §2.4 table), both at beta = pi."""
    data = ok_json("equilibria", SYSTEMS / "indicator.yaml", "--set", "Iz=0.8", "--sweep", "omega1=-20:20:21",
                   "-f", "json")
    bifs = data["bifurcations"]
    assert bifs, data
    for b in bifs:
        assert {"kind", "parameter", "value", "coordinates"} <= set(b)
        assert b["kind"] in {"fold", "branch_point", "hopf"}
        assert b["parameter"] == "omega1"
    assert sorted({round(b["value"], 6) for b in bifs}) == pytest.approx([-2.5, 10.0], abs=1e-6)


@pytest.mark.parametrize("spec", ["Mo=20:60", "Mo20:60:5", "Mo=a:60:5", "Mo=20:60:1", "Mo=20:60:5:7", "=1:2:3",
                                  "Mo=20:60:2.5"])
def test_bad_sweep_syntax_exits_2(spec):
    result = invoke("equilibria", SYSTEMS / "centrifuge.yaml", "--sweep", spec)
    assert result.exit_code == 2, result.output
    assert "--sweep" in result.output


def test_sweep_of_unknown_parameter_exits_2():
    result = invoke("equilibria", SYSTEMS / "centrifuge.yaml", "--sweep", "nosuch=1:2:3")
    assert result.exit_code == 2, result.output
    assert "nosuch" in result.output


def test_equilibria_of_a_non_autonomous_system_exits_1(tmp_path):
    """Equilibria need an autonomous system (part-2 digest §1.1, §1.3: f must not depend explicitly on t)."""
    model = tmp_path / "forced.yaml"
    model.write_text(
        "name: forced\n"
        "parameters: {k: 4, c: 0.5, F0: 1}\n"
        "coordinates:\n  x: {initial: 0, rate: 0}\n"
        "links:\n  mass:\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n    mass: 1\n"
        "forces:\n"
        "  - {type: potential, value: k*x^2/2}\n"
        "  - {type: generalized_force, coordinate: x, value: -c*der(x) + F0*sin(t)}\n")
    result = invoke("equilibria", model)
    assert result.exit_code == 1, result.output
    text = result.output.lower()
    assert "autonomous" in text, result.output
    assert "traceback" not in text


def test_modes_json_beads():
    """E001-8: w^2 = (4T/(m l)){2 - sqrt2, 2, 2 + sqrt2}, 4T/(m l) = 4000."""
    data = ok_json("modes", DATA / "beads_string.yaml", "-f", "json")
    assert data["coordinates"] == ["y1", "y2", "y3"]
    if "frequencies" in data:
        freqs = data["frequencies"]
    else:
        freqs = [m["frequency_rad_s"] for m in data["modes"]]
    s2 = math.sqrt(2)
    assert [w * w for w in freqs] == pytest.approx([4000 * (2 - s2), 8000.0, 4000 * (2 + s2)], rel=1e-9)


def test_modes_frf_csv(tmp_path):
    """--frf START:STOP:N with -f csv --output writes the receptance table (one row per frequency)."""
    out = tmp_path / "frf.csv"
    result = invoke("modes", DATA / "beads_string.yaml", "--frf", "1:200:40", "--input", "y1", "--response", "y3",
                    "-f", "csv", "--output", out)
    assert result.exit_code == 0, result.output
    assert out.is_file() and out.stat().st_size > 0
    rows = [r for r in csv.reader(out.read_text().splitlines()) if r]
    assert len(rows) == 41, rows[:3]
    first = [float(x) for x in rows[1][:2]]
    assert first[0] == pytest.approx(1.0)
    # receptance |(K - w^2 M)^-1|[y3, y1] at w = 1 (undamped), K = 400 tridiag(-1, 2, -1), M = 0.1 I
    import numpy as np

    K = 400.0 * np.array([[2, -1, 0], [-1, 2, -1], [0, -1, 2]])
    assert first[1] == pytest.approx(abs(np.linalg.inv(K - 0.1 * np.eye(3))[2, 0]), rel=1e-9)


@pytest.mark.parametrize("spec", ["1:200", "a:2:3", "1:2:1"])
def test_bad_frf_syntax_exits_2(spec):
    result = invoke("modes", DATA / "beads_string.yaml", "--frf", spec)
    assert result.exit_code == 2, result.output


@pytest.mark.parametrize("speed, count", [(3, 2), (12, 4), (25, 4)])
def test_centrifuge_steady_motions_beyond_the_default_rate_box(speed, count):
    """Issue 11 item 3: with dM = 50/7 and Mo = speed*dM the column turns steadily at `speed` rad/s; at 12 rad/s
    the default rate box (+-10) dropped every steady motion and printed an empty table with exit 0. Each steady
    motion must be a root of the arm's balance, derived by hand (effective potential V - T0, arm pivot at a,
    centre of mass at l, central inertias I2y, I2z):
        m g l sin(b) = w^2 (m (a + l sin b) l cos b + (I2y - I2z) sin b cos b),
    and every root of it in (-pi, pi] must be reported (counted here by sign changes on a fine grid)."""
    import math

    import numpy as np

    import mechsys
    from mechsys.analysis.equilibrium.equilibria import find_equilibria

    model = mechsys.load(CENTRIFUGE, {"dM": "50/7", "Mo": f"{speed}*50/7"})
    P = model.parameters
    m, g, a, l, I2y, I2z, w = P["m"], P["g"], P["a"], P["l"], P["I2y"], P["I2z"], float(speed)

    def balance(b):
        return m * g * l * np.sin(b) - w**2 * (m * (a + l * np.sin(b)) * l * np.cos(b)
                                               + (I2y - I2z) * np.sin(b) * np.cos(b))

    grid = np.linspace(-math.pi, math.pi, 200001)
    roots = int(np.sum(np.sign(balance(grid[:-1])) != np.sign(balance(grid[1:]))))
    assert roots == count
    result = find_equilibria(model)
    assert len(result.equilibria) == count, result.message
    for e in result.equilibria:
        assert e.rates["alpha"] == pytest.approx(w, rel=1e-12)
        assert abs(balance(e.coordinates["beta"])) < 1e-9


def test_no_steady_motion_message_names_the_region_covered():
    """When nothing is found, the message says which region the search covered (here a --search box that
    excludes the steady speed of 12 rad/s)."""
    result = runner.invoke(app, ["equilibria", str(CENTRIFUGE), "--set", "dM=50/7", "--set", "Mo=12*50/7",
                                 "--search", "der(alpha)=-5:5", "-f", "json"])
    assert result.exit_code == 0, result.output
    message = json.loads(result.stdout)["message"]
    assert "no equilibrium found" in message and "der(alpha) in [-5, 5]" in message and "beta in [" in message


def test_the_no_equilibrium_example_of_the_docs_is_what_the_tool_prints():
    """docs/equilibria.md §2.5 shows the output of a search that finds nothing: it must stay true."""
    doc = (ROOT / "docs" / "equilibria.md").read_text()
    command = "$ mechsys equilibria systems/problem57.yaml --search q=10:20 -f json\n"
    shown = doc.split(command, 1)[1].split("```", 1)[0]
    result = runner.invoke(app, ["equilibria", str(SYSTEMS / "problem57.yaml"), "--search", "q=10:20", "-f", "json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout) == json.loads(shown)


def test_the_fold_csv_example_of_the_docs_is_what_the_tool_prints():
    """docs/equilibria.md shows the branch table around the centrifuge's fold (trimmed): every row shown must be
    a row the tool prints, verdicts included."""
    doc = (ROOT / "docs" / "equilibria.md").read_text()
    command = ("$ mechsys equilibria systems/centrifuge.yaml --set dM=7.142857142857143 --sweep Mo=10:70:61 -f csv"
               "   (trimmed)\n")
    shown = [line for line in doc.split(command, 1)[1].split("```", 1)[0].splitlines() if line and line != "..."]
    result = runner.invoke(app, ["equilibria", str(CENTRIFUGE), "--set", "dM=7.142857142857143", "--sweep",
                                 "Mo=10:70:61", "-f", "csv"])
    assert result.exit_code == 0, result.output
    printed = result.stdout.splitlines()
    assert shown[0] == printed[0]
    for line in shown[1:]:
        assert line in printed, line


def _block_on(tmp_path, potential: str):
    """A block on a line in a potential (written as a user would, like tests/data/hilltop_block.yaml)."""
    path = tmp_path / "block.yaml"
    path.write_text("name: block\nparameters: {m: 2.0, k: 3.0}\ncoordinates:\n  x: {initial: 0.1}\nlinks:\n"
                    "  block:\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n    mass: m\n"
                    f"forces:\n  - {{type: potential, value: {potential}}}\n")
    return path


def test_modes_about_an_unstable_equilibrium_say_the_search_found_no_stable_one(tmp_path):
    """Without --at, modes vibrate about the first stable equilibrium found; when the search finds none (a block on
    a hilltop, V = -k x^2/2: x = 0 alone, unstable, w^2 = -k/m) the output says so and what the search covered,
    in the text and in JSON; with a stable one (V = +k x^2/2: w^2 = k/m) or with --at there is no such note."""
    hill = DATA / "hilltop_block.yaml"
    text = invoke("modes", hill)
    assert text.exit_code == 0, text.output
    flat = " ".join(text.output.split())
    assert "the search found no stable equilibrium (deflated Newton from" in flat and "give another with --at" in flat
    data = ok_json("modes", hill, "-f", "json")
    assert data["unstable_modes"] == 1 and data["note"].startswith("the search found no stable equilibrium")
    assert "note" not in ok_json("modes", hill, "--at", "x=0", "-f", "json")
    valley = ok_json("modes", _block_on(tmp_path, "k/2*x^2"), "-f", "json")
    assert "note" not in valley and valley["unstable_modes"] == 0
    assert valley["modes"][0]["frequency_rad_s"] ** 2 == pytest.approx(3.0 / 2.0, rel=1e-12)
