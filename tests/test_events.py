"""Events: zero crossings with a direction, recorded or stopping the integration (closed-form free fall)."""
import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.motion.simulate import simulate
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


GRAZE = ROOT / "tests" / "data" / "grazing_oscillator.yaml"
WALL = ROOT / "tests" / "data" / "grazing_wall.yaml"
OMEGA = math.sqrt(10.0)
AMPLITUDE = 0.316227766 / OMEGA  # x = AMPLITUDE sin(OMEGA t)
LEVEL = 0.09999


def _graze_roots(t_end: float, direction: str = "both", level: float = LEVEL) -> list[float]:
    """Closed-form crossings of x = level by x = AMPLITUDE sin(OMEGA t): rising at asin(level/A)/OMEGA + k T,
    falling at (pi - asin(level/A))/OMEGA + k T."""
    a = math.asin(level / AMPLITUDE)
    rising = [(a + 2 * math.pi * k) / OMEGA for k in range(100)]
    falling = [(math.pi - a + 2 * math.pi * k) / OMEGA for k in range(100)]
    chosen = {"rising": rising, "falling": falling, "both": rising + falling}[direction]
    return sorted(t for t in chosen if t <= t_end)


def _graze_model(tmp_path, direction: str = "both", action: str = "record", level: float = LEVEL):
    path = tmp_path / "graze.yaml"
    text = GRAZE.read_text().replace(f"level: {LEVEL}", f"level: {level}")
    path.write_text(text.replace("{name: touch, expression: x - level}",
                                 f"{{name: touch, expression: x - level, direction: {direction}, action: {action}}}"))
    return mechsys.load(path)


@pytest.mark.parametrize("method, t_end", [("DOP853", 20.0), ("RK45", 20.0), ("LSODA", 20.0), ("Radau", 5.0)])
def test_near_tangential_crossings_are_all_found(method, t_end):
    """Crossing pairs 0.0088 s apart inside one step (the event function has one sign at both step ends): all 20
    crossings in 20 s, at the closed-form times."""
    r = simulate(mechsys.load(GRAZE), t_end, 0.01, method=method)
    times = [e["t"] for e in r.events]
    expected = _graze_roots(t_end)
    assert len(expected) == {20.0: 20, 5.0: 6}[t_end] and len(times) == len(expected)
    assert max(abs(t - e) for t, e in zip(times, expected)) < 1e-6
    assert all(abs(e["state"]["x"] - LEVEL) < 1e-9 for e in r.events)


@pytest.mark.parametrize("direction", ["rising", "falling"])
def test_near_tangential_crossings_respect_the_direction(tmp_path, direction):
    r = simulate(_graze_model(tmp_path, direction), 20.0, 0.01)
    expected = _graze_roots(20.0, direction)
    assert len(expected) == 10 and len(r.events) == 10
    assert max(abs(e["t"] - t) for e, t in zip(r.events, expected)) < 1e-6
    sign = 1.0 if direction == "rising" else -1.0
    assert all(sign * e["state"]["der(x)"] > 0 for e in r.events)


def test_stop_at_the_first_near_tangential_crossing(tmp_path):
    r = simulate(_graze_model(tmp_path, "rising", "stop"), 20.0, 0.01)
    t_stop = math.asin(LEVEL / AMPLITUDE) / OMEGA  # 0.49226 s
    assert len(r.events) == 1 and abs(r.events[0]["t"] - t_stop) < 1e-6
    assert abs(r.t[-1] - t_stop) < 1e-6 and abs(r.q[-1, 0] - LEVEL) < 1e-9
    assert r.u[-1, 0] == pytest.approx(OMEGA * math.sqrt(AMPLITUDE ** 2 - LEVEL ** 2), rel=1e-5)


def test_cli_stops_at_the_first_near_tangential_crossing(tmp_path):
    text = GRAZE.read_text().replace("{name: touch, expression: x - level}",
                                     "{name: touch, expression: x - level, direction: rising, action: stop}")
    path = tmp_path / "graze.yaml"
    path.write_text(text)
    out = tmp_path / "events.json"
    r = CliRunner().invoke(app, ["simulate", str(path), "--t-end", "20", "--events", str(out)])
    assert r.exit_code == 0, r.output
    rows = json.loads(out.read_text())
    assert len(rows) == 1 and abs(rows[0]["t"] - math.asin(LEVEL / AMPLITUDE) / OMEGA) < 1e-6


