"""Pseudo-arclength continuation: folds, branch points and Hopf points of toy problems with known answers."""
from __future__ import annotations

import numpy as np
import pytest

from mechsys.analysis.equilibrium.continuation import (Bifurcation, Branch, BranchPoint, ContinuationOptions,
                                                       Undefined, continue_branch, sweep_parameter)


# -- toy problems ------------------------------------------------------------------------------------------
def fold_problem():
    F = lambda x, p: np.array([x[0] ** 2 + p])                 # noqa: E731
    Fx = lambda x, p: np.array([[2.0 * x[0]]])                 # noqa: E731
    Fp = lambda x, p: np.array([1.0])                          # noqa: E731
    eig = lambda x, p: np.array([-2.0 * x[0]])                 # noqa: E731  (xdot = -(x^2 + p))
    return F, Fx, Fp, eig


def pitchfork_problem():
    F = lambda x, p: np.array([p * x[0] - x[0] ** 3])          # noqa: E731
    Fx = lambda x, p: np.array([[p - 3.0 * x[0] ** 2]])        # noqa: E731
    Fp = lambda x, p: np.array([x[0]])                         # noqa: E731
    eig = lambda x, p: np.array([p - 3.0 * x[0] ** 2])         # noqa: E731
    return F, Fx, Fp, eig


E, FC, G = 3.8, 1.2, -39.24


def centrifuge_problem(damping: float = 0.5):
    def F(x, w):
        b = x[0]
        return np.array([E * w ** 2 * np.sin(b) * np.cos(b) + FC * w ** 2 * np.cos(b) + G * np.sin(b)])

    def Fx(x, w):
        b = x[0]
        return np.array([[E * w ** 2 * np.cos(2 * b) - FC * w ** 2 * np.sin(b) + G * np.cos(b)]])

    def Fp(x, w):
        b = x[0]
        return np.array([2 * w * (E * np.sin(b) * np.cos(b) + FC * np.cos(b))])

    def eig(x, w):  # state-space eigenvalues of  beta'' = F(beta, w) - c beta'  (size 2 = 2n)
        return np.linalg.eigvals(np.array([[0.0, 1.0], [Fx(x, w)[0, 0], -damping]]))

    return F, Fx, Fp, eig


def hopf_problem(shuffle: bool = False):
    rng = np.random.default_rng(1)

    def F(x, p):
        r2 = x[0] ** 2 + x[1] ** 2
        return np.array([p * x[0] - x[1] - x[0] * r2, x[0] + p * x[1] - x[1] * r2])

    def Fx(x, p):
        X, Y = x
        return np.array([[p - 3 * X ** 2 - Y ** 2, -1 - 2 * X * Y], [1 - 2 * X * Y, p - X ** 2 - 3 * Y ** 2]])

    def Fp(x, p):
        return np.array(x, dtype=float)

    def eig(x, p):
        ev = np.linalg.eigvals(np.array([[p, -1.0], [1.0, p]]))
        if shuffle:  # extra stable modes and an arbitrary order at every call
            ev = rng.permutation(np.concatenate([ev, [-3.0, -1.0 + 2.0j, -1.0 - 2.0j]]))
        return ev

    return F, Fx, Fp, eig


def kinds(branch: Branch) -> list[str]:
    return [b.kind for b in branch.bifurcations]


# -- 1. fold -------------------------------------------------------------------------------------------------
def test_fold_is_passed_and_located():
    F, Fx, Fp, eig = fold_problem()
    br = continue_branch(F, Fx, Fp, np.array([1.0]), -1.0, -2.0, 0.5, eig)
    assert kinds(br) == ["fold"]
    fold = br.bifurcations[0]
    assert abs(fold.p) < 1e-8 and abs(fold.x[0]) < 1e-6
    assert br.points[fold.index].x[0] > 0.0 >= br.points[fold.index + 1].x[0]
    assert any(pt.x[0] < 0.0 for pt in br.points)
    assert br.points[-1].p == -2.0
    assert br.points[-1].x[0] == pytest.approx(-np.sqrt(2.0), abs=1e-10)
    for pt in br.points:  # every point is on the branch x^2 = -p
        assert pt.x[0] ** 2 + pt.p == pytest.approx(0.0, abs=1e-9)
        assert pt.stable == (pt.x[0] > 0.0)


def test_fold_sweep_both_ends_exact():
    F, Fx, Fp, eig = fold_problem()
    # the second start lies on the same curve: deduplicated
    branches = sweep_parameter(F, Fx, Fp, [(np.array([1.0]), -1.0), (np.array([-1.2]), -1.44)], -2.0, 0.5, eig)
    assert len(branches) == 1
    br = branches[0]
    assert br.points[0].p == -2.0 and br.points[-1].p == -2.0
    assert br.points[0].x[0] == pytest.approx(np.sqrt(2.0), abs=1e-10)
    assert br.points[-1].x[0] == pytest.approx(-np.sqrt(2.0), abs=1e-10)
    assert kinds(br) == ["fold"]
    fold = br.bifurcations[0]
    assert abs(fold.p) < 1e-8
    assert br.points[fold.index].x[0] > 0.0 >= br.points[fold.index + 1].x[0]
    xs = [pt.x[0] for pt in br.points]
    assert all(a > b for a, b in zip(xs, xs[1:]))  # ordered along the arc


def test_start_at_fold_reports_it_once():
    F, Fx, Fp, eig = fold_problem()
    [br] = sweep_parameter(F, Fx, Fp, [(np.array([0.0]), 0.0)], -2.0, 0.5, eig)
    assert kinds(br) == ["fold"]
    assert br.bifurcations[0].p == 0.0
    assert {br.points[0].p, br.points[-1].p} == {-2.0}


