"""Rotation charts: where a joint's angles stop determining its angular velocity (gimbal lock), and how a steady
motion found there is classified in a regular sequence of the same joint instead."""
from __future__ import annotations

import copy
import itertools
import math
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mechsys.analysis.equilibrium.equilibria import Equilibrium, EquilibriumProblem
from mechsys.numeric.parameters import parameter_values
from mechsys.numeric import cache
from mechsys.numeric.lambdify import compile_exprs, generate_source
from mechsys.numeric.runtime import function_from_source
from mechsys.numeric.rotations import alternatives, angles_of, canonical, rate_matrix, ratio, rotation

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel

#: The chart is singular where the smallest singular value of the joint's map (angle rates -> angular velocity),
#: relative to the largest, is below this.
SINGULAR = 1e-7
#: A re-chart is accepted only where that ratio is at least this (well away from its own singular set).
REGULAR = 0.2

@dataclass
class Singularity:
    link: str
    joint_type: str
    angles: list[str]
    sequence: str | None
    ratio: float

    def describe(self) -> str:
        chart = f"the {self.sequence} angles" if self.sequence else "the angles"
        return (f"coordinate singularity: {chart} ({', '.join(self.angles)}) of the {self.joint_type} joint of "
                f"'{self.link}' do not determine its angular velocity here (gimbal lock: two rotation axes are "
                f"parallel)")


def rotation_joints(model: MechanicalModel) -> list[tuple]:
    """(joint info, angle coordinates, sequence) for every joint with two or more free angle coordinates."""
    out = []
    for j in model.kin.joints:
        names = [n for n in j.coordinates if n in model.coordinates and model.angles.get(n, False)]
        if len(names) >= 2:
            spec = model.doc.spec.links[j.link].joint
            sequence = getattr(spec, "sequence", None) if j.type in ("spherical", "free") else None
            out.append((j, names, sequence))
    return out


def _rate_map(model, link: str, names: list[str]):
    """Compiled d(omega of link)/d(rates of names) as a function of (q..., parameters...)."""
    memo = model.__dict__.setdefault("_chart_memo", {})
    key = (link, tuple(names))
    if key not in memo:
        omega = model.kin.frames[link].omega
        W = omega.jacobian([model.doc.rates[n] for n in names])
        memo[key] = compile_exprs(list(W), list(model.q) + list(model.parameter_symbols))
    return memo[key]


def singularities(model: MechanicalModel, coordinates: dict[str, float], p: np.ndarray) -> list[Singularity]:
    """The rotation joints whose angles are singular at this configuration (cyclic coordinates absent: at 0)."""
    q = [coordinates.get(c, 0.0) for c in model.coordinates]
    found = []
    for j, names, sequence in rotation_joints(model):
        W = np.array(_rate_map(model, j.link, names)(*q, *p), dtype=float).reshape(3, len(names))
        sv = np.linalg.svd(W, compute_uv=False)
        r = float(sv[-1] / sv[0]) if sv[0] > 0 else 0.0
        if r < SINGULAR:
            found.append(Singularity(j.link, j.type, names, sequence, r))
    return found


# ----------------------------------------------------------------------------------------- re-charting
_NAME = re.compile(r"[A-Za-z_][A-Za-z_0-9]*")
#: keys whose values are names or choices, not expressions of the file (a joint's own coordinates among them)
_NOT_EXPRESSIONS = frozenset({"type", "parent", "sequence", "name", "description", "coordinates", "units"})


def named_angles(model: MechanicalModel, angles: list[str]) -> str | None:
    """Where the file names one of ``angles`` outside the joints' own coordinate lists (a force's or a constraint's
    expression, der() included, the coordinate a force acts on, a link's geometry), as a path; None when it does
    not. Another sequence of the joint gives those names other angles, so re-charting would change what they
    define: a top's spin damping written -b*(der(psi)*cos(theta) + der(phi)) in zxz angles, read in zyx angles,
    turned 0.57 off in its rotation matrix within 2 s while the energy balance held to 1e-11. What the kinematics
    derive from the joints (positions, velocities, springs between points) is derived again in the other sequence
    and is not affected; outputs are evaluated in the file's angles."""
    wanted = set(angles)
    raw = model.doc.raw if isinstance(model.doc.raw, dict) else {}

    def walk(node, path: str) -> str | None:
        if isinstance(node, dict):
            for key, value in node.items():
                if key not in _NOT_EXPRESSIONS:
                    found = walk(value, f"{path}.{key}")
                    if found:
                        return found
        elif isinstance(node, list):
            for k, value in enumerate(node):
                found = walk(value, f"{path}[{k}]")
                if found:
                    return found
        elif isinstance(node, str):
            hit = sorted(wanted & set(_NAME.findall(node)))
            if hit:
                return f"{path} names {hit[0]}"
        return None

    for section in ("forces", "constraints", "links", "ground"):
        found = walk(raw.get(section), section)
        if found:
            return found
    return None


