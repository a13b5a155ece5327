"""The mechsys YAML language v1 as pydantic models (structure only; expressions are parsed later)."""
from __future__ import annotations

import math
from typing import Annotated, Literal, Union

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, field_validator, model_validator


def _expr(value: object) -> object:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        kind = {type(None): "nothing (null)", bool: "a boolean", list: "a list", dict: "a mapping"}.get(
            type(value), type(value).__name__)
        raise ValueError(f"expected a number or an expression, got {kind}")
    return value


Expr = Annotated[Union[int, float, str], BeforeValidator(_expr)]
"""A number or an expression string (parameters, coordinates, der(q), t; see docs/yaml-reference.md)."""
Vec3 = Annotated[list[Expr], Field(min_length=3, max_length=3)]
AxisName = Literal["x", "y", "z", "-x", "-y", "-z"]
Axis = Union[AxisName, Vec3]
PointRef = str
"""``link`` (its origin), ``link.com``, ``link.NAME`` (a named point), ``ground`` or ``ground.NAME``."""
Name = Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z_0-9]*$")]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)


# ----------------------------------------------------------------------------------------- coordinates
class Coordinate(Strict):
    """A generalized coordinate: free (initial value and rate) or prescribed as a function of ``t``."""

    initial: Expr = 0
    rate: Expr = 0
    prescribed: Expr | None = Field(None, description="expression of t and parameters (rheonomic driver)")
    angle: bool | None = Field(None, description="angular (wraps modulo 2*pi); default: inferred from joints")
    cyclic: bool | None = Field(None, description="ignorable: true declares it (checked), false denies it; "
                                                  "default: decided from the equations of motion")


# ----------------------------------------------------------------------------------------- inertia
class Inertia(Strict):
    """Inertia tensor components in link axes. Products are the integrals I_xy = ∫xy dm (book convention):
    the tensor holds -xy off the diagonal."""

    xx: Expr = 0
    yy: Expr = 0
    zz: Expr = 0
    xy: Expr = 0
    xz: Expr = 0
    yz: Expr = 0


class Rod(Strict):
    length: Expr
    axis: AxisName = "z"


class Disk(Strict):
    radius: Expr
    axis: AxisName = "z"


class Cylinder(Strict):
    radius: Expr
    length: Expr
    axis: AxisName = "z"


class Sphere(Strict):
    radius: Expr


class Box(Strict):
    size: Vec3


class Shape(Strict):
    """Exactly one shape helper: central inertia of a uniform body of the link's mass."""

    rod: Rod | None = None
    disk: Disk | None = None
    cylinder: Cylinder | None = None
    sphere: Sphere | None = None
    box: Box | None = None


# ----------------------------------------------------------------------------------------- joints
class _JointBase(Strict):
    parent: str = Field(description="parent link name, or 'ground'")
    origin: Vec3 | str = Field(default_factory=lambda: [0, 0, 0],
                               description="joint position in parent axes, or a named point of the parent")


class Revolute(_JointBase):
    type: Literal["revolute"]
    axis: Axis = "z"
    coordinate: Name


class Prismatic(_JointBase):
    type: Literal["prismatic"]
    axis: Axis = "x"
    coordinate: Name


class Cylindrical(_JointBase):
    type: Literal["cylindrical"]
    axis: Axis = "z"
    coordinates: Annotated[list[Name], Field(min_length=2, max_length=2)] = Field(
        description="[rotation angle, translation]")


class Universal(_JointBase):
    type: Literal["universal"]
    axes: Annotated[list[Axis], Field(min_length=2, max_length=2)] = Field(default_factory=lambda: ["x", "y"])
    coordinates: Annotated[list[Name], Field(min_length=2, max_length=2)]


class Spherical(_JointBase):
    type: Literal["spherical"]
    sequence: Annotated[str, Field(pattern=r"^[xyz]{3}$")] = "zyx"
    coordinates: Annotated[list[Name], Field(min_length=3, max_length=3)]


class Planar(_JointBase):
    type: Literal["planar"]
    normal: AxisName = "z"
    coordinates: Annotated[list[Name], Field(min_length=3, max_length=3)] = Field(
        description="[translation 1, translation 2, rotation about the normal]")


class Fixed(_JointBase):
    type: Literal["fixed"]


class Free(_JointBase):
    type: Literal["free"]
    sequence: Annotated[str, Field(pattern=r"^[xyz]{3}$")] = "zyx"
    coordinates: Annotated[list[Name], Field(min_length=6, max_length=6)] = Field(
        description="[x, y, z translations in parent axes, then three body-fixed rotation angles]")