# -- 2. pitchfork ------------------------------------------------------------------------------------------
def test_pitchfork_branch_point_on_trivial_branch():
    F, Fx, Fp, eig = pitchfork_problem()
    br = continue_branch(F, Fx, Fp, np.array([0.0]), -1.0, -1.0, 1.0, eig)
    assert kinds(br) == ["branch_point"]
    bp = br.bifurcations[0]
    assert abs(bp.p) < 1e-8 and abs(bp.x[0]) < 1e-12
    assert br.points[0].p == -1.0 and br.points[-1].p == 1.0
    stab = [pt.stable for pt in br.points]
    assert all(stab[: bp.index + 1]) and not any(stab[bp.index + 1:])


def test_pitchfork_sweep_dedupes_and_passes_nontrivial_branch():
    F, Fx, Fp, eig = pitchfork_problem()
    starts = [(np.array([0.0]), 0.5), (np.array([0.7]), 0.49), (np.array([-0.3]), 0.09), (np.array([0.0]), -0.5)]
    branches = sweep_parameter(F, Fx, Fp, starts, -1.0, 1.0, eig, x_scale=0.5, ds=0.02)
    assert len(branches) == 2
    trivial, parabola = branches
    assert [pt.p for pt in (trivial.points[0], trivial.points[-1])] == [-1.0, 1.0]
    assert kinds(trivial) == ["branch_point"]
    assert abs(trivial.bifurcations[0].p) < 1e-8
    # the parabola p = x^2 goes through the pitchfork point from x = -1 to x = 1
    assert sorted(pt.x[0] for pt in (parabola.points[0], parabola.points[-1])) == pytest.approx([-1.0, 1.0])
    for pt in parabola.points:
        assert pt.p == pytest.approx(pt.x[0] ** 2, abs=1e-9)
        assert pt.stable  # eig = p - 3 x^2 = -2 x^2
    # following the parabola, p turns at the pitchfork point: reported as a fold there
    assert kinds(parabola) == ["fold"] and abs(parabola.bifurcations[0].p) < 1e-8


def test_a_point_without_eigenvalues_ends_the_branch_with_the_reason_not_the_sweep():
    """The bicycle's default sweep stopped with "the saddle-point system is singular" where one odd branch reached
    v = 0 (a singular linearization). An eig callback that cannot linearize ends that branch there, with the
    reason; the other branches and the points before it are kept; a start without eigenvalues is skipped."""
    F, Fx, Fp, eig = fold_problem()  # x^2 + p = 0: the branch p = -x^2, folding at p = 0

    def partial_eig(x, p):
        if p > -0.25:
            raise Undefined("singular at this point")
        return eig(x, p)

    skipped = []
    starts = [(np.array([1.0]), -1.0), (np.array([0.1]), -0.01)]
    branches = sweep_parameter(F, Fx, Fp, starts, -1.0, 1.0, partial_eig, skipped=skipped, ds=0.05)
    assert skipped == [(-0.01, "singular at this point")]
    (branch,) = branches
    assert branch.points[0].p == -1.0 and all(pt.p <= -0.25 for pt in branch.points)
    (where, why), = branch.undefined
    assert -0.25 < where < 0.0 and why == "singular at this point"
    assert branch.points[-1].p > -0.25 - 1e-5  # it got as close as the smallest step allows
    assert kinds(branch) == []  # the fold lies beyond: not reported from a branch that never reached it


def test_a_branch_approaches_a_point_without_eigenvalues_and_finds_the_events_before_it():
    """The step that reaches a point without a linearization is retried shorter, so the branch ends close to that
    point and the events between the last regular point and it are found (the bicycle's steady turns as v -> 0:
    a real eigenvalue crossing zero at v = 0.045 lay inside a step ending at v = 0, where the split is singular).
    Branch x = p, its eigenvalue p - 0.33 crosses zero at p = 0.33; no linearization below p = 0.3. The steps of
    0.3 in arclength pass p = 0.364 and then fail at p = 0.152."""
    def F(x, p):
        return np.array([x[0] - p])

    def Fx(x, p):
        return np.array([[1.0]])

    def Fp(x, p):
        return np.array([-1.0])

    def eig(x, p):
        if p < 0.3:
            raise Undefined("singular below 0.3")
        return np.array([p - 0.33])

    (branch,) = sweep_parameter(F, Fx, Fp, [(np.array([1.0]), 1.0)], 0.0, 1.0, eig, ds=0.3, ds_max=0.3)
    assert kinds(branch) == ["zero_eigenvalue"]
    assert branch.bifurcations[0].p == pytest.approx(0.33, abs=1e-8)
    (where, why), = branch.undefined
    assert 0.3 - 1e-5 < where < 0.3 and why == "singular below 0.3"
    assert min(pt.p for pt in branch.points) == pytest.approx(0.3, abs=1e-5)
    assert all(pt.stable == (pt.p < 0.33) for pt in branch.points)


# -- 3. centrifuge-like fold -----------------------------------------------------------------------------
def test_centrifuge_fold_real_numbers():
    F, Fx, Fp, eig = centrifuge_problem()
    br = continue_branch(F, Fx, Fp, np.array([-1.249420]), 7.0, 3.0, 7.0, eig, direction=-1.0)
    assert kinds(br) == ["fold"]  # the real eigenvalue crossing 0 at the fold is not a branch point
    fold = br.bifurcations[0]
    assert fold.p == pytest.approx(5.127846, abs=1e-6)
    assert fold.x[0] == pytest.approx(-0.749096, abs=1e-6)
    assert br.points[0].p == 7.0 and br.points[-1].p == 7.0
    assert br.points[-1].x[0] == pytest.approx(-0.423246, abs=1e-6)
    assert min(pt.p for pt in br.points) == pytest.approx(5.127846, abs=0.05)
    # one side of the fold is stable, the other unstable
    assert br.points[0].stable != br.points[-1].stable