def _chart_model(model, link: str, sequence: str):
    """The same model with the joint of ``link`` written in ``sequence`` (derived once, kept on the model)."""
    memo = model.__dict__.setdefault("_chart_models", {})
    if (link, sequence) not in memo:
        from mechsys.mechanics.model import MechanicalModel

        doc = copy.copy(model.doc)
        spec = doc.spec.model_copy(deep=True)
        spec.links[link].joint.sequence = sequence
        doc.spec = spec
        doc.raw = copy.deepcopy(doc.raw)  # the compiled-code cache keys hash the file's structure: say it too
        doc.raw["links"][link]["joint"]["sequence"] = sequence
        chart = MechanicalModel(doc)
        # another sequence of a joint's angles adds no time dependence: the model's decision stands (deciding it
        # again scanned each chart's equations, seconds per chart of a chain of boxes)
        chart.__dict__["_autonomous"] = dict(model.__dict__.get("_autonomous", {}))
        memo[(link, sequence)] = chart
    return memo[(link, sequence)]


def reclassify(problem: EquilibriumProblem, e: Equilibrium, where: Singularity, p: np.ndarray) -> tuple | None:
    """Classify ``e`` (found at a singular point of ``where``'s chart) in a regular sequence of the same joint.
    Returns the steady motion's identity there (sequence, rounded state): roots of the singular chart that are
    one steady motion share it. None when it is not a steady motion there (an artefact of the singular chart).
    Raises Unchartable with the reason when no regular chart can be used."""
    from mechsys.analysis.equilibrium.stability import assess

    if where.sequence is None:
        raise Unchartable("only spherical and free joints can be re-charted (another rotation sequence)")
    if problem.m:
        raise Unchartable("re-charting is not available with closed-loop constraints")
    named = named_angles(problem.model, where.angles)
    if named:
        raise Unchartable(f"{named}, which another sequence of the joint would change")
    a_old = np.array([e.coordinates.get(n, 0.0) for n in where.angles])
    rates_old = np.array([e.rates.get(n, 0.0) for n in where.angles])
    R = rotation(where.sequence, a_old)
    omega = rate_matrix(where.sequence, a_old) @ rates_old
    best = None
    keep = "first" if where.angles[0] in problem.cyclic else "last" if where.angles[-1] in problem.cyclic else "any"
    for seq in alternatives(where.sequence, keep):
        a = angles_of(seq, R)
        if a is not None and (best is None or ratio(rate_matrix(seq, a)) > best[2]):
            best = (seq, a, ratio(rate_matrix(seq, a)))
    if best is None or best[2] < REGULAR:
        raise Unchartable("no other sequence of the joint is regular here")
    seq, a_new, _ = best
    rates_new = np.linalg.solve(rate_matrix(seq, a_new), omega)
    base = _chart_model(problem.model, where.link, seq)
    values = {n: float(v) for n, v in zip(where.angles, a_new)}
    values.update({f"der({n})": float(v) for n, v in zip(where.angles, rates_new)})
    values.update({f"der({c})": float(v) for c, v in e.rates.items() if c not in where.angles})
    values.update({s.name: float(v) for s, v in zip(problem.model.parameter_symbols, p)})  # a sweep's values
    alt = base.with_overrides(values)
    other = EquilibriumProblem(alt)
    moving = [n for n, v in zip(where.angles, rates_new) if abs(v) > 1e-9 * (1 + np.max(np.abs(rates_new)))
              and n not in other.cyclic]
    if moving:
        raise Unchartable(f"in the {seq} sequence the motion turns the non-cyclic angle(s) {', '.join(moving)}")
    coords = {c: values.get(c, e.coordinates.get(c, 0.0)) for c in other.free}
    rates = {c: values.get(f"der({c})", e.rates.get(c, 0.0)) for c in other.cyclic}
    e2 = Equilibrium(coords, rates, [])
    q2 = parameter_values(alt)
    z = other.state(e2)
    F = other.F(z, q2)
    if not np.all(np.isfinite(F)) or (F.size and np.max(np.abs(F)) > 1e-8 * _residual_scale(other, z, q2)):
        return None
    assess(other, e2, q2)
    e.eigenvalues, e.jacobian, e.critical = e2.eigenvalues, None, e2.critical
    e.stability = e2.stability
    e.reason = (f"classified in the {seq} sequence of the joint of '{where.link}' (the {where.sequence} angles are "
                f"singular here: gimbal lock); {e2.reason}")
    z = other.normalize(z)
    return (where.link, seq) + tuple(round(float(x), 6) + 0.0 for x in z)


