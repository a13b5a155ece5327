"""Simulation through gimbal lock: a spherical or free joint's angles are integrated in another sequence while
the file's own sequence is near its singular set, and every output is given back in the file's angles."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Callable, Optional

import numpy as np

from mechsys.errors import AnalysisError
from mechsys.numeric.rotations import alternatives, angles_closed, angles_near, frame, rate_matrix, ratio_at

if TYPE_CHECKING:  # the warm path (analysis/motion/warm.py) imports this module and must not import sympy
    from mechsys.analysis.motion.simulate import SimulationOptions, SimulationResult
    from mechsys.mechanics.model import MechanicalModel


@dataclass(frozen=True)
class ChartOptions:
    """Thresholds on a chart's conditioning ratio: smallest over largest singular value of its map from angle
    rates to angular velocity, tan(d/2) at an angle d from its singular set (rotations.ratio_at)."""

    switch: float = 0.3  # leave a chart whose ratio falls below this (d = 33 degrees from gimbal lock)
    back: float = 0.5  # return to the file's sequence once its ratio is above this again (d = 53 degrees)
    floor: float = 0.1  # a look-ahead window is sized so that its chart should stay above this (d = 11 degrees)
    sample_turn: float = 0.05  # rad: how far a chart's third axis may turn between two checked samples
    undefined: float = 1e-7  # below this the file's first and third angle rates are undefined (written as NaN)
    first_steps: float = 5e4  # step budget of the first, unwindowed run (one through a gimbal lock crawls)


OPTIONS = ChartOptions()
#: How the summary notes of this module start (a stored warm plan must not repeat them).
NOTES = ("chart switches", "angle rates undefined", "no chart switching")


def _margins(seq: str, A: np.ndarray, Ad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For rows of angles A and rates Ad in chart ``seq``: the angle d from its singular set (the ratio is
    tan(d/2)) and how fast its third axis turns, |omega x e3| = sqrt((a1' sin d)^2 + a2'^2) (the column of a2' is
    orthogonal to the others), the fastest d can change."""
    b = np.asarray(A, dtype=float)[:, 1]
    s = np.abs(np.cos(b) if seq[0] == seq[2] else np.sin(b))  # |e1 . R e3|
    d = np.arccos(np.minimum(s, 1.0))
    Ad = np.asarray(Ad, dtype=float)
    return d, np.hypot(Ad[:, 0] * np.sin(d), Ad[:, 1])


def _first_change(joints: list[tuple], charts: list[str], times: np.ndarray, Q: np.ndarray, U: np.ndarray,
                  opts: ChartOptions) -> tuple[int, str, float]:
    """The first sample of a run that calls for a change in its charts: 'bad' (a chart's ratio below ``switch``)
    or 'coarse' (the samples are too far apart to exclude a dip to within 2 x ``sample_turn`` of that level
    between two of them: d changes no faster than the third axis turns, so between samples it stays above
    (d1 + d2 - h max(rate))/2). Returns its index (the last one when none), the reason ('' for none) and the
    fastest turn rate there."""
    d_switch = 2 * math.atan(opts.switch)
    n = len(times)
    first, kind, rates = n - 1, "", np.zeros(n)
    for seq, (_link, _kind, _user, idx) in zip(charts, joints):
        d, rate = _margins(seq, Q[:, idx], U[:, idx])
        rates = np.maximum(rates, rate)
        bad = np.flatnonzero(d < d_switch)
        dip = (d[:-1] + d[1:] - np.diff(times) * np.maximum(rate[:-1], rate[1:])) / 2
        coarse = np.flatnonzero(dip < d_switch - 2 * opts.sample_turn) + 1
        for k, why in ((bad[0] if bad.size else n, "bad"), (coarse[0] if coarse.size else n, "coarse")):
            if k < first or (k == first and k < n and (kind == "" or why == "bad")):
                first, kind = int(k), why
    return first, kind, float(rates[first])


