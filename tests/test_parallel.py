"""Forked workers (numeric/parallel.py) give the serial loop's results, bit for bit: a sweep's multistart per sample
value and its continuation branches; plus the memo of the search that a sweep through the file's values reuses."""
from __future__ import annotations

import os

import numpy as np
import pytest

import mechsys
from mechsys.analysis.equilibrium import continuation as co
from mechsys.analysis.equilibrium import equilibria as eq
from mechsys.analysis.equilibrium.bifurcation import sweep
from mechsys.errors import InputError
from mechsys.numeric import parallel
from mechsys.numeric.parameters import parameter_values

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _branches_equal(a: list[co.Branch], b: list[co.Branch]) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert [p.p for p in x.points] == [p.p for p in y.points]
        assert all(np.array_equal(p.x, q.x) and np.array_equal(p.eigenvalues, q.eigenvalues)
                   and p.stable == q.stable and p.verdict == q.verdict for p, q in zip(x.points, y.points))
        assert [(c.kind, c.p, c.index) for c in x.bifurcations] == [(c.kind, c.p, c.index) for c in y.bifurcations]
        assert (x.truncated, x.stalled, x.undefined) == (y.truncated, y.stalled, y.undefined)


@pytest.fixture
def forked(monkeypatch):
    """Run with 2 forked workers (even on one core) and count the pools that really forked."""
    pools = []
    original = parallel.Workers.__init__

    def spy(self, *args, **kwargs):
        original(self, *args, **kwargs)
        pools.append(self.processes)

    monkeypatch.setattr(parallel.Workers, "__init__", spy)

    def use(workers: int) -> list[int]:
        monkeypatch.setenv(parallel.ENV, str(workers))
        pools.clear()
        return pools

    return use


def pitchfork_with_an_undefined_start():
    """p x - x^3 = 0, whose eigenvalue is undefined (Undefined) where x > 1.2: one start there is skipped."""
    F = lambda x, p: np.array([p * x[0] - x[0] ** 3])  # noqa: E731
    Fx = lambda x, p: np.array([[p - 3.0 * x[0] ** 2]])  # noqa: E731
    Fp = lambda x, p: np.array([x[0]])  # noqa: E731

    def eig(x, p):
        if x[0] > 1.2:
            raise co.Undefined("no eigenvalue beyond x = 1.2")
        return np.array([p - 3.0 * x[0] ** 2])

    return F, Fx, Fp, eig


def test_forked_continuation_keeps_the_branches_and_skips_of_the_serial_loop(forked):
    F, Fx, Fp, eig = pitchfork_with_an_undefined_start()
    # starts on the same branch (skipped), a start where eig is undefined, starts of two branches
    starts = [(np.array([0.0]), 0.5), (np.array([0.7]), 0.49), (np.array([-0.3]), 0.09), (np.array([0.0]), -0.5),
              (np.array([1.3]), 1.69), (np.array([-0.9]), 0.81)]
    runs = {}
    for workers in (1, 2):
        pools = forked(workers)
        skipped: list = []
        runs[workers] = (co.sweep_parameter(F, Fx, Fp, starts, -1.0, 2.0, eig, skipped=skipped, x_scale=0.5,
                                            ds=0.02), skipped)
        assert pools == [workers]
    _branches_equal(runs[1][0], runs[2][0])
    assert runs[1][1] == runs[2][1] == [(1.69, "no eigenvalue beyond x = 1.2")]
    assert len(runs[1][0]) == 2  # the trivial branch and the parabola (its upper end stops where eig is undefined)


