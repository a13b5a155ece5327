"""Linear vibration about an equilibrium: natural frequencies, damping ratios, mass-normalised modes, FRF."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg as sla

from mechsys.analysis.equilibrium import loops
from mechsys.analysis.equilibrium.equilibria import (Equilibrium, EquilibriumProblem, _polish, find_equilibria,
                                                      is_isolated, settle)
from mechsys.numeric.parameters import parameter_values
from mechsys.analysis.equilibrium.linearize import Linearization, linearize
from mechsys.analysis.equilibrium.stability import oscillating_eigenvalues, zero_length_reason, zero_like_eigenvalues
from mechsys.errors import AnalysisError, InputError
from mechsys.mechanics.model import MechanicalModel

if TYPE_CHECKING:
    import pandas as pd

    from mechsys.analysis.equilibrium.equilibria import SteadyOptions

#: A mode is rigid (zero frequency) when its omega^2 is within RIGID machine epsilons of K's and M's norms, the
#: rounding of the eigenvalue: |w^2| <= RIGID eps (|K| + |w^2| |M|) |phi|^2 (_rigid).
RIGID = 1000


@dataclass
class Modes:
    coordinates: list[str]
    equilibrium: Equilibrium
    frequencies: np.ndarray
    shapes: np.ndarray
    rigid_body: list[bool]
    damping_ratios: np.ndarray
    eigenvalues: np.ndarray
    condensed: list[str] = field(default_factory=list)
    unstable_modes: int = 0
    system: "ReducedSystem | None" = None
    note: str = ""  # why the equilibrium is an unstable one (the search found no stable equilibrium), else ""
    coupling: str = ""  # gyroscopic or circulatory terms: the motion's frequencies are not those above, else ""

    @property
    def frequencies_hz(self) -> np.ndarray:
        return self.frequencies / (2 * np.pi)

    def to_dict(self) -> dict:
        return {
            "coordinates": self.coordinates,
            "equilibrium": {"coordinates": self.equilibrium.coordinates, "rates": self.equilibrium.rates},
            "modes": [{"frequency_rad_s": float(w), "frequency_hz": float(w / (2 * np.pi)),
                       "damping_ratio": float(z), "rigid_body": bool(r),
                       "shape": {c: float(self.shapes[i, k]) for i, c in enumerate(self.coordinates)}}
                      for k, (w, z, r) in enumerate(zip(self.frequencies, self.damping_ratios, self.rigid_body))],
            "eigenvalues": [[float(v.real), float(v.imag)] for v in self.eigenvalues],
            "condensed": self.condensed,
            "unstable_modes": self.unstable_modes,
            **({"note": self.note} if self.note else {}),
            **({"coupling": self.coupling} if self.coupling else {}),
        }

    def _repr_markdown_(self) -> str:
        """Jupyter: the tables of `mechsys modes -f markdown`."""
        from mechsys.report.notebook import modes_markdown

        return modes_markdown(self)

    def to_dataframe(self) -> pd.DataFrame:
        """One row per mode: frequency [rad/s], frequency [Hz], damping ratio, rigid body (needs pandas:
        ``pip install 'mechsys[notebook]'``)."""
        from mechsys.report.notebook import modes_frame

        return modes_frame(self)


@dataclass
class ReducedSystem:
    """M, C (incl. gyroscopic), K (incl. circulatory) on independent coordinates, and the map back T (full = T r)."""

    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    T: np.ndarray
    names: list[str]
    #: before static condensation (constraints removed): M, C, K, the map back, and the static flexibility of the
    #: condensed coordinates on the full ones (a force on a massless coordinate deflects it at once)
    whole: tuple = ()
    flexibility: np.ndarray | None = None

    def receptance(self, omega: float, lin: Linearization) -> np.ndarray:
        """H(omega) = B (K - omega^2 M + i omega C)^-1 B^T on the full coordinates, with the constraints removed
        (B their null space) but nothing condensed: exact for massless coordinates, their dampers included (the
        condensed system dropped a massless coordinate's own static flexibility, and a damper on it: a mass held
        by a spring and a spring-damper in series was 19 % off at 20 rad/s)."""
        M, C, K, B = self.whole or (self.M, self.C, self.K, self.T)
        Z = K - omega**2 * M + 1j * omega * C
        return B @ np.linalg.solve(Z, B.T)

    def state_space(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        n = self.M.shape[0]
        Minv = np.linalg.inv(self.M)
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ self.K, -Minv @ self.C]])
        B = np.vstack([np.zeros((n, self.T.shape[0])), Minv @ self.T.T])
        Cout = np.hstack([self.T, np.zeros((self.T.shape[0], n))])
        D = self.flexibility if self.flexibility is not None else np.zeros((self.T.shape[0], self.T.shape[0]))
        return A, B, Cout, D


_STABLE = ("asymptotically stable", "stable")


def _first_stable(res, candidates: list[Equilibrium], kind: str = "equilibrium") -> tuple[Equilibrium, str]:
    """The stable equilibrium of the candidates nearest the file's initial state (coordinates and steady rates,
    angles on the circle), or (none stable) the first one with a note saying that the search found no stable
    equilibrium and what it covered (a long chain's multistart may miss its one stable rest among 2^n). Nearest,
    not first in sorted order: two masses on a lever started 1 cm from their springs' rest vibrated about a rest
    at x = -2 that the springs reach only through their anchors."""
    stable = [e for e in candidates if e.stability in _STABLE]
    if stable:
        return min(stable, key=lambda e: _from_initial(res.problem, e)), ""
    skipped = [e for e in res.equilibria if (e.chart or e.branch) and e.stability in _STABLE]
    if skipped:  # found, but where these coordinates cannot linearize it (a box's level rest at its zxz lock)
        where = skipped[0].chart or skipped[0].branch
        coords = ", ".join(f"{c} = {v:.6g}" for c, v in skipped[0].coordinates.items())
        return candidates[0], (f"the stable {kind} found ({coords}) is at a {where}, where these coordinates "
                               f"cannot be linearized: these modes are about the first regular one found "
                               f"({candidates[0].stability}); write the joint with another sequence to vibrate "
                               "about the stable one")
    what = f" ({res.search.text()})" if res.search is not None else ""
    return candidates[0], (f"the search found no stable {kind}{what}: these modes are about the first one "
                           f"found ({candidates[0].stability}); give another with --at")


def _from_initial(problem, e: Equilibrium) -> float:
    """The distance of e from the file's initial coordinates and rates (the problem's metric: angles on the
    circle); 0 for every e when the problem is not at hand."""
    if problem is None:
        return 0.0
    model = problem.model
    z = problem.state(e)
    start = z.copy()  # the rest of the state (multipliers, a nonholonomic problem's extra unknowns) as e's
    start[:problem.nq + len(problem.rate_unknowns)] = [model.doc.initial.get(c, 0.0) for c in problem.free] + \
        [model.doc.initial_rate.get(c, 0.0) for c in problem.rate_unknowns]
    return problem.distance(z, start)


def _settled(model: MechanicalModel) -> Equilibrium | None:
    """The stable equilibrium the model settles at from its initial configuration (equilibria.settle), or None:
    the flow does not come to rest, or comes to a rest that is not isolated, at a gimbal lock of the chart or not
    stable. Only where the unknowns are the coordinates alone (no cyclic coordinates, no closed loops)."""
    from mechsys.analysis.equilibrium.charts import singularities
    from mechsys.analysis.equilibrium.stability import assess

    problem = EquilibriumProblem(model)
    if problem.cyclic or problem.m or not problem.unknowns:
        return None
    p = parameter_values(model)
    z = settle(problem, np.array([model.doc.initial.get(c, 0.0) for c in problem.free], dtype=float), p)
    if z is None or problem.discontinuity(z, p) or not is_isolated(problem, z, p):
        return None
    e = problem.equilibrium(z)
    if singularities(model, e.coordinates, p):
        return None
    assess(problem, e, p)
    return e if e.stability in _STABLE else None


def _regular(res, kind: str) -> list[Equilibrium]:
    """The equilibria found that are not at a singular point of a rotation chart (charts.py) or of the closed loops
    (loops.py); none: an error."""
    regular = [e for e in res.equilibria if not (e.chart or e.branch)]
    if not regular:
        first = res.equilibria[0]
        if first.branch:
            raise AnalysisError(f"every {kind} found is {first.branch}; give another with --at")
        raise AnalysisError(f"every {kind} found is at a {first.chart}: the linearization in these "
                            "coordinates is singular; write the joint with another sequence")
    return regular


def _equilibrium(model: MechanicalModel, at: dict[str, float] | None) -> tuple[Equilibrium, str]:
    """The equilibrium to vibrate about and, when it is unstable for want of a stable one, a note saying so:
    the stable rest the model settles at from its initial configuration, else the first stable equilibrium of the
    search."""
    if at is None:
        settled = _settled(model)
        if settled is not None:
            return settled, ""
        res = find_equilibria(model)
        if not res.equilibria:
            raise AnalysisError("no equilibrium found to vibrate about; give one with --at")
        return _first_stable(res, _regular(res, "equilibrium"))
    problem = EquilibriumProblem(model)
    unknown = set(at) - set(problem.free) - set(problem.rate_unknowns)
    fixed = sorted(unknown & set(problem.fixed_rates))
    if fixed:
        c = fixed[0]
        raise InputError(f"--at: {c} is cyclic, and nothing acts on it at rest: every value of it is an equilibrium "
                         f"and its steady rate is the file's (der({c}) = {problem.fixed_rates[c]:g}; change it with "
                         f"--set 'der({c})=...'); give only {', '.join(problem.free) or 'the other coordinates'}")
    if unknown:
        raise InputError(f"--at: {', '.join(sorted(unknown))} is not a free coordinate "
                         f"(choose from {', '.join(problem.free + problem.rate_unknowns)})")
    p = parameter_values(model)
    start = np.array([at.get(c, model.doc.initial.get(c, 0.0)) for c in problem.free]
                     + [at.get(c, model.doc.initial_rate.get(c, 0.0)) for c in problem.rate_unknowns]
                     + [0.0] * problem.m)
    z = _polish(problem, start, p)
    if z is None or problem.distance(z, start) > 1e-6 * (1 + np.linalg.norm(start)):
        raise AnalysisError("--at is not an equilibrium (the equilibrium equations are not satisfied there)")
    from mechsys.analysis.equilibrium.stability import assess

    e = problem.equilibrium(z)
    _refuse_singular(model, e, p)
    branch = loops.branch_point(problem, z, p)
    if branch:
        raise AnalysisError(f"--at is {branch}")
    assess(problem, e, p)
    return e, ""


def _refuse_singular(model: MechanicalModel, e: Equilibrium, p: np.ndarray) -> None:
    """An error when the --at point is at a singular point of a rotation chart."""
    from mechsys.analysis.equilibrium.charts import singularities

    found = singularities(model, e.coordinates, p)
    if found:
        raise AnalysisError(f"--at is at a {found[0].describe()}: the linearization in these coordinates is "
                            "singular; write the joint with another sequence")


def reduce(model: MechanicalModel, lin: Linearization) -> tuple[ReducedSystem, list[str]]:
    """Remove constraint directions (null space of the constraint Jacobian), then statically condense massless
    coordinates (their rows of M vanish): T = [I; -Kss^-1 Ksr] on (retained, massless)."""
    n = len(lin.coordinates)
    Kfull, Cfull = lin.K + lin.N, lin.C + lin.G
    base = sla.null_space(lin.constraint_jacobian) if lin.constraint_jacobian.shape[0] else np.eye(n)
    M, K, C = base.T @ lin.M @ base, base.T @ Kfull @ base, base.T @ Cfull @ base
    names = list(lin.coordinates) if lin.constraint_jacobian.shape[0] == 0 else [f"eta{k + 1}" for k in range(M.shape[0])]
    scale = max(1e-300, float(np.max(np.abs(M)))) if M.size else 1.0
    massless = [i for i in range(M.shape[0]) if np.max(np.abs(M[i, :])) <= 1e-12 * scale]
    condensed = [names[i] for i in massless]
    whole, flexibility = (M, C, K, base), None
    if massless:
        keep = [i for i in range(M.shape[0]) if i not in massless]
        Kss = K[np.ix_(massless, massless)]
        kscale = max(1e-300, float(np.max(np.abs(K)))) if K.size else 1.0
        if np.linalg.matrix_rank(Kss, tol=1e-12 * kscale) < len(massless):
            loose = [names[i] for k, i in enumerate(massless) if np.max(np.abs(Kss[k, :])) <= 1e-12 * kscale]
            which = loose or condensed
            one = len(which) == 1
            raise AnalysisError(
                f"{', '.join(which)} carr{'ies' if one else 'y'} no mass or inertia and no stiffness holds "
                f"{'it' if one else 'them'}: static condensation is impossible and the linearized motion is not "
                f"determined (give {'it' if one else 'them'} mass or inertia, a spring, or make "
                f"{'it' if one else 'them'} prescribed)")
        G = -np.linalg.solve(Kss, K[np.ix_(massless, keep)])
        Tc = np.zeros((M.shape[0], len(keep)))
        Tc[keep, range(len(keep))] = 1.0
        Tc[massless, :] = G
        Bs = base[:, massless]  # a force's part on the condensed coordinates deflects them statically
        flexibility = Bs @ np.linalg.solve(Kss, Bs.T)
        M, C, K = Tc.T @ M @ Tc, Tc.T @ C @ Tc, Tc.T @ K @ Tc
        base = base @ Tc
        names = [names[i] for i in keep]
    return ReducedSystem(M, C, K, base, names, whole, flexibility), condensed


def vibration_modes(model: MechanicalModel, at: dict[str, float] | None = None,
                    options: SteadyOptions | None = None) -> Modes:
    """Modes about ``at`` (polished to an exact equilibrium) or about the first stable equilibrium found (else the
    first found, with a note: Modes.note)."""
    if not model.is_holonomic:
        return steady_modes(model, at, options)
    e, note = _equilibrium(model, at)
    lost = model.zero_length_elements(e.coordinates, dict(zip(model.parameter_symbols, parameter_values(model))))
    if lost:  # a damper between a block and its anchor gave a damping ratio of 0 at the rest where it is 0.1
        raise AnalysisError(f"at the equilibrium, {zero_length_reason(lost)}")
    lin = linearize(model, e)
    red, condensed = reduce(model, lin)
    Ks = (red.K + red.K.T) / 2
    if not all(np.all(np.isfinite(X)) for X in (red.M, red.C, red.K)):
        raise AnalysisError("the linearized equations are not finite at the equilibrium (an overflow or a division "
                            "by zero: check the parameter values, e.g. a length of 1e200 squared)")
    try:
        w2, phi = sla.eigh(Ks, red.M)
    except (np.linalg.LinAlgError, ValueError):
        raise AnalysisError("the reduced mass matrix is not positive definite") from None
    rigid = _rigid(w2, phi, Ks, red.M)
    unstable = int(sum(1 for x, r in zip(w2, rigid) if x < 0 and not r))
    freqs = np.sqrt(np.clip(w2, 0.0, None))
    freqs[rigid] = 0.0
    for k in range(phi.shape[1]):  # sign convention: the largest component is positive
        j = int(np.argmax(np.abs(phi[:, k])))
        if phi[j, k] < 0:
            phi[:, k] = -phi[:, k]
    shapes = red.T @ phi
    n = red.M.shape[0]
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-red.K, -red.C]])
    B = sla.block_diag(np.eye(n), red.M)
    vals = sla.eigvals(A, B)
    vals = vals[np.isfinite(vals)]
    vals = vals[np.lexsort((vals.imag, np.abs(vals)))]
    # modal damping ratios zeta_k = phi_k^T C phi_k / (2 omega_k) with mass-normalised phi (exact for
    # proportional damping; the damped eigenvalues are reported as well)
    Csym = (red.C + red.C.T) / 2
    zeta = np.zeros(len(freqs))
    for k, w in enumerate(freqs):
        if w > 0 and not rigid[k]:
            zeta[k] = float(phi[:, k] @ Csym @ phi[:, k]) / (2 * w)
            if abs(zeta[k]) < 1e-12:
                zeta[k] = 0.0
    names = list(lin.coordinates)
    top = max(1.0, float(np.max(np.abs(vals)))) if vals.size else 1.0
    # (a double zero eigenvalue split by rounding into +-4.8e-8 beside 15 rad/s is no growth: zero_like_eigenvalues)
    growing = [v for v, zero in zip(vals, zero_like_eigenvalues(vals, top)) if v.real > 1e-9 * top and not zero
               and v.imag >= 0]
    if growing and not unstable:  # no negative stiffness, yet the motion grows: flutter or a gyroscopic instability
        unstable = len(growing)
        note = "; ".join(x for x in (note, f"{len(growing)} eigenvalue(s) with a positive real part (up to "
                                     f"{max(v.real for v in growing):.6g} 1/s): the motion grows although no "
                                     f"stiffness is negative, and the damping ratios above (modal, §5) do not show "
                                     f"it") if x)
    damped = _damped_condensed(red, condensed)
    if damped:
        note = "; ".join(x for x in (note, damped) if x)
    return Modes(names, e, freqs, shapes, rigid, zeta, vals, condensed, unstable, red, note,
                 _coupling(red, vals, 2 * sum(map(bool, rigid))))


def _damped_condensed(red: ReducedSystem, condensed: list[str]) -> str:
    """A note when dampers act on statically condensed (massless) coordinates: the modes, the state space and the
    transfer function then hold the condensed system, an approximation (a spring and a damper in series behind a
    massless node: third order, two poles shown); --frf is exact."""
    if not condensed or not red.whole:
        return ""
    M, C, _K, _B = red.whole
    scale = max(1e-300, float(np.max(np.abs(M))))
    rows = [i for i in range(M.shape[0]) if np.max(np.abs(M[i, :])) <= 1e-12 * scale]
    cscale = float(np.max(np.abs(C))) if C.size else 0.0
    if not rows or cscale == 0.0 or float(np.max(np.abs(C[rows, :]))) <= 1e-12 * cscale:
        return ""
    return (f"damping acts on the condensed (massless) coordinate(s) {', '.join(condensed)}: the frequencies, damping "
            f"ratios, eigenvalues, state space and transfer function are those of the statically condensed system, "
            f"an approximation that drops the damper's own pole(s); --frf is exact (modes.md §3)")


def _rigid(w2: np.ndarray, phi: np.ndarray, K: np.ndarray, M: np.ndarray) -> list[bool]:
    """Which modes are rigid-body modes: omega^2 (of the mass-normalised shape phi) no larger than the rounding of
    the eigenvalue, RIGID eps (|K|_2 + |omega^2| |M|_2) |phi|^2. A bound relative to the largest omega^2 (1e-9 of it)
    called a chain's elastic first mode rigid when its springs spanned 1 to 1e8 (0.45 rad/s, 31,600 times below
    its highest mode); a bound of 1e-9 rad^2/s^2 called a mass on a spring of 1e-9 rigid."""
    if not w2.size:
        return []
    eps = np.finfo(float).eps
    k_norm, m_norm = float(np.linalg.norm(K, 2)), float(np.linalg.norm(M, 2))
    return [bool(abs(x) <= RIGID * eps * (k_norm + abs(x) * m_norm) * float(phi[:, i] @ phi[:, i]))
            for i, x in enumerate(w2)]


def _coupling(red: ReducedSystem, eigenvalues: np.ndarray, zeros: int = 0) -> str:
    """A note when gyroscopic (skew C) or circulatory (skew K) terms act: the natural frequencies are those of M
    and the symmetric K alone, and the motion oscillates at the damped eigenvalues' frequencies instead (a conical
    pendulum at 4 rad/s: 3.159944 rad/s from (K, M), 5.834747 rad/s in fact). ``zeros``: the zero eigenvalues of the
    rigid-body modes (oscillating_eigenvalues)."""
    M, C, K = red.M, red.C, red.K
    if not M.size:
        return ""
    G, N = (C - C.T) / 2, (K - K.T) / 2
    scale = float(np.sqrt(np.max(np.abs(M)) * max(float(np.max(np.abs(K))), 1e-300)))
    terms = [name for name, X, size in (("gyroscopic", G, scale), ("circulatory", N, float(np.max(np.abs(K)))))
             if float(np.max(np.abs(X))) > 1e-9 * size]
    if not terms:
        return ""
    found = sorted({round(v.imag, 12) for v in oscillating_eigenvalues(eigenvalues, zeros)})
    shown = ", ".join(f"{w:.7g}" for w in found[:8]) + (", ..." if len(found) > 8 else "")
    where = f"|Im λ| = {shown} rad/s" if found else "no oscillating eigenvalue"
    return (f"{' and '.join(terms)} terms couple the coordinates: the frequencies above are those of M and the "
            f"symmetric K alone; the motion oscillates at the damped eigenvalues' frequencies, {where} "
            f"(JSON eigenvalues; modes.md §5)")


def steady_modes(model: MechanicalModel, at: dict[str, float] | None = None,
                 options: SteadyOptions | None = None) -> Modes:
    """Modes of a nonholonomic steady motion (analysis/equilibrium/nonholonomic.py): one per eigenvalue of the reduced
    linearization with Im >= 0 (structural zeros apart), natural frequency |lambda|, damping ratio -Re/|lambda|
    (real roots: +-1), shapes on the independent shape coordinates (the eigenvector turned so that its largest
    component is real and positive, then its real part; normalised to 1)."""
    from mechsys.analysis.equilibrium.equilibria import make_problem
    from mechsys.analysis.equilibrium.nonholonomic import linearize_steady
    from mechsys.analysis.equilibrium.stability import assess

    problem = make_problem(model, options)
    p = parameter_values(model)
    if at is None:
        res = find_equilibria(model, options=options)
        if not res.equilibria:
            raise AnalysisError("no steady motion found to vibrate about; give one with --at")
        e, note = _first_stable(res, _regular(res, "steady motion"), "steady motion")
    else:
        note = ""
        unknown = set(at) - set(problem.free) - {f"der({c})" for c in problem.rate_unknowns}
        if unknown:
            raise InputError(f"--at: {', '.join(sorted(unknown))} is not a free shape coordinate "
                             f"(choose from {', '.join(problem.free)})")
        draw = np.array([at.get(c, model.doc.initial.get(c, 0.0)) for c in problem.free]
                        + [at.get(f"der({c})", model.doc.initial_rate.get(c, 0.0)) for c in problem.rate_unknowns])
        z = _polish(problem, problem.start(draw, p), p)
        if z is None or np.linalg.norm(z[:len(draw)] - draw) > 1e-6 * (1 + np.linalg.norm(draw)):
            raise AnalysisError("--at is not a steady motion (the steady-motion equations are not satisfied there)")
        e = problem.equilibrium(z)
        _refuse_singular(model, e, p)
        assess(problem, e, p)
    lin = linearize_steady(problem, e, p)
    nxi = len(lin.coordinates)
    vals, vecs = np.linalg.eig(lin.jacobian)
    chosen = []
    for v in lin.eigenvalues:
        if v.imag < -1e-12 * max(1.0, abs(v)):
            continue
        k = int(np.argmin(np.abs(vals - v)))
        vec = vecs[:nxi, k]
        j = int(np.argmax(np.abs(vec))) if nxi else 0
        shape = np.real(vec * np.exp(-1j * np.angle(vec[j]))) if nxi and abs(vec[j]) > 0 else np.zeros(nxi)
        top = float(np.max(np.abs(shape))) if nxi else 0.0
        chosen.append((v, shape / top if top > 0 else shape))
    freqs = np.array([abs(v) for v, _ in chosen])
    zeta = np.array([-v.real / abs(v) if abs(v) > 0 else 0.0 for v, _ in chosen])
    shapes = np.column_stack([s for _, s in chosen]) if chosen else np.zeros((nxi, 0))
    unstable = sum(1 for v, _ in chosen if v.real > 1e-9 * max(1.0, abs(v)))
    return Modes(list(lin.coordinates), e, freqs, shapes, [False] * len(chosen), zeta, lin.eigenvalues, [],
                 unstable, None, note)


def frf(model: MechanicalModel, modes: Modes, omegas: np.ndarray, inp: str, out: str) -> np.ndarray:
    """Receptance H_out,in(omega) (complex) at each omega, from the full linearization."""
    lin = linearize(model, modes.equilibrium)
    names = lin.coordinates
    for name in (inp, out):
        if name not in names:
            raise InputError(f"unknown coordinate {name!r} for --frf (choose from {', '.join(names)})")
    i, o = names.index(inp), names.index(out)
    try:
        return np.array([modes.system.receptance(w, lin)[o, i] for w in omegas])
    except np.linalg.LinAlgError:
        raise AnalysisError("the dynamic stiffness is singular at some frequency (an undamped resonance or a "
                            "rigid-body mode at omega = 0): move the frequency grid") from None


def transfer_function(modes: Modes, inp: str, out: str) -> tuple[np.ndarray, np.ndarray]:
    """Numerator and denominator (highest power first) of the displacement response out/in to a force on in."""
    from scipy import signal

    names = modes.coordinates
    for name in (inp, out):
        if name not in names:
            raise InputError(f"unknown coordinate {name!r} (choose from {', '.join(names)})")
    A, B, C, D = modes.system.state_space()
    i, o = names.index(inp), names.index(out)
    num, den = signal.ss2tf(A, B[:, [i]], C[[o], :], D[[o]][:, [i]])
    num = np.trim_zeros(np.where(np.abs(num[0]) < 1e-12 * max(1.0, np.max(np.abs(num))), 0.0, num[0]), "f")
    return num, den


def _figure():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_modes(modes: Modes, path: str) -> None:
    """Bar charts of the mass-normalised mode shapes, one panel per mode."""
    plt = _figure()
    k = max(1, len(modes.frequencies))
    fig, axes = plt.subplots(1, k, figsize=(3 * k, 3.2), squeeze=False)
    for j in range(len(modes.frequencies)):
        ax = axes[0, j]
        ax.bar(range(len(modes.coordinates)), modes.shapes[:, j], color=f"C{j % 10}")
        ax.set_xticks(range(len(modes.coordinates)), modes.coordinates, rotation=45)
        ax.set_title(f"mode {j + 1}: {modes.frequencies[j]:.4g} rad/s")
        ax.axhline(0, color="k", lw=0.6)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_frf(omegas: np.ndarray, H: np.ndarray, path: str, label: str) -> None:
    plt = _figure()
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    a1.semilogy(omegas, np.abs(H))
    a1.set_ylabel(f"|H| {label}")
    a1.grid(True, alpha=0.3)
    a2.plot(omegas, np.angle(H))
    a2.set_ylabel("phase [rad]")
    a2.set_xlabel("omega [rad/s]")
    a2.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