def test_centrifuge_sweep_with_max_steps():
    F, Fx, Fp, eig = centrifuge_problem()
    br = continue_branch(F, Fx, Fp, np.array([-1.249420]), 7.0, 3.0, 7.0, eig, direction=-1.0, max_steps=3)
    assert len(br.points) == 4 and br.bifurcations == []
    [sw] = sweep_parameter(F, Fx, Fp, [(np.array([-1.249420]), 7.0)], 3.0, 7.0, eig, ds=0.02, ds_max=0.1)
    assert kinds(sw) == ["fold"]
    assert sw.bifurcations[0].p == pytest.approx(5.127846, abs=1e-6)


# -- 4. Hopf ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("shuffle", [False, True])
def test_hopf_normal_form(shuffle):
    F, Fx, Fp, eig = hopf_problem(shuffle)
    br = continue_branch(F, Fx, Fp, np.array([0.0, 0.0]), -1.0, -1.0, 1.0, eig)
    assert kinds(br) == ["hopf"]
    hopf = br.bifurcations[0]
    assert isinstance(hopf, Bifurcation)
    assert abs(hopf.p) < 1e-8
    assert np.allclose(hopf.x, 0.0)
    assert br.points[0].p == -1.0 and br.points[-1].p == 1.0
    assert all(isinstance(pt, BranchPoint) and pt.eigenvalues.dtype.kind == "c" for pt in br.points)
    assert [pt.stable for pt in br.points] == [pt.p < 0 for pt in br.points]


# -- closed branch ---------------------------------------------------------------------------------------
def test_closed_loop_stops_at_start():
    F = lambda x, p: np.array([x[0] ** 2 + p ** 2 - 1.0])      # noqa: E731
    Fx = lambda x, p: np.array([[2.0 * x[0]]])                 # noqa: E731
    Fp = lambda x, p: np.array([2.0 * p])                      # noqa: E731
    eig = lambda x, p: np.array([-2.0 * x[0]])                 # noqa: E731
    branches = sweep_parameter(F, Fx, Fp, [(np.array([1.0]), 0.0), (np.array([-0.6]), 0.8)], -2.0, 2.0, eig)
    assert len(branches) == 1
    br = branches[0]
    assert br.points[-1].p == br.points[0].p and np.array_equal(br.points[-1].x, br.points[0].x)
    assert sorted(round(b.p, 9) for b in br.bifurcations) == [-1.0, 1.0]
    assert kinds(br) == ["fold", "fold"]


# -- 5. errors -------------------------------------------------------------------------------------------
def test_start_not_converging_raises():
    F = lambda x, p: np.array([x[0] ** 2 + 1.0])               # noqa: E731  (no real root)
    Fx = lambda x, p: np.array([[2.0 * x[0]]])                 # noqa: E731
    Fp = lambda x, p: np.array([0.0])                          # noqa: E731
    eig = lambda x, p: np.array([-1.0])                        # noqa: E731
    with pytest.raises(ValueError, match="did not converge"):
        continue_branch(F, Fx, Fp, np.array([1.0]), 0.0, -1.0, 1.0, eig)
    with pytest.raises(ValueError, match="outside"):
        continue_branch(*fold_problem()[:3], np.array([1.0]), -1.0, 0.0, 1.0, fold_problem()[3])


def test_continuation_options_are_checked_by_name_and_value():
    """The options object (ContinuationOptions) refuses an unknown name and steps out of order, for both entry
    points, before any tracing."""
    F, Fx, Fp, eig = fold_problem()
    for bad in ({"ds_min": 0.0}, {"ds_min": 0.6, "ds_max": 0.5}, {"ds": -0.1}):
        with pytest.raises(ValueError, match="ds_min <= ds_max"):
            continue_branch(F, Fx, Fp, np.array([1.0]), -1.0, -2.0, 0.5, eig, **bad)
        with pytest.raises(ValueError, match="ds_min <= ds_max"):
            sweep_parameter(F, Fx, Fp, [(np.array([1.0]), -1.0)], -2.0, 0.5, eig, **bad)
    with pytest.raises(TypeError, match="step"):
        sweep_parameter(F, Fx, Fp, [(np.array([1.0]), -1.0)], -2.0, 0.5, eig, step=0.1)
    assert ContinuationOptions().ds == 0.05 and ContinuationOptions(ds=0.02).max_steps == 2000


def test_a_branch_cut_by_the_step_limit_says_so():
    """A branch that runs out of steps inside the range used to end silently; sweeps then traced its untraced
    part again from another start and reported one branch as several (equilibria --sweep with 3000 points gave 8
    branches of the double pendulum instead of 4)."""
    line = (lambda x, p: np.array([x[0] - p]), lambda x, p: np.eye(1), lambda x, p: np.array([-1.0]))
    eig = lambda x, p: np.array([-1.0 + 0j])  # noqa: E731
    short = continue_branch(*line, [0.0], 0.0, 0.0, 10.0, eig, ds=0.01, ds_max=0.01, max_steps=50)
    assert short.truncated and short.points[-1].p < 1.0
    full = continue_branch(*line, [0.0], 0.0, 0.0, 10.0, eig, ds=0.01, ds_max=0.05, max_steps=2000)
    assert not full.truncated and full.points[-1].p == 10.0
    merged = sweep_parameter(*line, [(np.array([5.0]), 5.0)], 0.0, 10.0, eig, ds=0.01, ds_max=0.01, max_steps=50)
    assert len(merged) == 1 and merged[0].truncated


