"""Euler and Cardan sequences numerically: rotation matrices, angle-rate matrices, angles of a given rotation."""
from __future__ import annotations

import itertools
import math

import numpy as np

_AXES = {"x": np.array([1.0, 0, 0]), "y": np.array([0, 1.0, 0]), "z": np.array([0, 0, 1.0])}


def _elementary(axis: str, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i = "xyz".index(axis)
    R = np.eye(3)
    j, k = (i + 1) % 3, (i + 2) % 3
    R[j, j], R[j, k], R[k, j], R[k, k] = c, -s, s, c
    return R


def rotation(sequence: str, angles) -> np.ndarray:
    """Body-fixed (intrinsic) sequence: R = R1(a1) R2(a2) R3(a3), frame components -> parent components."""
    R = np.eye(3)
    for axis, angle in zip(sequence, angles):
        R = R @ _elementary(axis, angle)
    return R


def rate_matrix(sequence: str, angles) -> np.ndarray:
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


def canonical(sequence: str, a) -> np.ndarray:
    """The one of the two angle triples of a rotation that is conventional: middle angle in [-pi/2, pi/2] for
    Cardan sequences (xyz), in [0, pi] for proper Euler ones (zxz); the others in (-pi, pi]. The alternative is
    (a1 + pi, pi - a2, a3 + pi) for Cardan and (a1 + pi, -a2, a3 + pi) for Euler sequences."""
    a = _wrap(a)
    euler = sequence[0] == sequence[2]
    if (euler and a[1] < 0) or (not euler and abs(a[1]) > np.pi / 2):
        a = _wrap([a[0] + np.pi, -a[1] if euler else np.pi - a[1], a[2] + np.pi])
    return a


def alternatives(sequence: str) -> list[str]:
    """Sequences with the same first axis (so a rotation about the parent's axis stays the first angle, and a
    cyclic first angle stays cyclic), consecutive axes distinct."""
    return [s for s in ("".join(t) for t in itertools.product("xyz", repeat=3))
            if s[0] == sequence[0] and s[0] != s[1] and s[1] != s[2] and s != sequence]


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