def _residual_scale(problem: EquilibriumProblem, z: np.ndarray, p: np.ndarray) -> float:
    """The size of the rest equations' terms at z: the largest absolute value met evaluating them (dag.Evaluation:
    each shared node once, nothing compiled), at least 1; a residual below 1e-8 of it is round-off. The largest
    entry of their compiled Jacobian served before: compiling it was 60 % of the re-charting of a spinning chain
    of boxes on spherical joints, whose roots at a gimbal lock are mostly no steady motion in a regular chart."""
    from mechsys.mechanics.dag import Evaluation

    point = Evaluation(dict(zip(problem._args, [*z, *problem.extra(), *p])))
    sizes = [point.of(e) for e in problem.residual_exprs]
    return max([1.0, *(size for _, size in filter(None, sizes))])


def _state_fn(model):
    """Compiled physical state of every massive link at (q, u): centre-of-mass position and velocity in ground
    axes, and for rigid bodies the orientation and the angular velocity (ground axes); last, the potential energy,
    which sees what the masses do not (a spring on a massless sleeve's slider: two snap-through rests with the same
    mass positions and spring energies 8 and 128 were one). Two roots with the same physical state are one steady
    motion, whatever coordinates describe it."""
    memo = model.__dict__.setdefault("_chart_memo", {})
    if "state" not in memo:
        # the generated code is cached on disk like the simulation's (a bicycle's: a second of CSE per command)
        key = cache.model_key(model, "chart-state")
        entry = cache.load(key) or {}
        try:
            memo["state"] = function_from_source(entry["source"])
        except (KeyError, TypeError, ValueError, SyntaxError):  # absent, or not what this version writes
            import sympy as sp

            parts = []
            for body, r, v, w, frame in model._body_kinematics:
                # the velocity propagated link by link, mapped to ground axes (differentiating r: 4x the time)
                parts += list(r) + list(frame.home_R * v)
                if not body.particle:
                    parts += list(frame.R) + list(frame.R * w)
            parts.append(model.potential_energy)
            args = list(model.q) + list(model.u) + list(model.parameter_symbols) + [model.t]
            source = generate_source([sp.sympify(x) for x in parts], args)
            cache.store(key, {"source": source})
            memo["state"] = function_from_source(source)
    return memo["state"]


def _physical(problem: EquilibriumProblem, e: Equilibrium, p: np.ndarray, shift: dict[str, float]) -> np.ndarray:
    model = problem.model
    q = [e.coordinates.get(c, 0.0) + shift.get(c, 0.0) for c in model.coordinates]
    u = [e.rates.get(c, 0.0) for c in model.coordinates]
    return np.array(_state_fn(model)(*q, *u, *p, 0.0), dtype=float)


def _state(problem: EquilibriumProblem, e: Equilibrium, p: np.ndarray, shift: dict[str, float],
           memo: dict | None) -> np.ndarray:
    """_physical, remembered in ``memo`` by every number it reads (None: not remembered)."""
    if memo is None:
        return _physical(problem, e, p, shift)
    key = (tuple(e.coordinates.items()), tuple(e.rates.items()), np.asarray(p, dtype=float).tobytes(),
           tuple(shift.items()))
    if key not in memo:
        memo[key] = _physical(problem, e, p, shift)
    return memo[key]


