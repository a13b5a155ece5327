"""The file's `outputs:` evaluated along a motion: one column per output (accelerations from the equations)."""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Iterator, Sequence

import numpy as np

if TYPE_CHECKING:  # not at run time: the warm path of `simulate` imports this module without sympy
    from mechsys.analysis.motion.simulate import SimulationResult
    from mechsys.mechanics.model import MechanicalModel


def add_outputs(model: MechanicalModel, result: SimulationResult) -> SimulationResult:
    """``result`` with the file's outputs (at the model's parameter values) as ``result.outputs``."""
    import time

    from mechsys.numeric.parameters import parameter_values

    if model.outputs:
        t0 = time.perf_counter()
        result.outputs = output_columns(model, result, parameter_values(model))
        result.timings["outputs"] = time.perf_counter() - t0
        undefined = ~np.all(np.isfinite(result.u), axis=1) | at_lock(model, result)
        lost = [name for name, column in result.outputs.items() if np.any(np.isnan(column[undefined]))]
        if lost:
            times = ", ".join(f"{t:.6g}" for t in result.t[undefined][:8])
            result.warnings.append(f"outputs undefined: {', '.join(lost)} are NaN at t = {times} s with the angle "
                                   f"rates there (the rows where the file's angles are at gimbal lock)")
    return result


def output_columns(model: MechanicalModel, result: SimulationResult, p: np.ndarray) -> dict[str, np.ndarray]:
    """Each output of ``model`` at every output time of ``result`` (a simulation of this model with parameter
    vector ``p``). An output with accelerations (acceleration(P), der(der(q))) takes q'' from the equations of
    motion at each time, with the resting contacts of the run held as in the run."""
    if not model.outputs:
        return {}
    fn = compile_outputs(model)
    needs = needs_accelerations(model)
    rows = []
    states = zip(result.t, result.q, result.u)
    if needs:
        for (t, q, u), (a, lam) in zip(states, accelerations_along(model, result, p)):
            rows.append(fn(float(t), q, u, a, p, deferred_values(model, float(t), q, u, a, lam, p)))
    else:
        zero = np.zeros(len(model.q))
        rows = [fn(float(t), q, u, zero, p, ()) for t, q, u in states]
    data = np.array(rows, dtype=float).reshape(len(result.t), len(model.outputs))
    return {name: data[:, k] for k, (name, _e) in enumerate(model.outputs)}


def compile_outputs(model: MechanicalModel) -> Callable[[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                       Sequence[float]], list[float]]:
    """fn(t, q, u, q'', p, deferred) -> the outputs' values, in the order of ``model.outputs``; ``deferred``: the
    values of the multiplier and reaction placeholders (deferred_values)."""
    from mechsys.numeric.lambdify import compile_exprs

    raw = compile_exprs([e for _, e in model.outputs],
                        [model.t, *model.q, *model.u, *model.a, *model.parameter_symbols,
                         *model.deferred_quantities])
    return lambda t, q, u, a, p, deferred: raw(t, *q, *u, *a, *np.asarray(p, float), *deferred)


def needs_accelerations(model: MechanicalModel) -> bool:
    """Whether an output needs q'' (or multipliers, reactions): the equations are solved at each output time."""
    return bool(model.deferred_quantities) or any(set(model.a) & e.free_symbols for _, e in model.outputs)


def deferred_values(model: MechanicalModel, t: float, q: np.ndarray, u: np.ndarray, a: np.ndarray,
                    lam: np.ndarray, p: np.ndarray) -> list[float]:
    """The values of the placeholders of multipliers and joint reactions at one state."""
    if not model.deferred_quantities:
        return []
    wrench = None
    if any(kind == "reaction" for kind, _w, _k in model.deferred_quantities.values()):
        from mechsys.analysis.motion.reactions import wrenches

        wrench = wrenches(model, t, q, u, a, lam, p)
    return [float(lam[k]) if kind == "multiplier" else float(wrench[what][k])
            for kind, what, k in model.deferred_quantities.values()]


def at_lock(model: MechanicalModel, result: SimulationResult) -> np.ndarray:
    """Which rows of a run lie at a gimbal lock of the file's angles (a run that switched charts), where their q''
    (and the outputs that read it) are undefined: a free body started exactly at its zyx lock ran in another sequence, then
    its acceleration(P) output stopped the command with 'the mass matrix is singular at t = 0'."""
    from mechsys.analysis.motion.simulate import rotation_charts
    from mechsys.numeric.rotations import singular_chart

    charts = rotation_charts(model)
    return np.array([bool(charts) and bool(singular_chart(charts, q)) for q in result.q], dtype=bool)


def accelerations_along(model: MechanicalModel, result: SimulationResult,
                        p: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """(q'', multipliers) from the equations of motion at each output time of ``result``, the resting contacts
    of the run (captured impacts) held as in the run."""
    from mechsys.analysis.motion.simulate import RightHandSide, compile_model

    c = compile_model(model)
    rhs = RightHandSide(c, np.asarray(p, float))
    captured = [(im["t"], c.gap_names.index(im["contact"])) for im in result.impacts
                if im.get("captured") and im["contact"] in c.gap_names]
    lock = at_lock(model, result)
    for k, (t, q, u) in enumerate(zip(result.t, result.q, result.u)):
        if lock[k] or not np.all(np.isfinite(u)):  # a re-charted row at the file's gimbal lock: no q'' there
            yield np.full(len(q), np.nan), np.full(c.m, np.nan)
            continue
        rhs.persistent = sorted({k for tc, k in captured if tc <= t})
        yield rhs.accelerations(float(t), q, u)
