"""Warm start for `mechsys simulate`: a run plan keyed by the file's bytes and `--set` options, so a repeated run
skips sympy, pydantic and scipy and goes straight to the cached native integrator.

The plan holds only what the native path reads: coordinate names, parameter and initial values, the fastest
decay rate (auto's stiffness decision is redone for the new t_end), the generated source of T and V (and of the
constraint rows that projection reads), the rotation charts to watch, and the path of the compiled library. Scenes
with events, contacts or drives (whose forces need the Python equations) always take the full path, and so does a
warm run that comes near a gimbal lock of a watched chart (the full path switches charts: analysis/motion/charted.py).
Any change to the file, the options, mechsys or its code gives a new key. A plan is used only when it verifies
(numeric/cache.py: owner, signature) and is consistent with the library it names (sizes of every array, the
library's own signature); otherwise, and whenever MECHSYS_NATIVE=off, the run takes the full (cold) path, which
writes the plan again."""
from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Optional, Sequence

import numpy as np

from mechsys.analysis.motion.simulate import SimulationOptions, SimulationResult
from mechsys.numeric import cache

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel

STIFF_STEPS = 5e4  # the same threshold as simulate.choose_method


def plan_key(path: Path, overrides: Sequence[str], text: Optional[str] = None) -> Optional[str]:
    """Key of the run plan for this exact file content and options; None when caching is off or unreadable.
    ``text``: the content the plan was made from (the loaded model's), not the file as it is now: a file saved
    during a run stored the old content's plan under the new content's key."""
    if cache.cache_dir() is None:
        return None
    if text is None:
        from mechsys.errors import InputError
        from mechsys.model.files import read_model_text

        try:
            text = read_model_text(path)
        except InputError:
            return None
    from mechsys import __version__

    digest = hashlib.sha256(text.encode("utf-8"))
    digest.update(json.dumps({"set": list(overrides), "version": __version__, "code": cache.code_fingerprint(),
                              "what": "simulate-plan"}, sort_keys=True).encode())
    return digest.hexdigest()[:32]


def _load_plan(plan: dict) -> Optional[tuple]:
    """(integrator, Compiled, p, y0) from a verified plan, or None when anything in it is inconsistent: the
    library must verify and agree with every array (the C code reads them by position)."""
    from mechsys.analysis.motion.simulate import Compiled
    from mechsys.numeric.native import NativeIntegrator
    from mechsys.numeric.runtime import matrix_from_source

    try:
        library = cache.library(str(plan["library_key"]))
        if library is None:
            return None
        nat = NativeIntegrator(library)
        n, m = nat.n, int(plan["m"])
        p = np.array(plan["parameters"], dtype=float)
        y0 = np.array(plan["initial"], dtype=float)
        names = plan["coordinates"]
        # what projection and the energy columns read (the equations themselves are in the library)
        mats = {k: matrix_from_source(plan[k]) for k in ("A", "phi", "T", "V", "cv", "Q")}
        shapes = {"A": (m, n), "T": (1, 1), "V": (1, 1), "cv": (m, 1), "Q": (n, 1)}
        if (len(names) != n or not all(isinstance(x, str) for x in names) or m < 0
                or p.shape != (nat.n_parameters,) or y0.shape != (2 * n,) or not np.all(np.isfinite(y0))
                or any(mats[k].shape != shape for k, shape in shapes.items()) or mats["phi"].shape[1] != 1
                or not np.isfinite(float(plan["decay_rate"])) or not isinstance(plan["warnings"], list)
                or not all(isinstance(seq, str) and len(seq) == 3 and all(0 <= int(i) < n for i in idx)
                           and len(idx) == 3 for seq, idx in plan["charts"])):
            return None
    except (OSError, KeyError, TypeError, ValueError, SyntaxError, AttributeError):
        return None
    c = Compiled(None, mats["A"], None, mats["phi"], mats["T"], mats["V"], mats["cv"], n, m, 0.0, Q=mats["Q"],
                 Q_zero=bool(plan["Q_zero"]), rheonomic_rows=bool(plan["rheonomic_rows"]))
    if c.rheonomic_rows and m:
        return None  # the work of moving constraints needs their multipliers: the full path has the equations
    return nat, c, p, y0


