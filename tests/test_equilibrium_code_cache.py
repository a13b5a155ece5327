"""The generated code of the holonomic equilibrium analysis is cached like the equations (issue 13): the rest
equations, their Jacobians (unknowns, parameters, given rates) and the linearization's blocks. Code read back
equals code generated afresh, evaluates bit for bit the same, needs no differentiation, and is keyed by the
model's structure and the problem's split; an entry that does not fit the model is ignored."""
from __future__ import annotations

import numpy as np
import pytest

import mechsys
from helpers import SYSTEMS_DIR
from mechsys.analysis.equilibrium import equilibria as eqm
from mechsys.analysis.equilibrium.linearize import LinearPieces
from mechsys.numeric import cache
from mechsys.numeric.parameters import parameter_values

MODELS = ["gyrostabilizer", "four_bar", "centrifuge", "double_pendulum"]


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("MECHSYS_CACHE", str(folder))
    return folder


def _evaluations(model, rng, forbid_diff: bool = False):
    """F, J, dF/dp, dF/d(given rates) and the linearization's blocks at random points (forbid_diff: fail if the
    model differentiates anything)."""
    if forbid_diff:
        model.__dict__["diff"] = lambda *a: pytest.fail("differentiated with the code cached")
    problem = eqm.make_problem(model)
    pieces = LinearPieces(model)
    p = parameter_values(model)
    out = []
    for _ in range(3):
        z = rng.uniform(-1.5, 1.5, len(problem.unknowns))
        out += [problem.F(z, p), problem.J(z, p), problem.Fp(z, p), problem.Fr(z, p)]
        n = len(model.q)
        blocks = pieces.evaluate(rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, pieces.m), p)
        out += [blocks[k] for k in LinearPieces.KEYS]
    return out


@pytest.mark.parametrize("name", MODELS)
def test_cached_code_equals_fresh_code_without_differentiating(name, cache_dir, monkeypatch):
    path = SYSTEMS_DIR / f"{name}.yaml"
    fresh = _evaluations(mechsys.load(path), np.random.default_rng(3))
    assert any(cache_dir.glob("*.json"))
    cached = _evaluations(mechsys.load(path), np.random.default_rng(3), forbid_diff=True)
    assert len(fresh) == len(cached)
    for a, b in zip(fresh, cached):
        np.testing.assert_array_equal(a, b)
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    for a, b in zip(fresh, _evaluations(mechsys.load(path), np.random.default_rng(3))):
        np.testing.assert_array_equal(a, b)


def test_the_key_covers_the_split_of_the_problem(cache_dir):
    model = mechsys.load(SYSTEMS_DIR / "gyrostabilizer.yaml")
    problem = eqm.make_problem(model)
    key = eqm._source_key(problem, "F")
    assert key != eqm._source_key(problem, "J")
    for change in (lambda pr: pr.rate_unknowns.append("x"), lambda pr: pr.fixed_rates.update({"x": 1.0}),
                   lambda pr: pr.free.pop()):
        other = eqm.make_problem(model)
        change(other)
        assert eqm._source_key(other, "F") != key


def test_an_entry_that_does_not_fit_is_ignored(cache_dir):
    path = SYSTEMS_DIR / "four_bar.yaml"
    model = mechsys.load(path)
    key = cache.model_key(model, "linear-pieces")
    reference = LinearPieces(model)
    entry = cache.load(key)
    n = len(model.q)
    entry["layout"]["M"] = [0, [n - 1, n]]  # a block of another shape
    cache.store(key, entry)
    again = LinearPieces(mechsys.load(path))
    p = parameter_values(model)
    q, u, lam = np.full(n, 0.3), np.full(n, -0.2), np.full(again.m, 0.5)
    for k in LinearPieces.KEYS:
        np.testing.assert_array_equal(again.evaluate(q, u, lam, p)[k], reference.evaluate(q, u, lam, p)[k])
    assert cache.load(key)["layout"]["M"] == [0, [n, n]]  # stored again, as generated


@pytest.mark.parametrize("stored", [{"source": 42}, {"other": "x"},
                                    {"source": "import os\ndef _f(a0):\n    return [os.getpid()]"}])
