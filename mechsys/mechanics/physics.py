"""The model as sympy.physics.mechanics objects (frames, points, bodies, loads), and sympy's KanesMethod on them."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import sympy as sp
from sympy.physics import mechanics as me

from mechsys.mechanics.kinematics import FrameState

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel


@dataclass
class PhysicsModel:
    """sympy.physics.mechanics objects of a MechanicalModel, in dynamicsymbols q(t), u(t).

    ``extra_forces`` holds the generalized forces of elements that are not forces or torques on bodies
    (potentials other than gravity, springs on coordinates, dissipation functions, generalized forces).
    """

    N: me.ReferenceFrame
    origin: me.Point
    frames: dict[str, me.ReferenceFrame]
    points: dict[str, me.Point]
    bodies: list
    loads: list
    q: list
    u: list
    kd_eqs: list
    extra_forces: sp.Matrix
    to_symbols: dict = field(default_factory=dict)


def physics_model(model: MechanicalModel) -> PhysicsModel:
    """Build frames, points, rigid bodies/particles and loads for ``model`` (a MechanicalModel)."""
    qd = [me.dynamicsymbols(f"q_{n}") for n in model.coordinates]
    ud = [me.dynamicsymbols(f"u_{n}") for n in model.coordinates]
    tt = me.dynamicsymbols._t
    subs = {**dict(zip(model.q, qd)), **dict(zip(model.u, ud)), model.t: tt}
    back = {**{v: k for k, v in zip(model.q, qd)}, **{v: k for k, v in zip(model.u, ud)}, tt: model.t}

    def s(x):
        return sp.sympify(x).xreplace(subs)

    N = me.ReferenceFrame("N")
    O = me.Point("O")
    O.set_vel(N, 0)
    frames: dict[str, me.ReferenceFrame] = {}
    for name, fs in model.kin.frames.items():
        B = me.ReferenceFrame(name)
        R = fs.R.applyfunc(s)
        B.orient_explicit(N, R)
        if (N.dcm(B) - R).applyfunc(sp.expand) != sp.zeros(3, 3):
            B.orient_explicit(N, R.T)  # the other convention of older sympy versions
        w = fs.omega.applyfunc(s)
        B.set_ang_vel(N, w[0] * B.x + w[1] * B.y + w[2] * B.z)
        frames[name] = B

    def vec(m: sp.Matrix, frame: me.ReferenceFrame) -> me.Vector:
        m = m.applyfunc(s)
        return m[0] * frame.x + m[1] * frame.y + m[2] * frame.z

    def home(fs: FrameState, name: str) -> me.ReferenceFrame:
        return N if fs.pure else frames[name]

    points: dict[str, me.Point] = {}
    bodies = []
    loads = []
    for b, r, v, _w, fs in model._body_kinematics:
        P = me.Point(f"{b.name}_G")
        P.set_pos(O, vec(r, N))
        P.set_vel(N, vec(v, home(fs, b.name)))
        points[b.name] = P
        if b.particle:
            bodies.append(me.Particle(b.name, P, s(b.mass)))
        else:
            B = frames[b.name]
            I = b.inertia.applyfunc(s)
            dyadic = me.inertia(B, I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[1, 2], I[2, 0])
            bodies.append(me.RigidBody(b.name, P, B, s(b.mass), (dyadic, P)))
    n = len(model.q)
    extra = sp.zeros(n, 1)
    for k, load in enumerate(model.kin.loads):
        d = load.data
        if load.kind == "gravity":
            for b, *_rest in model._body_kinematics:
                if b.mass != 0:
                    loads.append((points[b.name], s(b.mass) * vec(d["g"], N)))
        elif load.kind == "torque":
            # d["M"] acts on a frame whose angular velocity relative to the torque axes is d["w"]; sympy needs
            # a frame: use a helper frame with that angular velocity, expressed in ground axes.
            T = me.ReferenceFrame(f"torque{k}")
            T.orient_explicit(N, sp.eye(3))
            w = d["w"].applyfunc(s)
            T.set_ang_vel(N, w[0] * N.x + w[1] * N.y + w[2] * N.z)
            loads.append((T, vec(d["M"], N)))
        elif load.kind == "force":
            P = me.Point(f"force{k}")
            P.set_vel(N, vec(d["v"], N))
            loads.append((P, vec(d["F"], N)))
        else:
            extra += _generalized(model, load)
    extra = extra.applyfunc(s)
    kd = [ui - qi.diff(tt) for qi, ui in zip(qd, ud)]
    return PhysicsModel(N, O, frames, points, bodies, loads, qd, ud, kd, extra, back)


def _generalized(model, load) -> sp.Matrix:
    """Generalized force of one non-body load: -dV/dq of its potential plus its non-potential part."""
    V = model._elastic_potential(load.kind, load.data)
    out = -sp.Matrix([sp.diff(V, q) for q in model.q]) if V != 0 else sp.zeros(len(model.q), 1)
    return out + model.nonconservative_forces([load])


def sympy_kane(model: MechanicalModel) -> tuple[sp.Matrix, sp.Matrix]:
    """M and f from sympy.physics.mechanics.KanesMethod on the physics objects (unconstrained systems),
    translated back to mechsys symbols; used to validate mechsys's own derivations."""
    pm = physics_model(model)
    kane = me.KanesMethod(pm.N, q_ind=pm.q, u_ind=pm.u, kd_eqs=pm.kd_eqs)
    kane.kanes_equations(pm.bodies, pm.loads)
    M = kane.mass_matrix
    f = kane.forcing + pm.extra_forces
    qdots = {qi.diff(me.dynamicsymbols._t): ui for qi, ui in zip(pm.q, pm.u)}
    back = pm.to_symbols
    return M.xreplace(qdots).xreplace(back), f.xreplace(qdots).xreplace(back)
