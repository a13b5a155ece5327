"""Speed against error: a tolerance x method grid compared with a tight reference solution."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from mechsys.analysis.motion.simulate import compile_model, simulate
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


def work_precision(model: MechanicalModel, t_end: float, methods: list[str], rtols: list[float],
                   dt: float | None = None) -> tuple[list[WorkPoint], float]:
    """Each (method, rtol) run against DOP853 at rtol 1e-13 (keep t_end inside the predictability horizon of
    chaotic scenes). Compilation is done once, before any timing. Returns the points and the reference time."""
    compile_model(model)
    t0 = time.perf_counter()
    ref = simulate(model, t_end, dt, "DOP853", rtol=1e-13, atol=1e-14)
    ref_seconds = time.perf_counter() - t0
    y_ref = np.concatenate([ref.q[-1], ref.u[-1]])
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
            err = float(np.max(np.abs(y - y_ref)) / max(1.0, float(np.max(np.abs(y_ref)))))
            points.append(WorkPoint(method, rtol, seconds, r.rhs_evaluations, err, r.energy_balance_error,
                                    float(np.max(r.residual))))
    return points, ref_seconds


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
