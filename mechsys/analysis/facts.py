"""The facts `info` reports, as plain data (no sympy: a warm `info` renders them from the cache)."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields


@dataclass
class JointRow:
    link: str
    parent: str
    type: str
    coordinates: list[str]
    joint_class: int
    reactions: int


@dataclass
class Info:
    name: str
    moving_links: int
    joints: list[JointRow]
    constraints: list[dict]
    mobility: int
    prescribed: list[str]
    dof_formula: int
    free_coordinates: list[str]
    constraint_rank: int
    holonomic_rank: int
    dof: int
    configuration_dof: int
    redundant_constraints: int
    holonomic: bool
    rheonomic: bool
    autonomous: bool
    cyclic: list[str]
    cyclic_basis: dict[str, str] = field(default_factory=dict)  # absent | symbolic | numeric | declared
    cyclic_denied: list[str] = field(default_factory=list)  # `cyclic: false` in the file
    massless_coordinates: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def system_class(self) -> str:
        parts = ["holonomic" if self.holonomic else "nonholonomic",
                 "rheonomic" if self.rheonomic else "scleronomic",
                 "autonomous" if self.autonomous else "non-autonomous"]
        return ", ".join(parts)

    def to_dict(self) -> dict:
        out = asdict(self)
        out["system_class"] = self.system_class
        return out

    @classmethod
    def from_dict(cls, data: dict) -> "Info":
        """The Info whose to_dict() is ``data`` (TypeError or ValueError when it is not of that shape)."""
        names = {f.name for f in fields(cls)}
        if not isinstance(data, dict) or not names <= set(data):
            raise ValueError("not the facts of info")
        values = {k: data[k] for k in names}
        values["joints"] = [JointRow(**row) for row in values["joints"]]
        info = cls(**values)
        if info.to_dict() != data:
            raise ValueError("not the facts of info")
        return info
