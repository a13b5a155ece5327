"""`mechsys simulate`, `bench`, `plot`, `export` from the command line: files, formats, exit codes."""
import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from mechsys.cli import app

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_simulate_writes_csv_with_the_documented_columns(tmp_path):
    out = tmp_path / "p1.csv"
    r = invoke("simulate", ROOT / "systems" / "motor_arm.yaml", "--t-end", 2, "--dt", 0.1, "-o", out, "-f", "json")
    assert r.exit_code == 0, r.output
    header = out.read_text().splitlines()[0].split(",")
    assert header == ["t", "alpha", "beta", "der(alpha)", "der(beta)", "T", "V", "E", "residual"]
    rows = out.read_text().splitlines()[1:]
    assert len(rows) == 21 and float(rows[-1].split(",")[0]) == 2.0
    summary = json.loads(r.stdout)
    assert "simulation summary" in summary


def test_export_round_trip_and_plot(tmp_path):
    csv_path, json_path, png = tmp_path / "r.csv", tmp_path / "r.json", tmp_path / "r.png"
    assert invoke("simulate", ROOT / "systems" / "double_pendulum.yaml", "--t-end", 1, "--dt", 0.05,
                  "-o", csv_path).exit_code == 0
    assert invoke("export", csv_path, "-o", json_path).exit_code == 0
    data = json.loads(json_path.read_text())
    values = np.array([[float(x) for x in ln.split(",")] for ln in csv_path.read_text().splitlines()[1:]])
    assert data["columns"][0] == "t" and np.array_equal(np.array(data["data"]), values)
    assert invoke("plot", json_path, "-o", png).exit_code == 0 and png.stat().st_size > 1000


def test_bad_inputs_exit_2(tmp_path):
    model = ROOT / "systems" / "motor_arm.yaml"
    assert invoke("simulate", model, "-o", tmp_path / "x.txt").exit_code == 2
    assert invoke("bench", model, "--methods", "Euler").exit_code == 2
    bad = tmp_path / "bad.csv"
    bad.write_text("not a result\n1,2\n")
    assert invoke("plot", bad, "-o", tmp_path / "x.png").exit_code == 2


def test_unknown_method_is_an_input_error():
    """An option value the command does not know is invalid input (exit 2), like any other bad option."""
    assert invoke("simulate", ROOT / "systems" / "motor_arm.yaml", "--method", "Euler").exit_code == 2


def test_bench_table_has_every_method_and_tolerance():
    r = invoke("bench", ROOT / "systems" / "double_pendulum.yaml", "--t-end", 0.5, "--methods", "RK45,DOP853",
               "--rtols", "1e-6,1e-9", "-f", "csv")
    assert r.exit_code == 0, r.output
    lines = r.stdout.strip().splitlines()
    assert lines[0].startswith("method,rtol") and len(lines) == 5
    errors = {(ln.split(",")[0], ln.split(",")[1]): float(ln.split(",")[4]) for ln in lines[1:]}
    assert errors[("DOP853", "1e-09")] < errors[("DOP853", "1e-06")] < 1e-4


def test_bench_takes_the_output_interval_which_no_longer_sets_the_step():
    """Issue 13: `bench` had no --dt, and the default interval t_end/1000 bounded the step of closed loops on scipy
    (one solve per output interval), so the work-precision table of Andrews' mechanism was flat. Now `--dt` is an
    option (validated like simulate's), a coarse grid costs the same evaluations as the default one, and the
    evaluations follow rtol."""
    args = ("bench", ROOT / "systems" / "four_bar.yaml", "--t-end", 1.0, "--methods", "DOP853", "--rtols",
            "1e-6,1e-10", "-f", "csv")
    fine, coarse = invoke(*args), invoke(*args, "--dt", 0.1)
    assert fine.exit_code == coarse.exit_code == 0, fine.output + coarse.output
    calls = [[int(line.split(",")[3]) for line in r.stdout.strip().splitlines()[1:]] for r in (fine, coarse)]
    for a, b in zip(*calls):
        assert abs(a - b) <= 0.1 * b, calls  # the grid does not set the step (it took 5x more at the default)
    assert calls[0][1] > 2 * calls[0][0], calls  # tighter rtol, more work: the table responds
    bad = invoke(*args, "--dt", 0)
    assert bad.exit_code == 2 and "--dt" in bad.output


