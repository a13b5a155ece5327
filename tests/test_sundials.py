"""SUNDIALS CVODE integrator (mechsys.analysis.motion.sundials) against scipy's integrators on mechsys scenes."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

pytest.importorskip("sksundae")

import mechsys  # noqa: E402
from mechsys.analysis.motion import sundials  # noqa: E402
from mechsys.analysis.motion.simulate import RightHandSide, initial_state  # noqa: E402
from mechsys.errors import AnalysisError  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def _scene(path: Path) -> tuple[RightHandSide, np.ndarray]:
    """The compiled right-hand side and consistent initial state, built as simulate() builds them."""
    c, p, y0 = initial_state(mechsys.load(path))
    return RightHandSide(c, p), y0


def test_available() -> None:
    assert sundials.available()


def test_stiff_chain_agrees_with_radau() -> None:
    # Tolerance: at rtol 1e-10 / atol 1e-12, benchmarks/stiff.py measures both methods against Radau at rtol
    # 1e-12 on this scene: CVODE's largest error over the grid is 2.2e-9 of each component's peak, Radau's 6e-11.
    # The two may therefore differ by ~2.3e-9 of the peak; 1e-7 leaves a 40x margin for other BLAS/CPUs, while
    # a wrong output time (one grid step is 0.5 ms against decay times of 0.03 ms ... 10 ms) or a wrong
    # state ordering would show up at the 1e-2 ... 1 level.
    rhs, y0 = _scene(ROOT / "tests/data/stiff_chain.yaml")
    grid = np.linspace(0.0, 0.5, 501)
    ref = solve_ivp(rhs, (0.0, 0.5), y0, method="Radau", t_eval=grid, rtol=1e-10, atol=1e-12)
    assert ref.success
    calls_before = rhs.calls
    sol = sundials.integrate(rhs, (0.0, 0.5), y0, grid, rtol=1e-10, atol=1e-12)
    assert sol.success, sol.message
    assert sol.status == 0
    np.testing.assert_array_equal(sol.t, grid)
    assert sol.y.shape == (6, len(grid))
    np.testing.assert_array_equal(sol.y[:, 0], y0)
    assert sol.nfev == rhs.calls - calls_before > 0
    assert sol.njev > 0  # BDF's Newton iterations need Jacobians (finite differences here)
    assert sol.nsteps is None  # on a t_eval grid scikit-sundae does not report the step count
    peak = np.max(np.abs(ref.y), axis=1)
    assert np.max(np.abs(sol.y - ref.y) / peak[:, None]) < 1e-7
    assert abs(sol.y[0, 0]) == pytest.approx(0.01)  # the chain starts displaced and has decayed by t = 0.5 s
    assert np.max(np.abs(sol.y[:3, -1])) < 1e-6


@pytest.mark.parametrize("method", ["BDF", "Adams"])
def test_double_pendulum_non_stiff_agrees_with_dop853(method: str) -> None:
    rhs, y0 = _scene(ROOT / "systems/double_pendulum.yaml")
    grid = np.linspace(0.0, 2.0, 201)
    ref = solve_ivp(rhs, (0.0, 2.0), y0, method="DOP853", t_eval=grid, rtol=1e-12, atol=1e-12)
    sol = sundials.integrate(rhs, (0.0, 2.0), y0, grid, rtol=1e-10, atol=1e-12, method=method)
    assert sol.success, sol.message
    np.testing.assert_array_equal(sol.t, grid)
    assert np.max(np.abs(sol.y - ref.y)) < 1e-6
    assert np.ptp(sol.y[0]) > 0.5  # it really swings (theta1 starts at 0.5 rad)


def test_internal_steps_without_t_eval() -> None:
    rhs, y0 = _scene(ROOT / "systems/double_pendulum.yaml")
    sol = sundials.integrate(rhs, (0.0, 1.0), y0, None, rtol=1e-9, atol=1e-11)
    assert sol.success
    assert sol.t[0] == 0.0 and sol.t[-1] == 1.0
    assert np.all(np.diff(sol.t) > 0)
    assert sol.nsteps == len(sol.t) - 1 > 10
    ref = solve_ivp(rhs, (0.0, 1.0), y0, method="DOP853", rtol=1e-12, atol=1e-12)
    assert np.max(np.abs(sol.y[:, -1] - ref.y[:, -1])) < 1e-6


def test_nan_right_hand_side_fails_with_message(capfd) -> None:
    rhs, y0 = _scene(ROOT / "tests/data/stiff_chain.yaml")

    def broken(t, y):
        dy = rhs(t, y)
        return dy if t < 0.1 else dy * np.nan

    grid = np.linspace(0.0, 0.5, 51)
    sol = sundials.integrate(broken, (0.0, 0.5), y0, grid, rtol=1e-8, atol=1e-10)
    assert not sol.success
    assert sol.status == -1
    assert "NaN/inf" in sol.message and "t = 0.1" in sol.message
    assert sol.nfev <= 10_000  # gives up after a bounded number of evaluations, not after max_num_steps steps
    # outputs stop at the last grid point before the failure, like solve_ivp's
    assert 0.05 <= sol.t[-1] <= 0.1
    np.testing.assert_array_equal(sol.t, grid[: len(sol.t)])
    assert sol.y.shape == (6, len(sol.t))
    out = capfd.readouterr()
    assert out.out == "" and "WARNING" not in out.err  # SUNDIALS' own prints do not reach the terminal


def test_sundials_failure_reports_sundials_message(capfd) -> None:
    rhs, y0 = _scene(ROOT / "tests/data/stiff_chain.yaml")
    sol = sundials.integrate(rhs, (0.0, 0.5), y0, [0.0, 0.25, 0.5], rtol=1e-10, atol=1e-12, max_num_steps=5)
    assert not sol.success
    assert sol.sundials_flag == -1
    assert "max_num_steps" in sol.message and "mxstep steps taken" in sol.message
    assert list(sol.t) == [0.0]
    assert capfd.readouterr().out == ""


def test_events_match_solve_ivp() -> None:
    rhs, y0 = _scene(ROOT / "systems/double_pendulum.yaml")

    def downward(t, y):  # theta1 through zero, falling
        return y[0]
    downward.direction = -1.0

    def any_theta2(t, y):
        return y[1]

    grid = np.linspace(0.0, 3.0, 301)
    ref = solve_ivp(rhs, (0.0, 3.0), y0, method="DOP853", t_eval=grid, rtol=1e-12, atol=1e-12,
                    events=[downward, any_theta2])
    sol = sundials.integrate(rhs, (0.0, 3.0), y0, grid, rtol=1e-10, atol=1e-12, events=[downward, any_theta2])
    assert sol.success and sol.status == 0
    for k in range(2):
        assert len(sol.t_events[k]) == len(ref.t_events[k]) > 0
        np.testing.assert_allclose(sol.t_events[k], ref.t_events[k], atol=1e-7)
        np.testing.assert_allclose(sol.y_events[k], ref.y_events[k], atol=1e-6)
    assert np.all(sol.y_events[0][:, 2] < 0)  # only falling crossings of theta1


def test_terminal_event_stops_like_solve_ivp() -> None:
    rhs, y0 = _scene(ROOT / "systems/double_pendulum.yaml")

    def stop(t, y):
        return y[0]
    stop.terminal = True

    grid = np.linspace(0.0, 3.0, 301)
    ref = solve_ivp(rhs, (0.0, 3.0), y0, method="DOP853", t_eval=grid, rtol=1e-12, atol=1e-12, events=[stop])
    sol = sundials.integrate(rhs, (0.0, 3.0), y0, grid, rtol=1e-10, atol=1e-12, events=[stop])
    assert sol.success and sol.status == 1 == ref.status
    assert len(sol.t_events[0]) == 1
    assert sol.t_events[0][0] == pytest.approx(ref.t_events[0][0], abs=1e-7)
    np.testing.assert_array_equal(sol.t, ref.t)  # the grid points before the event, the event itself not
    assert abs(sol.y_events[0][0][0]) < 1e-8


def test_analytic_jacobian_is_used() -> None:
    A = np.array([[-1e4, 1.0], [0.0, -1.0]])  # stiff linear test problem with exact solution expm(A t) y0
    y0 = np.array([1.0, 1.0])
    grid = np.linspace(0.0, 2.0, 21)
    jac_calls = []

    def jac(t, y):
        jac_calls.append(t)
        return A

    with_jac = sundials.integrate(lambda t, y: A @ y, (0.0, 2.0), y0, grid, rtol=1e-10, atol=1e-12, jac=jac)
    without = sundials.integrate(lambda t, y: A @ y, (0.0, 2.0), y0, grid, rtol=1e-10, atol=1e-12)
    exact = np.array([expm(A * t) @ y0 for t in grid]).T
    for sol in (with_jac, without):
        assert sol.success
        np.testing.assert_allclose(sol.y, exact, rtol=1e-6, atol=1e-9)
    assert len(jac_calls) == with_jac.njev > 0
    # finite differences cost one RHS call per state per Jacobian; the analytic one costs none
    assert without.nfev - with_jac.nfev >= without.njev * 2 - 5


def test_bad_arguments_raise_analysis_error() -> None:
    with pytest.raises(AnalysisError, match="unknown CVODE method"):
        sundials.integrate(lambda t, y: -y, (0.0, 1.0), np.ones(1), None, method="RK45")
    with pytest.raises(AnalysisError, match="forward only"):
        sundials.integrate(lambda t, y: -y, (1.0, 0.0), np.ones(1), None)
    with pytest.raises(AnalysisError, match="t_eval"):
        sundials.integrate(lambda t, y: -y, (0.0, 1.0), np.ones(1), [0.0, 2.0])


def test_simulate_auto_uses_cvode_for_the_stiff_chain_and_matches_radau():
    """Wired into simulate: auto picks CVODE for a stiff scene (at rtol/100) and agrees with a tight Radau run."""
    from mechsys.analysis.motion.simulate import simulate
    from tests.helpers import load_data

    model = load_data("stiff_chain")
    r = simulate(model, 3.0, dt=0.01)  # 2.9e4 1/s over 3 s: stiff
    ref = simulate(model, 3.0, dt=0.01, method="Radau", rtol=1e-12, atol=1e-14)
    assert r.method == "CVODE"
    scale = np.max(np.abs(ref.q), axis=0)
    assert np.max(np.abs(r.q - ref.q) / scale) < 1e-8


def test_cvode_refuses_contacts_with_a_reason():
    from mechsys.analysis.motion.simulate import simulate
    from mechsys.errors import AnalysisError
    from tests.helpers import load_system

    with pytest.raises(AnalysisError, match="contacts"):
        simulate(load_system("bouncing_ball"), 1.0, method="CVODE")
