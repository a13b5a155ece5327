"""Principal moments and axes of an inertia tensor (sorted, orthonormal, right-handed)."""
from __future__ import annotations

import numpy as np


def principal_inertia(tensor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ascending principal moments and the principal axes as columns (a right-handed orthonormal basis).
    Repeated moments (axisymmetric bodies) get an arbitrary orthonormal basis of their eigenspace."""
    I = np.asarray(tensor, dtype=float)
    if I.shape != (3, 3):
        raise ValueError("an inertia tensor is 3x3")
    moments, axes = np.linalg.eigh((I + I.T) / 2)
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    return moments, axes
