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


def _event_setup(events: Sequence[Callable] | None) -> tuple[Callable | None, list[float], list[int]]:
    """CVODE events function for scipy-style event callables g(t, y) (with .terminal and .direction)."""
    if not events:
        return None, [], []
    fns = list(events)

    def eventsfn(t, y, out):
        for k, g in enumerate(fns):
            out[k] = g(t, y)

    # terminal handled here (CVODE's step() only records roots): True = 1st occurrence, an int = that many
    limits = [float(int(getattr(g, "terminal", False))) if getattr(g, "terminal", False) else np.inf for g in fns]
    eventsfn.direction = [int(np.sign(getattr(g, "direction", 0.0))) for g in fns]
    eventsfn.terminal = [False] * len(fns)
    return eventsfn, limits, eventsfn.direction


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
    eventsfn, limits, _ = _event_setup(events)
    if eventsfn is not None:
        options["eventsfn"] = eventsfn
        options["num_events"] = len(limits)
    solver = CVODE(rhsfn, **options)

    ts: list[float] = []
    ys: list[np.ndarray] = []
    t_ev: list[list[float]] = [[] for _ in limits]
    y_ev: list[list[np.ndarray]] = [[] for _ in limits]
    counts = [0] * len(limits)
    seen_roots = 0
    status, flag, message, nsteps = 0, 0, "The solver successfully reached the end of the integration interval.", 0
    printed = io.StringIO()
    stats = {"njev": 0}

    def roots(r) -> bool:
        """Record the roots CVODE just returned; True when a terminal event has fired."""
        nonlocal seen_roots
        stop = False
        for info in r.i_events[seen_roots:]:
            for k in np.flatnonzero(info):
                t_ev[k].append(float(r.t))
                y_ev[k].append(np.array(r.y, dtype=float))
                counts[k] += 1
                stop = stop or counts[k] >= limits[k]
        seen_roots = len(r.i_events)
        return stop

    try:
        with contextlib.redirect_stdout(printed):  # scikit-sundae print()s SUNDIALS' error lines
            solver.init_step(t0, y0)
            if grid is None or (grid.size and grid[0] == t0):
                ts.append(t0)
                ys.append(y0.copy())
            targets = [] if grid is None else [t for t in grid if t > t0]
            k = 0
            while (k < len(targets)) if grid is not None else (not ts or ts[-1] < t1):
                if grid is None:
                    r = solver.step(t1, method="onestep", tstop=t1)
                else:
                    r = solver.step(float(targets[k]), method="normal", tstop=t1)
                flag = int(r.status)
                stats["njev"] = int(r.njev)
                if flag < 0:
                    status, message = -1, str(r.message)
                    break
                if flag == 2:  # CV_ROOT_RETURN: an event before the target; carry on unless terminal
                    if roots(r):
                        status, message = 1, "A termination event occurred."
                        if grid is None:
                            ts.append(float(r.t))
                            ys.append(np.array(r.y, dtype=float))
                        break
                    continue
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
        t_events=[np.array(v) for v in t_ev] if limits else None,
        y_events=[np.array(v).reshape(len(v), len(y0)) for v in y_ev] if limits else None,
        sundials_flag=flag, detail=detail)
