"""SUNDIALS CVODE (through scikit-sundae) as a drop-in for scipy's solve_ivp on stiff scenes."""
from __future__ import annotations

import contextlib
import io
import os
import re
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from mechsys.errors import AnalysisError

METHODS = ("BDF", "Adams")
NONFINITE_LIMIT = 100  # NaN/inf right-hand sides tolerated in a run (CVODE answers each by cutting h) before giving up


def available() -> bool:
    """True when scikit-sundae (import name sksundae) can be imported."""
    try:
        import sksundae.cvode  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass
class SundialsResult:
    """What solve_ivp's OdeResult offers that mechsys reads, from one CVODE run."""

    t: np.ndarray  # output times: the t_eval points reached (all internal steps without t_eval)
    y: np.ndarray  # (len(y0), len(t)), like solve_ivp
    success: bool
    message: str
    status: int  # as solve_ivp: -1 failure, 0 reached t_span[1], 1 a terminal event
    nfev: int  # calls of fun, including those of SUNDIALS' finite-difference Jacobians
    njev: int  # Jacobian evaluations (finite-difference or jac)
    nsteps: int | None  # internal steps; None on a t_eval grid (scikit-sundae does not expose CVodeGetNumSteps)
    t_events: list[np.ndarray] | None = None  # per event function, as solve_ivp
    y_events: list[np.ndarray] | None = None
    sundials_flag: int = 0  # the CVODE return flag of the last call (negative on failure)
    detail: list[str] = field(default_factory=list)  # SUNDIALS' own error lines, e.g. "At t = 0.5, ..."


class _NonFinite(Exception):
    """Raised inside the CVODE right-hand side when fun keeps returning NaN or inf."""


def _tspan(t_span: Sequence[float], t_eval: Sequence[float] | None) -> tuple[float, float, np.ndarray | None]:
    t0, t1 = float(t_span[0]), float(t_span[1])
    if not t1 > t0:
        raise AnalysisError(f"CVODE integrates forward only: t_span = ({t0:g}, {t1:g})")
    if t_eval is None:
        return t0, t1, None
    grid = np.asarray(t_eval, dtype=float).ravel()
    if grid.size and (np.any(np.diff(grid) <= 0) or grid[0] < t0 or grid[-1] > t1):
        raise AnalysisError("t_eval must increase strictly and lie within t_span")
    return t0, t1, grid


def _interpolant(solver, t1: float) -> Callable:
    """y(t) inside CVODE's last internal step (its interpolating polynomial), for a scalar t or an array of them."""
    def interp(t):
        times = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.array([np.array(solver.step(float(tk), method="normal", tstop=t1).y, dtype=float)
                        for tk in times]).T
        return out[:, 0] if np.ndim(t) == 0 else out
    return interp


def _located_run(solver, t0: float, t1: float, y0: np.ndarray, grid: np.ndarray | None, events: Sequence[Callable],
                 out: dict) -> tuple[int, int, str, int]:
    """CVODE one internal step at a time, the events located inside every step on CVODE's interpolant by
    mechsys.analysis.motion.events (CVODE's own root finder looks at the signs at step ends only and steps over a pair of
    crossings closer together than a step). Fills out["ts"], ["ys"], ["t_ev"], ["y_ev"]; returns (status, flag,
    message, steps)."""
    from mechsys.analysis.motion.events import crossings, event_settings

    limits, directions = event_settings(events)
    counts = np.zeros(len(events))
    g = [float(e(t0, y0)) for e in events]
    targets = None if grid is None else grid[grid > t0]
    interp = _interpolant(solver, t1)
    t_prev, first, steps, repeats = t0, True, 0, 0
    while t_prev < t1:
        r = solver.step(t1, method="onestep", tstop=t1)
        out["njev"] = int(r.njev)
        if int(r.status) < 0:
            return -1, int(r.status), str(r.message), steps
        t_cur = float(r.t)
        if t_cur <= t_prev:  # after interpolated outputs CVODE returns the end of its last step once more
            repeats += 1
            if repeats > 2:
                return -1, -99, f"CVODE made no progress at t = {t_cur:.6g}", steps
            continue
        repeats, steps = 0, steps + 1
        y_cur = np.array(r.y, dtype=float)
        g, found = crossings(events, directions, interp, t_prev, t_cur, g, y_cur, first)
        first, t_stop = False, None
        for t_e, k, _d in found:
            counts[k] += 1
            out["t_ev"][k].append(t_e)
            out["y_ev"][k].append(interp(t_e))
            if counts[k] >= limits[k]:
                t_stop = t_e
                break
        last = t_cur if t_stop is None else t_stop
        if grid is None:
            out["ts"].append(last)
            out["ys"].append(y_cur if t_stop is None else interp(t_stop))
        else:
            for tk in targets[(targets > t_prev) & (targets <= last)]:
                out["ts"].append(float(tk))
                out["ys"].append(y_cur if tk == t_cur else interp(float(tk)))
        if t_stop is not None:
            return 1, 0, "A termination event occurred.", steps
        t_prev = t_cur
    return 0, 0, "The solver successfully reached the end of the integration interval.", steps