def test_a_closed_branch_is_traced_once_whether_forked_or_not(forked):
    """A closed branch (the Hopf toy's circle in (x, p) never closes; a circle F = x^2 + p^2 - 1 does): the
    backward half a worker traced ahead is dropped."""
    F = lambda x, p: np.array([x[0] ** 2 + p ** 2 - 1.0])  # noqa: E731
    Fx = lambda x, p: np.array([[2.0 * x[0]]])  # noqa: E731
    Fp = lambda x, p: np.array([2.0 * p])  # noqa: E731
    eig = lambda x, p: np.array([-2.0 * x[0]])  # noqa: E731
    starts = [(np.array([1.0]), 0.0), (np.array([-1.0]), 0.0)]
    out = {}
    for workers in (1, 2):
        forked(workers)
        out[workers] = co.sweep_parameter(F, Fx, Fp, starts, -2.0, 2.0, eig, ds=0.05, ds_max=0.1)
    _branches_equal(out[1], out[2])
    assert len(out[1]) == 1 and out[1][0].points[0].p == out[1][0].points[-1].p  # one closed branch


def test_forked_starts_at_a_later_sample_value_wait_for_the_branches_traced_before(forked, monkeypatch):
    """Starts at a later sample value often lie on branches still being traced: they are not traced ahead (their
    tracing would be thrown away). Here every start at p = 0.81 lies on a branch of the starts at p = 0.5, so
    forked as serial no half is traced from one of them."""
    import multiprocessing

    traced = multiprocessing.Value("i", 0)  # halves traced from a start at p = 0.81, in any process
    run = co._Continuation.run

    def counted(self, z0, direction):
        if z0[-1] == 0.81:
            with traced.get_lock():
                traced.value += 1
        return run(self, z0, direction)

    monkeypatch.setattr(co._Continuation, "run", counted)  # before the workers fork: they inherit it
    F, Fx, Fp, eig = pitchfork_with_an_undefined_start()
    root = float(np.sqrt(0.5))
    starts = [(np.array([0.0]), 0.5), (np.array([root]), 0.5), (np.array([-root]), 0.5),
              (np.array([0.0]), 0.81), (np.array([0.9]), 0.81), (np.array([-0.9]), 0.81)]
    runs = {}
    for workers in (1, 2):
        forked(workers)
        traced.value = 0
        runs[workers] = co.sweep_parameter(F, Fx, Fp, starts, 0.1, 1.0, eig, ds=0.05, ds_max=0.1)
        assert traced.value == 0
    _branches_equal(runs[1], runs[2])
    assert len(runs[1]) == 3


def test_a_forked_sweep_of_a_rolling_disk_equals_the_serial_one(forked):
    """The whole sweep (multistart at 5 sample rates, continuation, verdicts from the linearizations the workers
    computed) of a nonholonomic model, forked and serial."""
    model = mechsys.load(os.path.join(ROOT, "systems/rolling_disk.yaml"), {"lean": 0, "der(yaw)": 0})
    results = {}
    for workers in (1, 2):
        pools = forked(workers)
        results[workers] = sweep(model, "der(spin)", 2.0, 5.0, 31, {"lean": (-0.5, 0.5)})
        # the multistart, the continuation, then the review of the branches (one branch here: no fork)
        assert pools == [workers, workers, 1]
    a, b = results[1], results[2]
    _branches_equal(a.branches, b.branches)
    assert a.bifurcations == b.bifurcations and a.notes == b.notes
    assert [e["kind"] for e in a.bifurcations] == ["zero_eigenvalue"]  # upright rolling's critical spin rate


def test_a_forked_sweep_of_the_indicator_equals_the_serial_one(forked):
    """A holonomic model with four branches and two pitchforks (docs/equilibria.md, 8.9)."""
    model = mechsys.load(os.path.join(ROOT, "systems/indicator.yaml"), {"Iz": 0.8, "Omega": 150})
    results = {}
    for workers in (1, 2):
        forked(workers)
        results[workers] = sweep(model, "omega1", -30.0, 30.0, 61)
    a, b = results[1], results[2]
    _branches_equal(a.branches, b.branches)
    # beta = 0, pi, the nontrivial loop through beta = +-pi (traced twice: once kept), and the two halves +-beta of
    # the pair born at omega1 = 10 (the -beta half was dropped as a 'twin' compared at beta = pi alone)
    assert a.bifurcations == b.bifurcations and a.notes == b.notes and len(a.branches) == 5