def test_a_stored_rest_equation_that_is_not_generated_code_is_ignored(stored, cache_dir):
    path = SYSTEMS_DIR / "gyrostabilizer.yaml"
    model = mechsys.load(path)
    problem = eqm.make_problem(model)
    p = parameter_values(model)
    z = np.full(len(problem.unknowns), 0.4)
    reference = problem.F(z, p)
    cache.store(eqm._source_key(problem, "F"), stored)
    again = eqm.make_problem(mechsys.load(path))
    np.testing.assert_array_equal(again.F(z, p), reference)
    assert isinstance(cache.load(eqm._source_key(again, "F"))["source"], str)  # generated and stored again


# A model no textbook case was tuned on, written as a user would from docs/yaml-reference.md: a three-link chain of
# rods (relative angles) with a spring-loaded slider on the last link, gravity along -y.
_USER_CHAIN = """
name: user_chain
parameters: {m: 0.7, l: 0.9, g: 9.81, k: 40.0, ms: 0.3}
coordinates:
  q1: {initial: 0.1}
  q2: {initial: -0.2}
  q3: {initial: 0.3}
  s: {initial: 0.2}
links:
  link1: {mass: m, center_of_mass: [l/2, 0, 0], shape: {rod: {length: l, axis: x}},
          joint: {type: revolute, parent: ground, axis: z, coordinate: q1}}
  link2: {mass: m, center_of_mass: [l/2, 0, 0], shape: {rod: {length: l, axis: x}},
          joint: {type: revolute, parent: link1, origin: [l, 0, 0], axis: z, coordinate: q2}}
  link3: {mass: m, center_of_mass: [l/2, 0, 0], shape: {rod: {length: l, axis: x}},
          joint: {type: revolute, parent: link2, origin: [l, 0, 0], axis: z, coordinate: q3}}
  slider: {mass: ms, joint: {type: prismatic, parent: link3, axis: x, coordinate: s}}
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
  - {type: spring, between: [link3, slider], stiffness: k, free_length: l/2}
"""


@pytest.mark.parametrize("name", ["gyrostabilizer", "four_bar", "centrifuge", "indicator", "user_chain"])
def test_compiled_blocks_equal_lagranges_symbolic_jacobians(name, tmp_path, cache_dir):
    """The compiled blocks come from Kane's equations; `--linearize` prints Lagrange's, differentiated here
    independently: the same numbers at random states (rates and multipliers nonzero)."""
    from mechsys.numeric.lambdify import compile_exprs

    if name == "user_chain":
        path = tmp_path / "user_chain.yaml"
        path.write_text(_USER_CHAIN)
    else:
        path = SYSTEMS_DIR / f"{name}.yaml"
    model = mechsys.load(path)
    pieces = LinearPieces(model)
    symbolic = pieces.blocks("lagrange")
    args = [*model.q, *model.u, *pieces.lam, *model.parameter_symbols]
    rng = np.random.default_rng(11)
    p = parameter_values(model)
    n = len(model.q)
    for _ in range(3):
        q, u, lam = rng.uniform(-1.5, 1.5, n), rng.uniform(-2, 2, n), rng.uniform(-1, 1, pieces.m)
        blocks = pieces.evaluate(q, u, lam, p)
        for key in LinearPieces.KEYS:
            mat = symbolic[key]
            if not mat.shape[0]:
                continue
            expected = np.array(compile_exprs(list(mat), args)(*q, *u, *lam, *p), dtype=float).reshape(mat.shape)
            np.testing.assert_allclose(blocks[key], expected, rtol=1e-10, atol=1e-10 * max(1.0, np.abs(expected).max()))


