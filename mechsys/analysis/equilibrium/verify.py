"""Stability verdicts checked by simulation: small perturbations of each equilibrium integrated and compared."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mechsys.analysis.equilibrium.equilibria import EquilibriaResult, Equilibrium, EquilibriumProblem
from mechsys.numeric.parameters import parameter_values
from mechsys.analysis.equilibrium.linearize import state_at
from mechsys.analysis.motion.simulate import compile_model, simulate
from mechsys.analysis.equilibrium.stability import ZERO_RE, reduced_pencil
from mechsys.errors import AnalysisError, InputError
from mechsys.mechanics.model import MechanicalModel

#: A run "grows" when its deviation reaches GROWTH times the initial deviation at any time ...
GROWTH = 100.0
#: ... or when the envelope over the last window is TREND times the envelope over the first one (slow growth).
TREND = 10.0
#: A run "decays" when the envelope over the last window is at most DECAY times the one over the first window.
DECAY = 0.5
#: Horizon with a growing linearization: the fastest growth amplifies a perturbation e^GROWTH_EFOLDS = 1e4 times.
GROWTH_EFOLDS = math.log(1e4)
#: Otherwise: PERIODS periods of the slowest oscillation and DECAY_TIMES time constants of the slowest decay.
PERIODS = 5.0
DECAY_TIMES = 5.0
#: Bounds of the horizon: at most MAX_CYCLES periods of the fastest oscillation and MAX_SPAN time constants of the
#: fastest eigenvalue (cost), at least MIN_SPAN time constants of the fastest eigenvalue.
MAX_CYCLES = 2000.0
MAX_SPAN = 1e7
MIN_SPAN = 10.0
#: Horizon when no eigenvalue is nonzero (model time units).
DEFAULT_HORIZON = 10.0
#: Output samples: SAMPLES_PER_PERIOD per period of the fastest oscillation, within [MIN_SAMPLES, MAX_SAMPLES].
SAMPLES_PER_PERIOD = 20
MIN_SAMPLES, MAX_SAMPLES, PLAIN_SAMPLES = 200, 20000, 1000
#: Eigenvalues with |Im| (or |lambda|) below TINY * max(1, max |lambda|) are not oscillations (or not time scales):
#: a numerically split zero eigenvalue would otherwise ask for a period of 1e8 s.
TINY = 1e-6


@dataclass
class VerifyOptions:
    """Knobs of the verification (defaults documented in docs/equilibria.md, --verify)."""

    perturbations: int = 4  # runs per equilibrium
    size: float = 1e-4  # initial deviation in the scaled norm (angles in rad, other coordinates relative)
    horizon_factor: float = 1.0  # multiplies the horizon derived from the eigenvalues (then clamped)
    seed: int = 0  # the perturbation directions are drawn from numpy's default_rng(seed)
    rtol: float = 1e-10
    atol: float = 1e-12
    method: str = "auto"  # the simulate method (auto: the compiled DOP853 loop, or an implicit one when stiff)

    def __post_init__(self) -> None:
        if self.perturbations < 1:
            raise InputError("verify: the number of perturbations must be at least 1")
        if not (0 < self.size < 1 and math.isfinite(self.size)):
            raise InputError("verify: the perturbation size must be in (0, 1)")
        if not (self.horizon_factor > 0 and math.isfinite(self.horizon_factor)):
            raise InputError("verify: the horizon factor must be positive")


@dataclass
class Run:
    """One perturbed motion: its ratios of deviation to the initial deviation."""

    observed: str  # "grows", "decays" or "bounded"
    peak: float  # max over time
    final: float  # max over the last window
    trend: float  # max over the last window / max over the first window


@dataclass
class Horizon:
    """How long the runs last, and why."""

    seconds: float  # the integration time used
    needed: float  # what the eigenvalues ask for (times horizon_factor), before the bounds
    window: float  # length of the first and last windows compared
    samples: int

    @property
    def clamped(self) -> bool:
        return self.seconds < self.needed * (1 - 1e-12)


@dataclass
class Verification:
    """The motion from small perturbations of one equilibrium, and whether it agrees with the verdict."""

    stability: str  # the verdict checked
    agrees: bool | None  # None: the verdict is undecided, or the runs cannot decide (note says why)
    observed: str  # "grows", "decays", "bounded", or "failed"/"not run"
    growth: float  # largest deviation at the end of a run, relative to its initial deviation
    peak: float  # largest deviation at any time of any run, relative to its initial deviation
    horizon: float  # integration time [model time units]
    size: float  # initial deviation (scaled norm)
    runs: list[Run] = field(default_factory=list)
    method: str = ""
    note: str = ""
    clamped: bool = False

    def summary(self) -> str:
        """e.g. 'grows (peak x1.2e+04 in 1.3 s)' or 'decays (x0.0031 after 264 s)'."""
        if self.observed in ("failed", "not run"):
            return self.observed
        if self.observed == "grows":
            return f"grows (peak x{self.peak:.3g} in {self.horizon:.3g} s)"
        return f"{self.observed} (x{self.growth:.3g} after {self.horizon:.3g} s)"

    def to_dict(self) -> dict:
        return {"agrees": self.agrees, "stability": self.stability, "observed": self.observed,
                "growth": _finite(self.growth), "peak": _finite(self.peak), "horizon": self.horizon,
                "clamped": self.clamped, "size": self.size, "perturbations": len(self.runs), "method": self.method,
                "note": self.note,
                "runs": [{"observed": r.observed, "growth": _finite(r.final), "peak": _finite(r.peak)}
                         for r in self.runs]}


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


# ----------------------------------------------------------------------------------------------- horizon
def horizon(eigenvalues: np.ndarray, factor: float = 1.0) -> Horizon:
    """Integration time from the eigenvalues of the reduced state.

    Some Re > tol (the verdicts' zero tolerance): GROWTH_EFOLDS / max Re (a perturbation grows 1e4 times).
    Otherwise the longer of PERIODS slowest oscillation periods and DECAY_TIMES slowest decay time constants.
    Times ``factor``, then bounded to [MIN_SPAN / max|lambda|, min(MAX_SPAN / max|lambda|, MAX_CYCLES fastest
    periods)]."""
    vals = np.asarray(eigenvalues, dtype=complex)
    vals = vals[np.isfinite(vals)]
    scale = max(1.0, float(np.max(np.abs(vals)))) if vals.size else 1.0
    tol, tiny = ZERO_RE * scale, TINY * scale
    fast = float(np.max(np.abs(vals))) if vals.size else 0.0
    osc = np.abs(vals.imag)[np.abs(vals.imag) > tiny]
    decays = -vals.real[vals.real < -tol]
    if fast <= tol:
        needed = DEFAULT_HORIZON
    elif np.max(vals.real) > tol:
        needed = GROWTH_EFOLDS / float(np.max(vals.real))
    else:
        parts = []
        if osc.size:
            parts.append(PERIODS * 2 * math.pi / float(np.min(osc)))
        if decays.size:
            parts.append(DECAY_TIMES / float(np.min(decays)))
        needed = max(parts) if parts else DEFAULT_HORIZON
    needed *= factor
    low, high = 0.0, math.inf
    if fast > tol:
        low, high = MIN_SPAN / fast, MAX_SPAN / fast
    if osc.size:
        high = min(high, MAX_CYCLES * 2 * math.pi / float(np.max(osc)))
    seconds = min(max(needed, low), high)
    slow_period = 2 * math.pi / float(np.min(osc)) if osc.size else 0.0
    window = max(seconds / 10, min(slow_period, seconds / 4))
    if osc.size:
        samples = int(min(MAX_SAMPLES, max(MIN_SAMPLES, math.ceil(
            SAMPLES_PER_PERIOD * seconds * float(np.max(osc)) / (2 * math.pi)))))
    else:
        samples = PLAIN_SAMPLES
    return Horizon(seconds, needed, window, samples)


# ----------------------------------------------------------------------------------------------- observation
def observe(t: np.ndarray, ratio: np.ndarray, window: float) -> Run:
    """Classify one run from its deviation ratio r(t) = |x(t)| / |x(0)|."""
    ratio = np.where(np.isfinite(ratio), ratio, np.inf)
    first = float(np.max(ratio[t <= t[0] + window]))
    last = float(np.max(ratio[t >= t[-1] - window]))
    peak = float(np.max(ratio))
    trend = last / first if first > 0 else math.inf
    if peak >= GROWTH or trend >= TREND:
        observed = "grows"
    elif trend <= DECAY:
        observed = "decays"
    else:
        observed = "bounded"
    return Run(observed, peak, last, trend)


def agreement(stability: str, observed: str, eigenvalues: np.ndarray, critical: bool,
              conclusive: bool) -> tuple[bool | None, str]:
    """Does the observed motion agree with the verdict? (True, False, or None with the reason it cannot say.)

    unstable <-> grows; asymptotically stable <-> decays; stable <-> does not grow; undecided -> None.
    A run that does not grow contradicts 'unstable' only when the linearization grows (an instability of
    higher order is too slow to show from a small perturbation) and the horizon was not cut short; a run that
    stays bounded without decaying contradicts 'asymptotically stable' only when the horizon was not cut short."""
    short = "the horizon was cut to its bound before the expected behaviour could show"
    if stability == "stable":
        return observed != "grows", ""
    if stability == "asymptotically stable":
        if observed in ("decays", "grows"):
            return observed == "decays", ""
        return (False, "") if conclusive else (None, short)
    if stability == "unstable":
        if observed == "grows":
            return True, ""
        vals = np.asarray(eigenvalues, dtype=complex)
        scale = max(1.0, float(np.max(np.abs(vals)))) if vals.size else 1.0
        linear_growth = bool(vals.size and np.max(vals.real) > ZERO_RE * scale)
        if critical and not linear_growth:
            return None, ("the instability comes from nonlinear terms (critical case): too slow to show from a "
                          "perturbation of this size")
        return (False, "") if conclusive else (None, short)
    return None, f"the verdict is {stability!r}: the motion is reported, not judged"


# ----------------------------------------------------------------------------------------------- runs
class _Frame:
    """The reduced state of an equilibrium as numbers: which coordinates count, their scales, the tangent basis."""

    def __init__(self, problem: EquilibriumProblem, e: Equilibrium, p: np.ndarray) -> None:
        model = problem.model
        self.names = list(model.coordinates)
        n = len(self.names)
        self.q0, self.u0 = state_at(model, e.coordinates, e.rates)
        # the cyclic angles are no part of the state; their rates are
        self.measured = [self.names.index(c) for c in problem.free]
        self.angle = np.array([bool(model.angles.get(c, False)) for c in self.names])
        self.scale = np.array([1.0 if self.angle[i] else
                               (max(abs(self.q0[i]), abs(model.doc.initial.get(c, 0.0))) or 1.0)
                               for i, c in enumerate(self.names)])
        vals = np.asarray(e.eigenvalues, dtype=complex)
        mags = np.abs(vals[np.isfinite(vals)])
        mags = mags[mags > TINY * max(1.0, float(np.max(mags, initial=0.0)))]
        self.omega = math.sqrt(float(np.min(mags)) * float(np.max(mags))) if mags.size else 1.0
        if problem.m:  # closed loops: perturb along the tangent space of the constraints
            problem.current_parameters = p
            self.tangent = reduced_pencil(problem, e)[2]
            self.rate_basis = self.tangent
        else:
            self.tangent = np.eye(n)[:, self.measured]
            self.rate_basis = np.eye(n)

    def deviation(self, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Scaled deviation of rows of states: non-cyclic coordinates (angles on the circle) and all rates."""
        dq = np.atleast_2d(q)[:, self.measured] - self.q0[self.measured]
        ang = self.angle[self.measured]
        dq[:, ang] = np.remainder(dq[:, ang] + np.pi, 2 * np.pi) - np.pi
        du = np.atleast_2d(u) - self.u0
        return np.hstack([dq / self.scale[self.measured], du / (self.omega * self.scale)])

    def perturbation(self, rng: np.random.Generator, size: float) -> tuple[np.ndarray, np.ndarray]:
        dq = self.tangent @ rng.standard_normal(self.tangent.shape[1])
        du = self.rate_basis @ rng.standard_normal(self.rate_basis.shape[1])
        norm = float(np.linalg.norm(self.deviation(self.q0 + dq, self.u0 + du)))
        return dq * size / norm, du * size / norm


def _start(model: MechanicalModel, names: list[str], q: np.ndarray, u: np.ndarray) -> MechanicalModel:
    values = {c: float(v) for c, v in zip(names, q)}
    values.update({f"der({c})": float(v) for c, v in zip(names, u)})
    return model.with_overrides(values)


def verify_equilibrium(model: MechanicalModel, e: Equilibrium, options: VerifyOptions | None = None, *,
                       problem: EquilibriumProblem | None = None) -> Verification:
    """Integrate from ``options.perturbations`` small perturbations of equilibrium ``e`` (as found by
    find_equilibria, with its eigenvalues and verdict) and compare the motion with ``e.stability``."""
    options = options or VerifyOptions()
    problem = problem or EquilibriumProblem(model)
    p = parameter_values(model)
    h = horizon(e.eigenvalues, options.horizon_factor)
    out = Verification(e.stability, None, "not run", math.nan, math.nan, h.seconds, options.size, clamped=h.clamped)
    if e.jacobian is None and not len(e.eigenvalues) and e.stability == "undecided":
        out.note = "no linearization to size the runs (see the verdict's reason)"
        return out
    frame = _Frame(problem, e, p)
    compile_model(model)  # once, before the copies of the model: they share the compiled code
    rng = np.random.default_rng(options.seed)
    dt = h.seconds / h.samples
    for _ in range(options.perturbations):
        dq, du = frame.perturbation(rng, options.size)
        try:
            run = simulate(_start(model, frame.names, frame.q0 + dq, frame.u0 + du), h.seconds, dt=dt,
                           method=options.method, rtol=options.rtol, atol=options.atol, overrides_p=p)
        except AnalysisError as exc:
            out.observed, out.note = "failed", f"the perturbed motion could not be integrated: {exc}"
            return out
        norms = np.linalg.norm(frame.deviation(run.q, run.u), axis=1)
        start = norms[0] if norms[0] > 0 else options.size  # after assembly onto a closed loop: ~ options.size
        out.runs.append(observe(run.t, norms / start, h.window))
        out.method = run.method
    observed = [r.observed for r in out.runs]
    out.observed = "grows" if "grows" in observed else "decays" if set(observed) == {"decays"} else "bounded"
    out.growth = max(r.final for r in out.runs)
    out.peak = max(r.peak for r in out.runs)
    out.agrees, note = agreement(e.stability, out.observed, e.eigenvalues, e.critical, not h.clamped)
    from mechsys.analysis.equilibrium.charts import singularities

    chart = singularities(model, e.coordinates, p)
    if chart and out.agrees is not None:
        out.agrees = None  # the verdict came from a regular chart; rates of singular angles blow up near it
        note = (f"{chart[0].describe()}: deviations of these angles do not measure the motion, so the runs are "
                "reported, not judged")
    if h.clamped:
        note = "; ".join(x for x in (note, f"horizon bounded to {h.seconds:.3g} (the eigenvalues ask for "
                                             f"{h.needed:.3g})") if x)
    out.note = note
    return out


def verify_equilibria(model: MechanicalModel, result: EquilibriaResult,
                      options: VerifyOptions | None = None) -> list[Verification]:
    """One Verification per equilibrium of ``result`` (same order)."""
    if not model.is_holonomic:
        from mechsys.errors import InputError

        raise InputError("--verify is not available for nonholonomic steady motions yet (the perturbed starts "
                         "would have to satisfy the rolling constraints); check a verdict with `mechsys simulate` "
                         "from a perturbed file")
    if not result.equilibria:
        return []
    problem = EquilibriumProblem(model)
    return [verify_equilibrium(model, e, options, problem=problem) for e in result.equilibria]


def disagreements(result: EquilibriaResult, verifications: list[Verification]) -> list[str]:
    """One line per equilibrium whose motion contradicts its verdict (empty when all agree or cannot say)."""
    lines = []
    for k, (e, v) in enumerate(zip(result.equilibria, verifications), start=1):
        if v.agrees is False:
            where = [f"{c} = {x:.6g}" for c, x in e.coordinates.items()]
            where += [f"der({c}) = {x:.6g}" for c, x in e.rates.items()]
            lines.append(f"equilibrium {k} ({', '.join(where) or 'the only state'}): the verdict is "
                         f"{v.stability!r}, but the perturbed motion {v.summary()}")
    return lines
