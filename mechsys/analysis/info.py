"""System facts: joints and classes, mobility MO = 6n - sum (6 - c) p_c, DOF, constraint ranks, system class."""
from __future__ import annotations

import numpy as np

from mechsys.analysis.crosscheck import random_states
from mechsys.analysis.facts import Info, JointRow
from mechsys.errors import AnalysisError
from mechsys.mechanics.dag import Evaluation
from mechsys.mechanics.model import INTERNAL_METHOD, MechanicalModel
from mechsys.numeric import cache, saddle
from mechsys.numeric.lambdify import matrix_source
from mechsys.numeric.runtime import matrix_from_source


def _rank(matrix: np.ndarray) -> int:
    """The numerical rank, relative to the matrix's own scale: a watch's balance wheel (I = 1.2e-10 kg m^2) or a
    MEMS linkage (lengths of 100 um) has entries far below 1, and a floor of 1 under the scale made its mass matrix
    singular and its loop's constraint rank 0."""
    if matrix.size == 0:
        return 0
    s = np.linalg.svd(matrix, compute_uv=False)
    return int(np.sum(s > 1e-9 * s[0])) if s[0] > 0 else 0


def _matrices(model: MechanicalModel):
    """The constraint Jacobian A and the mass matrix M as numeric functions of (t, q, u, p), their generated code
    cached on disk like the simulation's (keyed by the model's structure, parameters kept as symbols), so a second
    `info` on a model runs no CSE."""
    key = cache.model_key(model, "info")
    desc = cache.load(key)
    try:
        if desc is not None:
            return matrix_from_source(desc["A"]), matrix_from_source(desc["M"])
    except (KeyError, TypeError, ValueError, SyntaxError):
        pass  # another format: derive again
    args = (model.t, model.q, model.u, model.parameter_symbols)
    desc = {"A": matrix_source(model.constraint_jacobian, *args, light=True),  # evaluated at three states
            "M": matrix_source(model.equations(INTERNAL_METHOD).M, *args, light=True)}
    cache.store(key, desc)
    return matrix_from_source(desc["A"]), matrix_from_source(desc["M"])


def _at(model: MechanicalModel, states: list, p: list[float]) -> tuple[list, list]:
    """A and M at the states: over the DAGs, else compiled."""
    evaluated = _evaluated(model, states, p)
    if evaluated is None:
        A_fn, M_fn = _matrices(model)
        evaluated = ([A_fn(t, q, u, p) for t, q, u in states], [M_fn(t, q, u, p) for t, q, u in states])
    return evaluated


def _near_initial(model: MechanicalModel, states: list) -> list:
    """Sample states around the file's initial configuration (the first at it, the others 1e-3 (1 + |q|) away):
    a closed loop's constraints may have several branches of different rank (a parallelogram with a redundant bar
    moves on its parallelogram branch, DOF 1, but is rigid on the crossed one), and the file's configuration names
    the branch. The times and rates stay those of ``states``."""
    q0 = np.array([model.doc.initial.get(c, 0.0) for c in model.coordinates], dtype=float)
    rng = np.random.default_rng(11)
    return [(t, q0 + (0.0 if k == 0 else 1e-3 * (1 + np.abs(q0)) * rng.uniform(-1, 1, len(q0))), u)
            for k, (t, _q, u) in enumerate(states)]


def _onto_constraints(model: MechanicalModel, states: list, p: list[float]) -> list | None:
    """The sample states with their coordinates moved onto the holonomic constraints (Gauss-Newton on Phi = 0 with
    its Jacobian, the holonomic rows of A), those that get there; the states as they are without holonomic
    constraints; None when an entry cannot be evaluated over the DAG. The ranks are those of configurations the
    mechanism can take: off the constraints a parallelogram with a redundant third bar had rank 4 (DOF 0, nothing
    redundant), on them rank 3 (DOF 1, one redundant row)."""
    rows = [i for i, c in enumerate(model.kin.constraints) if c.kind == "holonomic"]
    if not rows:
        return states
    phi, jac = model.holonomic_constraints, model.constraint_jacobian[rows, :]
    out = []
    for t, q, u in states:
        q = np.array(q, dtype=float)
        for _ in range(50):
            point = Evaluation({model.t: t, **dict(zip(model.q, q)), **dict(zip(model.parameter_symbols, p))})
            values = [point.of(e) for e in phi]
            slopes = [point.of(e) for e in jac]
            if None in values or None in slopes:
                return None
            r = np.array([v for v, _ in values], dtype=float)
            if np.max(np.abs(r)) <= 1e-12 * (1 + np.max(np.abs(q))):
                out.append((t, q, u))
                break
            J = np.array([v for v, _ in slopes], dtype=float).reshape(len(rows), len(q))
            q = q - np.linalg.lstsq(J, r, rcond=None)[0]
    return out


