"""One interface for running any analysis as a task with scalar outputs (used by `check` and `sweep`)."""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from mechsys.mechanics.model import MechanicalModel

Outputs = dict[str, Any]


def _info(model: MechanicalModel, options: dict) -> Outputs:
    from mechsys.analysis.info import system_info

    info = system_info(model)
    return {"dof": info.dof, "mobility": info.mobility, "configuration_dof": info.configuration_dof,
            "redundant_constraints": info.redundant_constraints, "holonomic": info.holonomic,
            "autonomous": info.autonomous}


def search_boxes(value: Any) -> dict[str, tuple[float, float]] | None:
    """The ``search`` option: a mapping, or text "NAME=LO:HI, NAME=LO:HI" (what an expectation can hold)."""
    if value is None or isinstance(value, dict):
        return value
    from mechsys.errors import InputError

    boxes = {}
    for item in str(value).replace(",", " ").split():
        name, _, rng = item.partition("=")
        try:
            lo, hi = (float(x) for x in rng.split(":"))
        except ValueError:
            raise InputError(f"option search: {item!r} is not NAME=LO:HI") from None
        if not lo < hi:
            raise InputError(f"option search: {item!r}: LO must be less than HI")
        boxes[name.strip()] = (lo, hi)
    return boxes


def _equilibria(model: MechanicalModel, options: dict) -> Outputs:
    from mechsys.analysis.equilibrium.equilibria import find_equilibria

    res = find_equilibria(model, search_boxes(options.get("search")))
    out: Outputs = {"count": len(res.equilibria),
                    "stable_count": sum(e.stability in ("stable", "asymptotically stable") for e in res.equilibria)}
    for k, e in enumerate(res.equilibria, start=1):
        for name, v in e.coordinates.items():
            out[f"eq{k}.{name}"] = v
        for name, v in e.rates.items():
            out[f"eq{k}.der({name})"] = v
        out[f"eq{k}.stability"] = e.stability
        out[f"eq{k}.max_real"] = float(np.max(e.eigenvalues.real)) if len(e.eigenvalues) else math.nan
    return out


def _modes(model: MechanicalModel, options: dict) -> Outputs:
    from mechsys.analysis.equilibrium.modes import vibration_modes
    from mechsys.analysis.equilibrium.stability import oscillating_eigenvalues

    m = vibration_modes(model, options.get("at"))
    out: Outputs = {"modes": len(m.frequencies)}
    for k, (w, z) in enumerate(zip(m.frequencies, m.damping_ratios), start=1):
        out[f"mode{k}.frequency"] = float(w)
        out[f"mode{k}.damping_ratio"] = float(z)
    # the damped eigenvalues: with gyroscopic or circulatory terms the motion's own frequencies, which the modes'
    # (of M and the symmetric K) are not; a Campbell diagram reads these
    out["coupling"] = m.coupling.split(" terms")[0] if m.coupling else "none"
    oscillating = oscillating_eigenvalues(m.eigenvalues, 2 * sum(map(bool, m.rigid_body)))
    for k, v in enumerate(oscillating, start=1):
        out[f"damped{k}.frequency"] = float(v.imag)
        out[f"damped{k}.decay_rate"] = float(-v.real)
    out["unstable_modes"] = m.unstable_modes
    return out


def _simulate(model: MechanicalModel, options: dict) -> Outputs:
    from mechsys.analysis.motion.charted import simulate_charted
    from mechsys.analysis.motion.outputs import add_outputs
    from mechsys.analysis.motion.simulate import SimulationOptions, file_state

    run = SimulationOptions(float(options.get("t_end", 10.0)), options.get("dt"), options.get("method", "auto"))
    r = add_outputs(model, simulate_charted(model, run))
    q0, u0 = file_state(model)
    out: Outputs = {"t_end": float(r.t[-1]), "energy_drift": r.energy_drift,
                    "energy_balance": r.energy_balance_error, "impacts": len(r.impacts),
                    "max_residual": float(np.max(r.residual)), "rhs_evaluations": r.rhs_evaluations,
                    "events": len(r.events),
                    # how far the assembly onto the constraints moved the start from the task's values
                    "start_moved": float(np.max(np.abs(np.concatenate([r.q[0] - q0, r.u[0] - u0])), initial=0.0))}
    if model.kin.constraints:  # where the run started: a swept start value off the constraints is moved
        for k, c in enumerate(r.coordinates):
            out[f"start.{c}"], out[f"start.der({c})"] = float(r.q[0, k]), float(r.u[0, k])
    for k, c in enumerate(r.coordinates):
        out[f"final.{c}"] = float(r.q[-1, k])
        out[f"final.der({c})"] = float(r.u[-1, k])
        out[f"max.{c}"] = float(np.max(r.q[:, k]))
        out[f"min.{c}"] = float(np.min(r.q[:, k]))
    for name, values in r.driving.items():
        out[f"driving({name})"] = float(values[-1])
    for name, values in r.outputs.items():  # the file's outputs: final, largest and smallest value
        out[f"final.{name}"], out[f"max.{name}"], out[f"min.{name}"] = (float(values[-1]), float(np.max(values)),
                                                                        float(np.min(values)))
    return out