class Rotate(Strict):
    axis: Axis
    angle: Expr


class Step(Strict):
    """One step of a general transform: a rotation or a translation (in the current axes)."""

    rotate: Rotate | None = None
    translate: Vec3 | None = None


class Transform(_JointBase):
    type: Literal["transform"]
    steps: list[Step] = Field(min_length=1)


Joint = Annotated[
    Union[Revolute, Prismatic, Cylindrical, Universal, Spherical, Planar, Fixed, Free, Transform],
    Field(discriminator="type"),
]


# ----------------------------------------------------------------------------------------- links
class Link(Strict):
    """A rigid body (or a particle) attached to its parent by a joint."""

    particle: bool = False
    joint: Joint
    mass: Expr = 0
    center_of_mass: Vec3 = Field(default_factory=lambda: [0, 0, 0])
    inertia: Inertia | None = None
    inertia_about: Literal["center_of_mass", "origin"] = "center_of_mass"
    shape: Shape | None = None
    points: dict[Name, Vec3] = Field(default_factory=dict)


class Ground(Strict):
    points: dict[Name, Vec3] = Field(default_factory=dict)


# ----------------------------------------------------------------------------------------- constraints
class HolonomicConstraint(Strict):
    type: Literal["holonomic"]
    name: str | None = None
    expression: Expr = Field(description="expression of coordinates and t that must stay 0")


class PointOnPoint(Strict):
    type: Literal["point_on_point"]
    name: str | None = None
    points: Annotated[list[PointRef], Field(min_length=2, max_length=2)]


class PointOnLine(Strict):
    type: Literal["point_on_line"]
    name: str | None = None
    point: PointRef
    through: PointRef
    direction: Axis
    frame: str = "ground"


class PointOnPlane(Strict):
    type: Literal["point_on_plane"]
    name: str | None = None
    point: PointRef
    through: PointRef
    normal: Axis
    frame: str = "ground"


class NonholonomicConstraint(Strict):
    type: Literal["nonholonomic"]
    name: str | None = None
    expression: Expr = Field(description="expression linear in the rates der(q) that must stay 0")


class Rolling(Strict):
    """Rolling without slip: the link's material point at the contact has the velocity of the surface."""

    type: Literal["rolling"]
    name: str | None = None
    link: str
    contact: Vec3 = Field(description="contact point relative to the link origin, in 'frame' axes")
    frame: str | None = Field(None, description="axes of 'contact' (a link or ground) that do not turn with the link: "
                                                "for a disk a frame that leans but does not spin, for a ball ground")
    on: str = Field("ground", description="the link rolled on")
    components: list[Literal["x", "y", "z"]] = Field(default_factory=lambda: ["x", "y", "z"],
                                                      description="velocity components (in 'axes')")
    axes: str = Field("ground", description="axes of 'components' (a link or ground): on an incline, the incline, "
                                            "so that [x, y] are its tangent directions and the rows' force is the "
                                            "friction")


Constraint = Annotated[
    Union[HolonomicConstraint, PointOnPoint, PointOnLine, PointOnPlane, NonholonomicConstraint, Rolling],
    Field(discriminator="type"),
]


# ----------------------------------------------------------------------------------------- forces
class Gravity(Strict):
    type: Literal["gravity"]
    acceleration: Vec3


class Force(Strict):
    type: Literal["force"]
    at: PointRef
    value: Vec3
    frame: str = Field("ground", description="axes of the components: ground or a link")


class Torque(Strict):
    type: Literal["torque"]
    on: str
    value: Expr | Vec3 = Field(description="a vector, or a scalar about 'axis'")
    axis: Axis | None = None
    frame: str | None = Field(None, description="axes of value/axis; default the link 'on'")
    reaction: str | None = Field(None, description="link (or ground) that receives the opposite torque")


class Spring(Strict):
    type: Literal["spring"]
    between: Annotated[list[PointRef], Field(min_length=2, max_length=2)]
    stiffness: Expr
    free_length: Expr = 0


class Damper(Strict):
    type: Literal["damper"]
    between: Annotated[list[PointRef], Field(min_length=2, max_length=2)]
    coefficient: Expr


class Actuator(Strict):
    type: Literal["actuator"]
    between: Annotated[list[PointRef], Field(min_length=2, max_length=2)]
    value: Expr = Field(description="force along the line; positive pushes the points apart")


class TorsionalSpring(Strict):
    type: Literal["torsional_spring"]
    coordinate: Name
    stiffness: Expr
    free_angle: Expr = 0