def test_a_grazing_impact_is_not_stepped_over():
    """A wall at x = LEVEL, reached with an approach speed of 0.0045 m/s: the gap is positive at both ends of the
    step that holds the touch. Elastic bounces at t1 + j (T - (t2 - t1)) (the touch arc t1..t2 is cut off)."""
    r = simulate(mechsys.load(WALL), 5.0, 0.01)
    a = math.asin(LEVEL / AMPLITUDE)
    t1, t2, period = a / OMEGA, (math.pi - a) / OMEGA, 2 * math.pi / OMEGA
    expected = [t1 + j * (period - (t2 - t1)) for j in range(3)]
    expected = [t for t in expected if t <= 5.0]
    assert [i["contact"] for i in r.impacts] == ["wall"] * len(expected) == ["wall"] * 3
    assert max(abs(i["t"] - t) for i, t in zip(r.impacts, expected)) < 1e-6
    assert np.max(r.q[:, 0]) <= LEVEL + 1e-9  # never through the wall


def test_cvode_finds_the_near_tangential_crossings_too():
    """CVODE's own root finder looks at the signs at its step ends only (it found none of these crossings, 0.00045 s
    apart); they are located on its interpolant inside every step instead."""
    pytest.importorskip("sksundae")
    r = simulate(mechsys.load(GRAZE, {"level": "0.0999999"}), 20.0, 0.01, method="CVODE")
    expected = _graze_roots(20.0, level=0.0999999)
    assert len(r.events) == len(expected) == 20
    assert all(abs(e["state"]["x"] - 0.0999999) < 1e-12 for e in r.events)
    # crossing speed w sqrt(A^2 - level^2) = 4.5e-4 m/s: CVODE's amplitude error (~1e-9 m after 20 s at rtol 1e-10)
    # moves the crossings by ~1e-9/4.5e-4 = 2e-6 s
    assert max(abs(e["t"] - t) for e, t in zip(r.events, expected)) < 2e-5


def test_cvode_stops_at_the_first_near_tangential_crossing(tmp_path):
    pytest.importorskip("sksundae")
    r = simulate(_graze_model(tmp_path, "falling", "stop", level=0.0999999), 20.0, 0.01, method="CVODE")
    t_stop = (math.pi - math.asin(0.0999999 / AMPLITUDE)) / OMEGA  # 0.49694 s
    assert len(r.events) == 1 and abs(r.events[0]["t"] - t_stop) < 1e-6 and abs(r.t[-1] - t_stop) < 1e-6
    assert r.u[-1, 0] < 0


def test_a_crossing_on_an_output_time_of_a_closed_loop_is_recorded_once(tmp_path):
    """Closed loops integrate output interval by output interval: a crossing exactly at an output time ends one
    interval and starts the next (g = 0 there); it is one crossing."""
    text = (ROOT / "systems" / "four_bar.yaml").read_text()
    path = tmp_path / "m.yaml"
    path.write_text(text + "\nevents:\n  - {name: half, expression: t - 1/2, direction: rising}\n")
    r = simulate(mechsys.load(path), 1.0, 0.01, method="DOP853")
    assert 0.5 in r.t
    assert [e["t"] for e in r.events] == [0.5]


@pytest.mark.parametrize("method", ["DOP853", "Radau", "CVODE"])
def test_a_run_that_starts_on_an_event_surface_has_not_crossed_it(tmp_path, method):
    """y(0) = h on the surface y - h = 0 of both a recorded and a stop event (falling, and the ball falls at
    once): nothing at t = 0, the run is not stopped there, and the ground is still found at sqrt(2 h / g)."""
    if method == "CVODE":
        pytest.importorskip("sksundae")
    text = (ROOT / "tests" / "data" / "falling_events.yaml").read_text()
    text = text.replace("expression: y - h/2, direction: falling}", "expression: y - h, direction: falling}")
    text += "  - {name: start_level, expression: h - y, direction: rising, action: stop}\n"
    path = tmp_path / "start_on_surface.yaml"
    path.write_text(text)
    r = simulate(mechsys.load(path), 2.0, 0.01, method)
    assert [ev["event"] for ev in r.events] == ["ground"]
    assert r.events[0]["t"] == pytest.approx((2 * 2 / 9.81) ** 0.5, rel=1e-8)


