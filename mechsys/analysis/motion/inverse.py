"""Inverse dynamics at one instant: accelerations, driving forces, multipliers, joint reactions, without integrating."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mechsys.mechanics.model import MechanicalModel


@dataclass
class Instant:
    """The dynamics of a model at time ``t`` in the state (q, u) the file gives, assembled onto the constraints."""

    t: float
    coordinates: list[str]
    q: np.ndarray
    u: np.ndarray
    accelerations: np.ndarray  # q''
    driving: dict[str, float]  # prescribed coordinate -> the force or torque its drive supplies
    multipliers: dict[str, float]  # constraint row -> Lagrange multiplier
    reactions: dict[str, np.ndarray]  # link -> (Fx, Fy, Fz, Mx, My, Mz), ground axes, moments about the joint origin
    outputs: dict[str, float]
    warnings: list[str] = field(default_factory=list)


#: Largest change of the constraint residual between two assemblies on the way from t = 0 to the instant.
STEP = 0.02
#: Most assembly steps on the way to the instant (a drive turned 7e6 rad by 1e6 s needs 2e7)
MAX_STEPS = 100_000


def _path(c, p: np.ndarray, t: float, q: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Times from 0 to t at which the constraints (drives, rheonomic rows) move by at most STEP between
    neighbours, measured at the file's state."""
    if c.m == 0 or t == 0.0:
        return np.array([t])
    samples = np.linspace(0.0, t, 2001)
    with np.errstate(all="ignore"):
        phi = np.array([np.ravel(c.phi(s, q, u, p)) for s in samples])
        # the rows' own rate (A u + a_t at u = 0) times the time: samples of a fast drive alias, and a crank turning
        # 7 rad/s looked still at t = 1e6 s (every sample a whole number of turns apart)
        speed = max((float(np.max(np.abs(c.cv(s, q, np.zeros_like(u), p)), initial=0.0)) for s in samples),
                    default=0.0)
    variation = float(np.sum(np.max(np.abs(np.diff(phi, axis=0)), axis=1))) if phi.size else 0.0
    variation = max(variation, speed * abs(t))
    if not math.isfinite(variation):
        return np.linspace(0.0, t, 2001)
    steps = max(math.ceil(variation / STEP), 1)
    if steps > MAX_STEPS:
        from mechsys.errors import AnalysisError

        raise AnalysisError(f"--at {t:g}: the constraints move by about {variation:.3g} between t = 0 and the instant, "
                            f"more than {MAX_STEPS} assembly steps of {STEP}: each step could jump to another "
                            "assembly branch; give an earlier instant, or follow the motion with mechsys simulate")
    return np.linspace(0.0, t, steps + 1)


def inverse_dynamics(model: MechanicalModel, t: float = 0.0) -> Instant:
    """The instant ``t`` of ``model`` (loaded with its prescribed coordinates released into drives): the file's
    coordinates and rates put onto the constraints at t = 0 by the same Newton projection as `simulate`'s start
    (the branch nearest the file's values), then carried to time t in small steps (each assembly starts from the
    previous one, so a driven loop stays on its branch), then q'' and the multipliers from the equations of
    motion, the drives' forces, every joint's reaction and the file's outputs. The free coordinates of a model
    with degrees of freedom keep the file's values: the state at t of a motion is `simulate`'s."""
    from mechsys.numeric.parameters import parameter_values
    from mechsys.analysis.motion.outputs import compile_outputs, deferred_values
    from mechsys.analysis.motion.reactions import reaction_notes, wrenches
    from mechsys.analysis.motion.simulate import (RightHandSide, check_on_manifold, compile_model, file_state,
                                                  project, start_state)

    c = compile_model(model)
    p = parameter_values(model)
    guess_q, guess_u = file_state(model)
    q, u = start_state(model, c, p)  # (the values the user set held)
    for s in _path(c, p, t, guess_q, guess_u):  # follow the assembly along time: the branch the motion is on
        q, u = project(c, p, s, q, u)
        check_on_manifold(c, p, s, q, u)
    a, lam = RightHandSide(c, p).accelerations(t, q, u)
    rows = [con.name for con in model.kin.constraints]
    driving = {name[6:-1]: float(lam[k]) for k, name in enumerate(rows) if name.startswith("drive(")}
    multipliers = {name: float(lam[k]) for k, name in enumerate(rows) if not name.startswith("drive(")}
    w = wrenches(model, t, q, u, a, lam, p)
    reactions = {j.link: np.asarray(w[j.link], float) for j in model.kin.joints}
    outputs = {}
    if model.outputs:
        values = compile_outputs(model)(t, q, u, a, p, deferred_values(model, t, q, u, a, lam, p))
        outputs = {name: float(v) for (name, _e), v in zip(model.outputs, values)}
    warnings = []
    moved = [n for n, qa, qg in zip(model.coordinates, q, guess_q) if abs(qa - qg) > 1e-9 * (1 + abs(qg))]
    moved += [f"der({n})" for n, ua, ug in zip(model.coordinates, u, guess_u) if abs(ua - ug) > 1e-9 * (1 + abs(ug))]
    if moved:
        how = "assembled onto the constraints" if t == 0.0 else \
            f"assembled at t = 0 and carried along the constraints to t = {t:g}"
        warnings.append(f"the file's state {how} (the branch nearest the file's values): {', '.join(moved)} "
                        "differ from the file")
    warnings += reaction_notes(model)  # what the reactions leave inside the joints (as simulate --reactions says)
    return Instant(t, list(model.coordinates), q, u, np.asarray(a, float), driving, multipliers, reactions, outputs,
                   warnings)