def test_with_overrides_copies_share_the_compiled_rest_equations(monkeypatch):
    """A copy with other values (a sweep's task, the re-charted problem of each root at a gimbal lock) uses the
    code compiled for the first: the family-rate test and F, J are generated once (a 6-box spherical chain's
    `modes` generated them again for each of its 23 roots at a lock). The copy's results equal those of the same
    model loaded afresh with the values."""
    from mechsys.numeric import lambdify

    monkeypatch.delenv("MECHSYS_CACHE", raising=False)
    monkeypatch.setattr(cache, "cache_dir", lambda: None)
    base = mechsys.load(SYSTEMS_DIR / "centrifuge.yaml")
    rng = np.random.default_rng(4)
    _evaluations(base, np.random.default_rng(5))
    generated = []
    real = lambdify.generate_source
    monkeypatch.setattr(lambdify, "generate_source", lambda *a, **k: generated.append(1) or real(*a, **k))
    monkeypatch.setattr(eqm, "generate_source", lambda *a, **k: generated.append(1) or real(*a, **k))
    copy = base.with_overrides({"dM": 0.7})
    got = _evaluations(copy, rng)[:8]
    assert generated == []
    fresh = mechsys.load(SYSTEMS_DIR / "centrifuge.yaml", {"dM": "0.7"})
    want = _evaluations(fresh, np.random.default_rng(4))[:8]
    for a, b in zip(got, want):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("name", ["double_pendulum", "spring_chain", "beam_two_springs"])
def test_the_energy_hessian_from_the_compiled_jacobian_is_the_symbolic_one(name):
    """energy_verdict takes Hess V - dQ0/dq at a rest from minus the compiled Jacobian of the rest equations (the
    symbolic Hessian of V took 90 s of a 6-box chain's `modes`): the same matrix as the symbolic path, at every
    rest the search finds."""
    from mechsys.analysis.equilibrium import stability

    from helpers import DATA_DIR

    model = mechsys.load(next(d / f"{name}.yaml" for d in (SYSTEMS_DIR, DATA_DIR) if (d / f"{name}.yaml").exists()))
    result = eqm.find_equilibria(model)
    problem, p = result.problem, parameter_values(model)
    assert result.equilibria and not problem.cyclic and not problem.m
    for e in result.equilibria:
        U, qn = stability._effective_potential(problem, e)
        q0 = np.array([e.coordinates[c] for c in problem.free])
        symbolic = stability._hessian(U, qn, problem, q0, p) - stability._dissipation(problem, e, p)[3]
        rows = [model.coordinates.index(c) for c in problem.free]
        compiled = -problem.J(problem.state(e), p)[np.ix_(rows, range(len(qn)))]
        assert np.allclose(compiled, symbolic, rtol=1e-9, atol=1e-9 * max(1.0, float(np.max(np.abs(symbolic)))))


@pytest.mark.parametrize("name", ["torque_free_body", "sleeping_top_xyz", "conical_pendulum", "p41_double_pendulum",
                                  "two_free_bodies", "double_pendulum"])
def test_the_routh_hessian_from_the_compiled_linearization_is_the_symbolic_one(name):
    """energy_verdict takes Hess U - dQ0/dq of Routh's amended potential at a steady motion from the compiled
    linearization, -df/dq + G^T M_cc^-1 G with G = -df_c/du over the free rates (the symbolic Hessian took 30 s of
    a spinning chain's `equilibria`): the same matrix as the symbolic path, at every steady motion and rest the
    search finds, spinning ones included."""
    from mechsys.analysis.equilibrium import stability

    from helpers import DATA_DIR

    path = next(d / f"{name}.yaml" for d in (SYSTEMS_DIR, DATA_DIR, DATA_DIR / "beyond")
                if (d / f"{name}.yaml").exists())
    model = mechsys.load(path)
    result = eqm.find_equilibria(model)
    problem, p = result.problem, parameter_values(model)
    assert result.equilibria and not problem.m
    spinning = 0
    for e in result.equilibria:
        compiled = stability._compiled_hessian(problem, e, p)
        try:
            U, qn = stability._effective_potential(problem, e)
        except stability._MasslessCyclic as exc:  # the hanging conical pendulum: no Routh potential
            assert compiled == str(exc)
            continue
        q0 = np.array([e.coordinates[c] for c in problem.free])
        symbolic = stability._hessian(U, qn, problem, q0, p) - stability._dissipation(problem, e, p)[3]
        assert np.allclose(compiled, symbolic, rtol=1e-9, atol=1e-9 * max(1.0, float(np.max(np.abs(symbolic)))))
        spinning += any(e.rates.values())
    assert spinning or name == "double_pendulum"