def watched(model: MechanicalModel) -> list[tuple]:
    """(link, joint type, sequence, angle indices) of the spherical and free joints a simulation re-charts near
    gimbal lock (velocity constraints are derived again with the model in the other sequence); [] when it cannot:
    closed loops or drives, contacts, events, or a rotation chart of another
    kind (universal, transform, a spherical joint with a prescribed angle). Explicit time is checked only when a
    switch is needed (``_autonomous``)."""
    memo = model.__dict__.get("_charted_watch")
    if memo is None:
        from mechsys.analysis.equilibrium.charts import rotation_joints
        from mechsys.analysis.motion.simulate import rotation_charts

        charts = rotation_charts(model)
        links = {c[0] for c in charts}
        velocity_rows_only = all(c.kind == "nonholonomic" for c in model.kin.constraints)
        ok = bool(charts) and velocity_rows_only and not model.kin.contacts and not model.events and all(
            j.link in links and len(names) == 3 for j, names, _sequence in rotation_joints(model))
        memo = model.__dict__["_charted_watch"] = charts if ok else []
    return memo


def _kept(model: MechanicalModel, joints: list[tuple]) -> str | None:
    """Why the run must stay in the file's angles (None: it may switch charts): the equations have explicit time,
    or a force or constraint names the watched angles (equilibrium/charts.named_angles: another sequence would
    change it)."""
    from mechsys.analysis.equilibrium.charts import named_angles

    named = named_angles(model, [model.coordinates[i] for _l, _k, _s, idx in joints for i in idx])
    if named:
        return f"{named}, which another sequence of the joint would change"
    return None if _autonomous(model) else "the equations have explicit time"


def _autonomous(model: MechanicalModel) -> bool:
    """No explicit time in the equations of motion. Without constraints they come from T, V and the generalized
    forces alone, so t absent from those three decides it in milliseconds; otherwise ``model.is_autonomous``
    (which derives the equations) decides."""
    memo = model.__dict__.get("_charted_autonomous")
    if memo is None:
        used = set().union(*(e.free_symbols for e in (model.kinetic_energy, model.potential_energy,
                                                       model.generalized_forces)))
        memo = model.__dict__["_charted_autonomous"] = model.t not in used or model.is_autonomous()
    return memo


@dataclass
class _Look:
    """One joint at one sample: its pose and velocity, and the file's angles, rates and ratio there."""

    R: np.ndarray
    omega: np.ndarray
    a: np.ndarray
    ad: np.ndarray
    user_ratio: float
    seq: str = ""  # the chart integrated, and the angles and rates in it (the path to the next sample)
    chart_a: Optional[np.ndarray] = None
    chart_ad: Optional[np.ndarray] = None


def _look(seq: str, user: str, a: np.ndarray, ad: np.ndarray, prev: Optional[_Look], h: float,
          opts: ChartOptions) -> _Look:
    """A joint's sample in chart ``seq``, with its angles and rates converted to the file's sequence ``user``
    (continuous: followed along the path from the previous sample, ``_follow``)."""
    a, ad = np.array(a, dtype=float), np.array(ad, dtype=float)
    R, W = frame(seq, a)
    omega = W @ ad
    if seq == user:
        return _Look(R, omega, a, ad, ratio_at(seq, R), seq, a, ad)
    if prev.seq == seq and h > 0:
        a_user = _follow(seq, user, prev, a, ad, h)
    else:  # the first sample of a chart: the state converted at the switch itself
        a_user = angles_near(user, R, prev.a)
    if a_user is None:
        raise AnalysisError(f"no {user} angles reproduce the orientation reached in the {seq} angles")
    W = rate_matrix(user, a_user)
    r_user = ratio_at(user, R)
    if r_user >= opts.undefined:
        ad_user = np.linalg.solve(W, omega)
    else:  # gimbal lock to round-off: only the middle rate is defined (its column is orthogonal to the others)
        ad_user = np.array([np.nan, float(W[:, 1] @ omega), np.nan])
    return _Look(R, omega, a_user, ad_user, r_user, seq, a, ad)


