"""The Whipple bicycle benchmark (Meijaard, Papadopoulos, Ruina and Schwab 2007) through systems/bicycle.yaml:
eigenvalues against the paper's Table 2 and the published M0, C1, K0, K2 (tests/reference_nonholonomic.py, no
mechsys import), weave and capsize speeds from the sweep, and simulations of the nonlinear model that agree with
the verdicts. (Lagrange = Kane is tested on the rolling disk in test_nonholonomic.py: the bicycle's Lagrange
derivation alone costs 45 s.)"""
from __future__ import annotations

import functools
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.equilibrium.bifurcation import swept_parameter
from mechsys.analysis.equilibrium.equilibria import _polish
from mechsys.numeric.parameters import parameter_values
from mechsys.analysis.equilibrium.nonholonomic import NonholonomicProblem, linearize_steady
from mechsys.cli import app

sys.path.insert(0, str(Path(__file__).parent))
import reference_nonholonomic as ref  # noqa: E402
from helpers import SYSTEMS_DIR  # noqa: E402

BIKE = SYSTEMS_DIR / "bicycle.yaml"
runner = CliRunner()


@functools.lru_cache(maxsize=None)
def speed_problem(method: str = "kane"):
    """The steady-motion problem of the file and its parameter v (the given rates follow v: rate v/rR)."""
    problem = NonholonomicProblem(mechsys.load(BIKE), method=method)
    return problem, swept_parameter(problem, "v")


def upright(v: float, method: str = "kane"):
    """The linearization about upright straight running at speed v."""
    problem, speed = speed_problem(method)
    p = speed.at(v)
    z = _polish(problem, problem.start(np.zeros(problem.nq + len(problem.rate_unknowns)), p), p)
    assert z is not None
    e = problem.equilibrium(z)
    assert max(abs(x) for x in e.coordinates.values()) < 1e-12
    return linearize_steady(problem, e, p)


def same_roots(got: np.ndarray, want: np.ndarray, rel: float) -> bool:
    diff, _ = ref.max_eigenvalue_difference(got, want)
    return len(got) == len(want) and diff <= rel * max(1.0, float(np.max(np.abs(want))))


def test_eigenvalues_equal_table_2():
    """The 4 lean/steer eigenvalues at v = 0, 1, ..., 10 m/s: Table 2 of the paper to 1e-10 relative; the
    structural zeros of x, y, yaw, both wheel angles and the speed family are apart."""
    for v in range(11):
        lin = upright(float(v))
        assert same_roots(lin.eigenvalues, ref.TABLE2_EIGENVALUES[v], 1e-10), v
        assert same_roots(lin.eigenvalues, ref.benchmark_eigenvalues(float(v)), 1e-10), v
        assert lin.ignorable == ["x", "y", "yaw", "theta_R", "theta_F"] and lin.families == ["der(theta_R)"]


def test_reduced_matrices_equal_the_published_ones():
    """--independent lean,steer: M = M0, C = v C1, K = g K0 + v^2 K2 (read at v = 0 and v = 2) to 1e-10."""
    M, C0, K_0 = upright(0.0).second_order(["lean", "steer"])
    M2, C2, K_2 = upright(2.0).second_order(["lean", "steer"])
    assert np.allclose(M, ref.BENCH_M0, rtol=1e-10, atol=1e-12) and np.allclose(M2, ref.BENCH_M0, rtol=1e-10)
    assert np.allclose(C0, 0.0, atol=1e-10)
    assert np.allclose(C2 / 2.0, ref.BENCH_C1, rtol=1e-10, atol=1e-10)
    assert np.allclose(K_0 / ref.G_BENCH, ref.BENCH_K0, rtol=1e-10, atol=1e-10)
    assert np.allclose((K_2 - K_0) / 4.0, ref.BENCH_K2, rtol=1e-10, atol=1e-10)


def test_linearize_cli_prints_the_benchmark_matrices():
    result = runner.invoke(app, ["equilibria", str(BIKE), "--search", "lean=-0.3:0.3", "--search",
                                 "steer=-0.3:0.3", "--independent", "lean,steer", "--linearize", "-f", "markdown"])
    assert result.exit_code == 0, result.output
    text = result.stdout
    assert "M over lean, steer" in text and "80.81722" in text and "2.319413" in text
    assert "no second-order form" in text  # the two steady turns at 5 m/s couple lean and steer to the speed
    assert "asymptotically stable" in text  # v = 5 m/s (the file's speed) lies in the stable range