def run_planned(path: Path, overrides: Sequence[str], options: SimulationOptions,
                progress: Optional[Callable[[float], None]] = None) -> Optional[SimulationResult]:
    """The simulation from a stored plan, or None when there is no usable plan for this run (the caller then
    loads the model and runs `simulate`)."""
    t_end, method, rtol, atol, max_steps = options.t_end, options.method, options.rtol, options.atol, options.max_steps
    if method not in ("auto", "native") or t_end <= 0:
        return None
    from mechsys.numeric.native import compiler

    key = plan_key(path, overrides)
    plan = cache.load(key) if key and compiler() is not None else None
    t0 = time.perf_counter()
    loaded = _load_plan(plan) if plan else None
    if loaded is None:
        return None
    nat, c, p, y0 = loaded
    if method == "auto" and plan["decay_rate"] * t_end > STIFF_STEPS:
        return None  # stiff over this horizon: the full path chooses an implicit method
    from mechsys.analysis.motion.simulate import (constraint_residual, native_projected, nonconservative_work,
                                                  output_grid)

    n, m = c.n, c.m
    load_seconds = time.perf_counter() - t0
    grid = output_grid(t_end, options.dt)
    t1 = time.perf_counter()
    if m:
        Y, nfev, steps = native_projected(nat, c, p, grid, y0, rtol, atol, progress, max_steps)
        if Y is None:
            return None  # redundant constraints: the full path falls back to least squares and says so
    else:
        run = nat.run(p, y0, grid, rtol, atol, progress, max_steps=max_steps)
        if run.status:
            return None  # let the full path report the failure with its context
        Y, nfev, steps = run.y, run.nfev, run.nsteps
    seconds = time.perf_counter() - t1
    q, u = Y[:, :n], Y[:, n:]
    if plan["charts"]:
        from mechsys.analysis.motion.charted import regular_run

        if not regular_run(plan["charts"], grid, q, u):
            return None  # near a gimbal lock: the full path integrates that stretch in another sequence
    T = np.array([c.T(t, qi, ui, p)[0, 0] for t, qi, ui in zip(grid, q, u)])
    V = np.array([c.V(t, qi, ui, p)[0, 0] for t, qi, ui in zip(grid, q, u)])
    warnings = list(plan["warnings"])
    if method == "auto":
        warnings.append(f"auto method: native (non-stiff: fastest decay rate {plan['decay_rate']:.3g} 1/s)")
    timings = {"load compiled code (warm plan)": load_seconds, "integrate": seconds}
    out = SimulationResult(list(plan["coordinates"]), grid, q, u, T, V, constraint_residual(c, p, grid, q, u),
                           "native", nfev + (2 * n + 1 if method == "auto" else 0), steps, timings, warnings)
    out.work = nonconservative_work(c, p, grid, q, u)
    return out


def remember(path: Path, overrides: Sequence[str], model: MechanicalModel, result: SimulationResult) -> None:
    """Store the plan of a native run so the next identical run starts warm (no-op for other methods)."""
    key = plan_key(path, overrides, model.doc.text)  # the content this run was made from
    drives = any(con.name.startswith("drive(") for con in model.kin.constraints)  # need the multipliers
    if key is None or result.method != "native" or drives or model.events or model.kin.contacts:
        return
    from mechsys.analysis.motion.charted import NOTES, regular_run, watched
    from mechsys.numeric.parameters import parameter_values
    from mechsys.analysis.motion.simulate import RightHandSide, compile_model, stiffness

    if compile_model(model).explicit_time:
        return  # the work of what moves with time needs dL/dt: the full path has it

    charts = [[seq, list(idx)] for _link, _kind, seq, idx in watched(model)]
    if charts and not regular_run(charts, result.t[:1], result.q[:1], result.u[:1]):
        return  # it starts at (or near) a gimbal lock of the file's angles: every run needs the full path
    nat = compile_model(model).native
    entry = cache.load(cache.model_key(model, "simulate"))
    if nat is None or nat.key is None or entry is None:
        return
    p = parameter_values(model)
    y0 = np.concatenate([result.q[0], result.u[0]])
    radius, _ = stiffness(RightHandSide(compile_model(model), p), 0.0, y0, 1.0)
    cache.store(key, {"coordinates": list(model.coordinates), "parameters": [float(x) for x in p],
                      "initial": [float(x) for x in y0], "decay_rate": radius, "library_key": nat.key,
                      "T": entry["T"], "V": entry["V"], "phi": entry["phi"], "A": entry["A"], "cv": entry["cv"],
                      "m": entry["m"], "charts": charts, "Q": entry["Q"], "Q_zero": entry["Q_zero"],
                      "rheonomic_rows": entry["rheonomic_rows"],
                      "warnings": [w for w in result.warnings if not w.startswith(("auto method", *NOTES))]})


def declares_outputs(path: Path) -> bool:
    """Whether the file has a non-empty `outputs:` section (read as plain YAML; validation comes with the load)."""
    import yaml

    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError, UnicodeDecodeError):
        return False  # the load reports it
    return isinstance(data, dict) and bool(data.get("outputs"))


def simulate_file(path: Path, overrides: Sequence[str], options: SimulationOptions,
                  progress: Optional[Callable[[float], None]] = None, need_model: bool = False) -> tuple:
    """What `mechsys simulate FILE` runs: (result, model or None). A repeated run of the same file and options
    starts from its plan (no model is built, so None) unless ``need_model`` (reactions, animations); otherwise the
    model is loaded with prescribed coordinates released into drives (their driving forces become outputs),
    simulated (through gimbal locks: analysis/motion/charted.py), and its plan remembered. The timings gain "load":
    everything not derivation or integration."""
    from mechsys.analysis.motion.charted import simulate_charted
    from mechsys.analysis.motion.outputs import add_outputs

    t0 = time.perf_counter()
    need_model = need_model or declares_outputs(path)  # outputs are evaluated on the model
    result = None if need_model else run_planned(path, overrides, options, progress)
    model = None
    if result is None:
        import mechsys
        from mechsys.model.load import parse_assignments

        model = mechsys.load(path, parse_assignments(list(overrides)), release_prescribed=True)
        result = simulate_charted(model, options, progress=progress)
        add_outputs(model, result)
        remember(path, overrides, model, result)
    result.timings = {"load": time.perf_counter() - t0 - sum(result.timings.values()), **result.timings}
    return result, model