def test_bench_falls_back_to_an_implicit_reference_when_dop853_cannot_finish(monkeypatch):
    """A stiff scene spends DOP853's step budget at rtol 1e-13: bench stopped before any method ran, advising
    --method, which bench does not have. The reference is then CVODE at 1e-12 (Radau without SUNDIALS), named in
    the table's title and a note. Here DOP853's failure is simulated; the methods' errors are against the
    fallback's result."""
    from mechsys.analysis.motion import workprecision
    from mechsys.errors import AnalysisError

    real = workprecision.simulate

    def stiff_for_dop853(model, t_end, dt, method, **kw):
        if method == "DOP853" and kw.get("rtol") == 1e-13:
            raise AnalysisError("integration stopped at t = 0.04: the step budget (--max-steps) is spent: a stiff "
                                "scene (try --method Radau or CVODE)")
        return real(model, t_end, dt, method, **kw)

    monkeypatch.setattr(workprecision, "simulate", stiff_for_dop853)
    r = invoke("bench", ROOT / "systems" / "double_pendulum.yaml", "--t-end", 0.2, "--methods", "native",
               "--rtols", "1e-8", "-f", "json")
    assert r.exit_code == 0, r.output
    data = json.loads(r.stdout)
    (title,) = [k for k in data if k.startswith("work-precision")]
    assert title in ("work-precision (reference: CVODE, rtol 1e-12)", "work-precision (reference: Radau, rtol 1e-12)")
    assert data[title][0]["final error"] < 1e-6


OSCILLATOR = """\
name: mass on a spring
parameters: {m: 2, k: 18}
coordinates:
  x: {initial: 0.1, rate: 0}
links:
  block: {joint: {type: prismatic, parent: ground, axis: x, coordinate: x}, mass: m}
forces:
  - {type: torsional_spring, coordinate: x, stiffness: k, free_angle: 0}  # any coordinate, angular or not
"""


def test_a_t_end_that_is_not_a_whole_number_of_dt_still_ends_at_t_end(tmp_path):
    """--t-end 1 --dt 0.3 ended at 0.9 and called that row t_end; the last interval is now the remainder 0.1, and
    the final state is the closed form x = x0 cos(3 t) at t = 1 (every method)."""
    (tmp_path / "spring.yaml").write_text(OSCILLATOR, encoding="utf-8")
    for method in ("native", "DOP853", "Radau"):
        out = tmp_path / f"{method}.csv"
        r = invoke("simulate", tmp_path / "spring.yaml", "--t-end", 1, "--dt", 0.3, "--method", method, "-o", out,
                   "-f", "json")
        assert r.exit_code == 0, r.output
        rows = np.array([[float(x) for x in ln.split(",")] for ln in out.read_text().splitlines()[1:]])
        assert np.allclose(rows[:, 0], [0, 0.3, 0.6, 0.9, 1.0], rtol=0, atol=1e-15)
        assert abs(rows[-1, 1] - 0.1 * np.cos(3.0)) < 1e-8
        summary = json.loads(r.stdout)["simulation summary"]
        assert abs(summary["x(t_end)"] - 0.1 * np.cos(3.0)) < 1e-6


def test_bench_errors_are_relative_to_each_components_size_at_any_amplitude(tmp_path):
    """An oscillator (m = 1, k = 4) started at x = 1e-5: bench's final error is the largest of |x - x_ref| / A and
    |v - v_ref| / (A w), A w the sizes along the run (closed form x = A cos(w t)). It was measured against
    max(1, |final state|), so a state of 1e-5 showed errors 1e5 times too small (helper audit: a spring chain's RK45
    at rtol 1e-4 showed 3.6e-7 where it was off by 0.4 %)."""
    import math

    import mechsys
    from mechsys.analysis.motion.simulate import simulate
    from mechsys.analysis.motion.workprecision import work_precision

    A, w, t_end = 1e-5, 2.0, 3.0
    path = tmp_path / "osc.yaml"
    path.write_text(f"name: osc\ncoordinates:\n  x: {{initial: {A}}}\nlinks:\n  block:\n"
                    "    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n    mass: 1\n"
                    "forces:\n  - {type: torsional_spring, coordinate: x, stiffness: 4}\n")
    model = mechsys.load(path)
    points, _ = work_precision(model, t_end, ["RK45"], [1e-4, 1e-6])
    for point in points:
        r = simulate(model, t_end, method="RK45", rtol=point.rtol, atol=point.rtol * 1e-3)
        x_err = abs(r.q[-1, 0] - A * math.cos(w * t_end)) / A
        v_err = abs(r.u[-1, 0] + A * w * math.sin(w * t_end)) / (A * w)
        assert point.final_error == pytest.approx(max(x_err, v_err), rel=1e-4)  # sizes read at the output rows
        assert point.final_error > 1e-8  # a real relative error, not one scaled down by the amplitude