def integrate(fun: Callable[[float, np.ndarray], np.ndarray], t_span: Sequence[float], y0: np.ndarray,
              t_eval: Sequence[float] | None = None, rtol: float = 1e-10, atol: float | np.ndarray = 1e-12,
              method: str = "BDF", jac: Callable[[float, np.ndarray], np.ndarray] | None = None,
              events: Sequence[Callable] | None = None, max_num_steps: int = 100_000) -> SundialsResult:
    """Integrate y' = fun(t, y) with CVODE (BDF for stiff scenes, Adams otherwise) on the t_eval grid.

    A solve_ivp replacement: failures return success False with SUNDIALS' message (never raise); a Python
    exception inside fun propagates, as with solve_ivp. jac(t, y) -> (n, n) replaces finite differences."""
    if method not in METHODS:
        raise AnalysisError(f"unknown CVODE method {method!r}; use one of {', '.join(METHODS)}")
    if not available():
        raise AnalysisError("the SUNDIALS integrator needs scikit-sundae: pip install 'mechsys[sundials]'")
    from sksundae.cvode import CVODE

    # SUNDIALS logs warnings ("t + h = t on the next step") straight to the C stderr: keep the CLI output clean
    os.environ.setdefault("SUNLOGGER_WARNING_FILENAME", os.devnull)
    t0, t1, grid = _tspan(t_span, t_eval)
    y0 = np.array(y0, dtype=float).ravel()
    state = {"calls": 0, "bad": 0, "t_bad": None}

    def rhsfn(t, y, yp):
        state["calls"] += 1
        dy = fun(t, y)
        yp[:] = dy
        if np.all(np.isfinite(yp)):
            return
        state["bad"] += 1
        if state["bad"] == 1:
            state["t_bad"] = t
        if state["bad"] >= NONFINITE_LIMIT:
            raise _NonFinite(f"the right-hand side returned NaN/inf {NONFINITE_LIMIT} times (first at "
                             f"t = {state['t_bad']:.6g}, last at t = {t:.6g})")

    options = {"method": method, "rtol": float(rtol), "max_num_steps": int(max_num_steps),
               "atol": np.asarray(atol, dtype=float) if np.ndim(atol) else float(atol)}
    if jac is not None:
        def jacfn(t, y, yp, JJ):
            JJ[:, :] = jac(t, y)
        options["jacfn"] = jacfn
    events = list(events or [])  # located by mechsys (_located_run), not by CVODE's root finder
    solver = CVODE(rhsfn, **options)

    ts: list[float] = []
    ys: list[np.ndarray] = []
    t_ev: list[list[float]] = [[] for _ in events]  # per event function, as solve_ivp
    y_ev: list[list[np.ndarray]] = [[] for _ in events]
    status, flag, message, nsteps = 0, 0, "The solver successfully reached the end of the integration interval.", 0
    printed = io.StringIO()
    stats = {"njev": 0}

    try:
        with contextlib.redirect_stdout(printed):  # scikit-sundae print()s SUNDIALS' error lines
            solver.init_step(t0, y0)
            if grid is None or (grid.size and grid[0] == t0):
                ts.append(t0)
                ys.append(y0.copy())
            if events:
                out = {"ts": ts, "ys": ys, "t_ev": t_ev, "y_ev": y_ev, "njev": 0}
                status, flag, message, nsteps = _located_run(solver, t0, t1, y0, grid, events, out)
                stats["njev"] = out["njev"]
            targets = [] if grid is None or events else [t for t in grid if t > t0]
            k = 0
            while not events and ((k < len(targets)) if grid is not None else (not ts or ts[-1] < t1)):
                if grid is None:
                    r = solver.step(t1, method="onestep", tstop=t1)
                else:
                    r = solver.step(float(targets[k]), method="normal", tstop=t1)
                flag = int(r.status)
                stats["njev"] = int(r.njev)
                if flag < 0:
                    status, message = -1, str(r.message)
                    break
                ts.append(float(r.t))
                ys.append(np.array(r.y, dtype=float))
                nsteps += 1
                k += 1
    except _NonFinite as exc:
        status, flag, message = -1, -8, str(exc)
    detail = [m.group(1).strip() for m in re.finditer(r"\[CVode[^\]]*\]\s*(.+)", printed.getvalue())]
    if status == -1 and detail:
        message = f"{message} {detail[-1]}"
    y = np.array(ys).T if ys else np.zeros((len(y0), 0))
    return SundialsResult(
        t=np.array(ts), y=y.reshape(len(y0), len(ts)), success=status >= 0, message=message, status=status,
        nfev=state["calls"], njev=stats["njev"],
        nsteps=nsteps if grid is None else None,
        t_events=[np.array(v) for v in t_ev] if events else None,
        y_events=[np.array(v).reshape(len(v), len(y0)) for v in y_ev] if events else None,
        sundials_flag=flag, detail=detail)
