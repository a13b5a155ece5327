"""Shared helpers for the derivation tests: load bundled models, draw random states, evaluate numerically.

The checks compare sympy expressions *numerically* at random points (coordinates, rates, accelerations, time and,
optionally, parameter values), which is fast and does not depend on how sympy happens to simplify.
"""
from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np
import sympy as sp

import mechsys

ROOT = Path(__file__).resolve().parent.parent
SYSTEMS_DIR = ROOT / "systems"
DATA_DIR = ROOT / "tests" / "data"
METHODS = ("lagrange", "kane")


@functools.lru_cache(maxsize=None)
def _load_cached(path: str, overrides: tuple) -> "mechsys.mechanics.model.MechanicalModel":
    return mechsys.load(path, dict(overrides) or None)


def load_system(name: str, overrides: Mapping[str, object] | None = None):
    """The bundled model ``systems/<name>.yaml`` (cached per session: derivations happen once)."""
    return _load_cached(str(SYSTEMS_DIR / f"{name}.yaml"), tuple(sorted((overrides or {}).items())))


def load_data(name: str, overrides: Mapping[str, object] | None = None):
    """The test model ``tests/data/<name>.yaml`` (cached per session)."""
    return _load_cached(str(DATA_DIR / f"{name}.yaml"), tuple(sorted((overrides or {}).items())))


