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


def _equilibria(model: MechanicalModel, options: dict) -> Outputs:
    from mechsys.analysis.equilibria import find_equilibria

    res = find_equilibria(model, options.get("search"))
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
    from mechsys.analysis.modes import vibration_modes

    m = vibration_modes(model, options.get("at"))
    out: Outputs = {"modes": len(m.frequencies)}
    for k, (w, z) in enumerate(zip(m.frequencies, m.damping_ratios), start=1):
        out[f"mode{k}.frequency"] = float(w)
        out[f"mode{k}.damping_ratio"] = float(z)
    return out


def _simulate(model: MechanicalModel, options: dict) -> Outputs:
    from mechsys.analysis.simulate import simulate

    t_end = float(options.get("t_end", 10.0))
    r = simulate(model, t_end, options.get("dt"), options.get("method", "auto"))
    out: Outputs = {"t_end": float(r.t[-1]), "energy_drift": r.energy_drift,
                    "max_residual": float(np.max(r.residual)), "rhs_evaluations": r.rhs_evaluations,
                    "events": len(r.events)}
    for k, c in enumerate(r.coordinates):
        out[f"final.{c}"] = float(r.q[-1, k])
        out[f"final.der({c})"] = float(r.u[-1, k])
        out[f"max.{c}"] = float(np.max(r.q[:, k]))
        out[f"min.{c}"] = float(np.min(r.q[:, k]))
    for name, values in r.driving.items():
        out[f"driving({name})"] = float(values[-1])
    return out


ANALYSES: dict[str, Callable[[MechanicalModel, dict], Outputs]] = {
    "info": _info,
    "equilibria": _equilibria,
    "modes": _modes,
    "simulate": _simulate,
}


def run_task(path: str, analysis: str, overrides: dict | None = None, options: dict | None = None) -> Outputs:
    """Load ``path`` with ``overrides`` and run ``analysis``; the outputs are flat scalars (numbers, strings,
    booleans) named like ``eq2.beta`` or ``final.der(alpha)``."""
    import mechsys

    if analysis not in ANALYSES:
        from mechsys.errors import InputError

        raise InputError(f"unknown analysis {analysis!r} (choose from {', '.join(ANALYSES)})")
    release = analysis == "simulate"
    model = mechsys.load(path, overrides or {}, release_prescribed=release)
    return ANALYSES[analysis](model, options or {})