class TorsionalDamper(Strict):
    type: Literal["torsional_damper"]
    coordinate: Name
    coefficient: Expr


class GeneralizedForce(Strict):
    type: Literal["generalized_force"]
    coordinate: Name
    value: Expr


class Dissipation(Strict):
    type: Literal["dissipation"]
    value: Expr = Field(description="Rayleigh dissipation function D(q, der(q)); adds -dD/d(der(q))")


class Potential(Strict):
    type: Literal["potential"]
    value: Expr = Field(description="extra potential energy V(q, t)")


ForceSpec = Annotated[
    Union[Gravity, Force, Torque, Spring, Damper, Actuator, TorsionalSpring, TorsionalDamper, GeneralizedForce,
          Dissipation, Potential],
    Field(discriminator="type"),
]


# ----------------------------------------------------------------------------------------- events
class Event(Strict):
    """A zero crossing of an expression during simulation: recorded, or stopping the integration."""

    name: Name
    expression: Expr = Field(description="expression of coordinates, der(q), parameters and t")
    direction: Literal["rising", "falling", "both"] = "both"
    action: Literal["record", "stop"] = "record"


# ----------------------------------------------------------------------------------------- contacts
class ContactPlane(Strict):
    """A plane fixed in the link of ``point``: the side +normal is outside (gap > 0)."""

    point: PointRef = Field(description="a point of the plane; the plane moves with this point's link")
    normal: Axis = Field(description="outward normal of the plane, in 'frame' axes (parameters only)")
    frame: str | None = Field(None, description="axes of 'normal' (a link or ground); default the point's link")


class ContactLine(Strict):
    """A line in the x-y plane of ``frame``; the outside is to the left of ``direction`` (normal z x direction)."""

    point: PointRef = Field(description="a point of the line; the line moves with this point's link")
    direction: Axis = Field(description="direction of the line, in 'frame' axes (parameters only)")
    frame: str | None = Field(None, description="axes of 'direction' (a link or ground); default the point's link")


class PointPlane(Strict):
    """Gap = normal . (point - plane.point): a point of one link against a plane of another."""

    point: PointRef
    plane: ContactPlane


class SpherePlane(Strict):
    """Gap = normal . (center - plane.point) - radius: a sphere (or disk edge) against a plane."""

    center: PointRef
    radius: Expr
    plane: ContactPlane


class SphereSphere(Strict):
    """Gap = |center_a - center_b| - r_a - r_b; the normal points from b to a."""

    centers: Annotated[list[PointRef], Field(min_length=2, max_length=2)]
    radii: Annotated[list[Expr], Field(min_length=2, max_length=2)]


class PointLine(Strict):
    """Gap = signed 2-D distance of a point to a line: (z x direction) . (point - line.point)."""

    point: PointRef
    line: ContactLine


class Contact(Strict):
    """A contact pair for impacts: two points and a normal, a gap function (gap >= 0 means separated), or a named
    gap primitive (point_plane, sphere_plane, sphere_sphere, point_line)."""

    name: Name
    between: Annotated[list[PointRef], Field(min_length=2, max_length=2)] | None = Field(
        None, description="two points; the first is pushed along +normal, the second along -normal")
    normal: Axis | None = Field(None, description="contact normal (with 'between'), in 'frame' axes")
    frame: str = "ground"
    gap: Expr | None = Field(None, description="gap function of the coordinates (>= 0 separated); its gradient "
                                                "gives the normal direction in coordinate space")
    point_plane: PointPlane | None = Field(None, description="instead of 'gap': a point against a plane")
    sphere_plane: SpherePlane | None = Field(None, description="instead of 'gap': a sphere against a plane")
    sphere_sphere: SphereSphere | None = Field(None, description="instead of 'gap': two spheres")
    point_line: PointLine | None = Field(None, description="instead of 'gap': a point against a line (2-D)")
    restitution: Expr = Field(1, description="Newton's coefficient e (may depend on the approach speed 'vn')")
    friction: Expr = Field(0, description="Coulomb's coefficient mu >= 0 of the tangential impulse "
                                          "(parameters only; needs contact points: 'between' or a primitive)")


