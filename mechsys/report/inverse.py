"""Tables and JSON of `mechsys inverse`: one instant's accelerations, driving forces, multipliers and reactions."""
from __future__ import annotations

from mechsys.analysis.inverse import Instant
from mechsys.analysis.reactions import COMPONENTS
from mechsys.report.tables import Table


def instant_tables(inst: Instant) -> list[Table]:
    state = Table(f"state and accelerations at t = {inst.t:g}", ["coordinate", "value", "rate", "acceleration"])
    for name, q, u, a in zip(inst.coordinates, inst.q, inst.u, inst.accelerations):
        state.add(name, float(q), float(u), float(a))
    state.notes += inst.warnings
    tables = [state]
    if inst.driving:
        drives = Table("driving forces (what each drive supplies along its coordinate)", ["coordinate", "force"])
        for name, value in inst.driving.items():
            drives.add(name, value)
        tables.append(drives)
    if inst.multipliers:
        lam = Table("constraint multipliers (M q'' = f + A^T lambda)", ["constraint row", "lambda"])
        for name, value in inst.multipliers.items():
            lam.add(name, value)
        tables.append(lam)
    if inst.reactions:
        joints = Table("joint reactions on each link's subtree from its parent (ground axes, moments about the "
                       "joint origin)", ["link", *COMPONENTS])
        for link, w in inst.reactions.items():
            joints.add(link, *(float(x) for x in w))
        tables.append(joints)
    if inst.outputs:
        outs = Table("outputs", ["output", "value"])
        for name, value in inst.outputs.items():
            outs.add(name, value)
        tables.append(outs)
    return tables


def instant_payload(inst: Instant) -> dict:
    """The JSON object of `inverse -f json`, keyed by quantity."""
    return {
        "t": inst.t,
        "coordinates": {n: float(v) for n, v in zip(inst.coordinates, inst.q)},
        "rates": {n: float(v) for n, v in zip(inst.coordinates, inst.u)},
        "accelerations": {n: float(v) for n, v in zip(inst.coordinates, inst.accelerations)},
        "driving": inst.driving,
        "multipliers": inst.multipliers,
        "reactions": {link: dict(zip(COMPONENTS, (float(x) for x in w))) for link, w in inst.reactions.items()},
        "outputs": inst.outputs,
        "notes": inst.warnings,
    }