def test_an_auxiliary_unknown_weighted_down_in_the_arclength_is_still_solved_to_full_accuracy():
    """An auxiliary unknown that grows by orders of magnitude along the branch (a bicycle's multipliers with the
    square of a growing yaw rate) took every step of the arclength: the branch ended at the step limit at a tenth
    of the range. Weighted down (a large x_scale), the branch crosses the range; with tol_scale it is still solved
    to the full tolerance (closed form: x2 = 1e4 x1^4, x1 = p)."""
    def F(x, p):
        return np.array([x[0] - p, x[1] - 1e4 * x[0] ** 4])

    def Fx(x, p):
        return np.array([[1.0, 0.0], [-4e4 * x[0] ** 3, 1.0]])

    Fp = lambda x, p: np.array([-1.0, 0.0])                      # noqa: E731
    eig = lambda x, p: np.array([-1.0 + 0j, -1.0 + 0j])          # noqa: E731
    opts = dict(ds=0.05, ds_max=0.1, max_steps=300)
    plain = continue_branch(F, Fx, Fp, [0.0, 0.0], 0.0, 0.0, 10.0, eig, **opts)
    assert plain.truncated and plain.points[-1].p < 2.0
    weighted = continue_branch(F, Fx, Fp, [0.0, 0.0], 0.0, 0.0, 10.0, eig, x_scale=[1.0, 1e9],
                               tol_scale=[1.0, 1.0], **opts)
    assert not weighted.truncated and weighted.points[-1].p == 10.0 and len(weighted.points) < 150
    for pt in weighted.points:
        assert abs(pt.x[0] - pt.p) <= 1e-12 * (1 + pt.p)
        assert abs(pt.x[1] - 1e4 * pt.p ** 4) <= 1e-9 * (1 + 1e4 * pt.p ** 4)


def test_equilibria_sweep_step_limit_follows_the_points(monkeypatch):
    """bifurcation.sweep asks for enough steps to cross the range at the requested resolution, and reports a
    truncated branch in the notes of its table."""
    import mechsys
    from mechsys.analysis.equilibrium import bifurcation
    from mechsys.report.equilibria import sweep_tables

    seen = {}
    real = bifurcation.sweep_parameter

    def spy(*args, **kw):
        seen.update(kw)
        return real(*args, **{**kw, "max_steps": 5})

    monkeypatch.setattr(bifurcation, "sweep_parameter", spy)
    from tests.helpers import SYSTEMS_DIR

    result = bifurcation.sweep(mechsys.load(SYSTEMS_DIR / "double_pendulum.yaml"), "m1", 1.0, 2.0, 300)
    assert seen["max_steps"] >= 20 * 300
    assert result.notes and "step limit" in result.notes[0]
    assert any("incomplete" in note for table in sweep_tables(result) for note in table.notes)


def test_family_sweep_of_a_given_cyclic_rate_follows_the_closed_form():
    """Issue 11 item 4: with no torque on the column (Mo = dM = 0) and its rate given (der(alpha) = 7), the
    steady motions form a family and the column's equation holds identically: the equilibrium equations are
    over-determined, which ended in `internal error: ValueError: continuation: Newton correction ... nan`.
    Continuation now follows an independent square subset and checks every equation at every point. Each branch
    point satisfies the effective-potential balance derived by hand for the centrifuge (arm pivot at a on the
    column, centre of mass at l, central inertias I2y, I2z):
        m g l sin(b) = w^2 (m (a + l sin b) l cos b + (I2y - I2z) sin b cos b)."""
    import math

    import mechsys
    from mechsys.analysis.equilibrium.bifurcation import sweep
    from tests.helpers import SYSTEMS_DIR

    model = mechsys.load(SYSTEMS_DIR / "centrifuge.yaml", {"Mo": 0, "dM": 0, "der(alpha)": 7})
    result = sweep(model, "m", 4.0, 12.0, 9)
    P = model.parameters
    a, l, g, I2y, I2z, w = P["a"], P["l"], P["g"], P["I2y"], P["I2z"], 7.0
    assert len(result.branches) >= 2 and not result.notes
    for branch in result.branches:
        assert branch.points[0].p == pytest.approx(4.0) and branch.points[-1].p == pytest.approx(12.0)
        for pt in branch.points:
            b, m = float(pt.x[0]), pt.p
            balance = m * g * l * math.sin(b) - w**2 * (m * (a + l * math.sin(b)) * l * math.cos(b)
                                                        + (I2y - I2z) * math.sin(b) * math.cos(b))
            assert abs(balance) < 1e-8, (m, b, balance)


def test_conservative_branches_carry_the_point_verdict():
    """Issue 11 item 4: branch stability came from the eigenvalue test alone, so every conservative branch was
    drawn unstable (dashed). The double pendulum hanging at rest is a strict minimum of the potential for every
    mass (Lagrange-Dirichlet: stable); the three configurations with a rod upright are maxima or saddles of it
    (unstable). Along a sweep of m1 each branch point carries that verdict."""
    import mechsys
    from mechsys.analysis.equilibrium.bifurcation import sweep
    from mechsys.report.equilibria import sweep_tables
    from tests.helpers import SYSTEMS_DIR

    result = sweep(mechsys.load(SYSTEMS_DIR / "double_pendulum.yaml"), "m1", 1.0, 2.0, 11)
    assert len(result.branches) == 4
    for branch in result.branches:
        hanging = all(abs(float(x)) < 1e-9 for x in branch.points[0].x[:2])
        for pt in branch.points:
            assert pt.verdict == ("stable" if hanging else "unstable") and pt.stable == hanging
    rows = [t for t in sweep_tables(result) if t.title.startswith("branches")][0]
    assert rows.columns[-2:] == ["stable", "verdict"]