def _evaluated(model: MechanicalModel, states: list, p: list[float]) -> tuple[list, list] | None:
    """A and M at the states in floating point, over their expression DAGs (dag.Evaluation: each shared node once;
    three states need no compiled code: the 80-link chain's M took 22 s to generate and compile); None when an
    entry is not a finite value of sums, products, powers and elementary functions (then _matrices compiles)."""
    mats = (model.constraint_jacobian, model.equations(INTERNAL_METHOD).M)
    out: tuple[list, list] = ([], [])
    for t, q, u in states:
        point = Evaluation({model.t: t, **dict(zip(model.q, q)), **dict(zip(model.u, u)),
                            **dict(zip(model.parameter_symbols, p))})
        for mat, values in zip(mats, out):
            entries = [point.of(e) for e in mat]
            if None in entries:
                return None
            values.append(np.array([v for v, _ in entries], dtype=float).reshape(mat.shape))
    return out


def system_info(model: MechanicalModel) -> Info:
    kin = model.kin
    joints = [JointRow(j.link, j.parent, j.type, j.coordinates, j.joint_class, j.reactions) for j in kin.joints]
    constraint_rows = [{"type": t, "equations": n} for t, n in kin.constraint_elements]
    n = len(joints)
    mobility = 6 * n - sum(6 - min(j.joint_class, 6) for j in joints) - sum(c["equations"] for c in constraint_rows)
    # L of the DOF formula: the prescribed coordinates that joints use (one used only in a force, or to move a
    # joint's origin, adds no joint freedom to subtract; yaml-reference: coordinates)
    prescribed = [c for c in model.prescribed if any(c in j.coordinates for j in kin.joints)]
    params = model.parameter_symbols
    p = [model.parameters[s.name] for s in params]
    states = random_states(model, 3, seed=7)  # M (massless coordinates) at configurations in general position
    notes = []
    ranked = states  # A at configurations the mechanism can take
    if model.kin.constraints:
        assembled = _onto_constraints(model, _near_initial(model, states), p)
        if assembled:
            ranked = assembled
        elif assembled is not None:
            notes.append("the closed-loop constraints could not be met near the initial configuration (can the loop "
                         "be assembled?): the ranks are those of configurations off the constraints")
    As, Ms = _at(model, states, p)
    if ranked is not states:
        As = _at(model, ranked, p)[0]
    hol = [i for i, c in enumerate(kin.constraints) if c.kind == "holonomic"]
    rank = max(_rank(A) for A in As)
    hol_rank = max(_rank(A[hol, :]) for A in As) if hol else 0
    nfree = len(model.q)
    dof = nfree - rank
    massless = []
    if nfree:
        if not all(np.all(np.isfinite(M)) for M in Ms):
            raise AnalysisError("the mass matrix is not finite at sample states (an overflow or a division by zero: "
                                "check the parameter values, e.g. a mass of 1e200 squared)")
        massless = [c for i, c in enumerate(model.coordinates)  # relative to M's own scale, as _rank
                    if all(abs(M[i, i]) <= 1e-12 * float(np.max(np.abs(M))) for M in Ms)]
        dq = saddle.balance(Ms[0], np.zeros((0, nfree)))[0]  # each coordinate in its own units: a disk's
        if _rank(dq[:, None] * Ms[0] * dq) < nfree:  # m = 2e-9 kg beside m r^2 = 2e-18 kg m^2 is not singular
            notes.append("the mass matrix is singular (massless coordinates need condensation or constraints)")
    dof_formula = mobility - len(prescribed)
    redundant = max(0, len(kin.constraints) - rank)
    if dof != dof_formula:
        notes.append(f"the mobility formula gives {dof_formula} DOF but the constraint Jacobian's rank {rank} "
                     f"gives {nfree} - {rank} = {dof}: the formula counts dependent constraint equations (e.g. "
                     f"spatial counting of a planar loop, or rolling rows of which some are dependent)")
    return Info(
        name=model.name, moving_links=n, joints=joints, constraints=constraint_rows, mobility=mobility,
        prescribed=prescribed, dof_formula=dof_formula, free_coordinates=list(model.coordinates),
        constraint_rank=rank, holonomic_rank=hol_rank, dof=dof, configuration_dof=nfree - hol_rank,
        redundant_constraints=redundant, holonomic=model.is_holonomic, rheonomic=model.is_rheonomic,
        autonomous=model.is_autonomous() and not model.moving_constraints, cyclic=model.cyclic_coordinates(),
        cyclic_basis=dict(model.cyclic_decision.basis), cyclic_denied=list(model.cyclic_decision.denied),
        massless_coordinates=massless,
        notes=notes)
