"""Forward dynamics: compiled equations, scipy integrators (auto stiffness choice), constraint projection, energies."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from mechsys.errors import AnalysisError, InputError
from mechsys.numeric import saddle
from mechsys.numeric.native import BUDGET_SPENT, budget_spent

if TYPE_CHECKING:  # sympy and the model are imported only where used: a warm run (motion/warm.py) needs neither
    import pandas as pd
    from scipy.optimize import OptimizeResult

    from mechsys.analysis.motion.sundials import SundialsResult
    from mechsys.mechanics.model import MechanicalModel
    from mechsys.numeric.native import NativeIntegrator

METHODS = ("auto", "native", "CVODE", "RK45", "DOP853", "Radau", "BDF", "LSODA")
EVALUATIONS_PER_STEP = 20  # the scipy and CVODE paths count the step budget in right-hand-side evaluations
RESIDUAL_TOLERANCE = 1e-6  # a projected state must satisfy the constraints to 1e-6 x (1 + max |q|, |q'|)
PROJECTION_STEPS = 20  # steps (of the size reached) between two projections onto the constraints
class SlowPace(AnalysisError):
    """A scipy or CVODE run stopped because at its pace the budget would not reach the end (not spent yet): a
    re-charted window that crawls into a gimbal lock is tried again shorter."""


BUDGET_WINDOW = 10_000  # RHS evaluations between two checks of the pace of a scipy or CVODE run against its budget
SLOW_WINDOWS = 3  # consecutive windows whose pace would overspend the budget before a run is stopped (a transient
# that starts slowly, like the initial layer of a stiff scene at a tight tolerance, speeds up within one or two)

# auto runs CVODE at rtol/100: at equal rtol its error is 30-100x Radau's (benchmarks/stiff.py)
CVODE_TIGHTENING = 100.0


@dataclass(frozen=True)
class SimulationOptions:
    """What a run integrates and how (`mechsys simulate`'s options, docs/simulate.md): from t = 0 to ``t_end``,
    outputs every ``dt`` (None: t_end / 1000), ``method`` (METHODS) at ``rtol`` and ``atol``, impacts slower than
    ``capture_velocity`` ending in contact, and at most ``max_steps`` of work (the native loop's steps, or
    EVALUATIONS_PER_STEP times as many right-hand-side evaluations elsewhere). Changed copies with
    dataclasses.replace (a re-charted window, auto's tightened CVODE tolerances)."""

    t_end: float
    dt: float | None = None
    method: str = "auto"
    rtol: float = 1e-10
    atol: float = 1e-12
    capture_velocity: float = 1e-10
    max_steps: float = 1e6


@dataclass
class Compiled:
    """Numeric callables a simulation needs, compiled once per model."""

    eqs: object
    A: object
    b: object
    phi: object
    T: object
    V: object
    cv: object  # velocity-level constraint expressions (A u + a_t)
    n: int
    m: int
    seconds: float
    cache_hit: bool = False
    events: object = None
    gaps: object = None  # gap functions of the contacts that have one
    gap_A: object = None  # their normal-velocity Jacobians (persistent-contact rows)
    gap_b: object = None
    gap_names: list = field(default_factory=list)
    native: object = None  # the loaded native integrator (numeric/native.py), once asked for
    charts: list = field(default_factory=list)  # (link, joint type, sequence, angle indices) of rotation sequences
    Q: object = None  # generalized forces not derived from V (their power is the non-conservative work rate)
    Q_zero: bool = True  # Q vanishes identically
    rheonomic_rows: bool = False  # some constraint row depends on t explicitly (drives, moving surfaces)
    explicit_time: bool = False  # T or V depends on t explicitly (a moving joint origin, a spring's setting in t)
    Lt: object = None  # the partial derivative of L = T - V in t (with explicit_time)


@dataclass
class Integration:
    """One simulate call's integration problem, as the scipy, CVODE and impact paths take it (one object instead
    of ten positional arguments)."""

    model: MechanicalModel
    c: Compiled
    rhs: RightHandSide
    p: np.ndarray
    grid: np.ndarray  # output times
    method: str
    rtol: float
    atol: float
    event_fns: list  # the file's events as scipy event functions
    note_events: Callable[[Any], bool]  # records a solve's events; True when a stopping event fired


def _contact_sources(model: MechanicalModel, args) -> dict:
    """Gap functions of the contacts and the rows a captured (persistent) contact adds: A_c q'' = b_c."""
    import sympy as sp

    from mechsys.numeric.lambdify import matrix_source

    gap_contacts = [c for c in model.kin.contacts if c["gap"] is not None]
    if not gap_contacts:
        empty = matrix_source(sp.zeros(0, 1), *args)
        return {"gaps": empty, "gap_A": matrix_source(sp.zeros(0, len(model.q)), *args), "gap_b": empty,
                "gap_names": []}
    vn = sp.Matrix([c["vn"] for c in gap_contacts])
    return {"gaps": matrix_source(sp.Matrix([c["gap"] for c in gap_contacts]), *args),
            "gap_A": matrix_source(model.partials(vn), *args),
            "gap_b": matrix_source(-model.dt(vn), *args),
            "gap_names": [c["name"] for c in gap_contacts]}


def _compiled_from(desc: dict) -> Compiled | None:
    """The callables of a (cached) description; None when it is in another format or inconsistent."""
    from mechsys.numeric.kane import equations_from_source
    from mechsys.numeric.runtime import matrix_from_source

    try:
        out = Compiled(equations_from_source(desc["eqs"]), *(matrix_from_source(desc[k]) for k in
                                                                 ("A", "b", "phi", "T", "V", "cv")),
                       int(desc["n"]), int(desc["m"]), 0.0, cache_hit=True)
        out.events = matrix_from_source(desc["events"])
        out.gaps = matrix_from_source(desc["gaps"])
        out.gap_A = matrix_from_source(desc["gap_A"])
        out.gap_b = matrix_from_source(desc["gap_b"])
        out.gap_names = [str(x) for x in desc["gap_names"]]
        out.Q = matrix_from_source(desc["Q"])
        out.Q_zero, out.rheonomic_rows = bool(desc["Q_zero"]), bool(desc["rheonomic_rows"])
        out.Lt, out.explicit_time = matrix_from_source(desc["Lt"]), bool(desc["explicit_time"])
    except (KeyError, TypeError, ValueError, SyntaxError):
        return None
    n, m = out.n, out.m
    if out.eqs.n != n or out.A.shape != (m, n) or out.b.shape != (m, 1) or out.cv.shape != (m, 1):
        return None
    return out


def compile_model(model: MechanicalModel) -> Compiled:
    """Everything a simulation evaluates, compiled once per model and cached on disk (see numeric/cache.py):
    a second run of the same model structure skips derivation and compilation."""
    cached = getattr(model, "_simulation_compiled", None)
    if cached is not None:
        return cached
    import sympy as sp

    from mechsys.numeric import cache
    from mechsys.numeric.kane import equations_source
    from mechsys.numeric.lambdify import matrix_source

    t0 = time.perf_counter()
    key = cache.model_key(model, "simulate")
    desc = cache.load(key)
    out = _compiled_from(desc) if desc is not None else None
    if out is None:
        from mechsys.mechanics.dag import FreeSymbols

        args = (model.t, model.q, model.u, model.parameter_symbols)
        hol = model.holonomic_constraints if model.holonomic_constraints.shape[0] else sp.zeros(0, 1)
        T, V = model.kinetic_energy, model.potential_energy
        symbols = FreeSymbols()
        explicit = symbols.has(T, model.t) or symbols.has(V, model.t)
        desc = {
            "eqs": equations_source(model),
            "A": matrix_source(model.constraint_jacobian, *args),
            "b": matrix_source(model.constraint_rhs, *args),
            "phi": matrix_source(hol, *args),
            "T": matrix_source(sp.Matrix([model.kinetic_energy]), *args),
            "V": matrix_source(sp.Matrix([model.potential_energy]), *args),
            "cv": matrix_source(model.constraint_velocity if model.kin.constraints else sp.zeros(0, 1), *args),
            "n": len(model.q), "m": len(model.kin.constraints),
            "events": matrix_source(sp.Matrix([e[1] for e in model.events]) if model.events else sp.zeros(0, 1),
                                    *args),
            **_contact_sources(model, args),
            "Q": matrix_source(model.generalized_forces, *args),
            "Q_zero": all(e == 0 for e in model.generalized_forces),
            "rheonomic_rows": any(sp.sympify(c.velocity).xreplace({u: 0 for u in model.u}) != 0
                                  for c in model.kin.constraints),  # a_t != 0: the row moves by itself
            "explicit_time": explicit,
            "Lt": matrix_source(sp.Matrix([sp.diff(T - V, model.t) if explicit else 0]), *args),
        }
        cache.store(key, desc)
        out = _compiled_from(desc)
        out.cache_hit = False
    out.seconds = time.perf_counter() - t0
    out.charts = rotation_charts(model)
    model._simulation_compiled = out
    return out


def rotation_charts(model: MechanicalModel) -> list[tuple]:
    """(link, joint type, sequence, indices of its angles in q) of every spherical or free joint whose three
    angles are free coordinates: where to look when the mass matrix turns singular (numeric/rotations.py)."""
    out = []
    for j in model.kin.joints:
        angles = j.coordinates[-3:]
        if j.type in ("spherical", "free") and all(a in model.coordinates for a in angles):
            sequence = model.doc.spec.links[j.link].joint.sequence
            out.append((j.link, j.type, sequence, [model.coordinates.index(a) for a in angles]))
    return out


@dataclass
class SimulationResult:
    coordinates: list[str]
    t: np.ndarray
    q: np.ndarray  # (len(t), n)
    u: np.ndarray
    T: np.ndarray
    V: np.ndarray
    residual: np.ndarray  # max |constraint| at each output time (0 without constraints)
    method: str
    rhs_evaluations: int
    steps: int
    timings: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    driving: dict = field(default_factory=dict)  # prescribed coordinate -> driving force/torque at each output
    events: list[dict] = field(default_factory=list)  # {"t", "event", "state": {...}} in time order
    impacts: list[dict] = field(default_factory=list)  # {"t", "contact", "impulse", "rates_before", ...}
    outputs: dict = field(default_factory=dict)  # the file's `outputs:` column -> values (analysis/motion/outputs.py)
    work: np.ndarray | None = None  # work of the non-conservative forces since t = 0 (None: conservative run)

    @property
    def E(self) -> np.ndarray:
        return self.T + self.V

    @property
    def conservative(self) -> bool:
        """No non-conservative force, no driven or moving constraint, no impact: E(t) should stay E(0)."""
        return self.work is None and not self.impacts

    @property
    def energy_balance(self) -> np.ndarray:
        """E(t) - E(0) - W(t) - (the energy changes of the impacts up to t): zero up to the integration error."""
        out = self.E - self.E[0] - (self.work if self.work is not None else 0.0)
        for im in self.impacts:
            after = self.t >= im["t"]
            at = np.flatnonzero(self.t == im["t"])
            if len(at) > 1:  # the state before the impact is a row at its instant too (an impact at t = 0)
                after[at[0]] = False
            out = out + np.where(after, float(im["energy_loss"]), 0.0)
        return out

    @property
    def energy_balance_error(self) -> float:
        """max |energy_balance| / max(|E(0)|, max T, max |W|): the drift of a conservative run, and for any other
        run the part of the energy change that no force accounts for."""
        scale = max(abs(self.E[0]), float(np.max(np.abs(self.T))), 1e-300)
        if self.work is not None:
            scale = max(scale, float(np.max(np.abs(self.work))))
        return float(np.max(np.abs(self.energy_balance)) / scale)

    @property
    def work_quadrature_error(self) -> float:
        """The estimated error of W from the output grid (relative, as energy_balance_error): a balance error of
        this size says the grid is coarse for the quadrature (refine --dt), not that the integration is poor."""
        if self.work is None:
            return 0.0
        scale = max(abs(self.E[0]), float(np.max(np.abs(self.T))), float(np.max(np.abs(self.work))), 1e-300)
        return float(getattr(self.work, "quadrature_error", 0.0)) / scale

    @property
    def energy_drift(self) -> float:
        """max |E(t) - E(0)| / max(|E(0)|, max T): meaningful for conservative systems."""
        scale = max(abs(self.E[0]), float(np.max(np.abs(self.T))), 1e-300)
        return float(np.max(np.abs(self.E - self.E[0])) / scale)

    def columns(self) -> tuple[list[str], np.ndarray]:
        names = ["t", *self.coordinates, *[f"der({c})" for c in self.coordinates], "T", "V", "E", "residual"]
        names += [f"driving({c})" for c in self.driving] + list(self.outputs)
        data = np.column_stack([self.t, self.q, self.u, self.T, self.V, self.E, self.residual,
                                *self.driving.values(), *self.outputs.values()])
        return names, data

    def _repr_markdown_(self) -> str:
        """Jupyter: the summary table of `mechsys simulate -f markdown`."""
        from mechsys.report.notebook import simulation_markdown

        return simulation_markdown(self)

    def to_dataframe(self) -> pd.DataFrame:
        """One row per output time, the columns of the result file (`mechsys simulate -o x.csv`): t, the
        coordinates, der(q), T, V, E, residual, ... (needs pandas: ``pip install 'mechsys[notebook]'``)."""
        from mechsys.report.notebook import simulation_frame

        return simulation_frame(self)


class RightHandSide:
    """y' = g(t, y) for y = (q, u); with constraints the accelerations solve [[M, A^T], [A, 0]] [q''; -lambda] = [f; b]."""

    def __init__(self, c: Compiled, p: np.ndarray, progress=None, max_calls: float = float("inf")) -> None:
        self.c = c
        self.p = p
        self.calls = 0
        self.max_calls = max_calls  # the step budget of the scipy and CVODE paths, in evaluations
        self.horizon = float("inf")  # t_end, for the pace check (set by simulate)
        self.front = -float("inf")  # the latest time evaluated so far
        self.window_front = None  # the front at the start of the current window of BUDGET_WINDOW evaluations
        self.slow_windows = 0  # consecutive windows at a pace that would overspend the budget
        self.persistent = []
        self.rested: set[int] = set()  # gap contacts that were persistent at some time (the impact paths)
        self.progress = progress  # progress(t), called every 200 evaluations
        self.method: str | None = None  # the integrating method, for the budget's message (set by simulate)

    persistent: list[int] = []  # indices of captured (resting) gap contacts, added as constraint rows

    def accelerations(self, t: float, q: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        M, f = self.c.eqs.evaluate(t, q, u, self.p)
        if self.c.m == 0 and not self.persistent:
            try:
                return np.linalg.solve(M, f), np.zeros(0)
            except np.linalg.LinAlgError:
                from mechsys.numeric.rotations import singular_chart

                chart = singular_chart(self.c.charts, q)
                if chart:
                    raise AnalysisError(f"the mass matrix is singular at t = {t:.6g}: {chart}; start away from it or "
                                        "write the joint with another sequence (zyx is singular where the middle "
                                        "angle is +-pi/2, zxz where it is 0 or pi)") from None
                raise AnalysisError(f"the mass matrix is singular at t = {t:.6g}: a coordinate, or a combination "
                                    "of them such as a rod's spin about its own axis, carries no mass or inertia "
                                    "(make it prescribed, or give it mass or inertia)") from None
        A = self.c.A(t, q, u, self.p)
        b = self.c.b(t, q, u, self.p).ravel()
        if self.persistent:
            A = np.vstack([A, self.c.gap_A(t, q, u, self.p)[self.persistent]])
            b = np.concatenate([b, self.c.gap_b(t, q, u, self.p).ravel()[self.persistent]])
        n, m = self.c.n, A.shape[0]
        if not all(np.all(np.isfinite(x)) for x in (M, A, f, b)):  # an overflow or a domain error: the
            return np.full(n, np.nan), np.full(m, np.nan)  # integrator's step fails and reports t (no SVD of nan)
        return saddle.solve(M, A, f, b)  # in balanced units: the same at MEMS scale as in metres

    def _why_slow(self) -> str:
        """budget_spent's causes, or, for an implicit method where the fast motion here only decays (no eigenvalue
        of the linearized motion within 1e3 of the fastest oscillates), the round-off of the stiff forces: a
        stiff, heavily damped spring (k = 1e12, c = 1e7) turns the coordinates' round-off into velocity errors
        above --atol 1e-12, and CVODE cut its steps to 1e-9 s; the message blamed undamped oscillations and
        suggested the explicit method."""
        from mechsys.numeric.native import IMPLICIT_METHODS

        latest = getattr(self, "latest", None)
        if self.method not in IMPLICIT_METHODS or latest is None or self.c.m or self.persistent:
            return budget_spent(self.method)
        t, y = latest
        n = self.c.n
        with np.errstate(all="ignore"):
            a0 = self.accelerations(t, y[:n], y[n:])[0]
            J = np.zeros((2 * n, 2 * n))
            J[:n, n:] = np.eye(n)
            for k in range(2 * n):
                h = 1e-7 * (1 + abs(y[k]))
                z = y.copy()
                z[k] += h
                J[n:, k] = (self.accelerations(t, z[:n], z[n:])[0] - a0) / h
            lam = np.linalg.eigvals(J) if np.all(np.isfinite(J)) else np.zeros(0)
        fastest = float(np.max(np.abs(lam))) if lam.size else 0.0
        fast = lam[np.abs(lam) > 1e-3 * fastest]  # the eigenvalues that bound an implicit method's steps
        if not fast.size or np.any(np.abs(fast.imag) > 0.1 * np.abs(fast)):
            return budget_spent(self.method)
        floor = np.finfo(float).eps * max(1.0, float(np.max(np.abs(y[:n])))) * fastest
        return (f"{BUDGET_SPENT}: the fast motion here only decays (no fast eigenvalue of its linearization "
                f"oscillates; the fastest decays at {fastest:.3g} 1/s), so {self.method}'s steps are limited by "
                f"the tolerances: the stiff forces turn the round-off of the coordinates into rates off by about "
                f"{floor:.1g} per unit time, which --atol and --rtol must not ask below; loosen them (e.g. --atol "
                "1e-9 --rtol 1e-8)")

    def _check_pace(self) -> None:
        """Stop now when the pace of the last SLOW_WINDOWS windows of BUDGET_WINDOW evaluations would each spend the
        budget before t_end: a chattering law or a stiff scene on an explicit method then fails in seconds, not
        after hours of Python evaluations."""
        start, self.window_front = self.window_front, self.front
        if start is None or not np.isfinite(self.horizon):
            return
        progress, remaining = self.front - start, self.horizon - self.front
        needed = remaining / progress * BUDGET_WINDOW if progress > 0 else float("inf")
        self.slow_windows = self.slow_windows + 1 if remaining > 0 and needed > self.max_calls - self.calls else 0
        if self.slow_windows >= SLOW_WINDOWS:
            pace = f"advanced {progress:.3g} s; at that pace the remaining {remaining:.3g} s would need about " \
                f"{needed:.3g} evaluations" if progress > 0 else "did not advance the time at all"
            raise SlowPace(f"integration stopped at t = {self.front:.6g}: {self._why_slow()} (the last "
                                f"{BUDGET_WINDOW} right-hand-side evaluations {pace}, with "
                                f"{self.max_calls - self.calls:.3g} left of the budget of {self.max_calls:.3g}; "
                                "raise --max-steps if the run is only slow to start)")

    def __call__(self, t: float, y: np.ndarray) -> np.ndarray:
        self.calls += 1
        if self.calls > self.max_calls:
            raise AnalysisError(f"integration stopped at t = {t:.6g}: {budget_spent(self.method)}")
        if t >= self.front:
            self.latest = (t, y)
        self.front = max(self.front, t)
        if self.window_front is None:
            self.window_front = t
        if self.calls % BUDGET_WINDOW == 0:
            self._check_pace()
        if self.progress is not None and self.calls % 200 == 0:
            self.progress(t)
        n = self.c.n
        q, u = y[:n], y[n:]
        a, _ = self.accelerations(t, q, u)
        return np.concatenate([u, a])


def file_state(model: MechanicalModel) -> tuple[np.ndarray, np.ndarray]:
    """The initial coordinates and rates as the file (and --set) give them, before assembly onto constraints."""
    q0 = np.array([model.doc.initial[n] for n in model.coordinates], dtype=float)
    u0 = np.array([model.doc.initial_rate[n] for n in model.coordinates], dtype=float)
    return q0, u0


def initial_state(model: MechanicalModel) -> tuple[Compiled, np.ndarray, np.ndarray]:
    """(compiled code, parameter values, consistent initial state y0 = (q0, u0)), as ``simulate`` starts."""
    from mechsys.numeric.parameters import parameter_values

    c = compile_model(model)
    p = parameter_values(model)
    q0, u0 = start_state(model, c, p)
    return c, p, np.concatenate([q0, u0])


def held_start(model: MechanicalModel) -> tuple[np.ndarray, np.ndarray]:
    """Which initial coordinates and rates the user set (--set, a check's `set:`, a sweep's values): the assembly
    onto the constraints holds them where it can."""
    set_ = {(path[1], path[2]) for path in model.doc.overridden if len(path) == 3 and path[0] == "coordinates"}
    return (np.array([(name, "initial") in set_ for name in model.coordinates], dtype=bool),
            np.array([(name, "rate") in set_ for name in model.coordinates], dtype=bool))


@dataclass
class Start:
    """The initial state on the constraints, and which values set were held and which could not be."""

    q: np.ndarray
    u: np.ndarray
    held: list[str]
    dropped: list[str]


def start_state(model: MechanicalModel, c: Compiled, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q0, u0) of assemble_start."""
    start = assemble_start(model, c, p)
    return start.q, start.u


def assemble_start(model: MechanicalModel, c: Compiled, p: np.ndarray) -> Start:
    """The file's initial state assembled onto the constraints at t = 0: project from the file's values (the branch
    nearest them); with coordinates the user set (held_start), carry instead, which holds them; then the rates set
    held while the others satisfy the velocity rows. A value set that no state connected to the file's values has
    (a rocker angle beyond its swing), or rates set that conflict, cannot be held: then the projection's state
    (Start.dropped). `--set th1=0.6` on a four-bar whose file guesses its coupler started with the crank at 0.396,
    moved as much as the guesses."""
    q, u = file_state(model)
    names = list(model.coordinates)
    if c.m == 0:
        return Start(q, u, [], [])
    hq, hu = held_start(model)
    held, dropped = [], []
    projected = project(c, p, 0.0, q, u)[0]
    carried = None
    if np.any(hq):
        # the path from the guesses, else along the projection's branch to the values set
        angles = np.array([bool(model.angles[name]) for name in names])
        carried = carry(c, p, 0.0, q, q, u, hq, angles)
        carried = carried if carried is not None else carry(c, p, 0.0, projected, q, u, hq, angles)
        (held if carried is not None else dropped).extend(names[k] for k in np.flatnonzero(hq))
    q = _unwound(c, p, carried if carried is not None else projected, q, u,
                 [model.angles[name] and not (h and carried is not None) for name, h in zip(names, hq)])
    if np.any(hu):
        u_h = _rates(c, p, 0.0, q, u, ~hu)
        chosen = [f"der({names[k]})" for k in np.flatnonzero(hu)]
        if _residual(c, p, 0.0, q, u_h) <= 1e-12 * (1.0 + float(np.max(np.abs(np.concatenate([q, u_h]))))):
            return Start(q, u_h, held + chosen, dropped)
        dropped += chosen
    return Start(q, _rates(c, p, 0.0, q, u, None), held, dropped)


def carry(c: Compiled, p: np.ndarray, t: float, origin: np.ndarray, guess: np.ndarray, u: np.ndarray,
          held: np.ndarray, angles: np.ndarray) -> np.ndarray | None:
    """A state on the holonomic constraints with the ``held`` coordinates of ``guess``, reached from ``origin``
    along a path: the homotopy Phi(q) = (1 - s) Phi(origin), the held coordinates going from origin's to guess's
    with s, followed from s = 0 (origin itself) to 1 in steps: the tangent predicts (Euler), Gauss-Newton on the
    free coordinates corrects; a step is kept only where Newton contracts at once (its second step at most
    CONTRACTION of its first), corrects by at most CORRECTION of what the tangent moved and turns no angle by
    more than ANGLE_STEP, else halved (a crank set to 4.8 had its coupler turned by turns in one step). From the
    guesses (origin = guess: the held values fixed, the constraints closing) or from their projection
    (Phi(origin) = 0: along its branch, the held values moving). A settle straight from the guesses jumped branches
    (a four-bar's rocker pointing down), and so did steps that Newton corrected onto the other branch. None where
    the steps shrink below 1e-6 of the way: the path meets a singular point (beyond a rocker's swing, a dead
    centre)."""
    offset = np.ravel(c.phi(t, origin, u, p))
    if not np.all(np.isfinite(offset)):
        return None
    free = ~held
    move = np.where(held, guess - origin, 0.0)  # dq_held/ds
    q, s, ds = origin.copy(), 0.0, 1.0
    while s < 1.0:
        step = min(ds, 1.0 - s)
        A = c.A(t, q, u, p)[: offset.size]
        tangent = move.copy()  # J q' = -Phi(origin) along the path: the free part by least squares
        if np.any(free) and offset.size:
            tangent[free] = np.linalg.lstsq(A[:, free], -(A @ move) - offset, rcond=None)[0]
        trial = q + tangent * step
        trial[held] = guess[held] if s + step >= 1.0 else origin[held] + (s + step) * move[held]
        settled = _settle(c, p, t, trial, u, free, (1.0 - s - step) * offset)
        if settled is None or (np.max(np.abs(settled - trial), initial=0.0)
                               > CORRECTION * np.max(np.abs(trial - q), initial=0.0) + 1e-14 * (1 + np.max(np.abs(q)))
                               or np.max(np.abs(settled - q)[angles], initial=0.0) > ANGLE_STEP):
            ds /= 2
            if ds < 1e-6:
                return None
            continue
        q, s, ds = settled, s + step, min(2 * ds, 1.0)
    return q


#: a step of carry's path is kept where Newton's second step is at most CONTRACTION of its first (inside the
#: basin of the path), its correction at most CORRECTION of the tangent's move (the path, not a neighbouring
#: branch), and no angle turns by more than ANGLE_STEP [rad]
CONTRACTION = 0.25
CORRECTION = 0.2
ANGLE_STEP = 0.25


def _unwound(c: Compiled, p: np.ndarray, q: np.ndarray, guess: np.ndarray, u: np.ndarray, angles: list[bool]
             ) -> np.ndarray:
    """q with each angle (``angles``) within half a turn of its guess, where the constraints hold there as well:
    the same positions (a four-bar's rocker assembled 8 turns away wound its spring, V(0) = 658 J for 0.24 J); an
    angle the constraints read unwrapped (a drum's rope length) keeps its turns."""
    q = q.copy()
    tol = 1e-12 * (1.0 + float(np.max(np.abs(q), initial=0.0)))
    for k in np.flatnonzero(angles):
        turns = np.round((q[k] - guess[k]) / (2 * np.pi))
        if turns:
            trial = q.copy()
            trial[k] -= 2 * np.pi * turns
            if float(np.max(np.abs(c.phi(0.0, trial, u, p)), initial=0.0)) <= tol:
                q = trial
    return q


def _settle(c: Compiled, p: np.ndarray, t: float, q: np.ndarray, u: np.ndarray, free: np.ndarray,
            offset: np.ndarray) -> np.ndarray | None:
    """Gauss-Newton on Phi(q, t) = offset moving only the ``free`` coordinates (minimum-norm steps); None when it
    does not converge in 12 steps or its second step is not CONTRACTION of its first."""
    q = q.copy()
    steps: list[float] = []
    for _ in range(12):
        r = np.ravel(c.phi(t, q, u, p)) - offset
        if not np.all(np.isfinite(r)):
            return None
        if r.size == 0 or np.max(np.abs(r)) < 1e-14 * (1 + np.max(np.abs(q))):
            return q
        hol = c.A(t, q, u, p)[: r.size]
        dq = np.zeros_like(q)
        if np.any(free):
            dq[free] = np.linalg.lstsq(hol[:, free], r, rcond=None)[0]
        q = q - dq
        steps.append(float(np.max(np.abs(dq))))
        if len(steps) == 2 and steps[1] > CONTRACTION * steps[0]:
            return None
    return None


def _rates(c: Compiled, p: np.ndarray, t: float, q: np.ndarray, u: np.ndarray, free: np.ndarray | None
           ) -> np.ndarray:
    """u changed least (minimum norm, in the ``free`` rates only; None: all) so that A u + a_t = 0."""
    A = c.A(t, q, u, p)
    r = c.cv(t, q, u, p).ravel()  # A u + a_t: rheonomic drive constraints have a_t = -p'(t)
    du = np.zeros_like(u)
    if free is None:
        du = np.linalg.lstsq(A, r, rcond=None)[0]
    elif np.any(free):
        du[free] = np.linalg.lstsq(A[:, free], r, rcond=None)[0]
    return u - du


def _residual(c: Compiled, p: np.ndarray, t: float, q: np.ndarray, u: np.ndarray) -> float:
    return float(constraint_residual(c, p, np.array([t]), q[None], u[None])[0])


def project(c: Compiled, p: np.ndarray, t: float, q: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest consistent state: Gauss-Newton on Phi(q, t) = 0 (minimum-norm steps), then A u = -(A u)_t part."""
    if c.m == 0:
        return q, u
    q = q.copy()
    for _ in range(20):
        phi = c.phi(t, q, u, p).ravel()
        if phi.size == 0 or np.max(np.abs(phi)) < 1e-14 * (1 + np.max(np.abs(q))):
            break
        A = c.A(t, q, u, p)
        hol = A[: phi.size]
        q = q - np.linalg.lstsq(hol, phi, rcond=None)[0]
    return q, _rates(c, p, t, q, u, None)


def nonconservative_work(c: Compiled, p: np.ndarray, grid: np.ndarray, q: np.ndarray, u: np.ndarray,
                         lams: np.ndarray | None = None) -> np.ndarray | None:
    """W(t): the work since t = 0 of the generalized forces not derived from V (Q . q') and of the constraint
    forces of rows that depend on t (lambda . A q': drives, moving surfaces; a scleronomic row does no work), by
    a fourth-order quadrature on the output grid (_cumulative_integral; across an
    impact the power jumps, and the impact's own energy change is reported apart). None for a run whose forces
    are all conservative. ``lams``: the multipliers at the output times when the caller has them.

    With T or V explicit in t (a joint origin or a spring setting that moves with time) also the work of what moves
    them: Lagrange's equations times q' give dh/dt = Q . q' + lambda . A q' - dL/dt (partial), h = T2 - T0 + V
    the Jacobi integral, E = h + T1 + 2 T0 (T1, T0: the parts of T linear in and free of the rates), so that work is
    the integral of -dL/dt plus the change of T1 + 2 T0 (T(u) - T(-u))/2 + 2 T(0), read at each row."""
    explicit = getattr(c, "explicit_time", False)
    if c.Q is None or (c.Q_zero and not (c.rheonomic_rows and c.m) and not explicit):
        return None
    power = np.zeros(len(grid))
    if explicit:
        power -= np.array([float(c.Lt(t, qi, ui, p)[0, 0]) for t, qi, ui in zip(grid, q, u)])
    if not c.Q_zero:
        power += np.array([float(np.ravel(c.Q(t, qi, ui, p)) @ ui) for t, qi, ui in zip(grid, q, u)])
    if c.rheonomic_rows and c.m:
        if lams is None:
            rhs = RightHandSide(c, p)
            lams = np.array([rhs.accelerations(t, qi, ui)[1][:c.m] for t, qi, ui in zip(grid, q, u)])
        power += np.array([float(lam[:c.m] @ (c.A(t, qi, ui, p) @ ui)) for t, lam, qi, ui in zip(grid, lams, q, u)])
    work = _cumulative_integral(grid, power)
    coarse = _cumulative_integral(grid[::2], power[::2])  # Richardson: the error of the fine rule is ~ 1/15 of
    work.quadrature_error = float(np.max(np.abs(work[::2] - coarse))) / 15  # the difference (fourth order)
    if explicit:
        def T(t, qi, ui):
            return float(c.T(t, qi, ui, p)[0, 0])
        moving = np.array([(T(t, qi, ui) - T(t, qi, -ui)) / 2 + 2 * T(t, qi, 0 * ui) for t, qi, ui in zip(grid, q, u)])
        work += moving - moving[0]
    return work


class Work(np.ndarray):
    """W(t) at the output times, with ``quadrature_error``: an estimate of the error of the rule on this grid."""

    quadrature_error: float = 0.0


def _cumulative_integral(t: np.ndarray, y: np.ndarray) -> Work:
    """The integral of y from t[0], piece by piece between repeated times (the rows before and after an impact
    share their time: the power jumps there, the work does not). Numpy only: the warm start imports no scipy."""
    out = np.zeros(len(t))
    cuts = [0, *(np.flatnonzero(np.diff(t) <= 0) + 1), len(t)]
    for a, b in zip(cuts[:-1], cuts[1:]):
        out[a:b] = (out[a - 1] if a else 0.0) + np.concatenate([[0.0], np.cumsum(_interval_integrals(t[a:b],
                                                                                                    y[a:b]))])
    return out.view(Work)


def _interval_integrals(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The integral over each interval [t_i, t_i+1]: the mean of the two parabolas through (t_i-1, t_i, t_i+1)
    and (t_i, t_i+1, t_i+2) integrated there (fourth order on a uniform grid: h/24 (-y_i-1 + 13 y_i + 13 y_i+1 -
    y_i+2)), one parabola on the first and last intervals; two samples, or steps too uneven for both parabolas: the
    trapezoid."""
    h = np.diff(t)
    trapezoid = h * (y[1:] + y[:-1]) / 2
    if len(t) < 3:
        return trapezoid
    k = np.arange(len(t) - 1)
    right_first, left_first = np.minimum(k, len(t) - 3), np.maximum(k - 1, 0)
    right = _parabola_integrals(t, y, right_first)  # through t_i, t_i+1, t_i+2
    left = _parabola_integrals(t, y, left_first)  # through t_i-1, t_i, t_i+1
    # a parabola through steps of very different lengths extrapolates wildly over the long one (a Zeno run of
    # impacts, steps of 1e-11 s, then the output grid's 4e-4 s: W jumped by 53 J): use it only where its two steps
    # are within a factor 10 of each other, else the trapezoid
    def even(first: np.ndarray) -> np.ndarray:
        a, b = h[first], h[first + 1]
        return np.maximum(a, b) <= 10 * np.minimum(a, b)
    use_right, use_left = even(right_first) & (k <= len(t) - 3), even(left_first) & (k >= 1)
    return np.where(use_right & use_left, (left + right) / 2,
                    np.where(use_right, right, np.where(use_left, left, trapezoid)))


def _parabola_integrals(t: np.ndarray, y: np.ndarray, first: np.ndarray) -> np.ndarray:
    """For each interval [t_i, t_i+1] (i = 0 .. n-2) the integral of the parabola through the three samples
    starting at index ``first[i]``."""
    x0, x1, x2 = t[first], t[first + 1], t[first + 2]
    lo, hi = t[:-1] - x0, t[1:] - x0

    def integral(a, b):  # of (s - a)(s - b) over [lo, hi]
        def F(s):
            return s**3 / 3 - (a + b) * s**2 / 2 + a * b * s
        return F(hi) - F(lo)

    h1, h2 = x1 - x0, x2 - x0
    return (integral(h1, h2) / (h1 * h2) * y[first] + integral(0.0, h2) / (h1 * (h1 - h2)) * y[first + 1]
            + integral(0.0, h1) / (h2 * (h2 - h1)) * y[first + 2])


def residual_tolerance(q: np.ndarray, u: np.ndarray) -> float:
    """The largest constraint residual a projected state may keep: RESIDUAL_TOLERANCE x (1 + max |q|, |q'|).
    A converged projection leaves ~1e-14; more means no nearby state satisfies the constraints."""
    return RESIDUAL_TOLERANCE * (1.0 + max(float(np.max(np.abs(q), initial=0.0)),
                                           float(np.max(np.abs(u), initial=0.0))))


def singularity_note(c: Compiled, p: np.ndarray, t: float, y: np.ndarray) -> str:
    """Why a closed loop's integration may have failed at (t, y): '' unless its constraint Jacobian is (nearly)
    singular there, i.e. a dead-centre or locked configuration that the motion runs into."""
    if not c.m:
        return ""
    n = c.n
    with np.errstate(all="ignore"):
        A = c.A(t, y[:n], y[n:], p)
        if not np.all(np.isfinite(A)) or not A.size:
            return ""
        s = np.linalg.svd(A, compute_uv=False)
    ratio = float(s[-1] / s[0]) if s[0] > 0 and len(s) == A.shape[0] else 0.0
    if ratio > 1e-4:
        return ""
    return (f" (the constraint Jacobian is nearly singular at t = {t:.6g}: smallest/largest singular value "
            f"{ratio:.2g}; the loop reaches a dead-centre or locked configuration)")


#: A closed loop whose constraint Jacobian comes this close to losing rank (smallest over largest of its generic
#: rank's singular values, at an output row between two larger ones, relative to the largest such ratio of the run
#: so far: a mechanism's rows mix units, so its ratio is small or large by its scales alone) passed a change point
#: (PassageWatch).
PASSAGE = 0.02

#: The tolerance of PassageWatch's look inside an interval (scipy methods): it only places the ratio's minimum among
#: 64 points, and a Radau run integrated again through the flattened parallelogram at rtol 1e-10 took 13 s.
PROBE_RTOL = 1e-7


class PassageWatch:
    """Stops a closed-loop run with degrees of freedom where it passes near a configuration at which its constraint
    Jacobian loses rank: a local minimum below PASSAGE of the ratio of its smallest to its largest singular value
    (of the rank it has at the start: redundant rows apart). There the loop's branches of configurations cross (a
    parallelogram four-bar flattened: it and the antiparallelogram), and the index-1 equations do not tell them
    apart: a free parallelogram whirled through its flattened position went on as an antiparallelogram, its
    crank's rate jumping from 8.29 to -5.60 rad/s with energy kept (exit 0, no note). A fully driven loop (no
    degree of freedom) is not watched: its drives carry it on its branch.

    The ratio is read at the output rows. Where an interval may hide a passage (a ratio below 5 PASSAGE at an end
    or on the cubic path between its rows, or the loop's orientation, det(A R) for two fixed random R, reversed
    across it), it is read at 64 points of the interval that ``integrate(y, times)`` gives (the rows at those times
    from y at times[0]), and closer where it dips below 5 PASSAGE there. ``check`` is called with each solve's rows
    as they come, so the run stops at the first passage."""

    def __init__(self, c: Compiled, p: np.ndarray, t0: float, y0: np.ndarray,
                 integrate: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> None:
        self.c, self.p, self.integrate = c, p, integrate
        self.rank, self.last, self.best = 0, None, 0.0  # last: (t, y, ratio, signs) of the row checked last
        if not c.m:
            return
        with np.errstate(all="ignore"):
            A = c.A(t0, y0[:c.n], y0[c.n:], p)
        if not np.all(np.isfinite(A)):
            return
        sv = np.linalg.svd(A, compute_uv=False)
        rank = int(np.sum(sv > 1e-9 * max(float(sv[0]), 1e-300))) if sv.size else 0
        self.rank = rank if rank < c.n else 0
        rng = np.random.default_rng(7)
        self.probes = [rng.standard_normal((c.n, A.shape[0])) for _ in range(2)]

    def _measure(self, t: float, y: np.ndarray) -> tuple[float, np.ndarray]:
        """(the ratio relative to the largest met so far, the orientation signs) at one state."""
        ratio, signs = self._raw(t, y)
        self.best = max(self.best, ratio) if np.isfinite(ratio) else self.best
        return ratio / self.best if self.best > 0 else np.inf, signs

    def _raw(self, t: float, y: np.ndarray, orientation: bool = True) -> tuple[float, np.ndarray]:
        """(the ratio, the orientation signs: zeros unless asked for) at one state."""
        c, n = self.c, self.c.n
        with np.errstate(all="ignore"):
            A = c.A(float(t), y[:n], y[n:], self.p)
            if not np.all(np.isfinite(A)):
                return np.inf, np.zeros(2)
            sv = np.linalg.svd(A, compute_uv=False)
            signs = np.array([np.sign(np.linalg.det(A @ R)) if orientation and self.rank == A.shape[0] else 0.0
                              for R in self.probes])
        return (float(sv[self.rank - 1] / sv[0]) if sv[0] > 0 else np.inf), signs

    def check(self, t: np.ndarray, Y: np.ndarray) -> None:
        """AnalysisError at the first passage among the rows (t, Y), which follow the rows checked before."""
        if not self.rank:
            return
        rows = [self.last] if self.last is not None else []
        rows += [(float(ti), y, *self._measure(ti, y)) for ti, y in zip(t, Y)]
        for k in range(len(rows) - 1):
            (t0, y0, r0, s0), (t1, y1, r1, s1) = rows[k], rows[k + 1]
            if k + 2 < len(rows) and r1 < PASSAGE and r1 <= r0 and r1 <= rows[k + 2][2]:
                self._refuse(t1, r1)
            if min(r0, r1) < 5 * PASSAGE or bool(np.all(s0 * s1 < 0)) or self._dips(t0, y0, t1, y1, r0, r1):
                self._inside(t0, y0, t1)
        self.last = rows[-1]

    def _inside(self, t0: float, y0: np.ndarray, t1: float, depth: int = 0) -> None:
        """The ratio at 64 points of the integrated interval [t0, t1] from y0; its lowest local minimum is a passage
        below PASSAGE, or (below 5 PASSAGE) looked at closer, up to three times."""
        times = np.linspace(t0, t1, 65)
        rows = self.integrate(y0, times)
        inner = [self._measure(ti, y)[0] for ti, y in zip(times, rows)]
        low = [j for j in range(1, 64) if inner[j] <= inner[j - 1] and inner[j] <= inner[j + 1]]
        if not low:
            return
        j = min(low, key=lambda i: inner[i])
        if inner[j] < PASSAGE:
            self._refuse(float(times[j]), inner[j])
        if inner[j] < 5 * PASSAGE and depth < 3 and np.all(np.isfinite(rows[j - 1])):
            self._inside(float(times[j - 1]), rows[j - 1], float(times[j + 1]), depth + 1)

    def _dips(self, t0: float, y0: np.ndarray, t1: float, y1: np.ndarray, r0: float, r1: float) -> bool:
        """Whether the ratio dips below 5 PASSAGE along the cubic (Hermite) path through the two rows' positions and
        rates: a cheap look inside a coarse output interval (a whirled parallelogram crosses its flattened position
        between two rows 0.5 s apart), confirmed by integrating the interval. First at its middle: where the ratio
        there and at the rows (r0, r1, relative) stays above 6 PASSAGE and bends by less than a tenth of its size
        (a fine interval of a smooth motion: most intervals of Andrews' mechanism on its default grid), there is no
        dip; else at 16 points."""
        if self.best <= 0:
            return False
        middle = self._along(t0, y0, t1, y1, 0.5) / self.best
        if not np.isfinite(middle):
            return True
        low = min(r0, middle, r1)
        if low > 6 * PASSAGE and abs(r0 - 2 * middle + r1) < 0.1 * low:
            return False
        return any(self._along(t0, y0, t1, y1, s) < 5 * PASSAGE * self.best for s in np.linspace(0.0, 1.0, 18)[1:-1])

    def _along(self, t0: float, y0: np.ndarray, t1: float, y1: np.ndarray, s: float) -> float:
        """The (raw) ratio at the point s in [0, 1] of the cubic path between the two rows."""
        n, h = self.c.n, t1 - t0
        q0, v0, q1, v1 = y0[:n], y0[n:], y1[:n], y1[n:]
        h00, h10, h01, h11 = 2*s**3 - 3*s**2 + 1, s**3 - 2*s**2 + s, -2*s**3 + 3*s**2, s**3 - s**2
        q = h00 * q0 + h10 * h * v0 + h01 * q1 + h11 * h * v1
        return self._raw(t0 + s * h, np.concatenate([q, (1 - s) * v0 + s * v1]), orientation=False)[0]

    @staticmethod
    def _refuse(at: float, ratio: float) -> None:
        raise AnalysisError(
            f"the motion passed a singular configuration of its closed loop near t = {at:.6g} s (the constraint "
            f"Jacobian nearly lost rank: smallest/largest singular value {ratio:.2g}): a change point, where branches "
            "of the loop's configurations cross (a parallelogram four-bar flattened), and these equations do not "
            "tell them apart, so the motion after it may have gone on along another branch. Simulate up to it "
            "(--t-end), or drive a coordinate through it (a prescribed coordinate)")


def check_on_manifold(c: Compiled, p: np.ndarray, t: float, q: np.ndarray, u: np.ndarray) -> None:
    """AnalysisError (with the time, the residual, the tolerance and the likely reason) when a projected state is
    not on the constraints, instead of integrating on from a state that violates them."""
    if not c.m:
        return
    with np.errstate(all="ignore"):
        finite = np.all(np.isfinite(q)) and np.all(np.isfinite(u))
        res = max(float(np.max(np.abs(c.phi(t, q, u, p)), initial=0.0)),
                  float(np.max(np.abs(c.cv(t, q, u, p)), initial=0.0))) if finite else float("nan")
    tol = residual_tolerance(q, u) if finite else RESIDUAL_TOLERANCE
    if np.isfinite(res) and res <= tol:
        return
    if not np.isfinite(res):
        raise AnalysisError(f"the state or its constraint residual is not finite at t = {t:.6g} s: the motion "
                            "left the constraint manifold (a singular configuration of the constraints?)")
    with np.errstate(all="ignore"):
        A = c.A(t, q, u, p)
        rank = int(np.linalg.matrix_rank(A)) if np.all(np.isfinite(A)) else -1
    why = (f"the constraint Jacobian is rank deficient there (rank {rank} of {A.shape[0]} rows): conflicting or "
           "redundant constraints or drives, or a singular (dead-centre, locked) configuration"
           if 0 <= rank < A.shape[0] else "no nearby state satisfies the constraints")
    when = "the initial state cannot be assembled onto the constraints" if t == 0.0 else \
        "the motion left the constraint manifold"
    raise AnalysisError(f"the constraint residual reached {res:.3g} at t = {t:.6g} s (tolerance {tol:.3g}): {when} "
                        f"(projection did not converge: {why})")


def _event_functions(model: MechanicalModel, c: Compiled, p: np.ndarray) -> list:
    """scipy event callables g(t, y) for the file's events; direction and terminal set from the YAML.
    The collide issue plugs impacts in here: an action other than record/stop can re-initialize the state."""
    n = c.n
    fns = []
    for k, (_name, _expr, direction, action) in enumerate(model.events):
        def g(t, y, k=k):
            return float(c.events(t, y[:n], y[n:], p)[k, 0])
        g.direction = {"rising": 1.0, "falling": -1.0, "both": 0.0}[direction]
        g.terminal = action == "stop"
        g.start_counts = False  # a run that starts on the surface has not crossed it: no event at t = 0
        fns.append(g)
    return fns


def spectrum(rhs: RightHandSide, t0: float, y0: np.ndarray) -> np.ndarray:
    """The eigenvalues of the RHS Jacobian at the start, by finite differences (a heuristic's input)."""
    n = len(y0)
    f0 = rhs(t0, y0)
    J = np.zeros((n, n))
    for k in range(n):
        h = 1e-7 * max(1.0, abs(y0[k]))
        y = y0.copy()
        y[k] += h
        J[:, k] = (rhs(t0, y) - f0) / h
    return np.linalg.eigvals(J)


def stiffness(rhs: RightHandSide, t0: float, y0: np.ndarray, t_end: float) -> tuple[float, float]:
    """(spectral radius of the RHS Jacobian, stiffness ratio) at the start, by finite differences; a heuristic
    for choosing an implicit method, never used for results."""
    ev = spectrum(rhs, t0, y0)
    # stiffness is fast *decay*: lightly damped oscillations (large imaginary parts) must be resolved by any
    # method, so only the real parts call for an implicit integrator
    radius = float(np.max(np.abs(ev.real))) if ev.size else 0.0
    return radius, radius * (t_end - t0)


#: a right-hand side evaluated from Python (scipy, CVODE) costs about this many of the compiled loop's (measured
#: 67 us against 0.26 us on a chain of six masses; taken low, so the choice leans to the implicit methods)
PYTHON_COST = 100.0
EXPLICIT_STABILITY = 3.8  # DOP853's steps cover about this many units of (decay rate x time) at its stability edge


def explicit_is_cheaper(ev: np.ndarray, horizon: float, rtol: float) -> tuple[bool, float]:
    """Whether the compiled explicit loop should beat an implicit method (CVODE at rtol/100) on a stiff scene, and
    the lasting oscillation it rests on: oscillations that last over the run (decay rate x horizon below 20) must
    be followed by any method, BDF at about rtol^(-1/6) steps per radian (a two-minute CVODE run of a chain whose
    springs go from 1 to 1e8, against 2.4 s compiled), the explicit loop at rtol^(-1/8), or at its stability edge.
    The compiled loop takes 12 evaluations a step, CVODE about 5 Python ones."""
    radius = float(np.max(np.abs(ev.real))) if ev.size else 0.0
    lasting = ev[np.abs(ev.real) * horizon < 20]
    fastest = float(np.max(np.abs(lasting.imag))) if lasting.size else 0.0
    radians = fastest * horizon
    implicit = max(500.0, radians * (rtol / CVODE_TIGHTENING) ** (-1 / 6))
    explicit = max(radius * horizon / EXPLICIT_STABILITY, radians * rtol ** (-1 / 8))
    return 12 * explicit <= 5 * PYTHON_COST * implicit, fastest


def choose_method(rhs: RightHandSide, t0: float, y0: np.ndarray, t_end: float,
                  native_ok: bool = False, cvode_ok: Callable[[], bool] = lambda: False,
                  rtol: float = 1e-10) -> tuple[str, str]:
    """auto's choice; ``cvode_ok()`` is asked only for a stiff scene (importing scikit-sundae costs ~0.4 s)."""
    ev = spectrum(rhs, t0, y0)
    radius = float(np.max(np.abs(ev.real))) if ev.size else 0.0
    if radius * (t_end - t0) > 5e4:
        why = f"stiff: fastest decay rate {radius:.3g} 1/s over {t_end - t0:g} s"
        cheaper, fastest = explicit_is_cheaper(ev, t_end - t0, rtol)
        if native_ok and cheaper:
            return "native", (why + f", but oscillations up to {fastest:.3g} rad/s last through the run and any method "
                              "must follow them: the compiled explicit loop is cheaper than an implicit one")
        return ("CVODE", why + f"; SUNDIALS BDF at rtol/{CVODE_TIGHTENING:g}") if cvode_ok() else ("Radau", why)
    return ("native" if native_ok else "DOP853"), f"non-stiff: fastest decay rate {radius:.3g} 1/s"


def cvode_usable(c: Compiled, required: bool) -> bool:
    """SUNDIALS CVODE (scikit-sundae) for this scene: installed, and no contacts (the impact loop uses scipy)."""
    from mechsys.analysis.motion import sundials

    why = None
    if not sundials.available():
        why = "scikit-sundae is not installed (pip install mechsys[sundials])"
    elif c.gap_names:
        why = "contacts need scipy's event loop"
    if why is not None and required:
        raise AnalysisError(f"--method CVODE: {why}; use Radau")
    return why is None


def ivp_solver(chosen: str) -> Callable[..., OptimizeResult | SundialsResult]:
    """solve_ivp, or CVODE behind the same call signature (the subset simulate uses)."""
    if chosen != "CVODE":
        from mechsys.analysis.motion.events import solve_ivp  # events located inside steps, not only at step ends

        return solve_ivp
    from mechsys.analysis.motion import sundials

    def cvode(fun, t_span, y0, method=None, rtol=1e-10, atol=1e-12, t_eval=None, events=None):
        return sundials.integrate(fun, t_span, y0, t_eval=t_eval, rtol=rtol, atol=atol, events=events)
    return cvode


def native_integrator(model: MechanicalModel, c: Compiled, required: bool) -> NativeIntegrator | None:
    """The compiled DOP853 loop when this scene can use it (no contacts or events) and a C compiler is available;
    with ``required`` (--method native) a reason is raised instead of returning None."""
    from mechsys.numeric import native

    why, conflict = None, True  # conflict: the option does not fit the model (an input error, exit 2)
    if c.gap_names:
        why = "contacts need the impact event loop"
    elif model.events:
        why = "events need scipy's event location"
    elif native.compiler() is None:
        why, conflict = "no C compiler is available (set CC) or MECHSYS_NATIVE=off", False
    if why is not None:
        native.abandon(model)
        if required:
            raise (InputError if conflict else AnalysisError)(f"--method native: {why}; use DOP853")
        return None
    if getattr(c, "native", None) is None:  # kept with the compiled code, which with_overrides clones share
        c.native = native.load(model)
    else:
        native.abandon(model)  # a clone's own build, started before its compiled code was found shared
    return c.native


def native_projected(nat: NativeIntegrator, c: Compiled, p: np.ndarray, grid: np.ndarray, y0: np.ndarray, rtol: float,
                     atol: float, progress: Callable[[float], None] | None, max_steps: float) -> tuple:
    """Closed loops and drives on the compiled loop: native solves with dense output between projections onto the
    constraints. A solve spans as many output intervals as about PROJECTION_STEPS steps of the size reached cover
    (at least one), so the step is set by the tolerance, not by the output grid (one solve per output interval
    took a step per output: 2,500 steps for the indicator at --dt 0.01 instead of 650); the outputs inside a solve
    are its dense output, each projected onto the constraints, the last one is projected too, and the next solve
    continues with the step size reached. A solve whose dense outputs leave the constraints by more than its own
    error allows (``inner_rows``) is repeated over half the steps (down to one output interval, projected at its
    end). Returns (Y, RHS calls, steps), or (None, calls, t) when the augmented matrix is singular at t."""
    n = c.n
    ys, calls, steps = [y0], 0, 0
    y, h = y0, 0.0

    def integrate(y: np.ndarray, times: np.ndarray) -> np.ndarray:
        run = nat.run(p, y, times, rtol, atol, max_steps=max_steps)
        return run.y if not run.status and len(run.y) == len(times) else np.full((len(times), len(y)), np.nan)

    watch = PassageWatch(c, p, float(grid[0]), y0, integrate)
    watch.check(grid[:1], y0[None, :])
    k, last = 0, len(grid) - 1
    # steps per solve: halved (for the rest of the run) when the constraints drift beyond the tolerance inside a
    # solve; at 0 a solve spans one output interval
    reach = PROJECTION_STEPS
    while k < last:
        j = segment_end(grid, k, reach, h)
        run = nat.run(p, y, grid[k:j + 1], rtol, atol, max_steps=max_steps - steps, h0=h)
        calls += run.nfev
        steps += run.nsteps
        if run.status == -2:
            return None, calls, run.t_reached
        if run.status:
            raise AnalysisError(f"integration failed at t = {run.t_reached:.6g}: {run.message}"
                                f"{singularity_note(c, p, float(grid[k]), y)}")
        inner = inner_rows(c, p, grid[k + 1:j], run.y[1:-1], rtol, atol)
        if inner is None:
            reach //= 2  # the dense outputs drifted off the constraints: solve again, shorter
            continue
        h = run.h_next  # the next solve continues with the step size reached (no new initial-step search)
        q, u = project(c, p, float(grid[j]), run.y[-1, :n], run.y[-1, n:])
        check_on_manifold(c, p, float(grid[j]), q, u)
        y = np.concatenate([q, u])
        ys += list(inner) + [y]
        watch.check(grid[k + 1:j + 1], np.array(list(inner) + [y]))
        if progress is not None:
            progress(float(grid[j]))
        k = j
    return np.array(ys), calls, steps


def segment_end(grid: np.ndarray, k: int, reach: int, h: float) -> int:
    """The index of the output point where a projected solve from grid[k] ends: the last one within ``reach``
    steps of size h, at least the next one."""
    last = len(grid) - 1
    return max(k + 1, min(last, int(np.searchsorted(grid, grid[k] + reach * h, side="right")) - 1))


def inner_rows(c: Compiled, p: np.ndarray, t: np.ndarray, Y: np.ndarray, rtol: float, atol: float) -> np.ndarray | None:
    """The output rows inside a projected solve (its dense output), each projected onto the constraints; None when
    they left the constraints by more than the integration's own error over the solve allows
    (PROJECTION_STEPS x max(rtol, atol) x (1 + max |y|)): the caller then solves again over fewer steps."""
    if len(t) == 0:
        return Y
    n = c.n
    tol = PROJECTION_STEPS * max(rtol, atol) * (1.0 + float(np.max(np.abs(Y))))
    if float(np.max(constraint_residual(c, p, t, Y[:, :n], Y[:, n:]))) > tol:
        return None
    return np.array([np.concatenate(project(c, p, float(ti), y[:n], y[n:])) for ti, y in zip(t, Y)])


def output_grid(t_end: float, dt: float | None) -> np.ndarray:
    """Output times 0, dt, 2 dt, ..., t_end (default dt = t_end/1000). When t_end is not a whole number of dt
    (beyond rounding) the last interval is the shorter remainder, so the run still ends at t_end (it ended at the
    last whole multiple: --t-end 1 --dt 0.3 stopped at 0.9 and reported that state as the final one)."""
    dt = dt or t_end / 1000
    ratio = t_end / dt
    k = round(ratio)
    if abs(ratio - k) <= 1e-9 * max(1.0, ratio):
        grid = np.arange(0.0, t_end + 0.5 * dt, dt)
        grid[-1] = min(grid[-1], t_end)
        return grid
    return np.append(np.arange(math.floor(ratio) + 1) * dt, t_end)


def constraint_residual(c: Compiled, p: np.ndarray, grid: np.ndarray, q: np.ndarray, u: np.ndarray) -> np.ndarray:
    """At each output: the larger of max |Phi| (positions) and max |A q' + a_t| (velocities: the only residual of
    rolling constraints); zeros without constraints."""
    if not c.m:
        return np.zeros(len(grid))
    return np.array([max(np.max(np.abs(c.phi(t, qi, ui, p)), initial=0.0), np.max(np.abs(c.cv(t, qi, ui, p))))
                     for t, qi, ui in zip(grid, q, u)])


def _frictionless_rest(model: MechanicalModel, c: Compiled, p: np.ndarray, rested: set[int]) -> list[str]:
    """A warning naming the contacts with friction that came to rest: a resting contact carries no friction force
    (docs/collide.md), so a block the file gives mu = 0.5 on a 20 degree incline slid at g sin(alpha) with nothing
    said."""
    import sympy as sp

    gap_contacts = [entry for entry in model.kin.contacts if entry["gap"] is not None]
    values = dict(zip(model.parameter_symbols, (float(x) for x in p)))
    names = []
    for k in sorted(rested):
        mu = float(sp.sympify(gap_contacts[k].get("friction") or 0).xreplace(values))
        if mu != 0:
            names.append(f"'{c.gap_names[k]}' (friction {mu:g})")
    if not names:
        return []
    return [f"contact {', '.join(names)} came to rest: a resting contact carries no friction force in simulate "
            f"(friction acts in the impulses only, docs/collide.md), so the bodies slide freely along it"]


def _refuse_singular_chart(c: Compiled, q: np.ndarray) -> None:
    """An error when the start is at a gimbal lock of a rotation chart. The runs that can re-chart start in another
    sequence (charted.py) and never get here at a lock; without constraints the singular mass matrix stops the
    others at the first step, but with them (rolling, closed loops) the augmented system is only nearly singular,
    and a ball started at its zyx lock ground on for seconds before failing with another reason."""
    from mechsys.numeric.rotations import singular_chart

    chart = singular_chart(c.charts, q)
    if chart:
        raise AnalysisError(f"the start is at a {chart}; start away from it or write the joint with another sequence "
                            "(zyx is singular where the middle angle is +-pi/2, zxz where it is 0 or pi)")


def _start(model: MechanicalModel, c: Compiled, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The consistent initial state and what the summary should say about it (assembly, conditioning)."""
    guess_q, guess_u = file_state(model)
    start = assemble_start(model, c, p)
    q0, u0 = start.q, start.u
    try:
        check_on_manifold(c, p, 0.0, q0, u0)
    except AnalysisError as exc:
        if not start.dropped:
            raise
        raise AnalysisError(f"{', '.join(start.dropped)} as set: no path from the file's values of the other "
                            "coordinates reaches a state on the constraints with it, nor does their projection; "
                            "write guesses of the others near such a state in the file (values set are held), "
                            "or check the value; "
                            f"{exc}") from None
    _refuse_singular_chart(c, q0)
    warnings = []
    moved = [f"{name} = {qa:.10g} (guess {qg:.10g})" for name, qa, qg in zip(model.coordinates, q0, guess_q)
             if abs(qa - qg) > 1e-9 * (1 + abs(qg))]
    moved += [f"der({name}) = {ua:.10g} (given {ug:.10g})" for name, ua, ug in zip(model.coordinates, u0, guess_u)
              if abs(ua - ug) > 1e-9 * (1 + abs(ug))]
    if moved:
        how = (f"carried to {', '.join(start.held)} as set along a path from the file's values" if start.held else
               "by Newton from the file's values (the branch nearest them)")
        warnings.append(f"initial state assembled onto the constraints {how}: " + ", ".join(moved))
    if start.dropped:
        warnings.append(f"{', '.join(start.dropped)} as set cannot be held on the constraints (no path from the "
                        "file's values reaches it, nor the projection's branch, or the rates set conflict): moved as "
                        "above")
    with np.errstate(all="ignore"):
        M0, f0 = c.eqs.evaluate(0.0, q0, u0, p)
    if not (np.all(np.isfinite(M0)) and np.all(np.isfinite(f0))):
        raise AnalysisError("the mass matrix or the forces are not finite at t = 0 (an overflow or a division by "
                            "zero: check the parameter values, e.g. a mass of 1e200 squared)")
    cond = _motion_condition(c, p, q0, u0, M0)
    if _massless_driven(c, p, q0, u0, M0, np.ravel(f0)):
        raise AnalysisError("the mass matrix is singular at t = 0 on the motions the constraints allow: a force "
                            "drives one that carries no mass or inertia (a massless link that a torque turns while "
                            "the constraints let it), so the equations do not determine it; give it mass or inertia, "
                            "or make it prescribed")
    if cond > 1e8:
        warnings.append(f"the mass matrix is badly conditioned (cond = {cond:.2e}): results may lose accuracy")
    return q0, u0, warnings


def _multipliers(rhs: RightHandSide, grid: np.ndarray, q: np.ndarray, u: np.ndarray, active: list[tuple] | None,
                 m: int) -> np.ndarray:
    """The multipliers of the model's m constraint rows at each output row. With contacts, each row's with the
    contacts persistent at it: a ball riding a driven table loads the drive only while it rests on it, and the
    drive's force and work were computed without the contact (the energy balance error read 0.4)."""
    if active is None:
        return np.array([rhs.accelerations(t, qi, ui)[1][:m] for t, qi, ui in zip(grid, q, u)])
    saved = list(rhs.persistent)
    out = []
    try:
        for t, qi, ui, rows in zip(grid, q, u, active):
            rhs.persistent[:] = list(rows)
            out.append(rhs.accelerations(t, qi, ui)[1][:m])
    finally:
        rhs.persistent[:] = saved
    return np.array(out)


def _motion_condition(c: Compiled, p: np.ndarray, q: np.ndarray, u: np.ndarray, M: np.ndarray) -> float:
    """The condition number of M on the motions the constraints allow (N^T M N, N a basis of A's null space): a
    prescribed coordinate of a massless body is a zero row of M that its drive row holds, and a ball on a massless
    turntable was warned 'badly conditioned (cond = inf)' at cond 250."""
    import scipy.linalg as sla

    if not M.size:
        return 1.0
    scale = float(np.linalg.norm(M, 2))
    if c.m:
        with np.errstate(all="ignore"):
            A = c.A(0.0, q, u, p)
        if np.all(np.isfinite(A)):
            N = sla.null_space(A)
            M = N.T @ M @ N
    if not M.size:
        return 1.0
    return float(np.linalg.cond(M))


def _massless_driven(c: Compiled, p: np.ndarray, q: np.ndarray, u: np.ndarray, M: np.ndarray, f: np.ndarray) -> bool:
    """Whether a motion the constraints allow carries no mass or inertia (on N^T M N, N a basis of A's null space,
    against the whole M's size) while a force drives it (f along it): the equations then do not determine it. A
    massless hub turned by a torque, its wheel's absolute angle locked, stayed at rest (0/0). A massless motion that
    no force drives (a rod's spin about its own axis in an RSSR linkage) is left to the least-squares solve."""
    import scipy.linalg as sla

    if not c.m or not M.size:
        return False
    with np.errstate(all="ignore"):
        A = c.A(0.0, q, u, p)
    if not np.all(np.isfinite(A)):
        return False
    N = sla.null_space(A)
    if not N.size:
        return False
    w, V = np.linalg.eigh(N.T @ ((M + M.T) / 2) @ N)
    scale = float(np.linalg.norm(M, 2))
    free = N @ V[:, w <= 1e-13 * scale]  # massless allowed motions (unit columns)
    return bool(free.size and np.max(np.abs(free.T @ f)) > 1e-9 * max(float(np.linalg.norm(f)), 1e-300))


def _closed_loop_scipy(job: Integration, y0: np.ndarray) -> tuple:
    """Closed loops on scipy or CVODE: projected solves as in ``native_projected`` (each spans about
    PROJECTION_STEPS steps of the size reached, ends on an output point where the state is projected onto the
    constraints, starts with the step size reached; shortened when its dense outputs drift off the constraints).
    One solve per output interval restarted the method at every output. A stopping event ends the rows with the
    projected state at the event."""
    rhs, c, p, grid, method, rtol, atol = job.rhs, job.c, job.p, job.grid, job.method, job.rtol, job.atol
    solve_ivp = ivp_solver(method)
    n = c.n
    ys, times, steps, y = [y0], [0.0], 0, y0
    k, last, h, reach = 0, len(grid) - 1, 0.0, PROJECTION_STEPS

    def integrate(y: np.ndarray, at: np.ndarray) -> np.ndarray:
        calls = rhs.calls  # (the check's evaluations are not the integration's work)
        sol = solve_ivp(rhs, (float(at[0]), float(at[-1])), y, method=method, rtol=max(rtol, PROBE_RTOL),
                        atol=max(atol, PROBE_RTOL * 1e-3), t_eval=at)
        rhs.calls = calls
        return sol.y.T if sol.success and sol.y.shape[1] == len(at) else np.full((len(at), len(y)), np.nan)

    watch = PassageWatch(c, p, 0.0, y0, integrate)
    watch.check(np.zeros(1), y0[None, :])
    while k < last:
        j = segment_end(grid, k, reach, h)
        first = {"first_step": min(h, float(grid[j] - grid[k]))} if h > 0.0 and method != "CVODE" else {}
        sol = solve_ivp(rhs, (float(grid[k]), float(grid[j])), y, method=method, rtol=rtol, atol=atol,
                        t_eval=grid[k + 1:j + 1], events=job.event_fns or None, **first)
        if not sol.success:
            t_fail, y_fail = getattr(sol, "t_reached", None), getattr(sol, "y_reached", None)
            if t_fail is None:  # CVODE on a grid: its last output
                t_fail, y_fail = (sol.t[-1], sol.y[:, -1]) if len(sol.t) else (grid[k], y)
            raise AnalysisError(f"integration failed at t = {t_fail:.6g}: {sol.message}"
                                f"{singularity_note(c, p, float(t_fail), y_fail)}")
        stopped = sol.status == 1
        inner = sol.t < grid[j] if not stopped else np.ones(len(sol.t), dtype=bool)
        rows = inner_rows(c, p, sol.t[inner], sol.y[:, inner].T, rtol, atol)
        if rows is None and reach:
            reach //= 2  # the dense outputs drifted off the constraints: solve again, shorter
            continue
        nsteps = getattr(sol, "nsteps", None) or max(1, int(sol.nfev))  # CVODE on a grid: evaluations bound steps
        steps += nsteps
        h = getattr(sol, "h_next", None) or (float(grid[j] - grid[k]) / nsteps)
        ys += list(sol.y[:, inner].T if rows is None else rows)
        times += list(sol.t[inner])
        first = len(ys) - int(np.sum(inner))
        if stopped:
            t_stop, y_stop = max(((float(ts[-1]), ye[-1]) for ts, ye in zip(sol.t_events, sol.y_events) if len(ts)),
                                 key=lambda ev: ev[0])  # the stopping event is the last one the solve recorded
        else:
            t_stop, y_stop = float(grid[j]), sol.y[:, -1]
        q, u = project(c, p, t_stop, y_stop[:n], y_stop[n:])
        check_on_manifold(c, p, t_stop, q, u)
        y = np.concatenate([q, u])
        ys.append(y)
        times.append(t_stop)
        watch.check(np.array(times[first:]), np.array(ys[first:]))
        if job.note_events(sol) and stopped:
            break
        k = j
    return np.array(times), np.array(ys), steps


def _plain_scipy(job: Integration, y0: np.ndarray) -> tuple:
    """No constraints: one solve_ivp (or CVODE) call over the output grid; a stopping event ends the rows.
    scipy runs with dense output (the same per-step interpolants t_eval would use) so its steps can be counted."""
    rhs, grid, method, rtol, atol, event_fns = job.rhs, job.grid, job.method, job.rtol, job.atol, job.event_fns
    if method == "CVODE":
        sol = ivp_solver(method)(rhs, (0.0, float(grid[-1])), y0, t_eval=grid, rtol=rtol, atol=atol,
                                 events=event_fns or None)
        Y, steps = sol.y.T, sol.nsteps
    else:
        sol = ivp_solver(method)(rhs, (0.0, float(grid[-1])), y0, method=method, rtol=rtol, atol=atol,
                                 events=event_fns or None, dense_output=True)
        Y, steps = None, len(sol.t) - 1
    if not sol.success:
        raise AnalysisError(f"integration failed at t = {sol.t[-1]:.6g}: {sol.message}")
    if Y is None:
        grid = grid[grid <= sol.t[-1]]
        Y = sol.sol(grid).T
    else:
        grid = sol.t
    if job.note_events(sol) and sol.y_events is not None:
        # a stopping event: the last output row is the state at the event
        k, t_stop = min(((k, ts[-1]) for k, ts in enumerate(sol.t_events)
                         if len(ts) and job.model.events[k][3] == "stop"), key=lambda kv: kv[1])
        Y = np.vstack([Y[grid < t_stop], sol.y_events[k][-1]])
        grid = np.append(grid[grid < t_stop], t_stop)
    return grid, Y, steps


def simulate(model: MechanicalModel, t_end: float, dt: float | None = None, method: str = "auto",
             rtol: float = 1e-10, atol: float = 1e-12, overrides_p: np.ndarray | None = None,
             capture_velocity: float = 1e-10, progress: Callable[[float], None] | None = None,
             max_steps: float = 1e6) -> SimulationResult:
    """Integrate from the file's initial state to t_end; outputs every dt (default t_end/1000): ``integrate`` with
    the options by name (SimulationOptions tells what each does)."""
    return integrate(model, SimulationOptions(t_end, dt, method, rtol, atol, capture_velocity, max_steps),
                     overrides_p, progress)


def integrate(model: MechanicalModel, options: SimulationOptions, overrides_p: np.ndarray | None = None,
              progress: Callable[[float], None] | None = None) -> SimulationResult:
    """The run ``options`` describe, from the file's initial state, at the parameter vector ``overrides_p`` (None:
    the file's). ``progress(t)`` is called now and then with the time reached (for a progress bar). The work bound
    makes a chattering discontinuous law fail with a reason instead of running for hours."""
    t_end, dt, method, rtol, atol = options.t_end, options.dt, options.method, options.rtol, options.atol
    capture_velocity, max_steps = options.capture_velocity, options.max_steps
    if method not in METHODS:
        raise InputError(f"--method: unknown method {method!r}; use one of {', '.join(METHODS)}")
    if t_end <= 0:
        raise InputError("--t-end must be positive")
    from mechsys.numeric.parameters import parameter_values

    timings = {}
    t0 = time.perf_counter()
    if method in ("auto", "native") and getattr(model, "_simulation_compiled", None) is None \
            and not model.events and not any(c["gap"] is not None for c in model.kin.contacts):
        from mechsys.numeric import native

        native.start(model)  # the integrator compiles (its own process) while compile_model generates Python
    try:
        c = compile_model(model)
        timings["derive + compile" if not getattr(c, "cache_hit", False) else "load compiled code (cached)"] = \
            time.perf_counter() - t0
        p = parameter_values(model) if overrides_p is None else overrides_p
        q0, u0, warnings = _start(model, c, p)
        from mechsys.analysis.motion.jumps import refuse_jumps  # sympy: not on the warm path's imports

        refuse_jumps(model, p, q0, t_end)
        unwatched = [entry["name"] for entry in model.kin.contacts if entry["gap"] is None]
        if unwatched:
            warnings.append(f"contact {', '.join(repr(n) for n in unwatched)} (between two points, without a gap) is "
                            "not watched in simulate: the bodies pass through each other; `mechsys collide` resolves "
                            "it at a given state, and a gap or a gap primitive (point_plane, sphere_sphere, ...) makes "
                            "it an event")
    except BaseException:
        from mechsys.numeric import native

        native.abandon(model)  # the build started above, which nothing will take now
        raise
    y0 = np.concatenate([q0, u0])
    rhs = RightHandSide(c, p, progress, EVALUATIONS_PER_STEP * max_steps)
    rhs.horizon = float(t_end)
    chosen = method
    t1 = time.perf_counter()
    nat = native_integrator(model, c, required=method == "native") if method in ("auto", "native") else None
    if nat is not None and not nat.from_cache:
        timings["compile native"] = time.perf_counter() - t1
    if method == "auto":
        chosen, why = choose_method(rhs, 0.0, y0, t_end, native_ok=nat is not None,
                                    cvode_ok=lambda: cvode_usable(c, False), rtol=rtol)
        warnings.append(f"auto method: {chosen} ({why})")
        if chosen == "CVODE":
            rtol, atol = rtol / CVODE_TIGHTENING, atol / CVODE_TIGHTENING
    elif method == "CVODE":
        cvode_usable(c, True)
    rhs.method = chosen
    grid = output_grid(t_end, dt)
    t1 = time.perf_counter()
    n = c.n
    event_fns = _event_functions(model, c, p)
    recorded: list[dict] = []
    impacts: list[dict] = []

    def note_events(sol) -> bool:
        """Record the crossings of this solve; True when a stopping event fired."""
        stop = False
        for k, (times, states) in enumerate(zip(sol.t_events or [], sol.y_events or [])):
            for t_ev, y_ev in zip(times, states):
                name, _expr, _direction, action = model.events[k]
                if any(ev["event"] == name and abs(ev["t"] - t_ev) <= 1e-12 * max(1.0, abs(t_ev))
                       for ev in recorded[-len(model.events):]):
                    continue  # a crossing at an output time, seen again at the start of the next interval
                recorded.append({"t": float(t_ev), "event": name, "action": action,
                                 "state": {**{cn: float(v) for cn, v in zip(model.coordinates, y_ev[:n])},
                                           **{f"der({cn})": float(v) for cn, v in zip(model.coordinates, y_ev[n:])}}})
                stop = stop or action == "stop"
        return stop

    Y = None
    if chosen == "native" and c.m:
        Y, calls, steps = native_projected(nat, c, p, grid, y0, rtol, atol, progress, max_steps)
        rhs.calls += calls
        if Y is None:  # a singular [[M, A^T], [A, 0]]: redundant constraints need the least-squares solve
            if method == "native":
                raise AnalysisError(f"integration failed at t = {steps:.6g}: the constraint Jacobian is rank "
                                    "deficient (redundant constraints?); --method DOP853 solves it by least squares")
            warnings.append(f"native: [[M, A^T], [A, 0]] is singular at t = {steps:.6g} (redundant constraints?); "
                            "continuing with DOP853 and least squares")
            chosen = "DOP853"
    elif chosen == "native":
        run = nat.run(p, y0, grid, rtol, atol, progress, max_steps=max_steps)
        if run.status:
            raise AnalysisError(f"integration failed at t = {run.t_reached:.6g}: {run.message}")
        rhs.calls += run.nfev
        Y, steps = run.y, run.nsteps
    job = Integration(model, c, rhs, p, grid, chosen, rtol, atol, event_fns, note_events)
    active = None  # with contacts: the persistent contacts at each output row
    if Y is not None:
        grid = grid[:len(Y)]
    elif c.gap_names:
        from mechsys.analysis.impact.impacts import integrate_with_impacts

        grid, Y, steps, impacts, _stopped, active = integrate_with_impacts(job, y0, capture_velocity)
        warnings += _frictionless_rest(model, c, p, rhs.rested)
    elif c.m:
        grid, Y, steps = _closed_loop_scipy(job, y0)
    else:
        grid, Y, steps = _plain_scipy(job, y0)
    timings["integrate"] = time.perf_counter() - t1
    q, u = Y[:, :n], Y[:, n:]
    T = np.array([c.T(t, qi, ui, p)[0, 0] for t, qi, ui in zip(grid, q, u)])
    V = np.array([c.V(t, qi, ui, p)[0, 0] for t, qi, ui in zip(grid, q, u)])
    res = constraint_residual(c, p, grid, q, u)
    driving = {}
    rows = [k for k, con in enumerate(model.kin.constraints) if con.name.startswith("drive(")]
    lams = None
    if rows or (active is not None and c.rheonomic_rows and c.m):
        lams = _multipliers(rhs, grid, q, u, active, c.m)
        for k in rows:
            driving[model.kin.constraints[k].name[6:-1]] = lams[:, k]
    work = nonconservative_work(c, p, grid, q, u, lams)
    recorded.sort(key=lambda ev: ev["t"])
    out = SimulationResult(list(model.coordinates), grid, q, u, T, V, res, chosen, rhs.calls, steps, timings,
                           warnings, driving, recorded)
    out.impacts = impacts
    out.work = work
    return out