def _follow(seq: str, user: str, prev: _Look, a: np.ndarray, ad: np.ndarray, h: float, turn: float = 0.2,
            most: int = 4096) -> Optional[np.ndarray]:
    """The file's angles at the end of a sample interval, continued from ``prev`` along the path: the chart's
    angles interpolated (cubic Hermite in its angles and rates, accurate where the chart is well conditioned) at
    sub-steps fine enough that no angle of the file's sequence turns by more than ``turn`` between two of them.
    Near the file's gimbal lock its first and third angles swing by about pi within a short time, to one side or
    the other depending on which side the path passes; taking the nearer triple at the samples alone made the
    angles depend on --dt (a tumbling box's theta(4 s): -0.39 at --dt 0.01, 3.53 at --dt 0.02)."""
    a0, ad0 = prev.chart_a, prev.chart_ad
    steps = 1
    while True:
        current = prev.a
        for i in range(1, steps + 1):
            s = i / steps
            path = ((2 * s**3 - 3 * s**2 + 1) * a0 + (s**3 - 2 * s**2 + s) * h * ad0 + (3 * s**2 - 2 * s**3) * a
                    + (s**3 - s**2) * h * ad)
            following = angles_near(user, frame(seq, path if i < steps else a)[0], current)
            if following is None or (steps < most and np.max(np.abs(following - current)) > turn):
                break
            current = following
        else:
            return current
        if steps >= most:
            return following
        steps *= 2


def _scan(joints: list[tuple], charts: list[str], times: np.ndarray, Q: np.ndarray, U: np.ndarray,
          prev: list[_Look], opts: ChartOptions) -> tuple[list[list[_Look]], int, str, float]:
    """The samples of a run up to its first change (``_first_change``, or 'back': the file's sequence is regular
    again), each looked at in the file's angles; also that change's index, reason and fastest turn rate."""
    first, kind, rate = _first_change(joints, charts, times, Q, U, opts)
    looks: list[list[_Look]] = []
    for k in range(first + 1):
        h = float(times[k] - times[k - 1]) if k else 0.0
        row = [_look(seq, j[2], Q[k, j[3]], U[k, j[3]], prev[i], h, opts)
               for i, (j, seq) in enumerate(zip(joints, charts))]
        looks.append(row)
        if k and (k < first or kind == "") and any(
                seq != j[2] and x.user_ratio >= opts.back for j, seq, x in zip(joints, charts, row)):
            return looks, k, "back", rate
        prev = row
    return looks, first, kind, rate


def regular_run(charts: list, t: np.ndarray, q: np.ndarray, u: np.ndarray, options: ChartOptions = OPTIONS) -> bool:
    """Whether a run integrated in the file's own angles can stand as it is: at every output row each chart
    (``charts``: (sequence, angle indices)) keeps its ratio at least ``switch``, and the rows are dense enough
    that no approach to gimbal lock hides between two of them (what a warm run checks before it is used)."""
    joints = [("", "", str(seq), list(idx)) for seq, idx in charts]
    return _first_change(joints, [j[2] for j in joints], t, q, u, options)[1] == ""


@dataclass
class _Window:
    """A piece of the run in one chart: its samples' global times and which of them are output rows."""

    times: np.ndarray
    outputs: dict  # sample index -> output row index
    length: float
    h: float


