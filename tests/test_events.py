"""Events: zero crossings with a direction, recorded or stopping the integration (closed-form free fall)."""
import csv
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.simulate import simulate
from mechsys.cli import app
from mechsys.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
FALL = ROOT / "tests" / "data" / "falling_events.yaml"


def test_free_fall_events_at_closed_form_times():
    r = simulate(mechsys.load(FALL), 5.0, 0.01)
    half = [e for e in r.events if e["event"] == "half_height"]
    ground = [e for e in r.events if e["event"] == "ground"]
    assert len(half) == 1 and abs(half[0]["t"] - math.sqrt(2 / 9.81)) < 1e-9
    assert len(ground) == 1 and abs(ground[0]["t"] - math.sqrt(4 / 9.81)) < 1e-9
    assert r.t[-1] == pytest.approx(math.sqrt(4 / 9.81), abs=1e-12)  # stopped at the ground
    assert abs(r.q[-1, 0]) < 1e-9 and r.u[-1, 0] == pytest.approx(-math.sqrt(2 * 9.81 * 2), rel=1e-9)


def test_direction_filters_crossings(tmp_path):
    text = FALL.read_text().replace("direction: falling}", "direction: rising}", 1)
    path = tmp_path / "m.yaml"
    path.write_text(text)
    r = simulate(mechsys.load(path), 5.0, 0.01)
    assert [e["event"] for e in r.events] == ["ground"]


def test_bad_event_expression_is_an_input_error(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text(FALL.read_text().replace("expression: y - h/2", "expression: y - hh/2"))
    with pytest.raises(InputError, match="did you mean 'h'"):
        mechsys.load(path)


def test_cli_writes_the_event_table(tmp_path):
    out = tmp_path / "events.csv"
    r = CliRunner().invoke(app, ["simulate", str(FALL), "--t-end", "5", "--events", str(out)])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader(out.open()))
    assert [row["event"] for row in rows] == ["half_height", "ground"] and rows[1]["action"] == "stop"
