"""Render the `info` facts as a rich table, Markdown or JSON."""
from __future__ import annotations

import json
from typing import TYPE_CHECKING

from mechsys.analysis.facts import Info

if TYPE_CHECKING:
    from rich.console import Group


def render_json(info: Info) -> str:
    return json.dumps(info.to_dict(), indent=2) + "\n"


def _facts(info: Info) -> list[tuple[str, str]]:
    return [
        ("moving links n", str(info.moving_links)),
        ("mobility MO, loop rows included", str(info.mobility)),
        ("prescribed coordinates L", ", ".join(info.prescribed) or "0"),
        ("DOF by formula M = MO - L", str(info.dof_formula)),
        ("free coordinates", ", ".join(info.free_coordinates) or "none"),
        ("constraint equations / rank", f"{sum(c['equations'] for c in info.constraints)} / {info.constraint_rank}"),
        ("DOF (independent velocities)", str(info.dof)),
        ("configuration DOF", str(info.configuration_dof)),
        ("redundant constraints", str(info.redundant_constraints)),
        ("system class", info.system_class),
        ("cyclic coordinates", _cyclic(info)),
        ("massless coordinates", ", ".join(info.massless_coordinates) or "none"),
    ]


#: How each cyclic coordinate was decided, in the text outputs (JSON carries the bare keyword).
_BASIS = {"absent": "", "symbolic": " (after simplification)", "numeric": " (numerically, not proven)",
          "declared": " (declared)"}


def _cyclic(info: Info) -> str:
    text = ", ".join(f"{c}{_BASIS.get(info.cyclic_basis.get(c, 'absent'), '')}" for c in info.cyclic) or "none"
    if info.cyclic_denied:
        text += f"; not treated as cyclic (the file says so): {', '.join(info.cyclic_denied)}"
    return text


def render_markdown(info: Info) -> str:
    out = [f"# {info.name}", "", "| link | parent | joint | coordinates | class c | reactions |", "|---|---|---|---|---|---|"]
    for j in info.joints:
        out.append(f"| {j.link} | {j.parent} | {j.type} | {', '.join(j.coordinates) or '-'} | {j.joint_class} "
                   f"| {j.reactions} |")
    out += ["", "| fact | value |", "|---|---|"]
    out += [f"| {k} | {v} |" for k, v in _facts(info)]
    out += [""] + [f"- note: {n}" for n in info.notes]
    return "\n".join(out) + "\n"


def render_rich(info: Info) -> Group:  # -> rich renderable
    from rich.console import Group
    from rich.table import Table

    joints = Table(title=f"{info.name}: links and joints")
    for col in ("link", "parent", "joint", "coordinates", "class c", "reactions"):
        joints.add_column(col)
    for j in info.joints:
        joints.add_row(j.link, j.parent, j.type, ", ".join(j.coordinates) or "-", str(j.joint_class),
                       str(j.reactions))
    facts = Table(show_header=False, title="facts")
    facts.add_column("fact", style="bold")
    facts.add_column("value")
    for k, v in _facts(info):
        facts.add_row(k, v)
    parts = [joints, facts]
    if info.constraints:
        cons = Table(title="extra constraints")
        cons.add_column("type")
        cons.add_column("equations")
        for c in info.constraints:
            cons.add_row(c["type"], str(c["equations"]))
        parts.insert(1, cons)
    parts += [f"note: {n}" for n in info.notes]
    return Group(*parts)
