"""Tables and JSON of `mechsys inverse`: one instant's accelerations, driving forces, multipliers and reactions."""
from __future__ import annotations

import numpy as np

from mechsys.analysis.motion.inverse import Instant
from mechsys.analysis.motion.reactions import COMPONENTS
from mechsys.report.tables import Table


def instant_tables(inst: Instant) -> list[Table]:
    """The state with its accelerations, then (when the model has them) the drives, the multipliers, the joint
    reactions and the outputs."""
    state = Table(f"state and accelerations at t = {inst.t:g}", ["coordinate", "value", "rate", "acceleration"])
    for name, q, u, a in zip(inst.coordinates, inst.q, inst.u, inst.accelerations):
        state.add(name, float(q), float(u), float(a))
    state.notes += inst.warnings
    sections = [("driving forces (what each drive supplies along its coordinate)", ["coordinate", "force"],
                 inst.driving),
                ("constraint multipliers (M q'' = f + A^T lambda)", ["constraint row", "lambda"], inst.multipliers),
                ("joint reactions on each link's subtree from its parent (ground axes, moments about the joint "
                 "origin)", ["link", *COMPONENTS], inst.reactions),
                ("outputs", ["output", "value"], inst.outputs)]
    tables = [state]
    for title, columns, values in sections:
        if values:
            table = Table(title, columns)
            for name, value in values.items():
                table.add(name, *(float(x) for x in np.atleast_1d(value)))
            tables.append(table)
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