@dataclass
class _Charted:
    """State of a run that switches charts: the output table being filled, the current chart of every joint, and
    what the summary reports."""

    model: MechanicalModel
    joints: list[tuple]
    grid: np.ndarray
    opts: ChartOptions
    Q: np.ndarray = None
    U: np.ndarray = None
    T: np.ndarray = None
    V: np.ndarray = None
    switches: list = field(default_factory=list)  # (t, link, from, to)
    undefined: list = field(default_factory=list)  # (t, link, sequence, ratio, names of the undefined rates)

    def __post_init__(self) -> None:
        shape = (len(self.grid), len(self.model.coordinates))
        self.Q, self.U = np.full(shape, np.nan), np.full(shape, np.nan)
        self.T, self.V = np.full(len(self.grid), np.nan), np.full(len(self.grid), np.nan)
        lengths = np.diff(self.grid)
        # the last output index a window of equal output intervals starting at j may reach
        self.block = np.arange(1, len(self.grid))
        for j in range(len(lengths) - 2, -1, -1):
            if abs(lengths[j + 1] - lengths[j]) <= 1e-9 * lengths[j]:
                self.block[j] = self.block[j + 1]

    def chart_model(self, charts: list[str]) -> MechanicalModel:
        from mechsys.analysis.equilibrium.charts import _chart_model
        from mechsys.analysis.motion.simulate import compile_model

        m = self.model
        for (link, _kind, user, _idx), seq in zip(self.joints, charts):
            if seq != user:
                m = _chart_model(m, link, seq)
        compile_model(m)  # kept on the model, so every window's with_overrides clone shares it
        return m

    def record(self, j: int, row: list[_Look], q: np.ndarray, u: np.ndarray, T: float, V: float) -> None:
        q, u = q.copy(), u.copy()
        for (link, _kind, user, idx), x in zip(self.joints, row):
            q[idx], u[idx] = x.a, x.ad
            if not np.all(np.isfinite(x.ad)):
                names = [self.model.coordinates[idx[0]], self.model.coordinates[idx[2]]]
                self.undefined.append((float(self.grid[j]), link, user, x.user_ratio, names))
        self.Q[j], self.U[j], self.T[j], self.V[j] = q, u, T, V

    def switch(self, charts: list[str], looks: list[list[_Look]], r: int, k: int, kind: str, q: np.ndarray,
               u: np.ndarray, t: float) -> list[str]:
        """New charts at sample r (a chart bad at sample k goes to the sequence best conditioned at both; one
        whose file sequence is regular again goes back to it); q and u are rewritten in them in place."""
        new = list(charts)
        for i, (link, _kind, user, idx) in enumerate(self.joints):
            here = looks[r][i]
            if kind == "bad" and ratio_at(charts[i], looks[k][i].R) < self.opts.switch:
                candidates = [s for s in [user, *alternatives(user)] if s != charts[i]]
                new[i] = max(candidates, key=lambda s: min(ratio_at(s, here.R), ratio_at(s, looks[k][i].R)))
            elif charts[i] != user and here.user_ratio >= self.opts.back:
                new[i] = user
            if new[i] == charts[i]:
                continue
            if new[i] == user:
                a, ad = here.a, here.ad
            else:
                a = angles_near(new[i], here.R, angles_closed(new[i], here.R))
                if a is None:
                    raise AnalysisError(f"no {new[i]} angles reproduce the orientation of '{link}' at t = {t:.6g}")
                ad = np.linalg.solve(rate_matrix(new[i], a), here.omega)
            q[idx], u[idx] = a, ad
            self.switches.append((t, link, charts[i], new[i]))
        return new

    def plan(self, charts: list[str], q: np.ndarray, u: np.ndarray, t: float, j: int, at_output: bool,
             rate_floor: float, shrink: float) -> _Window:
        """The next look-ahead window from (t, q, u): long enough to be cheap, short enough that its chart should
        stay above ``floor``, with samples dense enough for ``sample_turn``; it ends at an output time or keeps
        to equal output intervals, so every output row is a sample of some window."""
        budget, h_max = math.inf, math.inf
        for seq, (_link, _kind, _user, idx) in zip(charts, self.joints):
            (d,), (rate,) = _margins(seq, q[None, idx], u[None, idx])
            rate = max(float(rate), rate_floor)
            if rate > 0:
                d = float(d) - 2 * math.atan(self.opts.floor)
                budget = min(budget, max(d, self.opts.sample_turn) / rate)
                h_max = min(h_max, self.opts.sample_turn / rate)
        budget *= shrink
        if not math.isfinite(budget) and shrink < 1:  # at rest, so no turn rate to size it: a shorter window
            budget = shrink * (self.grid[-1] - t)
        grid = self.grid
        step = grid[j + 1] - grid[j]
        if at_output and step <= min(h_max, budget):
            K = int(min(max(1, math.floor(budget / step)) if math.isfinite(budget) else math.inf,
                        self.block[j] - j))
            return _Window(grid[j:j + K + 1], {i: j + i for i in range(K + 1)}, K * step, step)
        end, hits = t + budget, False
        if end >= grid[j + 1] - 1e-12 * max(1.0, abs(grid[j + 1])):
            end, hits = grid[j + 1], True
        length = end - t
        n = max(1, math.ceil(length / h_max)) if math.isfinite(h_max) else 1
        times = t + np.arange(n + 1) * (length / n)
        times[-1] = end
        return _Window(times, {n: j + 1} if hits else {}, length, length / n)


