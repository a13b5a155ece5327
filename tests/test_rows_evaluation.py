"""Generated code evaluated at many points in one pass (runtime.rows_function_from_code) gives, row by row, bit for
bit what the code gives one point at a time, or None where it cannot (conditions, min/max, floating-point
exceptions); the equilibria's linearizations evaluated that way (LinearPieces.evaluated_ahead) leave every
verdict and eigenvalue as it was."""
from __future__ import annotations

import numpy as np
import pytest

import mechsys
from helpers import DATA_DIR, SYSTEMS_DIR
from mechsys.analysis.equilibrium import equilibria as eqm
from mechsys.analysis.equilibrium import linearize, stability
from mechsys.analysis.equilibrium.linearize import pieces
from mechsys.numeric import cache
from mechsys.numeric.parameters import parameter_values
from mechsys.numeric.runtime import check_source, function_from_code, rows_function_from_code

# powers (integer, fractional, negative, of a sum), math functions of one and two arguments, constants,
# an output that does not depend on the arguments, a Rational as generated code prints it, floored remainders
# (a Mod) and quotients
SOURCE = """def _f(a0, a1, a2):
    x0 = math.sin(a0)
    x1 = (a0*a1 + a2)
    return [(x0)**2 + (a1)**3, (x1)**(-2), (a2*a2 + 1.5)**(0.3333333333333333), math.atan2(a1, a0)*math.exp(a2),
            (1/3)*math.sqrt(abs(a1)) - math.pi, (2)**(3), abs(a0)**(a2), -(x1)/(a0 - 7.25), math.cosh(a1),
            a1 % 1.7, (-(a0)) % (a2 + 3.5), 2.5 % (a2 + 3.5), (a0*a1) // 0.3]
"""


def _one_by_one(source: str, rows: np.ndarray) -> np.ndarray:
    fn = function_from_code(check_source(source))
    return np.array([np.asarray(fn(*row), dtype=float) for row in rows])


def test_rows_equal_one_point_at_a_time_bit_for_bit():
    rows = np.random.default_rng(3).uniform(-3, 3, (400, 3))
    together = rows_function_from_code(check_source(SOURCE))(rows)
    assert together is not None and together.shape == (400, 13)
    assert np.array_equal(together, _one_by_one(SOURCE, rows))


@pytest.mark.parametrize("body", [
    "return [a0 if a1 > 0 else a1]",            # a condition on the points
    "return [min(a0, a1)]",                     # min of arrays
    "return [float(a0)]",                       # a conversion of one value
    "return [a0/(a1 - a1)]",                    # a division by zero
    "return [(a0 - 5)**0.5]",                   # a complex power (Python) where numpy gives nan
    "return [math.log(a0 - 5)]",                # a math domain error
    "return [math.exp(a1*1000)]",               # an overflow
    "x0 = -2.0\n    x1 = x0**0.5\n    return [x1*a0]",  # a complex constant times the points
])
def test_code_that_cannot_run_on_rows_exactly_says_so(body):
    rows = np.random.default_rng(4).uniform(0.5, 3, (5, 2))
    assert rows_function_from_code(check_source(f"def _f(a0, a1):\n    {body}\n")) (rows) is None


def _chain(n: int) -> str:
    """A planar chain of n rods written as a user would (relative angles; not a bundled model)."""
    links = "".join(
        f"  l{i}:\n    joint: {{type: revolute, parent: {'ground' if i == 1 else f'l{i - 1}'}, axis: z, "
        f"coordinate: th{i}{'' if i == 1 else ', origin: [a, 0, 0]'}}}\n    mass: m{i}\n"
        f"    center_of_mass: [a/2, 0, 0]\n    shape: {{rod: {{length: a, axis: x}}}}\n" for i in range(1, n + 1))
    return (f"name: rods{n}\nparameters: {{a: 0.8, g: 9.81, {', '.join(f'm{i}: {1 + i / 3:.3f}' for i in range(1, n + 1))}}}\n"
            f"coordinates: {{{', '.join(f'th{i}: {{initial: 0}}' for i in range(1, n + 1))}}}\n"
            f"links:\n{links}forces:\n  - {{type: gravity, acceleration: [0, -g, 0]}}\n")


@pytest.mark.parametrize("case", ["chain4", "four_bar", "furuta", "bicycle"])
def test_blocks_evaluated_ahead_equal_blocks_evaluated_one_by_one(case, tmp_path, monkeypatch):
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    if case == "chain4":
        (tmp_path / "rods.yaml").write_text(_chain(4))
        path = tmp_path / "rods.yaml"
    else:
        path = {"four_bar": SYSTEMS_DIR / "four_bar.yaml", "bicycle": SYSTEMS_DIR / "bicycle.yaml",
                "furuta": DATA_DIR / "beyond" / "furuta_rod_arm.yaml"}[case]
    model = mechsys.load(path)
    lp = pieces(model)
    rng = np.random.default_rng(5)
    p = parameter_values(model)
    n = len(model.q)
    states = [(rng.uniform(-2, 2, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, lp.m), p) for _ in range(30)]
    alone = [lp.evaluate(*s) for s in states]
    calls = []
    scalar = lp._fn
    monkeypatch.setattr(lp, "_fn", lambda *a: calls.append(1) or scalar(*a))
    with lp.evaluated_ahead(states):
        lp.evaluate(*states[0])["M"][:] = np.nan  # a caller's changes to what it was given stay its own
        ahead = [lp.evaluate(*s) for s in states]
    assert not calls and not lp._evaluated  # all read from the one pass, and forgotten after the block
    for a, b in zip(alone, ahead):
        assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    lp.evaluate(*states[0])
    assert calls  # outside the block: one by one again


def test_equilibria_with_their_blocks_evaluated_ahead_are_those_evaluated_one_by_one(tmp_path, monkeypatch):
    """A user's 5-rod chain (32 equilibria) and a closed loop: the same verdicts, eigenvalues and Jacobians."""
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    (tmp_path / "rods.yaml").write_text(_chain(5))
    for path in (tmp_path / "rods.yaml", SYSTEMS_DIR / "four_bar.yaml"):
        results, passes = [], []
        real = linearize.rows_function_from_code
        for ahead in (True, False):
            model = mechsys.load(path)
            monkeypatch.setattr(linearize, "rows_function_from_code",
                                lambda code: passes.append(1) or real(code) if ahead else lambda rows: None)
            results.append(eqm.find_equilibria(model).equilibria)
            monkeypatch.undo()
            monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
        fast, slow = results
        assert len(fast) == len(slow) > 1
        if path.name == "rods.yaml":
            assert len(fast) == 32 >= stability.AHEAD_FROM and passes  # evaluated ahead
        else:
            assert len(fast) < stability.AHEAD_FROM and not passes  # a few: one by one
        for a, b in zip(fast, slow):
            assert a.coordinates == b.coordinates and a.stability == b.stability
            assert np.array_equal(a.eigenvalues, b.eigenvalues)
            assert (a.jacobian is None) == (b.jacobian is None)
            assert a.jacobian is None or np.array_equal(a.jacobian, b.jacobian)
    assert cache.cache_dir() is not None
