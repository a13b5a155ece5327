"""Steady motions of systems with velocity constraints at a singular point of a rotation chart (equilibria.md
§2.7): kept as `undecided` with the chart's reason, never classified off the singular chart, and never the point
`modes` vibrates about.

The model (tests/data/beyond/pushed_ball.yaml, written as a user would): a solid ball, m = 1, rolling without slip
on a plane, pushed at its centre by F = 1.4. Rolling: F - f = m a, f r = (2/5) m r^2 (a / r), so a = 5F/(7m) = 1
m/s^2 in every orientation and nothing about it is steady. At the zyx gimbal lock (a2 = +-pi/2) the singular chart
made four 'unstable steady motions' with eigenvalues of 4.4e8, and `modes` reported 70 MHz modes.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mechsys.cli import app

BALL = Path(__file__).resolve().parent / "data" / "beyond" / "pushed_ball.yaml"


def _run(*args: str):
    return CliRunner().invoke(app, [*args])


def test_the_ball_accelerates_at_five_sevenths_of_f_over_m():
    """The model is right: x(2 s) = a t^2 / 2 = 2 with a = 5F/(7m) = 1, from rest."""
    result = _run("simulate", str(BALL), "--t-end", "2", "-f", "json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["simulation summary"]["x(t_end)"] == pytest.approx(2.0, rel=1e-9)


def test_steady_motions_at_the_gimbal_lock_are_undecided_with_the_reason():
    result = _run("equilibria", str(BALL), "-f", "json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert len(data["equilibria"]) == 4, "the search finds the singular chart's four points (equilibria.md §2.7)"
    for e in data["equilibria"]:
        assert abs(abs(e["coordinates"]["a2"]) - 1.5707963267948966) < 1e-9
        assert e["stability"] == "undecided"
        assert e["reason"].startswith("coordinate singularity: the zyx angles (a1, a2, a3) of the spherical joint")
        assert "re-charting is not available for systems with velocity constraints" in e["reason"]
    assert f"{len(data['equilibria'])} steady motions are at a coordinate singularity" in data["message"]


@pytest.mark.parametrize("at", [(), ("--at", "a1=1.5707963267948966", "--at", "a2=1.5707963267948966")])
def test_modes_refuse_the_singular_chart(at):
    result = _run("modes", str(BALL), *at)
    assert result.exit_code == 1
    assert "coordinate singularity: the zyx angles" in result.output
    assert "the linearization in these coordinates is singular" in result.output


def test_a_run_started_at_the_gimbal_lock_rolls_through_it_in_another_chart():
    """Started at the zyx lock, the pushed ball is re-charted like a free body (velocity constraints are re-derived
    with the model in the other sequence): x(t) = t^2/2 from rest, a = 5F/(7m) = 1 (before: it stopped at once,
    and a ball rolling down an incline from a regular start crawled into the lock for minutes and then blamed a
    stiff scene)."""
    result = _run("simulate", str(BALL), "-s", "a1=1.5707963267948966", "-s", "a2=1.5707963267948966", "--t-end",
                  "3", "-f", "json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)["simulation summary"]
    assert summary["x(t_end)"] == pytest.approx(4.5, rel=1e-9)
    assert summary["max constraint residual"] < 1e-9
    text = _run("simulate", str(BALL), "-s", "a1=1.5707963267948966", "-s", "a2=1.5707963267948966", "--t-end", "3")
    assert "chart switches:" in " ".join(text.output.split())


INCLINE = Path(__file__).resolve().parent / "data" / "beyond" / "ball_on_incline.yaml"


@pytest.mark.parametrize("components", ["", ", components: [x, y]", ", components: [x, y], axes: incline"])
def test_a_ball_rolling_down_an_incline_passes_the_gimbal_lock(tmp_path, components):
    """x = 5/14 g sin(alpha) t^2 (rolling: a = g sin(alpha) / (1 + 2/5)); the three rows of the default components
    have rank 2 (least squares). That run crawled into the lock and stopped after minutes blaming a stiff scene."""
    path = tmp_path / "incline.yaml"
    text = INCLINE.read_text(encoding="utf-8")
    path.write_text(text.replace(", components: [x, y], axes: incline", components), encoding="utf-8")
    result = _run("simulate", str(path), "--t-end", "1", "--dt", "0.01", "-f", "json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)["simulation summary"]
    assert summary["x(t_end)"] == pytest.approx(5 / 14 * 9.81 * math.sin(0.3), rel=1e-8)
    assert summary["max constraint residual"] < 1e-9


def test_steady_motions_where_the_speeds_move_no_mass_are_undecided_not_classified():
    """A ball rolling in a bowl on the arm of a universal joint (tests/data/beyond/ball_in_bowl_universal.yaml).
    Where the arm lies along the joint's first axis (p2 = +-pi/2), p1 only turns the arm about its own length and
    the ball's relative angles can undo it: a combination of the speeds moves no mass. Those points were listed as
    'unstable (critical)' with eigenvalues of 6e8; no verdict can be read there. At the bottom the ball oscillates
    at w^2 = 5 g / (7 (R - r)) (a ball rolling in a spherical bowl, closed form)."""
    path = Path(__file__).resolve().parent / "data" / "beyond" / "ball_in_bowl_universal.yaml"
    result = _run("equilibria", str(path), "-f", "json")
    assert result.exit_code == 0, result.output
    rows = json.loads(result.output)["equilibria"]
    singular = [e for e in rows if abs(abs(e["coordinates"]["p2"]) - math.pi / 2) < 1e-6]
    assert singular, "the search meets the singular points"
    for e in singular:
        assert e["stability"] == "undecided" and not e["eigenvalues"]
        assert e["reason"].startswith("coordinate singularity: a combination of the independent speeds moves no mass")
    for e in rows:
        assert all(math.hypot(*v) < 10 for v in e["eigenvalues"]), e
    bottom = [e for e in rows if abs(e["coordinates"]["p1"]) < 1e-6 and abs(e["coordinates"]["p2"]) < 1e-6]
    assert len(bottom) == 1
    # the ball rests in every orientation (a1, a2): one continuum per position of the arm (p1, p2), one row each
    # (the tangent test read a ball's zero columns of rounding as directions: 14 rows, 'each of 14 continua')
    arms = [tuple(round(e["coordinates"][c] / (math.pi / 2)) % 4 for c in ("p1", "p2")) for e in rows]
    assert len(set(arms)) == len(arms) == 7
    assert json.loads(result.output)["message"].startswith(
        "the equilibria are not isolated (singular Jacobian: e.g. a free rigid-body motion); "
        "one representative of each of 7 continua is shown")
    w = math.sqrt(5 * 9.81 / (7 * (0.6 - 0.05)))
    oscillating = sorted(abs(v[1]) for v in bottom[0]["eigenvalues"] if abs(v[1]) > 1e-6)
    assert oscillating == pytest.approx([w] * 4, rel=1e-9)