@pytest.mark.parametrize("fmt", ["json", "text"])
def test_the_summary_says_which_event_stopped_the_run_and_when(fmt, monkeypatch):
    """A run ended by a stop event printed y(t_end), der(y)(t_end) ... with nothing to say they are at the stop,
    not at --t-end. The summary now names the event and the time: the ground at sqrt(2h/g) = 0.638551 s (h = 2),
    where der(y) = -sqrt(2 g h); a run with no stop keeps its summary as it was."""
    monkeypatch.setenv("COLUMNS", "120")
    path = FALL
    t_ground = math.sqrt(2 * 2 / 9.81)
    result = CliRunner().invoke(app, ["simulate", str(path), "--t-end", "5", "-f", fmt])
    assert result.exit_code == 0, result.output
    if fmt == "json":
        summary = json.loads(result.output)["simulation summary"]
        assert summary["stopped by event"] == "ground"
        assert summary["stopped at t"] == pytest.approx(t_ground, rel=1e-8)
        assert summary["der(y)(t_end)"] == pytest.approx(-math.sqrt(2 * 9.81 * 2), rel=1e-8)
        keys = list(summary)
        assert keys.index("stopped at t") < keys.index("y(t_end)")
        before = json.loads(CliRunner().invoke(app, ["simulate", str(path), "--t-end", "0.5", "-f", "json"]).output)
        assert "stopped by event" not in before["simulation summary"]
    else:
        assert "stopped by event" in result.output and "ground" in result.output
        assert f"{t_ground:.6f}" in result.output


def test_native_with_events_is_an_option_conflict():
    """`--method native` on a model with events is an input error (exit 2, one line), like other option
    conflicts; it exited 1, as if the analysis had failed."""
    from test_cli_hardening import invoke, one_line

    line = one_line(invoke("simulate", FALL, "--method", "native", "--t-end", "0.1"), code=2)
    assert "--method native: events need scipy's event location; use DOP853" in line


BOUNCING = """\
name: ball_events
parameters: {m: 0.1, h: 1.0, e: 0.5, g: 9.81}
coordinates:
  y: {initial: h, rate: 0}
links:
  ball:
    particle: true
    joint: {type: prismatic, parent: ground, axis: y, coordinate: y}
    mass: m
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
contacts:
  - {name: floor, gap: y, restitution: e}
events:
"""


@pytest.mark.parametrize("method,rtol", [("auto", 1e-10), ("auto", 1e-8), ("RK45", 1e-10)])
def test_events_of_a_model_with_contacts_stop_and_record_where_they_cross(tmp_path, method, rtol):
    """A ball dropped from h onto a floor with restitution e touches down at t1 = sqrt(2 h / g), t1 (1 + 2 e) and
    t1 (1 + 2 e + 2 e^2) (closed form). With a contact in the model:
    - a stop event at y = h/8 stopped the run without its state: the last row was the output point before
      (y = 0.1265 at t = 0.422) and the summary did not say it stopped; the run now ends at the event;
    - an event written as the contact's gap (`y` falling) crosses at each impact's instant, and scipy kept only
      whichever of the two came first by rounding: a stop at the first touchdown stopped at the second, or never,
      and a recorded touch was listed at one touchdown of three, or none, depending on rtol and the method."""
    t1 = math.sqrt(2 * 1.0 / 9.81)
    touchdowns = [t1, t1 * (1 + 2 * 0.5), t1 * (1 + 2 * 0.5 + 2 * 0.25)]
    for event, t_stop, y_stop in (("{name: low, expression: y - h/8, direction: falling, action: stop}",
                                   math.sqrt(2 * 0.875 / 9.81), 0.125),
                                  ("{name: ground, expression: y, direction: falling, action: stop}", t1, 0.0)):
        path = tmp_path / "stop.yaml"
        path.write_text(BOUNCING + f"  - {event}\n")
        r = simulate(mechsys.load(path), 1.2, 0.001, method=method, rtol=rtol)
        assert r.t[-1] == pytest.approx(t_stop, abs=1e-9) and r.q[-1, 0] == pytest.approx(y_stop, abs=1e-9)
        assert [e["action"] for e in r.events] == ["stop"]
    path = tmp_path / "record.yaml"
    path.write_text(BOUNCING + "  - {name: touch, expression: y, direction: falling}\n")
    r = simulate(mechsys.load(path), 1.2, 0.001, method=method, rtol=rtol)
    assert [e["t"] for e in r.events] == pytest.approx(touchdowns, abs=1e-9)
    assert [round(i["t"], 9) for i in r.impacts][:3] == [round(t, 9) for t in touchdowns]