def _note_switches(joints: list[tuple], switches: list, opts: ChartOptions) -> str:
    shown = []
    several = len(joints) > 1
    for t, link, old, new in switches[:8]:
        user = next(j[2] for j in joints if j[0] == link)
        what = f"back to {new}" if new == user and several else ("back" if new == user else f"{old} -> {new}")
        shown.append(f"{repr(link) + ' ' if several else ''}{what} at t = {t:.6g} s")
    more = f", {len(switches) - 8} more" if len(switches) > 8 else ""
    where = ", ".join(f"the {j[2]} angles of the {j[1]} joint of '{j[0]}'" for j in joints
                      if any(s[1] == j[0] for s in switches))
    return (f"chart switches: {len(switches)} ({', '.join(shown)}{more}): {where} came within a conditioning "
            f"ratio of {opts.switch:g} of gimbal lock, so the motion was integrated in another sequence of the same "
            f"joint there (same physics; T, V and E from it); the outputs are converted back to the file's angles")


def _note_undefined(undefined: list, opts: ChartOptions) -> list[str]:
    notes = []
    for link, user in dict.fromkeys((x[1], x[2]) for x in undefined):
        rows = [x for x in undefined if x[1] == link]
        times = ", ".join(f"{x[0]:.6g}" for x in rows[:8]) + (f" and {len(rows) - 8} more" if len(rows) > 8 else "")
        a, b = rows[0][4]
        notes.append(f"angle rates undefined: der({a}) and der({b}) are NaN at t = {times} s, where the {user} "
                     f"angles of '{link}' are at gimbal lock to round-off (ratio below {opts.undefined:g}): only "
                     f"their sum or difference is determined there; the angles are its continuous split, the "
                     f"middle rate is defined")
    return notes


def _unswitched(result: SimulationResult, joints: list[tuple], opts: ChartOptions, why: str) -> SimulationResult:
    """A run kept in the file's angles (``why``: _kept's reason), with a warning when they came near a gimbal
    lock."""
    ratios = [min(ratio_at(seq, frame(seq, q[idx])[0]) for _l, _k, seq, idx in joints) for q in result.q]
    k = int(np.argmin(ratios))
    if ratios[k] < opts.switch:
        result.warnings.append(
            f"no chart switching: the rotation angles come within a conditioning ratio of {ratios[k]:.2g} of gimbal "
            f"lock at t = {result.t[k]:.6g} s, where their rates grow like 1/ratio and accuracy suffers; it is not "
            f"re-charted because {why} (write the joint with a sequence whose singular set the motion avoids)")
    return result