# -- issue 11: continuation that agrees with the point analysis ------------------------------------------
def gyroscopic_problem(k: float = 1.0, G: float = 1.0):
    """x'' + p G J x' - k x = 0 (J a quarter turn, x in the plane): an inverted pendulum stabilized by spin p.
    Eigenvalues: (s^2 - k)^2 + (p G)^2 s^2 = 0, a quadruplet +-alpha +- i beta for p G < 2 sqrt(k), four
    imaginary ones above: they meet on the imaginary axis at p = 2 sqrt(k) / G (Krein collision)."""
    F = lambda x, p: np.array([x[0], x[1]])                    # noqa: E731
    Fx = lambda x, p: np.eye(2)                                # noqa: E731
    Fp = lambda x, p: np.zeros(2)                              # noqa: E731

    def eig(x, p):
        J = np.array([[0.0, -1.0], [1.0, 0.0]])
        return np.linalg.eigvals(np.block([[np.zeros((2, 2)), np.eye(2)], [k * np.eye(2), -p * G * J]]))

    return F, Fx, Fp, eig


@pytest.mark.parametrize("p0, direction, ds", [(1.0, 1.0, 0.05), (3.0, -1.0, 0.05), (1.0, 1.0, 0.1)])
def test_krein_collision_of_a_gyroscopic_branch_is_not_a_hopf_point(p0, direction, ds):
    """Gyroscopic stabilization: the eigenvalues collide on the imaginary axis and leave it as a quadruplet;
    none crosses it transversally. The count of unstable eigenvalues changes, which was reported as a Hopf point
    (traced downwards 0.12 away from p = 2). Now a `collision` exactly where they meet, also when a point falls
    on the collision itself (ds = 0.1 from p = 1 lands on p = 2)."""
    F, Fx, Fp, eig = gyroscopic_problem()
    br = continue_branch(F, Fx, Fp, [0.0, 0.0], p0, 1.0, 3.0, eig, ds=ds, ds_max=ds, direction=direction)
    assert kinds(br) == ["collision"]
    assert br.bifurcations[0].p == pytest.approx(2.0, abs=1e-9)


@pytest.mark.parametrize("p0, direction", [(-1.0, 1.0), (1.0, -1.0), (0.0, 1.0), (0.0, -1.0)])
def test_transversal_hopf_on_a_grid_point_is_found_once(p0, direction):
    """A Hopf point on which a continuation point falls (Re = 0 there) is decided by a probe beyond it: still a
    transversal crossing, reported once and not also as a collision."""
    F, Fx, Fp, eig = hopf_problem(shuffle=True)
    br = continue_branch(F, Fx, Fp, np.zeros(2), p0, -1.0, 1.0, eig, ds=0.1, ds_max=0.1, direction=direction)
    assert kinds(br) == ["hopf"] and abs(br.bifurcations[0].p) < 1e-12


FREE_CENTRIFUGE = {"Mo": 0, "dM": 0}


def centrifuge_family(beta, w, P):
    """The steady motions of the centrifuge's arm at a given column rate w, from a Lagrangian written here:
    G(beta, w) = dL/dbeta = 0 with the arm's centre of mass at (0, a + l sin b, -l cos b) in the column frame,
    angular velocity (b', w sin b, w cos b) in the arm frame,
        T = m (w^2 (a + l sin b)^2 + l^2 b'^2) / 2 + (I2x b'^2 + I2y w^2 sin^2 b + I2z w^2 cos^2 b) / 2,
        V = -m g l cos b,
    and the column's angular momentum h = dT/dw + I1 w, conserved when nothing acts on the column."""
    m, g, l, a, I1, I2y, I2z = (P[k] for k in ("m", "g", "l", "a", "I1", "I2y", "I2z"))
    s, c = np.sin(beta), np.cos(beta)
    G = w**2 * (m * l * c * (a + l * s) + (I2y - I2z) * s * c) - m * g * l * s
    h = (I1 + I2y * s**2 + I2z * c**2 + m * (a + l * s) ** 2) * w
    return G, h


@pytest.fixture(scope="module")
def free_centrifuge_rate_sweep():
    import mechsys
    from mechsys.analysis.equilibrium.bifurcation import sweep
    from tests.helpers import SYSTEMS_DIR

    model = mechsys.load(SYSTEMS_DIR / "centrifuge.yaml", FREE_CENTRIFUGE)
    return model.parameters, sweep(model, "der(alpha)", 3.0, 12.0, 10)