def _bifurcations(model: MechanicalModel, options: dict) -> Outputs:
    from mechsys.analysis.equilibrium.bifurcation import sweep

    res = sweep(model, str(options["parameter"]), float(options["start"]), float(options["stop"]),
                int(options.get("points", 61)))
    out: Outputs = {"count": len(res.bifurcations)}
    counters: dict[str, int] = {}
    for b in res.bifurcations:
        counters[b["kind"]] = counters.get(b["kind"], 0) + 1
        key = f"{b['kind']}{counters[b['kind']]}"
        out[f"{key}.value"] = b["value"]
        for name, v in b["coordinates"].items():
            out[f"{key}.{name}"] = v
    out.update({f"{k}_count": v for k, v in counters.items()})
    return out


def _derive(model: MechanicalModel, options: dict) -> Outputs:
    """The equations as sympy objects (not scalars): M[i,j], f[i], T, V, Q[i], for expression checks."""
    eq = model.equations(str(options.get("method", "lagrange")))
    out: Outputs = {"T": eq.T, "V": eq.V}
    n = len(eq.q)
    for i in range(n):
        out[f"f[{i + 1}]"] = eq.f[i]
        out[f"Q[{i + 1}]"] = eq.Q[i]
        for j in range(n):
            out[f"M[{i + 1},{j + 1}]"] = eq.M[i, j]
    return out


def _collide(model: MechanicalModel, options: dict) -> Outputs:
    from mechsys.analysis.impact.collide import resolve

    r = resolve(model, options.get("impact"))
    out: Outputs = {"energy_loss": r.energy_loss}
    for name, U in zip(r.contacts, r.impulses):
        out[f"impulse({name})"] = float(U)
    for c, v in zip(r.coordinates, r.rates_after):
        out[f"after.der({c})"] = float(v)
    for link, vec in r.joint_impulses.items():
        for axis, x in zip("xyz", vec):
            out[f"joint({link}).{axis}"] = x
    return out


ANALYSES: dict[str, Callable[[MechanicalModel, dict], Outputs]] = {
    "collide": _collide,
    "derive": _derive,
    "bifurcations": _bifurcations,
    "info": _info,
    "equilibria": _equilibria,
    "modes": _modes,
    "simulate": _simulate,
}


#: The options each analysis reads, and what a value must be: a positive finite number, a number, a whole number
#: of at least 2, text, or anything (search and at: text or a mapping, the task parses them).
OPTIONS: dict[str, dict[str, str]] = {
    "collide": {"impact": "any"},
    "derive": {"method": "text"},
    "bifurcations": {"parameter": "text", "start": "number", "stop": "number", "points": "count"},
    "info": {},
    "equilibria": {"search": "any"},
    "modes": {"at": "any"},
    "simulate": {"t_end": "positive", "dt": "positive", "method": "text"},
}


def option_problem(analysis: str, key: str, value: object) -> str | None:
    """Why ``key: value`` is not an option of ``analysis`` (None: it is). A `check` expectation whose options
    were misspelt ran with the defaults and passed: `{tend: 0.3}` simulated 10 s."""
    import difflib

    kinds = OPTIONS.get(analysis, {})
    if key not in kinds:
        close = difflib.get_close_matches(key, list(kinds), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        return f"{analysis} has no option {key!r}{hint} (options: {', '.join(kinds) or 'none'})"
    kind = kinds[key]
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind == "positive" and not (number and math.isfinite(value) and value > 0):
        return f"{key} must be a positive finite number, not {value!r}"
    if kind == "number" and not (number and math.isfinite(value)):
        return f"{key} must be a finite number, not {value!r}"
    if kind == "count" and not (number and float(value).is_integer() and value >= 2):
        return f"{key} must be a whole number of at least 2, not {value!r}"
    if kind == "text" and not isinstance(value, str):
        return f"{key} must be text, not {value!r}"
    return None


def run_task(path: str, analysis: str, overrides: dict | None = None, options: dict | None = None) -> Outputs:
    """Load ``path`` with ``overrides`` and run ``analysis``; the outputs are flat scalars (numbers, strings,
    booleans) named like ``eq2.beta`` or ``final.der(alpha)``."""
    import mechsys

    if analysis not in ANALYSES:
        from mechsys.errors import InputError

        raise InputError(f"unknown analysis {analysis!r} (choose from {', '.join(ANALYSES)})")
    release = analysis in ("simulate", "collide")
    model = mechsys.load(path, overrides or {}, release_prescribed=release)
    return ANALYSES[analysis](model, options or {})