# ----------------------------------------------------------------------------------------- expectations
class Expectation(Strict):
    """An expected analysis result with its tolerance, checked by `mechsys check`."""

    name: str = Field(description="what the check is called in reports")
    analysis: Literal["info", "derive", "equilibria", "modes", "simulate", "bifurcations", "collide"]
    set: dict[str, Union[int, float, str]] = Field(default_factory=dict, description="overrides, like --set")
    options: dict[str, Union[int, float, str, bool]] = Field(default_factory=dict,
                                                             description="analysis options, e.g. t_end")
    output: str | None = Field(None, description="an output of the analysis, e.g. dof, eq2.beta, final.beta")
    equilibrium: dict[str, float] | None = Field(None, description="equilibria: some equilibrium has these values")
    stability: Literal["asymptotically stable", "stable", "unstable", "undecided"] | None = Field(
        None, description="with 'equilibrium': its expected verdict")
    expression: str | None = Field(None, description="derive: the expected expression of 'output' (e.g. M[1,1])")
    value: Union[int, float, str, bool, None] = None
    tolerance: float = Field(0.0, ge=0, description="absolute tolerance on 'value'")
    rel_tolerance: float = Field(0.0, ge=0, description="relative tolerance on 'value'")
    min: float | None = None
    max: float | None = None

    @model_validator(mode="after")
    def _can_fail(self) -> "Expectation":
        """An expectation that states nothing to compare would pass whatever the analysis gives (or crash): each
        kind must say what it expects, and keys that would be ignored are refused."""
        compared = [k for k in ("value", "min", "max") if getattr(self, k) is not None]
        for k in ("value", "min", "max", "tolerance", "rel_tolerance"):  # nan and inf never fail or never pass
            v = getattr(self, k)
            if isinstance(v, float) and not math.isfinite(v):
                raise ValueError(f"'{k}' must be a finite number, not {v}")
        if self.min is not None and self.max is not None and self.min > self.max:
            raise ValueError(f"'min' ({self.min:g}) is above 'max' ({self.max:g}): nothing can pass")
        if self.equilibrium is not None:
            if self.analysis != "equilibria":
                raise ValueError("'equilibrium' belongs to analysis: equilibria")
            if not self.equilibrium:
                raise ValueError("'equilibrium' is empty: give the coordinate values of the equilibrium expected")
            unused = compared + [k for k in ("output", "expression") if getattr(self, k) is not None]
            if unused:
                raise ValueError(f"{', '.join(repr(k) for k in unused)} is not used with 'equilibrium' (its values "
                                 "and 'stability' are the expectation)")
            return self
        if self.stability is not None:
            raise ValueError("'stability' needs 'equilibrium' (the coordinate values of the equilibrium it is about)")
        if self.output is None:
            raise ValueError("an expectation needs 'output' (or, for equilibria, 'equilibrium')")
        if self.analysis == "derive":
            if self.expression is None or compared:
                raise ValueError("a derive expectation compares an expression: give 'expression' (not value, min "
                                 "or max)")
        elif self.expression is not None:
            raise ValueError("'expression' belongs to analysis: derive")
        elif not compared:
            raise ValueError("nothing to compare: give 'value', 'min' or 'max' (an expectation without them passes "
                             "whatever the analysis gives)")
        return self


# ----------------------------------------------------------------------------------------- the file
class System(Strict):
    """A mechanical system: the root of a mechsys YAML file."""

    name: str
    description: str | None = None
    parameters: dict[Name, Expr] = Field(default_factory=dict)
    coordinates: dict[Name, Coordinate] = Field(default_factory=dict)
    ground: Ground = Field(default_factory=Ground)
    links: dict[Name, Link] = Field(min_length=1)
    constraints: list[Constraint] = Field(default_factory=list)
    forces: list[ForceSpec] = Field(default_factory=list)
    events: list[Event] = Field(default_factory=list)
    contacts: list[Contact] = Field(default_factory=list)
    outputs: dict[Name, Expr] = Field(default_factory=dict, description="named output quantities: expressions "
                                      "of t, coordinates, der(q), der(der(q)), parameters and the built-in "
                                      "quantities position(P), velocity(P), acceleration(P), angular_velocity(L), "
                                      "momentum(L|system), angular_momentum(L|system[, P]), kinetic_energy(L|system), "
                                      "momentum_of(q); columns of simulate results (docs/outputs.md)")
    expect: list[Expectation] = Field(default_factory=list)

    @field_validator("coordinates", mode="before")
    @classmethod
    def _none_is_default(cls, value: object) -> object:
        if isinstance(value, dict):
            return {k: ({} if v is None else v) for k, v in value.items()}
        return value


def json_schema() -> dict:
    """The JSON Schema of the language, for editor completion (``mechsys schema``)."""
    schema = System.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "mechsys model file (v1)"
    return schema