def _reference(problem: EquilibriumProblem, a: Equilibrium, p: np.ndarray, memo: dict | None
               ) -> tuple[np.ndarray, float]:
    """The physical state of ``a`` and the tolerance the other motion's state is compared with."""
    ref = _state(problem, a, p, {}, memo)
    tol = np.full(ref.shape, 1e-7 * (1.0 + float(np.max(np.abs(ref[:-1]), initial=0.0))))
    tol[-1:] = 1e-7 * (1.0 + float(np.max(np.abs(ref[-1:]), initial=0.0)))  # the potential energy on its own scale
    return ref, tol


def _shifted_states(problem: EquilibriumProblem, b: Equilibrium, p: np.ndarray, memo: dict | None):
    """The physical states of ``b`` with each cyclic angle turned by nothing or a half turn (lazily)."""
    turning = [c for c in problem.cyclic if problem.angles.get(c, False)][:3]
    for halves in itertools.product((0.0, math.pi), repeat=len(turning)):
        yield _state(problem, b, p, dict(zip(turning, halves)), memo)


def same_motion(problem: EquilibriumProblem, a: Equilibrium, b: Equilibrium, p: np.ndarray,
                memo: dict | None = None) -> bool:
    """``a`` and ``b`` are one steady motion: the same physical state of every massive link, up to a half turn of
    each cyclic angle (a rotation sequence reaches every orientation twice, (psi, theta, phi) and
    (psi + pi, pi - theta, phi + pi); a prismatic coordinate along a turning axis reaches each point twice).
    ``memo``: the physical states already computed, by every number they read (a sweep compares many pairs)."""
    if any(abs(a.rates.get(c, 0.0) - b.rates.get(c, 0.0)) > 1e-7 * (1 + abs(a.rates.get(c, 0.0))) for c in a.rates):
        return False
    ref, tol = _reference(problem, a, p, memo)
    return any(bool(np.all(np.abs(state - ref) <= tol)) for state in _shifted_states(problem, b, p, memo))


class _Motions:
    """Steady motions kept so far, each new one compared with all of them at once (numpy arrays of their rates,
    physical states and tolerances): same_motion(kept, new) for every kept motion, which review asked pair by
    pair, quadratic in the roots in Python (the 20-link chain's 504 roots: 127,000 pairs)."""

    def __init__(self, problem: EquilibriumProblem, p: np.ndarray, memo: dict) -> None:
        self.problem, self.p, self.memo = problem, p, memo
        self.names: list[str] | None = None
        self.rates: list[list[float]] = []
        self.refs: list[np.ndarray] = []
        self.tols: list[np.ndarray] = []

    def _rates(self, e: Equilibrium) -> list[float]:
        """The rates in the kept motions' order (one problem's motions share the rates' names)."""
        if self.names is None:
            self.names = list(e.rates)
        return [e.rates.get(c, 0.0) for c in self.names]

    def first_same(self, e: Equilibrium) -> int | None:
        """The position (in the order kept) of the first kept motion that is ``e``, or None."""
        if not self.refs:
            return None
        kept_rates, rates = np.array(self.rates, dtype=float), np.array(self._rates(e), dtype=float)
        match = ~np.any(np.abs(kept_rates - rates) > 1e-7 * (1 + np.abs(kept_rates)), axis=1)
        refs, tols = np.array(self.refs), np.array(self.tols)
        same = np.zeros(len(refs), dtype=bool)
        for state in _shifted_states(self.problem, e, self.p, self.memo):
            same |= np.all(np.abs(refs - state) <= tols, axis=1)
        hits = np.flatnonzero(match & same)
        return int(hits[0]) if hits.size else None

    def keep(self, e: Equilibrium, at: int | None = None) -> None:
        """Remember ``e`` as a new kept motion, or in place of the one at position ``at``."""
        ref, tol = _reference(self.problem, e, self.p, self.memo)
        row = (self._rates(e), ref, tol)
        if at is None:
            self.rates.append(row[0])
            self.refs.append(row[1])
            self.tols.append(row[2])
        else:
            self.rates[at], self.refs[at], self.tols[at] = row


