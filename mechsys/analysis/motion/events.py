"""Event location inside integrator steps: sign changes and near-tangential touches found on the dense output."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

if TYPE_CHECKING:
    from scipy.optimize import OptimizeResult

SAMPLES = 8  # sub-intervals of every step on which the event functions are sampled
DIP_MARGIN = 4.0  # a sampled minimum of |g| is searched when it is below DIP_MARGIN x the local variation of g
EPS = np.finfo(float).eps


def event_settings(events: Sequence[Callable]) -> tuple[np.ndarray, np.ndarray]:
    """(max occurrences, direction) of scipy-style event callables (``.terminal``, ``.direction``)."""
    limits, directions = np.full(len(events), np.inf), np.zeros(len(events))
    for k, g in enumerate(events):
        terminal = getattr(g, "terminal", False)
        if terminal:
            limits[k] = float(terminal)
        directions[k] = float(np.sign(getattr(g, "direction", 0.0)))
    return limits, directions


def _root(h: Callable[[float], float], a: float, b: float) -> float:
    """The zero of h in [a, b] (h(a), h(b) of opposite signs or one of them zero), to rounding."""
    from scipy.optimize import brentq

    ha, hb = h(a), h(b)
    if ha == 0.0:
        return a
    if hb == 0.0:
        return b
    return float(brentq(h, a, b, xtol=4 * EPS, rtol=4 * EPS))


def _dip(h: Callable[[float], float], s: float, a: float, b: float) -> tuple[float, float]:
    """(t, s*h(t)) at the minimum of s*h on [a, b] by a bounded scalar search (Brent)."""
    from scipy.optimize import minimize_scalar

    res = minimize_scalar(lambda t: s * h(t), bounds=(a, b), method="bounded",
                          options={"xatol": 1e-13 * max(1.0, abs(a), abs(b)), "maxiter": 200})
    return float(res.x), float(res.fun)


def _sign_changes(h, ts: np.ndarray, G: np.ndarray, first: bool) -> list[tuple[float, float]]:
    """(time, direction) of the crossings between consecutive samples. A sample exactly at zero belongs to the
    interval that ends there; at the start of a solve a zero start value counts (as scipy's solve_ivp does)."""
    out = []
    for j in range(len(ts) - 1):
        a, b = G[j], G[j + 1]
        if a < 0.0 <= b or (first and j == 0 and a == 0.0 < b):
            out.append((_root(h, ts[j], ts[j + 1]), 1.0))
        elif a > 0.0 >= b or (first and j == 0 and a == 0.0 > b):
            out.append((_root(h, ts[j], ts[j + 1]), -1.0))
    return out


def _dip_brackets(h, ts: np.ndarray, G: np.ndarray) -> list[tuple[float, float, float]]:
    """(sign, a, b): sub-intervals where |g| has a sampled local minimum without a sign change, so that g may touch
    or cross zero twice between two samples. At a step end the slope (by a difference on the dense output) must
    show that the minimum lies inside the step; otherwise the neighbouring step finds it."""
    K = len(ts) - 1
    out = []
    for j in range(K + 1):
        s = float(np.sign(G[j]))
        lo, hi = max(j - 1, 0), min(j + 1, K)
        if s == 0.0 or np.any(np.sign(G[lo:hi + 1]) != s):
            continue
        v = s * G[j]
        if j > 0 and not v < s * G[j - 1] or j < K and not v <= s * G[j + 1]:
            continue
        variation = max(abs(G[lo] - G[j]), abs(G[hi] - G[j]))
        if j in (0, K):
            delta = 1e-3 * (ts[hi] - ts[lo])
            slope = (h(ts[j] + delta) - G[j]) / delta if j == 0 else (G[j] - h(ts[j] - delta)) / delta
            if (j == 0 and s * slope >= 0.0) or (j == K and s * slope <= 0.0):
                continue  # s*g increases from the step start (or decreases into the step end): no minimum inside
            variation = max(variation, abs(slope) * (ts[hi] - ts[lo]))
        if v <= DIP_MARGIN * variation:
            out.append((s, float(ts[lo]), float(ts[hi])))
    return out


def crossings(events: Sequence[Callable], directions: np.ndarray, interp: Callable, t_old: float, t_new: float,
              g_old: Sequence[float], y_new: np.ndarray, first: bool = False) -> tuple[list[float], list[tuple]]:
    """Zero crossings of every event function in the step (t_old, t_new] whose state is ``interp(t)``: sign changes
    between samples of the dense output, and pairs of roots inside a dip of |g| that does not change sign at any
    sample (a near-tangential touch). Returns (g at t_new, [(t, event index, direction)] in time order), keeping
    only the crossings each event's direction asks for. At the ``first`` step of a solve a zero start value counts
    as a crossing (as scipy's solve_ivp does; what a restart after an impact relies on), except for an event
    function with ``start_counts = False``: the file's events, whose start on the surface is not an event."""
    g_new = [float(g(t_new, y_new)) for g in events]
    if not t_new > t_old:
        return g_new, []
    ts = np.linspace(t_old, t_new, SAMPLES + 1)
    inner = np.asarray(interp(ts[1:-1]))
    found = []
    for k, g in enumerate(events):
        def h(t, g=g):
            return float(g(t, y_new if t == t_new else interp(t)))
        G = np.array([g_old[k], *(float(g(t, inner[:, i])) for i, t in enumerate(ts[1:-1])), g_new[k]])
        roots = _sign_changes(h, ts, G, first and getattr(g, "start_counts", True))
        for s, a, b in _dip_brackets(h, ts, G):
            t_min, value = _dip(h, s, a, b)
            if value < 0.0:  # g crosses zero and comes back: both roots, falling then rising for s > 0
                roots += [(_root(h, a, t_min), -s), (_root(h, t_min, b), s)]
        found += [(t, k, d) for t, d in roots if directions[k] == 0.0 or directions[k] == d]
    found.sort(key=lambda item: item[0])
    return g_new, found


def _solver_class(method: str):
    from scipy.integrate import BDF, DOP853, LSODA, RK23, RK45, Radau

    classes = {"RK23": RK23, "RK45": RK45, "DOP853": DOP853, "Radau": Radau, "BDF": BDF, "LSODA": LSODA}
    if method not in classes:
        raise ValueError(f"unknown method {method!r}")
    return classes[method]


def _solution(ts: list, interpolants: list, method: str):
    from scipy.integrate import OdeSolution

    try:
        return OdeSolution(ts, interpolants, alt_segment=method in ("BDF", "LSODA"))
    except TypeError:  # scipy < 1.11
        return OdeSolution(ts, interpolants)


def _not_finite_is_an_analysis_error(action: Callable, t: float):
    """``action()``; scipy's implicit methods refuse a non-finite Jacobian or state with a bare ValueError
    ("array must not contain infs or NaNs"), which becomes the AnalysisError the native path gives."""
    from mechsys.errors import AnalysisError

    try:
        return action()
    except ValueError as exc:
        if "inf" not in str(exc) and "nan" not in str(exc).lower():
            raise
        raise AnalysisError(f"integration failed at t = {t:.6g}: the state or its derivative is not finite (an "
                            "overflow: check the parameter values)") from None


def solve_ivp(fun: Callable, t_span: Sequence[float], y0: np.ndarray, method: str = "DOP853",
              t_eval: np.ndarray | None = None, dense_output: bool = False, events: Sequence[Callable] | None = None,
              **options: Any) -> OptimizeResult:
    """scipy's solve_ivp (the subset mechsys uses: forward in time, method by name), with events located inside
    every step by ``crossings`` instead of by the signs at step ends only, which steps over a crossing pair
    closer together than a step. The result also tells ``nsteps`` (steps taken) and ``h_next`` (the step size the
    method would take next, None for LSODA), so a following solve can start with it (``first_step``), and where it
    stopped (``t_reached``, ``y_reached``: with ``t_eval`` the last output may lie before a failure)."""
    from scipy.optimize import OptimizeResult

    t0, tf = map(float, t_span)
    y0 = np.asarray(y0, dtype=float)
    solver = _not_finite_is_an_analysis_error(lambda: _solver_class(method)(fun, t0, y0, tf, **options), t0)
    t_eval = None if t_eval is None else np.asarray(t_eval, dtype=float)
    ts, ys, interpolants, t_eval_i = ([t0], [y0], [], 0) if t_eval is None else ([], [], [], 0)
    knots = [t0]
    events = list(events or [])
    limits, directions = event_settings(events)
    counts = np.zeros(len(events))
    g = [float(e(t0, y0)) for e in events]
    t_events: list[list[float]] = [[] for _ in events]
    y_events: list[list[np.ndarray]] = [[] for _ in events]
    status, message, first = None, "", True
    while status is None:
        message = _not_finite_is_an_analysis_error(solver.step, solver.t)
        if solver.status == "failed":
            status = -1
            break
        status = 0 if solver.status == "finished" else None
        t, y = solver.t, solver.y
        sol = solver.dense_output()
        if events:
            g, found = crossings(events, directions, sol, solver.t_old, t, g, y, first)
            first = False
            for t_ev, k, _d in found:
                counts[k] += 1
                t_events[k].append(t_ev)
                y_events[k].append(sol(t_ev))
                if counts[k] >= limits[k]:
                    status, t, y = 1, t_ev, sol(t_ev)
                    break
        interpolants.append(sol)
        knots.append(t)
        if t_eval is None:
            ts.append(t)
            ys.append(y)
        else:
            stop = np.searchsorted(t_eval, t, side="right")
            if stop > t_eval_i:
                ts.append(t_eval[t_eval_i:stop])
                ys.append(sol(t_eval[t_eval_i:stop]))
                t_eval_i = stop
    messages = {0: "The solver successfully reached the end of the integration interval.",
                1: "A termination event occurred."}
    if t_eval is None:
        T, Y = np.array(ts), np.vstack(ys).T
    elif ts:
        T, Y = np.hstack(ts), np.hstack(ys)
    else:
        T, Y = np.zeros(0), np.zeros((len(y0), 0))
    return OptimizeResult(
        t=T, y=Y, sol=_solution(knots, interpolants, method) if dense_output and interpolants else None,
        t_events=[np.asarray(v) for v in t_events] if events else None,
        y_events=[np.asarray(v).reshape(len(v), len(y0)) for v in y_events] if events else None,
        nfev=solver.nfev, njev=solver.njev, nlu=solver.nlu, status=status, message=messages.get(status, message),
        success=status >= 0, nsteps=len(knots) - 1, h_next=getattr(solver, "h_abs", None), t_reached=solver.t,
        y_reached=solver.y)