@pytest.mark.parametrize("workers", [1, 2])
def test_the_review_of_the_branches_raises_in_the_serial_order(forked, monkeypatch, workers):
    """Every branch's residual check comes before any verdict: a residual failing on branch 2 is the error even
    when branch 1's verdicts raise (forked or not); without it, the verdicts' own error."""
    from mechsys.analysis.equilibrium import bifurcation
    from mechsys.errors import AnalysisError

    class Residual:  # F = x: a point with x != 0 does not satisfy the equations
        def F(self, x, P):
            return np.array([x[0]])

        def J(self, x, P):
            return np.array([[1.0]])

    def branch(p, x):
        return co.Branch(points=[co.BranchPoint(p=p, x=np.array([x]), eigenvalues=np.zeros(0), stable=False)])

    def verdicts(problem, b, at):
        raise RuntimeError("no verdict")

    forked(workers)
    monkeypatch.setattr(bifurcation, "_verdicts", verdicts)
    with pytest.raises(AnalysisError, match="on branch 2 at v = 1 the equilibrium equations do not all hold"):
        bifurcation._review(Residual(), [branch(0.0, 0.0), branch(1.0, 0.5)], lambda p: np.zeros(0), "v")
    with pytest.raises(RuntimeError, match="no verdict"):
        bifurcation._review(Residual(), [branch(0.0, 0.0), branch(1.0, 0.0)], lambda p: np.zeros(0), "v")


def test_workers_fork_only_once_and_say_how_many(monkeypatch):
    monkeypatch.setenv(parallel.ENV, "2")
    assert parallel.available() == 2
    # inside a worker, no further processes (a batch command's workers, or this module's)
    assert parallel.fork_map(lambda k: (k, parallel.available()), 3) == [(0, 1), (1, 1), (2, 1)]
    monkeypatch.setenv(parallel.ENV, "one")
    with pytest.raises(InputError, match="MECHSYS_WORKERS"):
        parallel.available()
    monkeypatch.setenv(parallel.ENV, "1")
    assert parallel.fork_map(lambda k: os.getpid(), 2) == [os.getpid()] * 2  # serial: here


def test_an_exception_in_a_worker_is_raised_here(monkeypatch):
    monkeypatch.setenv(parallel.ENV, "2")

    def task(k):
        if k == 1:
            raise ArithmeticError("math domain error")
        return k

    with pytest.raises(ArithmeticError, match="math domain error"):
        parallel.fork_map(task, 3)


def test_state_shared_back_from_the_workers(monkeypatch):
    """share = (take, give): what each task left in its worker reaches this process."""
    monkeypatch.setenv(parallel.ENV, "2")
    memo: dict[int, int] = {}

    def task(k):
        memo[k] = k * k
        return k

    def take():
        out = dict(memo)
        memo.clear()
        return out

    assert parallel.fork_map(task, 4, (take, memo.update)) == [0, 1, 2, 3]
    assert memo == {0: 0, 1: 1, 2: 4, 3: 9}