@pytest.mark.slow
def test_sweep_finds_weave_and_capsize_speeds(tmp_path):
    """The command of docs/equilibria.md 11.6 (its stability plot included) over 4..6.5 m/s with the same step
    (the test suite's time; the docs' 0..10 run gives the same two values)."""
    figure = tmp_path / "bicycle_eigenvalues.png"
    result = runner.invoke(app, ["equilibria", str(BIKE), "--search", "lean=-0.3:0.3", "--search", "steer=-0.3:0.3",
                                 "--sweep", "v=4:6.5:26", "--plot", str(figure), "--plot-coordinate", "eigenvalues",
                                 "-f", "json"])
    assert result.exit_code == 0, result.output
    assert figure.stat().st_size > 10_000
    bifs = json.loads(result.stdout)["bifurcations"]
    upright = [b for b in bifs if max(abs(x) for x in b["coordinates"].values()) < 1e-9]
    hopf = [b["value"] for b in upright if b["kind"] == "hopf"]
    # capsize: a real root crosses zero, and the branches of steady turns meet straight running there
    real = [b["value"] for b in upright if b["kind"] in ("branch_point", "zero_eigenvalue")]
    assert len(hopf) == 1 and hopf[0] == pytest.approx(ref.WEAVE_SPEED, abs=1e-8)
    assert len(real) == 1 and real[0] == pytest.approx(ref.CAPSIZE_SPEED, abs=1e-8)


# ------------------------------------------------------------------------------------------- the nonlinear model
def simulate(*sets: str, t_end: float = 4.0) -> dict:
    args = ["simulate", str(BIKE), "--t-end", str(t_end), "--dt", "0.5", "-f", "json"]
    for s in sets:
        args += ["--set", s]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)["simulation summary"]