def test_rate_family_of_the_free_centrifuge_follows_its_closed_form(free_centrifuge_rate_sweep):
    """Issue 11: `--sweep der(alpha)=3:12:10` on the centrifuge without motor (a family of steady motions whose
    rate is given) said `unknown parameter`. The rate is now the continuation parameter. Every branch point solves
    the steady-motion equation G(beta, w) = 0, and at w = 3 and w = 12 the branch ends are exactly the roots of G
    on the circle (2 and 4 of them). The fold is where G and dG/dbeta vanish (the saddle-node, w = 5.127846)."""
    from scipy.optimize import brentq, fsolve

    P, result = free_centrifuge_rate_sweep
    assert result.parameter == "der(alpha)" and result.names == ["beta"] and not result.notes
    for branch in result.branches:
        for pt in branch.points:
            assert abs(centrifuge_family(pt.x[0], pt.p, P)[0]) < 1e-9 * (1 + pt.p**2)
    for w in (3.0, 12.0):
        grid = np.linspace(-np.pi, np.pi, 2001)
        g = centrifuge_family(grid, w, P)[0]
        roots = sorted(brentq(lambda b: centrifuge_family(b, w, P)[0], x, y, xtol=1e-14)
                       for x, y, gx, gy in zip(grid, grid[1:], g, g[1:]) if gx * gy < 0)
        ends = sorted(float(pt.x[0]) for br in result.branches for pt in (br.points[0], br.points[-1]) if pt.p == w)
        assert len(roots) == (2 if w == 3.0 else 4)
        assert ends == pytest.approx(roots, abs=1e-6)

    def fold(v):
        b, w = v
        dG = (centrifuge_family(b + 1e-6, w, P)[0] - centrifuge_family(b - 1e-6, w, P)[0]) / 2e-6
        return [centrifuge_family(b, w, P)[0], dG]

    b_fold, w_fold = fsolve(fold, [-0.75, 5.1], xtol=1e-13)
    [event] = [e for e in result.bifurcations if e["kind"] == "fold"]
    assert event["parameter"] == "der(alpha)"
    assert event["value"] == pytest.approx(w_fold, abs=1e-6) and w_fold == pytest.approx(5.127846, abs=1e-6)
    assert event["coordinates"]["beta"] == pytest.approx(b_fold, abs=1e-6)


def test_free_centrifuge_stability_changes_at_the_extremum_of_the_column_momentum(free_centrifuge_rate_sweep):
    """With no torque on the column its momentum h is conserved, and the steady motions' stability (Routh) changes
    where h is extremal along the family, not at the fold in w. A real eigenvalue passes through 0 there while the
    family in w neither folds nor branches: a `zero_eigenvalue` event (it was a `branch_point`), at the minimum of
    h(beta) = h(beta, w(beta)) on the upper half of the fold, with the verdict changing between its neighbours."""
    from scipy.optimize import minimize_scalar

    P, result = free_centrifuge_rate_sweep

    def h_on_family(b):
        m, g, l, a, I2y, I2z = (P[k] for k in ("m", "g", "l", "a", "I2y", "I2z"))
        s, c = np.sin(b), np.cos(b)
        w = np.sqrt(m * g * l * s / (m * l * c * (a + l * s) + (I2y - I2z) * s * c))
        return centrifuge_family(b, w, P)[1], w

    b_min = minimize_scalar(lambda b: h_on_family(b)[0], bounds=(-0.74, -0.45), method="bounded",
                            options={"xatol": 1e-12}).x
    [event] = [e for e in result.bifurcations if e["kind"] == "zero_eigenvalue"]
    assert event["value"] == pytest.approx(h_on_family(b_min)[1], abs=1e-6)  # w = 5.279974
    assert event["coordinates"]["beta"] == pytest.approx(b_min, abs=1e-5)
    assert {e["kind"] for e in result.bifurcations} == {"fold", "zero_eigenvalue"}
    branch = next(br for br in result.branches if any(b.kind == "zero_eigenvalue" for b in br.bifurcations))
    k = next(b.index for b in branch.bifurcations if b.kind == "zero_eigenvalue")
    before, after = branch.points[k], branch.points[k + 1]
    assert {before.verdict, after.verdict} == {"stable", "unstable"}
    lower = before if before.x[0] < after.x[0] else after
    assert lower.verdict == "stable"  # beta below the momentum minimum: the stable side


def test_rate_sweep_refused_where_the_rate_is_not_a_family_parameter():
    """der(alpha) with the motor: the torque balance fixes the steady rate (an unknown, not a parameter); der(beta):
    beta is not cyclic; der(gamma): no such coordinate. Each is one line and exit 2."""
    import mechsys
    from mechsys.analysis.equilibrium.bifurcation import sweep
    from mechsys.errors import InputError
    from tests.helpers import SYSTEMS_DIR

    motor = mechsys.load(SYSTEMS_DIR / "centrifuge.yaml")
    with pytest.raises(InputError, match=r"der\(alpha\): the steady rate of the cyclic coordinate alpha is an "
                                         r"unknown .*torque balance"):
        sweep(motor, "der(alpha)", 3.0, 12.0, 10)
    free = mechsys.load(SYSTEMS_DIR / "centrifuge.yaml", FREE_CENTRIFUGE)
    with pytest.raises(InputError, match=r"der\(beta\): beta is not a cyclic coordinate"):
        sweep(free, "der(beta)", 3.0, 12.0, 10)
    with pytest.raises(InputError, match=r"der\(gamma\): unknown coordinate"):
        sweep(free, "der(gamma)", 3.0, 12.0, 10)
    from typer.testing import CliRunner

    from mechsys.cli import app

    res = CliRunner().invoke(app, ["equilibria", str(SYSTEMS_DIR / "centrifuge.yaml"), "--sweep",
                                   "der(alpha)=3:12:10"])
    assert res.exit_code == 2 and "internal error" not in res.output
    assert len(res.stderr.strip().splitlines()) == 1 and "torque balance" in res.stderr


