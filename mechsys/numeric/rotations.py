"""Euler and Cardan sequences numerically: rotation matrices, angle-rate matrices, angles of a given rotation."""
from __future__ import annotations

import itertools
import math
from typing import Sequence

import numpy as np

_AXES = {"x": np.array([1.0, 0, 0]), "y": np.array([0, 1.0, 0]), "z": np.array([0, 0, 1.0])}
_INDEX = {"x": 0, "y": 1, "z": 2}


def _elementary(axis: str, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i = "xyz".index(axis)
    R = np.eye(3)
    j, k = (i + 1) % 3, (i + 2) % 3
    R[j, j], R[j, k], R[k, j], R[k, k] = c, -s, s, c
    return R


def rotation(sequence: str, angles: Sequence[float] | np.ndarray) -> np.ndarray:
    """Body-fixed (intrinsic) sequence: R = R1(a1) R2(a2) R3(a3), frame components -> parent components."""
    R = np.eye(3)
    for axis, angle in zip(sequence, angles):
        R = R @ _elementary(axis, angle)
    return R


def rate_matrix(sequence: str, angles: Sequence[float] | np.ndarray) -> np.ndarray:
    """W with omega (child components) = W @ angle rates."""
    cols = []
    for k, axis in enumerate(sequence):
        after = rotation(sequence[k + 1:], angles[k + 1:])
        cols.append(after.T @ _AXES[axis])
    return np.array(cols).T


def ratio(W: np.ndarray) -> float:
    """Smallest over largest singular value: 0 where the angles stop determining the angular velocity."""
    sv = np.linalg.svd(W, compute_uv=False)
    return float(sv[-1] / sv[0])


def angles_of(sequence: str, R: np.ndarray) -> np.ndarray | None:
    """Angles of ``sequence`` giving R (least squares from a few starts; the first exact fit), or None. The two
    solutions of a sequence away from its singular set are equally well conditioned, so either will do."""
    from scipy.optimize import least_squares

    for start in itertools.product((-1.2, 1.9), repeat=3):
        sol = least_squares(lambda a: (rotation(sequence, a) - R).ravel(), np.array(start), xtol=1e-15,
                            ftol=1e-15, gtol=1e-15)
        if np.max(np.abs(rotation(sequence, sol.x) - R)) < 1e-12:
            return canonical(sequence, sol.x)
    return None


def _wrap(a) -> np.ndarray:
    return np.remainder(np.asarray(a, dtype=float) + np.pi, 2 * np.pi) - np.pi


def canonical(sequence: str, a: Sequence[float] | np.ndarray) -> np.ndarray:
    """The one of the two angle triples of a rotation that is conventional: middle angle in [-pi/2, pi/2] for
    Cardan sequences (xyz), in [0, pi] for proper Euler ones (zxz); the others in (-pi, pi]. The alternative is
    (a1 + pi, pi - a2, a3 + pi) for Cardan and (a1 + pi, -a2, a3 + pi) for Euler sequences."""
    a = _wrap(a)
    euler = sequence[0] == sequence[2]
    if (euler and a[1] < 0) or (not euler and abs(a[1]) > np.pi / 2):
        a = _wrap(other_branch(sequence, a))
    return a


def other_branch(sequence: str, a: Sequence[float] | np.ndarray) -> np.ndarray:
    """The other angle triple of the same rotation (not wrapped): (a1 + pi, pi - a2, a3 + pi) for Cardan,
    (a1 + pi, -a2, a3 + pi) for proper Euler sequences."""
    a = np.asarray(a, dtype=float)
    return np.array([a[0] + np.pi, -a[1] if sequence[0] == sequence[2] else np.pi - a[1], a[2] + np.pi])


def ratio_at(sequence: str, R: np.ndarray) -> float:
    """``ratio(rate_matrix(sequence, angles))`` for any angles giving R, from R alone: with s = e1 . R e3 (first
    axis in the parent, third in the body; |s| = 1 at gimbal lock) the singular values are sqrt(1 +- |s|), so
    the ratio is sqrt((1 - |s|)/(1 + |s|)) = tan(d/2), d = arccos |s| the angle from the singular set; computed
    as sin(d)/(1 + |s|), sin(d) from the rest of the unit row e1 . R, so it keeps its digits near gimbal lock."""
    i, k = _INDEX[sequence[0]], _INDEX[sequence[2]]
    s = abs(float(R[i, k]))
    sin_d = math.hypot(*(float(R[i, j]) for j in range(3) if j != k))
    return min(1.0, sin_d / (1.0 + s))


def log_vector(R: np.ndarray) -> np.ndarray:
    """Rotation vector (axis times angle in [0, pi]) of a rotation matrix."""
    angle = math.acos(max(-1.0, min(1.0, (float(np.trace(R)) - 1.0) / 2.0)))
    vee = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2.0
    if angle < 3.0:
        return vee * (angle / math.sin(angle) if angle > 1e-8 else 1.0 + angle * angle / 6.0)
    # near a half turn: the axis from the symmetric part, its sign from the (small) antisymmetric one
    B = (R + R.T) / 2.0 - math.cos(angle) * np.eye(3)
    axis = B[int(np.argmax(np.diag(B)))]
    axis = axis / np.linalg.norm(axis)
    return angle * (axis if axis @ vee >= 0 else -axis)


def frame(sequence: str, angles: Sequence[float] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(rotation(sequence, angles), rate_matrix(sequence, angles))`` of a three-angle sequence in one pass."""
    E1, E2, E3 = (_elementary(axis, float(x)) for axis, x in zip(sequence, angles))
    E23 = E2 @ E3
    W = np.column_stack([E23[_INDEX[sequence[0]]], E3[_INDEX[sequence[1]]], _AXES[sequence[2]]])
    return E1 @ E23, W


def angles_closed(sequence: str, R: np.ndarray) -> np.ndarray:
    """Angles of a three-angle sequence giving R, in closed form (middle angle in [-pi/2, pi/2] for Cardan,
    [0, pi] for proper Euler sequences). At a gimbal lock the first angle is 0 (only a sum or difference is
    determined); close to one the middle angle loses digits (asin/acos near +-1): polish with ``angles_near``."""
    i, j = "xyz".index(sequence[0]), "xyz".index(sequence[1])
    if sequence[0] == sequence[2]:
        k = 3 - i - j
        sign = 1.0 if (i, j, k) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
        b = math.acos(max(-1.0, min(1.0, float(R[i, i]))))
        if math.sin(b) < 1e-12:
            return np.array([0.0, b, math.atan2(-sign * float(R[j, k]), float(R[j, j]))])  # R = R_j(b) R_i(c)
        return np.array([math.atan2(float(R[j, i]), -sign * float(R[k, i])), b,
                         math.atan2(float(R[i, j]), sign * float(R[i, k]))])
    k = "xyz".index(sequence[2])
    sign = 1.0 if (i, j, k) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
    b = math.asin(max(-1.0, min(1.0, sign * float(R[i, k]))))
    if math.cos(b) < 1e-12:
        return np.array([0.0, b, math.atan2(sign * float(R[j, i]), float(R[j, j]))])  # R = R_j(b) R_k(c)
    return np.array([math.atan2(-sign * float(R[j, k]), float(R[k, k])), b,
                     math.atan2(-sign * float(R[i, j]), float(R[i, i]))])


def _newton(sequence: str, R: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, float]:
    """Angles giving R from the start ``a`` and their misfit max |R(a) - R|: Newton on the body-frame rotation
    error, R(a + da) = R(a) exp(W da), with minimum-norm steps (at a gimbal lock the split of the free angle sum
    that moves least), until the step is at the rounding level or stalls in the direction the chart lacks."""
    for _ in range(60):
        Ra, W = frame(sequence, a)
        e = log_vector(Ra.T @ R)
        if not np.all(np.isfinite(e)):
            return a, math.inf
        step = np.linalg.lstsq(W, e, rcond=1e-10)[0]
        a = a + step
        if np.linalg.norm(step) < 1e-13:
            break
    misfit = float(np.max(np.abs(rotation(sequence, a) - R)))
    return a, misfit if math.isfinite(misfit) else math.inf


def angles_near(sequence: str, R: np.ndarray, near: Sequence[float] | np.ndarray) -> np.ndarray | None:
    """Angles of ``sequence`` giving R closest to ``near``: the closed form polished by Newton, or near a gimbal
    lock (ratio below 1e-3, where the closed form's split is arbitrary) Newton from ``near`` itself; then the
    nearer of the two triples, each shifted by multiples of 2 pi towards ``near``. They reproduce R to 1e-12, or
    within the distance from the singular set when that is below ~1e-10 (there the split of the free angle sum
    is set by rounding, and the one nearest ``near`` is kept). None when nothing fits R."""
    near = np.asarray(near, dtype=float)
    r = ratio_at(sequence, R)
    tolerance = 1e-12 + 4 * r
    a, misfit = near, math.inf
    if r < 1e-3:
        a, misfit = _newton(sequence, R, near.copy())
    if misfit > tolerance:
        a, misfit = _newton(sequence, R, angles_closed(sequence, R))
    if misfit > tolerance:
        return None
    two_pi = 2 * np.pi
    options = [b + two_pi * np.round((near - b) / two_pi) for b in (a, other_branch(sequence, a))]
    return min(options, key=lambda b: float(np.linalg.norm(b - near)))


def alternatives(sequence: str, keep: str = "first") -> list[str]:
    """Other valid sequences (consecutive axes distinct) with the same first axis (``keep='first'``: a rotation
    about the parent's axis stays the first angle, so a cyclic first angle stays cyclic), the same last axis
    (``'last'``: a spin about the body's own axis stays the last angle), or any (``'any'``)."""
    def kept(s: str) -> bool:
        return {"first": s[0] == sequence[0], "last": s[2] == sequence[2]}.get(keep, True)
    return [s for s in ("".join(t) for t in itertools.product("xyz", repeat=3))
            if kept(s) and s[0] != s[1] and s[1] != s[2] and s != sequence]


def singular_chart(charts: list[tuple], q: np.ndarray, threshold: float = 1e-6) -> str:
    """'' or why the configuration ``q`` is a coordinate singularity of one of ``charts``: (link, joint type,
    sequence, indices of its three angles in q) of the spherical and free joints."""
    for link, kind, sequence, idx in charts:
        angles = [float(q[i]) for i in idx]
        if ratio(rate_matrix(sequence, angles)) < threshold:
            return (f"coordinate singularity: the {sequence} angles of the {kind} joint of '{link}' are singular at "
                    f"this orientation (gimbal lock: the first and third rotation axes are parallel, middle angle "
                    f"{angles[1]:.6g}); the body itself is fine, its chart is not")
    return ""