def simulate_charted(model: MechanicalModel, run_options: SimulationOptions, overrides_p: Optional[np.ndarray] = None,
                     progress: Optional[Callable[[float], None]] = None,
                     options: ChartOptions = OPTIONS) -> SimulationResult:
    """``integrate``, carrying spherical and free joints through gimbal lock (docs/simulate.md, "Rotations
    through gimbal lock"). A run that never comes near a singular chart is ``integrate``'s own result, unchanged;
    otherwise it continues from the last good output row in look-ahead windows, each an ``integrate`` run from
    t = 0 of the model re-derived in the joint's best-conditioned sequence, with its times shifted."""
    from mechsys.analysis.motion.simulate import (CVODE_TIGHTENING, EVALUATIONS_PER_STEP, METHODS, SimulationResult,
                                                  SlowPace, compile_model, integrate, output_grid, start_state)

    t_end, dt, max_steps = run_options.t_end, run_options.dt, run_options.max_steps
    joints = watched(model) if run_options.method in METHODS and t_end > 0 else []
    if not joints:
        return integrate(model, run_options, overrides_p, progress)
    from mechsys.numeric.parameters import parameter_values
    from mechsys.numeric.native import BUDGET_SPENT, budget_spent

    started = time.perf_counter()
    p = parameter_values(model) if overrides_p is None else overrides_p
    # the start on the constraints, as each run starts (a rolling ball's file rates, off its rolling rows by 0.1,
    # were the first row of a run that switched charts, and the warm plan kept them as its start)
    q0, u0 = start_state(model, compile_model(model), p)
    user = [j[2] for j in joints]
    first_look = [_look(seq, seq, q0[idx], u0[idx], None, 0.0, options) for _l, _k, seq, idx in joints]
    totals = {"rhs": 0, "steps": 0, "used": 0.0, "seconds": 0.0}
    timings: dict[str, float] = {}
    warnings: list[str] = []
    chosen = run_options  # the method and tolerances of every window: auto's choice holds for the whole run

    def run(m: MechanicalModel, length: float, h: Optional[float], shift: float,
            cap: float = math.inf) -> SimulationResult:
        nonlocal chosen
        left = min(max_steps - totals["used"], cap)
        if left < 1:
            raise AnalysisError(f"integration stopped at t = {shift:.6g}: {budget_spent(chosen.method)}")
        t1 = time.perf_counter()
        res = integrate(m, replace(chosen, t_end=length, dt=h, max_steps=left), p,
                        None if progress is None else (lambda t: progress(shift + t)))
        totals["seconds"] += time.perf_counter() - t1
        if chosen.method == "auto":  # auto runs CVODE at rtol/100
            tight = CVODE_TIGHTENING if res.method == "CVODE" else 1.0
            chosen = replace(chosen, method=res.method, rtol=chosen.rtol / tight, atol=chosen.atol / tight)
        totals["rhs"] += res.rhs_evaluations
        totals["steps"] += res.steps or 0
        totals["used"] += res.steps if res.method == "native" else res.rhs_evaluations / EVALUATIONS_PER_STEP
        for key, value in res.timings.items():
            timings[key] = timings.get(key, 0.0) + value
        warnings.extend(w for w in res.warnings if w not in warnings)
        return res

    grid = output_grid(t_end, dt)
    state = _Charted(model, joints, grid, options)
    charts = list(user)
    if all(x.user_ratio >= options.switch for x in first_look):
        try:
            first = run(model, t_end, dt, 0.0, options.first_steps)
            kind = _first_change(joints, charts, first.t, first.q, first.u, options)[1]
        except AnalysisError:
            if _kept(model, joints):  # today's run, with the whole budget (and its message if it fails)
                return integrate(model, run_options, overrides_p, progress)
            first, kind = None, "failed"
        if kind == "":
            return first
        if _kept(model, joints):
            return _unswitched(first, joints, options, _kept(model, joints))
    elif _kept(model, joints):
        return _unswitched(integrate(model, run_options, overrides_p, progress), joints, options,
                           _kept(model, joints))
    else:
        first, kind = None, "start"
    if first is not None:  # keep the good rows of the first run and go on from the last of them
        looks, k, kind, rate = _scan(joints, charts, first.t, first.q, first.u, first_look, options)
        r = max(k - 1, 0)
        state.Q[0], state.U[0], state.T[0], state.V[0] = q0, u0, first.T[0], first.V[0]
        for i in range(1, r + 1):
            state.record(i, looks[i], first.q[i], first.u[i], first.T[i], first.V[i])
        prev, q, u, j = looks[r], first.q[r].copy(), first.u[r].copy(), r
        if kind == "bad":
            charts = state.switch(charts, looks, r, k, kind, q, u, float(grid[r]))
        rate_floor = rate if kind == "coarse" else 0.0
    else:
        prev, q, u, j, rate_floor = first_look, q0.copy(), u0.copy(), 0, 0.0
        if kind == "start":
            charts = state.switch(charts, [first_look], 0, 0, "bad", q, u, 0.0)
    t, at_output, stalled, shrink = float(grid[j]), True, 0, 1.0
    while not (at_output and j == len(grid) - 1):
        w = state.plan(charts, q, u, t, j, at_output, rate_floor, shrink)
        values = {c: float(v) for c, v in zip(model.coordinates, q)}
        values.update({f"der({c})": float(v) for c, v in zip(model.coordinates, u)})
        try:
            res = run(state.chart_model(charts).with_overrides(values), w.length, w.h, t)
        except AnalysisError as exc:
            if (BUDGET_SPENT in str(exc) and not isinstance(exc, SlowPace)) or shrink < 1e-3:
                raise AnalysisError(f"{exc} (times counted from t = {t:.6g} s, in the {'/'.join(charts)} "
                                    f"angles)") from None
            shrink /= 4
            continue
        if len(res.t) != len(w.times):
            raise AnalysisError(f"a re-charted window from t = {t:.6g} s ended early at t = {t + res.t[-1]:.6g}")
        if not np.isfinite(state.T[0]):
            state.Q[0], state.U[0], state.T[0], state.V[0] = q0, u0, res.T[0], res.V[0]
        looks, k, kind, rate = _scan(joints, charts, w.times, res.q, res.u, prev, options)
        r = k if kind in ("", "back") else max(k - 1, 0)
        for i in range(1, r + 1):
            if i in w.outputs:
                state.record(w.outputs[i], looks[i], res.q[i], res.u[i], res.T[i], res.V[i])
        prev, q, u, t = looks[r], res.q[r].copy(), res.u[r].copy(), float(w.times[r])
        at_output = r in w.outputs or (r == 0 and at_output)
        j = w.outputs.get(r, j)
        if kind in ("bad", "back"):
            charts = state.switch(charts, looks, r, k, kind, q, u, t)
        rate_floor = rate if kind == "coarse" else 0.0
        stalled = stalled + 1 if r == 0 else 0
        shrink = 1.0
        if stalled > 20:
            raise AnalysisError(f"chart switching made no progress at t = {t:.6g} s (the {'/'.join(charts)} angles "
                                "keep calling for another chart)")
    notes = []
    if state.switches:
        notes.append(_note_switches(joints, state.switches, options))
    notes += _note_undefined(state.undefined, options)
    timings["re-charting"] = max(0.0, time.perf_counter() - started - totals["seconds"])
    from mechsys.analysis.motion.simulate import compile_model, constraint_residual, nonconservative_work

    c = compile_model(model)
    with np.errstate(all="ignore"):  # the work rate and the rows in the file's angles, finite off the lock itself
        residual = constraint_residual(c, p, grid, state.Q, state.U)
        work = nonconservative_work(c, p, grid, state.Q, state.U)
    out = SimulationResult(list(model.coordinates), grid, state.Q, state.U, state.T, state.V, residual,
                           chosen.method, totals["rhs"], totals["steps"], timings, warnings + notes)
    out.work = work if work is None or np.all(np.isfinite(work)) else None
    return out