def test_swept_rate_derivatives_are_exact(tmp_path):
    """dF/dp of the continuation: for der(alpha) the column of the family rate; for a parameter W with the file's
    `rate: 2*W` the same through the rate's expression (the rate follows its parameter along a sweep of W), and
    the parameters' own column. Checked against central differences on the free centrifuge."""
    import mechsys
    from mechsys.analysis.equilibrium.bifurcation import swept_parameter
    from mechsys.analysis.equilibrium.equilibria import EquilibriumProblem
    from tests.helpers import SYSTEMS_DIR

    text = (SYSTEMS_DIR / "centrifuge.yaml").read_text()
    text = text.replace("  g: 9.81\n", "  g: 9.81\n  W: 3.5\n").replace("alpha: {initial: 0, rate: 0}",
                                                                        "alpha: {initial: 0, rate: 2*W}")
    path = tmp_path / "free_centrifuge.yaml"
    path.write_text(text, encoding="utf-8")
    problem = EquilibriumProblem(mechsys.load(path, FREE_CENTRIFUGE))
    assert problem.fixed_rates == {"alpha": 7.0}
    x = np.array([-0.9])
    for name, p, slope, rate in (("der(alpha)", 6.0, 1.0, 6.0), ("W", 3.0, 2.0, 6.0), ("m", 6.0, 0.0, 7.0)):
        par = swept_parameter(problem, name)
        exact = par.Fp(x, p)
        assert problem.fixed_rates == {"alpha": rate}
        fd = (problem.F(x, par.at(p + 1e-5)) - problem.F(x, par.at(p - 1e-5))) / 2e-5
        assert np.max(np.abs(exact)) > 1e-3 and exact == pytest.approx(fd, rel=1e-7, abs=1e-9)
        assert np.all(par.drates(p, par.pvec(p)) == slope)


def test_sleeping_top_loses_gyroscopic_stability_by_a_collision_not_a_hopf_point():
    """Issue 11: a heavy symmetric top spinning upright (xyz chart, regular there) is stable iff C^2 w^2 > 4 A m g l
    (A about the pivot). Its branch is conservative: the eigenvalues collide on the imaginary axis at w_c, they do
    not cross it, and a Hopf point used to be reported 0.3 rad/s away. Along `--sweep w=20:40:21`: no Hopf point,
    a collision at w_c = 2 sqrt(A m g l) / C, and the verdict of the upright branch turns from unstable to stable
    between the grid points that bracket w_c."""
    import math

    import mechsys
    from mechsys.analysis.equilibrium.bifurcation import sweep
    from tests.helpers import DATA_DIR

    model = mechsys.load(DATA_DIR / "sleeping_top_xyz.yaml")
    P = model.parameters
    A = P["At"] + P["m"] * P["l"] ** 2
    w_c = 2.0 * math.sqrt(A * P["m"] * P["g"] * P["l"]) / P["C"]
    result = sweep(model, "w", 20.0, 40.0, 21)
    assert not any(e["kind"] == "hopf" for e in result.bifurcations)
    upright = [e for e in result.bifurcations if e["coordinates"] == {"a": 0.0, "b": 0.0}]
    assert [e["kind"] for e in upright] == ["collision"] and upright[0]["value"] == pytest.approx(w_c, abs=1e-6)
    [branch] = [br for br in result.branches if np.allclose(br.points[0].x[:2], 0.0)]
    below = [pt for pt in branch.points if pt.p < w_c]
    above = [pt for pt in branch.points if pt.p > w_c]
    assert below and above and all(np.allclose(pt.x[:2], 0.0, atol=1e-12) for pt in branch.points)
    assert {pt.verdict for pt in below} == {"unstable"} and {pt.verdict for pt in above} == {"stable"}
    assert max(pt.p for pt in below) > w_c - 1.0 and min(pt.p for pt in above) < w_c + 1.0


SELF_EXCITED_PENDULUM = """
name: self_excited_pendulum
description: pendulum with a van der Pol torque, negative damping for mu > 0
parameters: {m: 1.0, l: 1.0, g: 9.81, mu: -0.5}
coordinates:
  th: {initial: 0.1, rate: 0}
links:
  rod:
    joint: {type: revolute, parent: ground, axis: z, coordinate: th}
    mass: m
    center_of_mass: [0, -l, 0]
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
  - {type: torque, on: rod, axis: z, value: (mu - th**2)*der(th)}
"""


def test_negative_damping_gives_a_genuine_hopf_point(tmp_path):
    """A transversal crossing is still a Hopf point: hanging, the pendulum's pair is (mu +- sqrt(mu^2 - 4 m^2 g l^3))
    / (2 m l^2), Re = mu / 2 crosses 0 at mu = 0 with speed 1/2 and frequency sqrt(g/l). Upright it is a saddle
    (real eigenvalues of both signs): nothing there."""
    import mechsys
    from mechsys.analysis.equilibrium.bifurcation import sweep

    path = tmp_path / "self_excited_pendulum.yaml"
    path.write_text(SELF_EXCITED_PENDULUM, encoding="utf-8")
    result = sweep(mechsys.load(path), "mu", -1.0, 1.0, 11)
    assert [e["kind"] for e in result.bifurcations] == ["hopf"]
    assert result.bifurcations[0]["value"] == pytest.approx(0.0, abs=1e-9)
    assert result.bifurcations[0]["coordinates"]["th"] == pytest.approx(0.0, abs=1e-9)


def test_failed_newton_correction_is_a_clear_error_not_an_internal_one(tmp_path, monkeypatch):
    """A start whose Newton correction fails ends the command with exit 1 and the continuation's message (forced
    here: one Newton iteration allowed, from a start off the equilibrium)."""
    import mechsys.analysis.equilibrium.bifurcation as bifurcation
    import mechsys.analysis.equilibrium.continuation as continuation
    from typer.testing import CliRunner

    from mechsys.cli import app

    path = tmp_path / "self_excited_pendulum.yaml"
    path.write_text(SELF_EXCITED_PENDULUM, encoding="utf-8")
    real = bifurcation.solve_equilibria
    monkeypatch.setattr(bifurcation, "solve_equilibria", lambda *a, **k: [z + 0.3 for z in real(*a, **k)])
    monkeypatch.setattr(continuation, "_MAX_START_ITER", 1)
    res = CliRunner().invoke(app, ["equilibria", str(path), "--sweep", "mu=-1:1:11"])
    assert res.exit_code == 1, res.output
    assert "internal error" not in res.stderr
    assert "--sweep mu: continuation: Newton correction of the start point" in res.stderr
    assert "did not converge" in res.stderr


