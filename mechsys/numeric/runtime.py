"""Runtime of generated code, without sympy: functions and matrix evaluators rebuilt from (cached) source."""
from __future__ import annotations

import ast
import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np


# What generated source may contain: one function `_f` of plain arguments that assigns and returns arithmetic,
# conditional expressions and calls of math functions. Anything else (imports, attributes other than math.*,
# other calls, loops, nested functions) is refused before the source is compiled.
_NODES = (ast.Module, ast.FunctionDef, ast.arguments, ast.arg, ast.Assign, ast.Return, ast.List, ast.Tuple,
          ast.Name, ast.Load, ast.Store, ast.Constant, ast.BinOp, ast.UnaryOp, ast.IfExp, ast.Compare, ast.BoolOp,
          ast.Call, ast.Attribute, ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow, ast.Mod, ast.FloorDiv, ast.USub,
          ast.UAdd, ast.Not, ast.And, ast.Or, ast.Eq, ast.NotEq, ast.Lt, ast.LtE, ast.Gt, ast.GtE)
_BUILTINS = frozenset({"abs", "min", "max", "float"})
_MATH = frozenset(name for name in dir(math) if not name.startswith("_"))


_ALLOWED = frozenset(_NODES)
_FLOAT_WORDS = ("nan", "inf", "-inf")


def check_source(source: str) -> ast.Module:
    """Raise ValueError unless ``source`` is generated arithmetic of the form above (so source read back from
    the cache is data in a tiny language, whatever happened to the file). Returns the parsed tree (compiled as
    it is: the source is parsed once). One walk over the nodes, each checked by its exact type (the linearization
    sources of a 20-link chain: 700 kB, 2.7 s with three walks and isinstance tests)."""
    tree = ast.parse(source, mode="exec")
    if len(tree.body) != 1 or not isinstance(tree.body[0], ast.FunctionDef) or tree.body[0].name != "_f":
        raise ValueError("generated source must define exactly one function _f")
    fn = tree.body[0]
    if fn.decorator_list or fn.returns or fn.args.defaults or fn.args.vararg or fn.args.kwarg or fn.args.kwonlyargs:
        raise ValueError("generated _f must take plain positional arguments")
    # names and constants a parent allows: `math` under math.<function>, the strings of float('nan'), ... (ast.walk
    # is breadth-first: a parent is checked, and allows its child, before the child comes)
    allowed_math, allowed_words = set(), set()
    for node in ast.walk(fn):
        kind = type(node)
        if kind not in _ALLOWED or (kind is ast.FunctionDef and node is not fn):
            raise ValueError(f"generated source contains {kind.__name__}")
        if kind is ast.Attribute:
            if not (type(node.value) is ast.Name and node.value.id == "math" and node.attr in _MATH):
                raise ValueError("generated source may only use attributes of math")
            allowed_math.add(id(node.value))
        elif kind is ast.Call:
            func = node.func
            if node.keywords or not (type(func) is ast.Attribute or (type(func) is ast.Name and func.id in _BUILTINS)):
                raise ValueError("generated source calls something other than math functions")
            # sympy prints nan and infinities as float('nan'), float('inf'), float('-inf'): the only strings allowed
            if type(func) is ast.Name and func.id == "float" and len(node.args) == 1 \
                    and type(node.args[0]) is ast.Constant and node.args[0].value in _FLOAT_WORDS:
                allowed_words.add(id(node.args[0]))
        elif kind is ast.Constant:
            if type(node.value) not in (int, float, bool) and id(node) not in allowed_words:
                raise ValueError("generated source contains a non-numeric constant")
        elif kind is ast.Name:
            if (node.id.startswith("_") or node.id == "math") and id(node) not in allowed_math:
                raise ValueError(f"generated source uses the name {node.id}")
    return tree


def function_from_source(source: str) -> Callable[..., list[float]]:
    """The function defined by generated source (printed by sympy from parsed expressions, or read back from
    mechsys's own signed cache), after `check_source` has confirmed it is arithmetic only."""
    tree = check_source(source)
    namespace: dict = {"math": math, "__builtins__": {"abs": abs, "min": min, "max": max, "float": float}}
    exec(compile(tree, "<mechsys-generated>", "exec"), namespace)  # noqa: S102
    return namespace["_f"]


def call_generated(fn: Callable[..., list[float]], args: Sequence[float], size: int) -> list[float]:
    """``fn(*args)`` with IEEE semantics: Python's float arithmetic raises where numpy and C give inf or nan (x**2
    past 1e308, 1/0, sqrt or asin outside their domain), so those become inf or nan entries and the callers'
    finiteness checks report them."""
    try:
        return fn(*args)
    except OverflowError:
        return [math.inf] * size
    except (ZeroDivisionError, ValueError):  # ValueError: math domain error (the source is arithmetic only)
        return [math.nan] * size


@dataclass
class StateFunction:
    """``fn(t, q, u, p)`` evaluating a symbolic matrix at numeric arrays; shape is the matrix shape."""

    shape: tuple[int, int]
    _fn: Callable[..., list[float]]

    def __call__(self, t: float, q: Sequence[float], u: Sequence[float], p: Sequence[float]) -> np.ndarray:
        if self.shape[0] == 0 or self.shape[1] == 0:
            return np.zeros(self.shape)
        return np.array(call_generated(self._fn, (t, *q, *u, *p), self.shape[0] * self.shape[1]),
                        dtype=float).reshape(self.shape)


def matrix_from_source(desc: dict) -> StateFunction:
    shape = tuple(desc["shape"])
    if desc["source"] is None:
        return StateFunction(shape, lambda *a: [])
    return StateFunction(shape, function_from_source(desc["source"]))
