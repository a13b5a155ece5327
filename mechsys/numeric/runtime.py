"""Runtime of generated code, without sympy: functions and matrix evaluators rebuilt from (cached) source."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np


def function_from_source(source: str) -> Callable[..., list[float]]:
    """The function defined by generated source (printed by sympy from parsed expressions, or read back from
    mechsys's own cache): no user text reaches it."""
    namespace: dict = {"math": math}
    exec(compile(source, "<mechsys-generated>", "exec"), namespace)  # noqa: S102
    return namespace["_f"]


@dataclass
class StateFunction:
    """``fn(t, q, u, p)`` evaluating a symbolic matrix at numeric arrays; shape is the matrix shape."""

    shape: tuple[int, int]
    _fn: Callable[..., list[float]]

    def __call__(self, t: float, q: Sequence[float], u: Sequence[float], p: Sequence[float]) -> np.ndarray:
        if self.shape[0] == 0 or self.shape[1] == 0:
            return np.zeros(self.shape)
        out = self._fn(t, *q, *u, *p)
        return np.array(out, dtype=float).reshape(self.shape)


def matrix_from_source(desc: dict) -> StateFunction:
    shape = tuple(desc["shape"])
    if desc["source"] is None:
        return StateFunction(shape, lambda *a: [])
    return StateFunction(shape, function_from_source(desc["source"]))