def test_equations_undefined_beyond_a_point_end_the_branch_with_a_note(tmp_path):
    """sqrt(mu) in a torque: the equations are not defined for mu < 0 and not smooth at 0. The starts there are
    skipped with a note (it was `internal error: ValueError: math domain error`), and the branches, whose
    corrector fails at mu -> 0, end there with a note saying so."""
    import mechsys
    from mechsys.analysis.equilibrium.bifurcation import sweep

    path = tmp_path / "sqrt_torque.yaml"
    text = SELF_EXCITED_PENDULUM.replace("(mu - th**2)*der(th)", "sqrt(mu) - der(th)").replace("mu: -0.5", "mu: 0.5")
    path.write_text(text, encoding="utf-8")
    result = sweep(mechsys.load(path), "mu", -1.0, 1.0, 11)
    assert len(result.branches) == 2
    assert "cannot be evaluated at mu = -1 (a force is not defined there), mu = -0.5" in result.notes[0]
    ends = [n for n in result.notes if "ends inside the range" in n]
    assert len(ends) == 2 and all("did not converge even with the smallest step" in n for n in ends)
    for branch in result.branches:
        assert min(pt.p for pt in branch.points) < 1e-6 and max(pt.p for pt in branch.points) == 1.0


@pytest.mark.parametrize("command", [
    "$ mechsys equilibria systems/centrifuge.yaml --set Mo=0 --set dM=0 --sweep 'der(alpha)=3:12:10' -f json",
    "$ mechsys equilibria tests/data/sleeping_top_xyz.yaml --sweep w=20:40:21 -f json",
])
def test_the_continuation_examples_of_the_docs_are_what_the_tool_prints(command):
    """docs/equilibria.md §7 shows the events of a rate sweep (the free centrifuge) and of the sleeping top."""
    import json
    import shlex

    from typer.testing import CliRunner

    from mechsys.cli import app
    from tests.helpers import ROOT

    doc = (ROOT / "docs" / "equilibria.md").read_text()
    block = doc.split(command + "   (bifurcations only)\n", 1)[1].split("```", 1)[0]
    shown = json.loads(block)
    args = shlex.split(command[2:])[2:]
    args[0] = str(ROOT / args[0])
    res = CliRunner().invoke(app, ["equilibria", *args])
    assert res.exit_code == 0, res.output
    printed = json.loads(res.stdout)["bifurcations"]
    assert len(printed) == len(shown)
    for got, want in zip(printed, shown):
        assert {k: got[k] for k in ("kind", "parameter")} == {k: want[k] for k in ("kind", "parameter")}
        assert got["value"] == pytest.approx(want["value"], abs=1e-9)
        assert got["coordinates"] == pytest.approx(want["coordinates"], abs=1e-9)


def test_parameters_defined_from_a_swept_one_follow_it_and_an_override_cuts_the_link():
    """parameter_values remembers which parameters follow a changed one (a continuation sets the same parameter
    thousands of times); the memo belongs to the definitions: after --set dM=2 (with_overrides), dM no longer
    follows Mo, even when the original model was asked first."""
    import mechsys
    from mechsys.numeric.parameters import parameter_values
    from tests.helpers import SYSTEMS_DIR

    model = mechsys.load(SYSTEMS_DIR / "centrifuge.yaml")
    names = [str(s) for s in model.parameter_symbols]
    moved = dict(zip(names, parameter_values(model, {"Mo": 70.0})))
    assert moved["Mo"] == 70.0 and moved["dM"] == pytest.approx(10.0)
    fixed = model.with_overrides({"dM": 2.0})
    again = dict(zip(names, parameter_values(fixed, {"Mo": 70.0})))
    assert again["Mo"] == 70.0 and again["dM"] == 2.0
    assert dict(zip(names, parameter_values(model, {"Mo": 14.0})))["dM"] == pytest.approx(2.0)


def test_the_sleeping_tops_collision_is_found_in_zxz_angles_too(tmp_path):
    """The same top written in zxz angles: upright is their gimbal lock, where continuation's eigenvalues are those
    of the singular chart. The verdicts (classified in a regular chart) turned from unstable to stable with no event
    reported (helper audit). The change is now located on the regular chart's verdicts: a collision at
    w_c = 2 sqrt(A m g l) / C, as in xyz angles."""
    import math

    import mechsys
    from mechsys.analysis.equilibrium.bifurcation import sweep
    from tests.helpers import DATA_DIR

    text = (DATA_DIR / "sleeping_top_xyz.yaml").read_text().replace("sequence: xyz", "sequence: zxz")
    path = tmp_path / "sleeping_top_zxz.yaml"
    path.write_text(text)
    model = mechsys.load(path)
    P = model.parameters
    w_c = 2.0 * math.sqrt((P["At"] + P["m"] * P["l"] ** 2) * P["m"] * P["g"] * P["l"]) / P["C"]
    result = sweep(model, "w", 20.0, 40.0, 11)
    upright = [e for e in result.bifurcations if abs(e["coordinates"]["b"]) < 1e-12]
    assert [e["kind"] for e in upright] == ["collision"] and upright[0]["value"] == pytest.approx(w_c, abs=1e-6)
