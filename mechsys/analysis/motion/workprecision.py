"""Speed against error: a tolerance x method grid compared with a tight reference solution."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from mechsys.analysis.motion.simulate import compile_model, native_integrator, simulate
from mechsys.mechanics.model import MechanicalModel


@dataclass
class WorkPoint:
    method: str
    rtol: float
    seconds: float
    rhs_evaluations: int
    final_error: float
    energy_balance_error: float  # the energy drift of a conservative run (SimulationResult.energy_balance_error)
    residual: float
    failed: str = ""


#: The reference runs tried in order: DOP853, then, where a stiff scene spends its budget, CVODE and Radau
#: (implicit; CVODE needs the optional SUNDIALS). A chain with springs of 1 to 1e8 stopped bench before any method
#: ran ("try --method Radau or CVODE", an option bench does not have).
REFERENCES = (("DOP853", 1e-13, 1e-14), ("CVODE", 1e-12, 1e-14), ("Radau", 1e-12, 1e-14))


@dataclass
class Reference:
    method: str
    rtol: float
    seconds: float
    note: str = ""  # why an earlier reference was not used

    @property
    def label(self) -> str:
        return f"{self.method}, rtol {self.rtol:g}"


def work_precision(model: MechanicalModel, t_end: float, methods: list[str], rtols: list[float],
                   dt: float | None = None) -> tuple[list[WorkPoint], Reference]:
    """Each (method, rtol) run against a tight reference: DOP853 at rtol 1e-13, or CVODE (else Radau) at 1e-12 where
    DOP853 cannot finish (a stiff scene); keep t_end inside the predictability horizon of chaotic scenes. Compilation
    (of the Python code and of the native C library) is done once, before any timing. Returns the points and the
    reference."""
    from mechsys.errors import AnalysisError
    from mechsys.numeric.native import BUDGET_SPENT

    c = compile_model(model)
    if "native" in methods:
        # the C library too: built inside the first timed native run, it made that run's time 30x its cost
        native_integrator(model, c, required=False)
    failed = []
    for method, rtol, atol in REFERENCES:
        t0 = time.perf_counter()
        try:
            ref = simulate(model, t_end, dt, method, rtol=rtol, atol=atol)
        except AnalysisError as exc:
            if BUDGET_SPENT not in str(exc):
                raise  # not a stiff scene (a degenerate contact, a singular mass matrix): another method fails alike
            failed.append(f"{method} at rtol {rtol:g} could not finish ({str(exc).split(' (')[0]})")
            if method == REFERENCES[-1][0]:
                raise AnalysisError("no reference solution: " + "; ".join(failed)) from None
            continue
        reference = Reference(method, rtol, time.perf_counter() - t0, "; ".join(failed))
        break
    y_ref = np.concatenate([ref.q[-1], ref.u[-1]])
    sizes = _sizes(ref.q, ref.u)
    points = []
    for method in methods:
        for rtol in rtols:
            t0 = time.perf_counter()
            try:
                r = simulate(model, t_end, dt, method, rtol=rtol, atol=rtol * 1e-3)
            except Exception as exc:  # noqa: BLE001 - a failing combination is a result of the study
                points.append(WorkPoint(method, rtol, time.perf_counter() - t0, 0, np.nan, np.nan, np.nan, str(exc)))
                continue
            seconds = time.perf_counter() - t0
            y = np.concatenate([r.q[-1], r.u[-1]])
            err = float(np.max(np.abs(y - y_ref) / sizes))
            points.append(WorkPoint(method, rtol, seconds, r.rhs_evaluations, err, r.energy_balance_error,
                                    float(np.max(r.residual))))
    return points, reference


def plot_work_precision(points: list[WorkPoint], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for k, method in enumerate(sorted({p.method for p in points})):
        pts = [p for p in points if p.method == method and not p.failed and p.final_error > 0]
        if pts:
            ax.loglog([p.final_error for p in pts], [p.seconds for p in pts], "o-", color=f"C{k}", label=method)
    ax.set_xlabel("final-state error (relative)")
    ax.set_ylabel("wall time [s]")
    ax.set_title("work-precision")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _sizes(q: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The size each final coordinate and rate is measured against: its largest |value| along the reference run; one
    that stays 0 takes the largest of its kind (coordinates or rates), and 1 if those do too. The error was measured
    against max(1, |final state|), absolute for a small state: a spring chain moving 1e-5 m showed 3.6e-7 where
    RK45 at rtol 1e-4 was off by 0.4 %."""
    out = []
    for block in (np.abs(q), np.abs(u)):
        size = np.max(block, axis=0) if block.size else np.zeros(block.shape[1])
        kind = float(np.max(size)) if size.size else 0.0
        out.append(np.where(size > 0, size, kind if kind > 0 else 1.0))
    return np.concatenate(out)