def _conventional(problem: EquilibriumProblem, e: Equilibrium) -> bool:
    """Rotation angles in their conventional triple, and no negative prismatic coordinate (display preference)."""
    for _j, names, sequence in rotation_joints(problem.model):
        if sequence is not None and len(names) == 3:
            a = [e.coordinates.get(n, 0.0) for n in names]
            if any(abs(math.remainder(x - y, 2 * math.pi)) > 1e-9 for x, y in zip(a, canonical(sequence, a))):
                return False
    return all(v >= 0 or problem.angles.get(c, False) for c, v in e.coordinates.items())


class Unchartable(Exception):
    """No regular chart is available for an equilibrium at a coordinate singularity."""


def review(problem: EquilibriumProblem, equilibria: list[Equilibrium], p: np.ndarray) -> tuple[list[Equilibrium], str]:
    """Equilibria at a singular point of a rotation chart: classified in a regular chart, or 'undecided' with the
    reason; candidates that are no steady motion in a regular chart (artefacts of the singular one) are dropped.
    Returns the equilibria kept and a note (empty when nothing happened)."""
    kept, dropped, undecided, seen, regular = [], 0, 0, set(), []
    motions = _Motions(problem, p, {})  # the regular ones, in the order of `regular`
    # the singular ones kept: one steady motion is a continuum of the singular chart's angles (zxz at theta = pi:
    # only psi - phi counts), re-charted to whichever sequence is best at each point (a box's rest at the zxz lock
    # was listed three times, twice in xzy and once in xyz)
    locked = _Motions(problem, p, motions.memo)
    for e in equilibria:
        found = singularities(problem.model, e.coordinates, p)
        if not found:
            j = motions.first_same(e)
            if j is None:
                regular.append(len(kept))
                kept.append(e)
                motions.keep(e)
            elif _conventional(problem, e) and not _conventional(problem, kept[regular[j]]):
                kept[regular[j]] = e  # show the conventional coordinates (e.g. |theta| <= pi/2 for zyx, r >= 0)
                motions.keep(e, j)
            continue
        if locked.first_same(e) is not None:
            continue
        where = found[0]
        e.chart = where.describe()
        try:
            recharted = reclassify(problem, e, where, p)
            if recharted is None:
                dropped += 1
                continue
            if recharted in seen:
                continue  # the same steady motion, reached at another point of the singular chart's continuum
            seen.add(recharted)
        except (Unchartable, np.linalg.LinAlgError) as exc:
            undecided += 1
            _undecided(e, where, str(exc))
        kept.append(e)
        locked.keep(e)
    notes = []
    if dropped:
        notes.append(f"{dropped} solution(s) at a gimbal-lock point are not steady motions in a regular chart "
                     f"(artefacts of the singular angles) and are not listed")
    if undecided:
        notes.append(_undecided_note(undecided, "equilibri" + ("um is" if undecided == 1 else "a are")))
    return kept, "; ".join(notes)


def mark_unchartable(problem: EquilibriumProblem, equilibria: list[Equilibrium],
                     p: np.ndarray) -> tuple[list[Equilibrium], str]:
    """review for systems with velocity constraints: a steady motion at a singular point of a rotation chart is
    kept as 'undecided' with the reason (its linearization, read off the singular chart, is meaningless: a rolling
    ball pushed by a force had made-up steady motions at the zyx gimbal lock, 'unstable' with eigenvalues of 4e8),
    since re-charting solves the holonomic rest equations only. Returns the equilibria and a note."""
    undecided = 0
    for e in equilibria:
        found = singularities(problem.model, e.coordinates, p)
        if found:
            undecided += 1
            e.chart = found[0].describe()
            _undecided(e, found[0], "re-charting is not available for systems with velocity constraints")
    plural = "steady motion is" if undecided == 1 else "steady motions are"
    return equilibria, _undecided_note(undecided, plural) if undecided else ""


def _undecided(e: Equilibrium, where: Singularity, why: str) -> None:
    e.eigenvalues, e.jacobian, e.critical = np.zeros(0, complex), None, False
    e.stability = "undecided"
    e.reason = f"{where.describe()}; {why}: no verdict from this chart (write the joint with another " \
               f"sequence whose singular set avoids this orientation)"


def _undecided_note(count: int, what: str) -> str:
    return f"{count} {what} at a coordinate singularity and could not be classified"