def chain_file(n: int, folder: Path) -> Path:
    """The n-link planar pendulum of rods of benchmarks/derive_chain.py, written as a model file in ``folder``."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("derive_chain", ROOT / "benchmarks" / "derive_chain.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    path = folder / f"chain{n}.yaml"
    path.write_text(bench.chain_yaml(n), encoding="utf-8")
    return path


def sym(model, name: str) -> sp.Symbol:
    """The sympy symbol of parameter ``name``."""
    return model.doc.parameters[name]


def coords(model) -> dict[str, tuple[sp.Symbol, sp.Symbol, sp.Symbol]]:
    """name -> (q, der(q), der(der(q))) symbols of each free coordinate."""
    return {n: (q, u, a) for n, q, u, a in zip(model.coordinates, model.q, model.u, model.a)}


def parameter_values(model, rng: np.random.Generator | None = None, spread: float = 0.3) -> dict[sp.Symbol, float]:
    """Parameter symbol -> value: the file's values, or (with ``rng``) each scaled by a random factor in
    [1 - spread, 1 + spread] (zero-valued parameters get a random value in [0.5, 1.5])."""
    out: dict[sp.Symbol, float] = {}
    for name, symbol in model.doc.parameters.items():
        value = float(model.parameters[name])
        if rng is not None:
            value = value * rng.uniform(1 - spread, 1 + spread) if value != 0 else rng.uniform(0.5, 1.5)
        out[symbol] = value
    return out


def _is_angle(model, name: str) -> bool:
    angles = getattr(getattr(model, "kin", None), "angles", {}) or {}
    return bool(angles.get(name, True))


def random_point(model, rng: np.random.Generator, *, randomize_parameters: bool = False,
                 ranges: Mapping[str, tuple[float, float]] | None = None,
                 angle_span: float = math.pi, length_span: float = 0.1,
                 rate_span: float = 2.0, accel_span: float = 3.0) -> dict[sp.Symbol, float]:
    """A random substitution for every symbol a model's equations may contain.

    Angular coordinates are drawn in (-angle_span, angle_span), translations in (-length_span, length_span)
    (small, so springs keep their orientation); ``ranges`` overrides the interval of a named coordinate.
    """
    point = parameter_values(model, rng if randomize_parameters else None)
    ranges = dict(ranges or {})
    for name, (q, u, a) in coords(model).items():
        if name in ranges:
            lo, hi = ranges[name]
        else:
            span = angle_span if _is_angle(model, name) else length_span
            lo, hi = -span, span
        point[q] = rng.uniform(lo, hi)
        point[u] = rng.uniform(-rate_span, rate_span)
        point[a] = rng.uniform(-accel_span, accel_span)
    point[model.t] = rng.uniform(0.0, 3.0)
    return point


def evaluate(expr, model, rng: np.random.Generator | None = None, point: Mapping | None = None):
    """Numeric value of ``expr`` (float, or a float array for a matrix) at ``point``, or at a fresh random
    point of ``model`` (coordinates, rates, accelerations, t random; parameters from the file) drawn with ``rng``.
    Raises if a symbol is left over (e.g. a name the model should not contain)."""
    if point is None:
        if rng is None:
            raise ValueError("give a point or an rng")
        point = random_point(model, rng)
    if isinstance(expr, sp.MatrixBase):
        value = expr.xreplace(dict(point)).evalf()
        leftover = value.free_symbols
        if leftover:
            raise AssertionError(f"symbols left after substitution: {sorted(map(str, leftover))}")
        return np.array(value.tolist(), dtype=float).reshape(value.shape)
    value = sp.sympify(expr).xreplace(dict(point)).evalf()
    if value.free_symbols:
        raise AssertionError(f"symbols left after substitution: {sorted(map(str, value.free_symbols))}")
    return float(value)


def assert_close(got, want, rtol: float = 1e-9, atol: float = 0.0, what: str = "") -> None:
    """Elementwise |got - want| <= rtol * max(|got|, |want|) + atol, with a readable message."""
    got = np.atleast_1d(np.asarray(got, dtype=float))
    want = np.atleast_1d(np.asarray(want, dtype=float))
    assert got.shape == want.shape, f"{what}: shape {got.shape} != {want.shape}"
    bound = rtol * np.maximum(np.abs(got), np.abs(want)) + atol
    bad = np.abs(got - want) > bound
    assert not bad.any(), (f"{what}: mismatch\n got  = {got}\n want = {want}\n diff = {got - want}")


def assert_rows_match(model, method: str, book_rows: Iterable, rng: np.random.Generator, *,
                      n_points: int = 5, rtol: float = 1e-9, signs: Iterable[int] | None = None,
                      randomize_parameters: bool = True, ranges: Mapping | None = None) -> None:
    """Each row of the model's residual M*a - f equals sign_i * book_row_i at random points.

    ``book_rows`` are the textbook equations written as "expression = 0" in the model's symbols, one per free
    coordinate (in ``model.coordinates`` order). ``signs`` fixes the orientation of each row (default +1).
    """
    book = list(book_rows)
    eq = model.equations(method)
    assert len(book) == eq.M.rows, f"{len(book)} book rows for {eq.M.rows} coordinates"
    s = np.array(list(signs) if signs is not None else [1] * len(book), dtype=float)
    residual = eq.residual()
    for _ in range(n_points):
        point = random_point(model, rng, randomize_parameters=randomize_parameters, ranges=ranges)
        got = evaluate(residual, model, point=point).ravel()
        want = s * np.array([evaluate(b, model, point=point) for b in book])
        # the absolute floor guards rows that happen to be ~0 at a point: 1e-12 of the largest term magnitude
        scale = max(1.0, float(np.max(np.abs(want))), float(np.max(np.abs(got))))
        assert_close(got, want, rtol=rtol, atol=1e-12 * scale, what=f"{model.name} [{method}] residual rows")


def simplifies_to_zero(expr) -> bool:
    """Symbolic check for small expressions."""
    return sp.simplify(sp.expand(sp.sympify(expr))) == 0


def double_pendulum_accelerations(q, u, m1: float = 1.0, m2: float = 0.8, l1: float = 0.6, l2: float = 0.5,
                                  g: float = 9.81) -> np.ndarray:
    """q'' from the equations written in the header of systems/double_pendulum.yaml (uniform rods, th1 absolute,
    th2 relative), derived by hand: an independent check of the derived and compiled equations."""
    th1, th2 = q
    w1, w2 = u
    c2, s2 = math.cos(th2), math.sin(th2)
    M = np.array([[m1 * l1**2 / 3 + m2 * (l1**2 + l2**2 / 3 + l1 * l2 * c2), m2 * (l2**2 / 3 + l1 * l2 * c2 / 2)],
                  [m2 * (l2**2 / 3 + l1 * l2 * c2 / 2), m2 * l2**2 / 3]])
    f = np.array([m2 * l1 * l2 * s2 * (w1 * w2 + w2**2 / 2) - (m1 / 2 + m2) * g * l1 * math.sin(th1)
                  - m2 * g * l2 / 2 * math.sin(th1 + th2),
                  -m2 * l1 * l2 * s2 * w1**2 / 2 - m2 * g * l2 / 2 * math.sin(th1 + th2)])
    return np.linalg.solve(M, f)