@pytest.mark.slow
def test_upright_running_keeps_energy_and_constraints():
    s = simulate("v=5", t_end=2.0)
    assert abs(s["max relative energy drift"]) < 1e-10 and s["max constraint residual"] < 1e-10
    assert abs(s["lean(t_end)"]) < 1e-12 and s["x(t_end)"] == pytest.approx(10.0, rel=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("v, grows", [(5.0, False), (3.0, True)])
def test_a_lean_perturbation_decays_in_the_stable_range_and_grows_below_weave(v, grows):
    """A lean rate of 0.05 rad/s: at 5 m/s (between weave 4.29 and capsize 6.02) the bicycle rights itself, at
    3 m/s the weave grows (Re = +1.71 at 3 m/s, Table 2)."""
    s = simulate(f"v={v}", "der(lean)=0.05", t_end=4.0)
    final = abs(s["lean(t_end)"]) + abs(s["der(lean)(t_end)"])
    if grows:
        assert final > 0.5
    else:
        assert final < 0.05 * 0.2


def test_modes_at_5_m_s_are_weave_capsize_and_castor():
    """docs/modes.md 12: one mode per eigenvalue with Im >= 0, |lambda| and -Re/|lambda| of Table 2 at 5 m/s."""
    result = runner.invoke(app, ["modes", str(BIKE), "--at", "lean=0", "--at", "steer=0", "-f", "json"])
    assert result.exit_code == 0, result.output
    modes = json.loads(result.stdout)["modes"]
    want = [v for v in ref.TABLE2_EIGENVALUES[5] if v.imag >= 0]
    got = sorted((m["frequency_rad_s"], m["damping_ratio"]) for m in modes)
    assert np.allclose(got, sorted((abs(v), -v.real / abs(v)) for v in want), rtol=1e-10)


# ------------------------------------------------------------------------------------- coordinate singularities
def test_a_bicycle_lying_flat_is_a_coordinate_singularity_not_a_steady_motion():
    """Lying flat (lean = pi/2) the front contact frame's chi and the pitch are not determined by the holonomic
    constraints (their Jacobian in chi, pitch vanishes: the wheel plane is horizontal, every chi touches the
    ground). The default search finds such roots; they are named in a note, not listed, and the sweep does not try
    to continue them (it stopped with a Newton error before). Upright running is regular."""
    problem, speed = speed_problem()
    p = speed.at(5.0)
    flat = problem.start(np.array([np.pi / 2, -2.6054, np.pi, 1.61561]), p)
    assert problem.split_singularity(flat, p) == "the holonomic constraints do not determine chi, pitch"
    z = _polish(problem, problem.start(np.zeros(problem.nq + len(problem.rate_unknowns)), p), p)
    assert problem.split_singularity(z, p) is None
    result = runner.invoke(app, ["equilibria", str(BIKE), "-f", "json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert "coordinate singularities of the model" in out["message"] and "not isolated" not in out["message"]
    assert all(abs(abs(e["coordinates"]["lean"]) - np.pi / 2) > 1e-6 for e in out["equilibria"])
    (up,) = [e for e in out["equilibria"] if max(abs(x) for x in e["coordinates"].values()) < 1e-9]
    assert up["stability"] == "asymptotically stable"


def test_a_steady_motion_whose_split_is_singular_to_round_off_has_no_linearization():
    """At v = 0 a steady turn of the upside-down bicycle ends in a pivot about the rear contact (front wheel and yaw
    turning, 21.7 and 6.94 rad/s): a root of the steady-motion equations where the velocity constraints do not
    determine the dependent speeds (their block in them is singular to round-off, A itself is not). The solves of
    the linearization passed there and gave eigenvalues of 7e7 and a verdict "unstable" in the sweep's table;
    the test that drops such roots from a search (with a margin) now ends a branch next to it, with the reason."""
    from mechsys.errors import AnalysisError

    problem, speed = speed_problem()
    p = speed.at(0.0)
    z = np.array([3.135923747987055, 2.6131589388272718, -1.5995573978259874, -0.3378905747362833,
                  -1.2959596337500634e-18, -3.3881006952286914e-21, 21.715458216562787, 6.938202940146218,
                  4.739714389653464e-19, -1.203586352136275e-17, -1.2868103266088941e-15, -4.2213732675506364e-16,
                  -7.533320116453745e-30, -27.208215065034747, 9.572175357520338e-19, -1.311983677014752,
                  50.08276038451176, 1.8465042908069744])
    assert np.max(np.abs(problem.F(z, p))) < 1e-10  # a steady motion
    assert np.linalg.svd(problem._at(z, p)["A"], compute_uv=False)[-1] > 0.1  # A has full rank
    why = problem.split_singularity(z, p)
    assert why is not None and why.startswith("the velocity constraints do not determine der(chi)")
    with pytest.raises(AnalysisError, match="to the precision a linearization needs"):
        linearize_steady(problem, problem.equilibrium(z), p)
    # on the branch towards it the block is nearly singular: its smallest singular value falls as v, and the
    # eigenvalues lose digits about as its square; below LINEARIZATION_RTOL (relative) there is no linearization
    near = _polish(problem, z, speed.at(1e-6))
    assert near is not None and problem.split_singularity(near, speed.at(1e-6)) is None
    with pytest.raises(AnalysisError, match="to the precision a linearization needs"):
        linearize_steady(problem, problem.equilibrium(near), speed.at(1e-6))


def test_compiled_pieces_equal_the_python_ones():
    """The bicycle's steady-motion pieces run as C (numeric/native.py) when a compiler is present: the same
    numbers as the generated Python to round-off, at random states."""
    problem, _ = speed_problem()
    pieces = problem.pieces
    if pieces._native is None:
        pytest.skip("no C compiler")
    rng = np.random.default_rng(11)
    p = parameter_values(problem.model)
    for _ in range(3):
        args = [rng.uniform(-1, 1, pieces.n), rng.uniform(-1, 1, pieces.n), rng.uniform(-1, 1, pieces.n),
                rng.uniform(-100, 100, pieces.m), p]
        flat = np.concatenate(args)
        native = pieces._native("mechsys_full", flat)
        python = np.asarray(pieces._fn(*flat), dtype=float)
        assert np.allclose(native, python, rtol=1e-13, atol=1e-11 * np.max(np.abs(python)))
        assert np.allclose(pieces.residual(*args), np.asarray(pieces._values(*flat), dtype=float),
                           rtol=1e-13, atol=1e-11)
