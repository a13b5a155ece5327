"""Tables for equilibria, stability, linearization, sweeps and vibration modes."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mechsys.analysis.equilibrium.equilibria import EquilibriaResult
from mechsys.analysis.equilibrium.linearize import Linearization
from mechsys.report.tables import Table, fmt_number

if TYPE_CHECKING:
    from mechsys.analysis.equilibrium.bifurcation import SweepResult
    from mechsys.analysis.equilibrium.modes import Modes
    from mechsys.analysis.equilibrium.nonholonomic import SteadyLinearization


def mode_rows(eigenvalues: np.ndarray) -> list[tuple[complex, float, float]]:
    """(eigenvalue, natural frequency |lambda|, damping ratio -Re/|lambda|) for each root with Im >= 0."""
    out = []
    for v in eigenvalues:
        if v.imag < -1e-12 * max(1.0, abs(v)):
            continue
        w = abs(v)
        out.append((complex(v), float(w), float(-v.real / w) if w > 0 else 0.0))
    return out


def equilibria_tables(result: EquilibriaResult) -> list[Table]:
    t = Table("equilibria", ["#", "coordinates", "steady rates", "stability", "eigenvalues"])
    for k, e in enumerate(result.equilibria, start=1):
        coords = ", ".join(f"{c} = {fmt_number(v)}" for c, v in e.coordinates.items()) or "-"
        rates = ", ".join(f"der({c}) = {fmt_number(v)}" for c, v in e.rates.items()) or "-"
        eigs = "; ".join(fmt_number(complex(v)) for v in e.eigenvalues)
        t.add(k, coords, rates, e.stability + (" (critical)" if e.critical else ""), eigs)
    if result.message:
        t.notes.append(result.message)
    if result.search is not None and not result.message.startswith("no equilibrium found"):
        t.notes.append(f"search: {result.search.text()}")
    if result.exhaustive is not None:
        t.notes.append(f"search: {result.exhaustive.text()}")
    if result.formulation:
        t.notes.append(f"nonholonomic steady motions: {result.formulation}")
    if result.fixed_rates:
        t.notes.append("steady motions form a family; rates fixed at the initial rate: "
                       + ", ".join(f"der({c}) = {fmt_number(v)}" for c, v in result.fixed_rates.items()))
    modes = Table("modes of the linearized motion", ["#", "eigenvalue", "natural frequency [rad/s]",
                                                     "frequency [Hz]", "damping ratio"])
    reasons = Table("verdicts", ["#", "reason"])
    for k, e in enumerate(result.equilibria, start=1):
        for v, w, z in mode_rows(e.eigenvalues):
            if abs(v.imag) <= 1e-12 * max(1.0, abs(v)):
                modes.add(k, v, "-", "-", "non-oscillatory (real root)")
            else:
                modes.add(k, v, w, w / (2 * np.pi), z)
        reasons.add(k, e.reason)
    return [t, modes, reasons]


def verification_table(result: EquilibriaResult, verifications: list) -> Table:
    """--verify: the motion from small perturbations of each equilibrium against its verdict (analysis/equilibrium/verify.py);
    a disagreement is a note in capitals that names the equilibrium, the verdict and the motion."""
    from mechsys.analysis.equilibrium.verify import disagreements

    t = Table("verification (perturbed motions)", ["#", "stability", "perturbed motion", "agrees"])
    for k, v in enumerate(verifications, start=1):
        t.add(k, v.stability, v.summary(), {True: "yes", False: "NO", None: "-"}[v.agrees])
    t.notes += [f"DISAGREEMENT: {line}" for line in disagreements(result, verifications)]
    t.notes += [f"{k}: {v.note}" for k, v in enumerate(verifications, start=1) if v.note and v.agrees is not False]
    if verifications:
        runs, size = max(len(v.runs) for v in verifications), verifications[0].size
        t.notes.append(f"{runs} runs per equilibrium from perturbations of scaled size {size:g}; the factor is the "
                       "deviation at the end relative to the initial one (for grows: the largest)")
    return t


def equilibria_payload(result: EquilibriaResult, bifurcations: list | None = None,
                       verifications: list | None = None, sweep_notes: list[str] | None = None) -> dict:
    if verifications is not None:
        return {**equilibria_payload(result, bifurcations, sweep_notes=sweep_notes),
                "equilibria": [{**e.to_dict(), "verification": v.to_dict()}
                               for e, v in zip(result.equilibria, verifications)]}
    payload = {"equilibria": [e.to_dict() for e in result.equilibria], "bifurcations": bifurcations or [],
               "message": result.message, "cyclic": result.cyclic,
               **({"formulation": result.formulation} if result.formulation else {}),
               "search": result.search.to_dict() if result.search is not None else None}
    if result.exhaustive is not None:  # --exhaustive only
        payload["exhaustive"] = result.exhaustive.to_dict()
    if sweep_notes is not None:  # --sweep only: what the text prints under the branches
        payload["sweep_notes"] = list(sweep_notes)
    return payload


def matrix_table(title: str, names: list[str], matrix: np.ndarray, row_names: list[str] | None = None) -> Table:
    t = Table(title, [""] + names)
    for name, row in zip(row_names or names, np.atleast_2d(matrix)):
        t.add(name, *[float(x) for x in row])
    return t


def linearization_tables(lin: Linearization, label: str, hurwitz: bool,
                         reduced_jacobian: np.ndarray | None = None) -> list[Table]:
    names = lin.coordinates
    tables = [matrix_table(f"{label}: {key}", names, getattr(lin, key)) for key in ("M", "C", "G", "K", "N")]
    if np.linalg.cond(lin.M) < 1e12:
        states = names + [f"der({c})" for c in names]
        tables.append(matrix_table(f"{label}: A (state {', '.join(states)})", states, lin.A))
        tables.append(matrix_table(f"{label}: B (generalized forces)", names, lin.B, states))
    if hurwitz:
        tables += hurwitz_tables(lin, label, reduced_jacobian)
    return tables


def hurwitz_tables(lin: Linearization, label: str, reduced_jacobian: np.ndarray | None = None) -> list[Table]:
    """With cyclic coordinates or constraints the polynomial of the reduced state Jacobian (monic) is the one
    stability is about; otherwise det(M s^2 + (C+G) s + K + N) as the book writes it."""
    if reduced_jacobian is not None:
        from mechsys.analysis.equilibrium.linearize import hurwitz_determinants

        coeffs = np.real(np.poly(reduced_jacobian))
        n = len(coeffs) - 1
        poly = Table(f"{label}: characteristic polynomial of the reduced state Jacobian (monic)",
                     ["power of s", "coefficient"])
        for k, c in enumerate(coeffs):
            poly.add(n - k, float(c))
        dets = hurwitz_determinants(coeffs)
        return [poly, _hurwitz_conditions(label, coeffs, dets)]
    coeffs = lin.characteristic_polynomial()
    n = len(coeffs) - 1
    poly = Table(f"{label}: characteristic polynomial det(M s^2 + (C+G) s + K + N)", ["power of s", "coefficient"])
    for k, c in enumerate(coeffs):
        poly.add(n - k, float(c))
    dets = lin.hurwitz_determinants()
    return [poly, _hurwitz_conditions(label, coeffs, dets)]


def _hurwitz_conditions(label: str, coeffs, dets) -> Table:
    hur = Table(f"{label}: Routh-Hurwitz conditions (all > 0 <=> asymptotically stable)", ["condition", "value", "holds"])
    hur.add("all coefficients > 0", min(float(c) for c in coeffs), bool(all(c > 0 for c in coeffs)))
    for k, d in enumerate(dets, start=1):
        hur.add(f"Delta_{k} > 0", d, bool(d > 0))
    return hur


def symbolic_tables(mats: dict, names: list[str]) -> list[Table]:
    from mechsys.report.printing import to_text

    tables = []
    for key, mat in mats.items():
        t = Table(f"{key} (about any state of rest where no spring has zero length; expressions of the "
                  "coordinates)", [""] + names)
        for i, name in enumerate(names):
            t.add(name, *[to_text(mat[i, j]) for j in range(mat.shape[1])])
        tables.append(t)
    return tables


def sweep_tables(result: SweepResult) -> list[Table]:
    t = Table(f"branches over {result.parameter}", ["branch", result.parameter, *result.names, "stable", "verdict"])
    for row in result.rows():
        t.add(*row)
    t.notes.extend(getattr(result, "notes", []))
    b = Table("bifurcations", ["kind", "parameter", "value", "coordinates"])
    for bif in result.bifurcations:
        b.add(bif["kind"], bif["parameter"], bif["value"],
              ", ".join(f"{k} = {fmt_number(v)}" for k, v in bif["coordinates"].items()))
    return [b, t]


def modes_tables(modes: Modes) -> list[Table]:
    where = ", ".join(f"{c} = {fmt_number(v)}" for c, v in modes.equilibrium.coordinates.items()) or "the equilibrium"
    rates = ", ".join(f"der({c}) = {fmt_number(v)}" for c, v in modes.equilibrium.rates.items())
    t = Table(f"natural frequencies about {where}{f' with {rates}' if rates else ''}",
              ["mode", "frequency [rad/s]", "frequency [Hz]", "damping ratio", "rigid body"])
    for k, (w, z, r) in enumerate(zip(modes.frequencies, modes.damping_ratios, modes.rigid_body), start=1):
        t.add(k, float(w), float(w / (2 * np.pi)), float(z), "yes" if r else "")
    title = ("mass-normalised mode shapes (columns)" if modes.system is not None
             else "mode shapes (columns; independent shape coordinates, largest component 1, at phase 0)")
    s = Table(title, ["coordinate"] + [f"mode {k}" for k in range(1, len(modes.frequencies) + 1)])
    for i, c in enumerate(modes.coordinates):
        s.add(c + (" (condensed)" if c in modes.condensed else ""), *[float(x) for x in modes.shapes[i]])
    if modes.unstable_modes:
        t.notes.append(f"{modes.unstable_modes} mode(s) with negative stiffness: the equilibrium is statically unstable")
    if modes.note:
        t.notes.append(modes.note)
    if modes.coupling:
        t.notes.append(modes.coupling)
    if not modes.coordinates:  # e.g. a two-wheel robot's steady run: its modes are of the speeds alone
        t.notes.append("no shape coordinates: every coordinate is cyclic or fixed by the constraints, so these modes "
                       "are perturbations of the steady speeds alone (`mechsys equilibria --linearize` prints A and B)")
        return [t]
    return [t, s]


def steady_linearization_tables(lin: SteadyLinearization, label: str, independent: list[str] | None,
                                hurwitz: bool) -> list[Table]:
    """Nonholonomic steady motion (analysis/equilibrium/nonholonomic.py): Kane's M, C, K over the independent speeds, the
    kinematic rows, the first-order A and B; with --independent, the second-order form over those coordinates."""
    from mechsys.errors import AnalysisError

    tables = []
    speeds = [f"der({c})" for c in lin.speeds]
    coupled = ""
    if independent:
        try:
            M, C, K = lin.second_order(independent)
        except AnalysisError as exc:  # e.g. a steady turn couples lean and steer to the speed: Kane's form instead
            coupled = str(exc)
            independent = None
    if independent:
        for key, mat in (("M", M), ("C", C), ("K", K)):
            tables.append(matrix_table(f"{label}: {key} over {', '.join(independent)} "
                                       f"(M q'' + C q' + K q = generalized forces)", independent, mat))
        n = len(independent)
        Minv = np.linalg.inv(M)
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ C]])
        states = independent + [f"der({c})" for c in independent]
        tables.append(matrix_table(f"{label}: A (state {', '.join(states)})", states, A))
        tables.append(matrix_table(f"{label}: B (generalized forces)", independent, np.vstack([np.zeros((n, n)), Minv]),
                                   states))
    else:
        tables.append(matrix_table(f"{label}: M (Kane's generalized mass over the independent speeds)", speeds, lin.M))
        if coupled:
            tables[-1].notes.append(coupled.split(": there is no")[0] + ": no second-order form over the "
                                    "--independent coordinates alone here; Kane's form over all independent "
                                    "speeds follows")
        tables.append(matrix_table(f"{label}: C (rows: independent speeds)", speeds, lin.C))
        if lin.coordinates:
            tables.append(matrix_table(f"{label}: K (rows: independent speeds)", lin.coordinates, lin.K, speeds))
            tables.append(matrix_table(f"{label}: kinematics d(xi)/dt = W xi + V nu: W", lin.coordinates, lin.W))
            tables.append(matrix_table(f"{label}: kinematics: V", speeds, lin.V, lin.coordinates))
        states = lin.states
        t = matrix_table(f"{label}: A (state {', '.join(states)})", states, lin.jacobian)
        if lin.structural:
            t.notes.append(f"structural zero eigenvalues reported apart: {lin.structural_text()}")
        tables.append(t)
        n = len(lin.coordinates)
        try:
            B = np.vstack([np.zeros((n, len(speeds))), np.linalg.inv(lin.M)])
            tables.append(matrix_table(f"{label}: B (generalized forces along the independent speeds)", speeds, B,
                                       states))
        except np.linalg.LinAlgError:  # e.g. a disk spinning about its lean axis: a speed that carries no inertia
            t.notes.append("B is not listed: the reduced mass matrix M is singular at this steady motion (an "
                           "independent speed carries no inertia), so generalized forces do not determine the "
                           "accelerations")
    if hurwitz:
        tables += hurwitz_tables(None, label, lin.deflated)
    return tables
