"""Pseudo-arclength continuation: folds, branch points and Hopf points of toy problems with known answers."""
from __future__ import annotations

import numpy as np
import pytest

from mechsys.analysis.continuation import Bifurcation, Branch, BranchPoint, continue_branch, sweep_parameter


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


def test_equilibria_sweep_step_limit_follows_the_points(monkeypatch):
    """bifurcation.sweep asks for enough steps to cross the range at the requested resolution, and reports a
    truncated branch in the notes of its table."""
    import mechsys
    from mechsys.analysis import bifurcation
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
    from mechsys.analysis.bifurcation import sweep
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
    from mechsys.analysis.bifurcation import sweep
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