# -- the search memo ----------------------------------------------------------------------------------------
def test_the_search_is_remembered_per_problem_and_everything_it_reads(monkeypatch):
    monkeypatch.setattr(eq, "_disk_key", lambda *a: None)  # this process's memo alone (the disk: the next test)
    model = mechsys.load(os.path.join(ROOT, "systems/rolling_disk.yaml"))
    problem = eq.make_problem(model)
    p = parameter_values(model)
    calls = []
    original = eq._search
    monkeypatch.setattr(eq, "_search", lambda *a: calls.append(1) or original(*a))
    first = eq.solve_equilibria(problem, p)
    again = eq.solve_equilibria(problem, p)
    assert len(calls) == 1 and all(np.array_equal(x, y) for x, y in zip(first, again)) and len(first) == len(again)
    fresh = eq.solve_equilibria(eq.make_problem(model), p)  # cached equals uncached
    assert len(calls) == 2 and all(np.array_equal(x, y) for x, y in zip(first, fresh)) and len(first) == len(fresh)
    # each of these is a new search: other parameters, another given rate, another seed, number of starts or box
    rate = next(iter(problem.fixed_rates))
    eq.solve_equilibria(problem, p * 1.01)
    problem.fixed_rates[rate] += 1.0
    eq.solve_equilibria(problem, p)
    problem.fixed_rates[rate] -= 1.0
    eq.solve_equilibria(problem, p, seed=1)
    eq.solve_equilibria(problem, p, starts=10)
    eq.solve_equilibria(problem, p, {"lean": (-0.5, 0.5)})
    assert len(calls) == 7
    eq.solve_equilibria(problem, p)
    assert len(calls) == 7


@pytest.mark.parametrize("path", ["systems/rolling_disk.yaml", "systems/bicycle.yaml"])
def test_the_jacobian_of_the_steady_motion_equations_is_their_derivative(path):
    """dF/dz (gathered from the compiled M, A and dE/d(q, u) in one indexing) against central differences of F,
    at a random point: every unknown (shape coordinates, rates, accelerations, multipliers) and every row."""
    model = mechsys.load(os.path.join(ROOT, path))
    problem = eq.make_problem(model)
    p = parameter_values(model)
    z = np.random.default_rng(3).uniform(-0.5, 0.5, len(problem.unknowns))
    J = problem.J(z, p)
    h = 1e-6
    numeric = np.column_stack([(problem.F(z + h * e, p) - problem.F(z - h * e, p)) / (2 * h)
                               for e in np.eye(len(z))])
    assert J.shape == numeric.shape
    assert np.max(np.abs(J - numeric)) <= 1e-6 * max(1.0, np.max(np.abs(J)))


def test_a_search_stored_on_disk_equals_a_fresh_one_and_is_verified(monkeypatch, tmp_path):
    """The next command on the model (modes after equilibria) reads the search back: the same roots, bit for bit,
    no Newton run; another initial value (where the starts come from) or formulation is another search; a stored
    entry whose 'root' is not one is ignored and the search runs again."""
    from mechsys.numeric import cache

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    path = os.path.join(ROOT, "systems/rolling_disk.yaml")
    calls, keys = [], []
    search, disk_key = eq._search, eq._disk_key
    monkeypatch.setattr(eq, "_search", lambda *a: calls.append(1) or search(*a))
    monkeypatch.setattr(eq, "_disk_key", lambda *a: keys.append(disk_key(*a)) or keys[-1])

    def solve(overrides=None):
        model = mechsys.load(path, overrides)  # a new model and problem each time: a new command
        return eq.solve_equilibria(eq.make_problem(model), parameter_values(model))

    first = solve()
    again = solve()
    assert len(calls) == 1 and keys[0] == keys[1] and len(first) == len(again) >= 1
    assert all(np.array_equal(x, y) for x, y in zip(first, again))
    solve({"lean": 0.2})
    assert len(calls) == 2 and keys[2] != keys[0]
    entry = cache.load(keys[0])
    entry["roots"][0] = [r + 0.1 for r in entry["roots"][0]]
    cache.store(keys[0], entry)
    tampered = solve()
    assert len(calls) == 3 and all(np.array_equal(x, y) for x, y in zip(first, tampered))
    # the same steady motions posed from Lagrange's equations: other residual rows, another search
    from mechsys.analysis.equilibrium.nonholonomic import NonholonomicProblem

    model = mechsys.load(path)
    eq.solve_equilibria(NonholonomicProblem(model, method="lagrange"), parameter_values(model))
    assert len(calls) == 4 and keys[-1] != keys[0]