def test_bench_times_no_compilation(tmp_path, monkeypatch):
    """bench builds what the methods run (the Python code, the native C library) before it times any run: with an
    empty cache the first native run built the library inside its timing (0.42 s for a 0.013 s run of the double
    pendulum, 30x). Every timed run finds the library built."""
    from mechsys.analysis.motion import workprecision
    from mechsys.numeric import native

    if native.compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    real, seen = workprecision.simulate, []

    def timed(model, t_end, dt, method, **kw):
        compiled = getattr(model, "_simulation_compiled", None)
        seen.append((method, getattr(compiled, "native", None) is not None))
        return real(model, t_end, dt, method, **kw)

    monkeypatch.setattr(workprecision, "simulate", timed)
    r = invoke("bench", ROOT / "systems" / "double_pendulum.yaml", "--t-end", 0.2, "--methods", "native",
               "--rtols", "1e-6,1e-8", "-f", "json")
    assert r.exit_code == 0, r.output
    assert [m for m, _ in seen] == ["DOP853", "native", "native"]
    assert all(built for _, built in seen), seen


def _four_bar_path(guess: list[float], held: int, steps: int = 2000) -> np.ndarray:
    """The end of the homotopy Phi(q) = (1 - s) Phi(guess) of tests/data/beyond/rough_four_bar.yaml (crank a, coupler
    b, rocker c, ground d) with coordinate ``held`` fixed, followed in ``steps`` equal steps of Newton on the loop
    equations written here (not mechsys's), its angles wrapped to (-pi, pi]."""
    a, b, c, d = 0.1, 0.35, 0.25, 0.3

    def phi(q):
        t1, t2, t3 = q
        return np.array([a * np.cos(t1) + b * np.cos(t1 + t2) - d - c * np.cos(t3),
                         a * np.sin(t1) + b * np.sin(t1 + t2) - c * np.sin(t3)])

    def jac(q):
        t1, t2, t3 = q
        return np.array([[-a * np.sin(t1) - b * np.sin(t1 + t2), -b * np.sin(t1 + t2), c * np.sin(t3)],
                         [a * np.cos(t1) + b * np.cos(t1 + t2), b * np.cos(t1 + t2), -c * np.cos(t3)]])

    free = [k for k in range(3) if k != held]
    q = np.array(guess, dtype=float)
    offset = phi(q)
    for i in range(1, steps + 1):
        for _ in range(4):
            q[free] -= np.linalg.solve(jac(q)[:, free], phi(q) - (1 - i / steps) * offset)
    return q


@pytest.mark.parametrize("held, value", [("th1", 0.6), ("th1", 1.2), ("th1", -1.8), ("th1", -1.5), ("th1", 4.8),
                                         ("th3", 2.2), ("th3", 1.65)])
def test_a_start_value_set_is_held_by_the_assembly_onto_the_constraints(tmp_path, held, value):
    """A four-bar whose file guesses the coupler and rocker angles (tests/data/beyond/rough_four_bar.yaml). With
    `--set th1=0.6` the assembly moved the crank too (to 0.396, as much as the guesses). The value set is now held
    and the others follow the homotopy from the guesses: its end, computed here in 2000 small steps, to 1e-9 (the
    angles up to whole turns). A direct solve jumped to the crossed branch (th1 = 1.2) and wound angles by turns
    (th1 = -1.8: th3 = 52.45); steps that Newton corrected onto another path (th1 = -1.5, 4.8) did too; a value near
    the rocker's swing limit (th3 = 2.2 of 2.2143) was moved back. The warning names what moved and what was
    carried to its value set."""
    path = ROOT / "tests" / "data" / "beyond" / "rough_four_bar.yaml"
    out = tmp_path / "run.csv"
    r = invoke("simulate", path, "--t-end", 0.001, "--dt", 0.001, "--set", f"{held}={value}", "-o", out, "-f", "json")
    assert r.exit_code == 0, r.output
    first = dict(zip(*(line.split(",") for line in out.read_text().splitlines()[:2])))
    got = np.array([float(first[name]) for name in ("th1", "th2", "th3")])
    k = ("th1", "th2", "th3").index(held)
    assert got[k] == value
    guess = [1.0, 0.3, 1.7]
    guess[k] = value
    want = _four_bar_path(guess, k)
    turns = np.round((got - want) / (2 * math.pi))
    assert np.allclose(got - 2 * math.pi * turns, want, atol=1e-9), (got, want)
    assert np.all(np.abs(np.delete(got - guess, k)) <= math.pi)  # within half a turn of the guesses
    warning = next(n for n in json.loads(r.stdout)["notes"] if "assembled onto the constraints" in n)
    assert f"carried to {held} as set" in warning and f"{held} = " not in warning


def test_a_start_value_no_closed_position_has_is_moved_and_said_so(tmp_path):
    """The rocker set beyond its swing (th3 = 3.0; it swings over [acos(1/3), acos(-0.6)]) cannot be held: the
    start is the projection's, and a warning says the value set was not held. Rates set that conflict (der(th1) =
    der(th3) = 1 with th1 = 0.6) are not held either, while th1 = 0.6 still is."""
    path = ROOT / "tests" / "data" / "beyond" / "rough_four_bar.yaml"
    out = tmp_path / "run.csv"
    r = invoke("simulate", path, "--t-end", 0.001, "--dt", 0.001, "--set", "th3=3.0", "-o", out, "-f", "json")
    assert r.exit_code == 0, r.output
    notes = json.loads(r.stdout)["notes"]
    assert any(n.startswith("th3 as set cannot be held on the constraints") for n in notes)
    # the projection's angles within half a turn of their guesses (it wound the rocker by 2 turns: its spring's
    # energy 81.9 J where the same position stores 7 J)
    first = dict(zip(*(line.split(",") for line in out.read_text().splitlines()[:2])))
    th1, th2, th3 = (float(first[name]) for name in ("th1", "th2", "th3"))
    assert abs(th3 - 3.0) <= math.pi and abs(th2 - 0.3) <= math.pi and abs(th1 - 1.0) <= math.pi
    a, b, c, d = 0.1, 0.35, 0.25, 0.3
    assert abs(a * np.cos(th1) + b * np.cos(th1 + th2) - d - c * np.cos(th3)) < 1e-12
    r = invoke("simulate", path, "--t-end", 0.001, "--dt", 0.001, "--set", "th1=0.6", "--set", "der(th1)=1",
               "--set", "der(th3)=1", "-o", out, "-f", "json")
    assert r.exit_code == 0, r.output
    first = dict(zip(*(line.split(",") for line in out.read_text().splitlines()[:2])))
    assert float(first["th1"]) == 0.6
    notes = json.loads(r.stdout)["notes"]
    assert any(n.startswith("der(th1), der(th3) as set cannot be held") for n in notes)
    assert any("carried to th1 as set" in n for n in notes)


def test_a_value_set_that_no_path_reaches_is_refused_naming_it(tmp_path):
    """The rocker set to -1.5: within its swing, but no path from the file's guesses (th1 = 1, th2 = 0.3) reaches a
    closed position with it, and their projection does not converge. The refusal named no value set ('no nearby
    state satisfies the constraints'); it now names th3 and what to do."""
    path = ROOT / "tests" / "data" / "beyond" / "rough_four_bar.yaml"
    r = invoke("simulate", path, "--t-end", 0.01, "--set", "th3=-1.5")
    assert r.exit_code == 1
    assert "th3 as set: no path from the file's values of the other coordinates reaches a state" in r.stderr
