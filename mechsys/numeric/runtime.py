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


def check_source(source: str) -> None:
    """Raise ValueError unless ``source`` is generated arithmetic of the form above (so source read back from
    the cache is data in a tiny language, whatever happened to the file)."""
    tree = ast.parse(source, mode="exec")
    if len(tree.body) != 1 or not isinstance(tree.body[0], ast.FunctionDef) or tree.body[0].name != "_f":
        raise ValueError("generated source must define exactly one function _f")
    fn = tree.body[0]
    if fn.decorator_list or fn.returns or fn.args.defaults or fn.args.vararg or fn.args.kwarg or fn.args.kwonlyargs:
        raise ValueError("generated _f must take plain positional arguments")
    nodes = list(ast.walk(fn))
    math_bases = set()
    for node in nodes:
        if isinstance(node, ast.Attribute):
            if not (isinstance(node.value, ast.Name) and node.value.id == "math" and node.attr in _MATH):
                raise ValueError("generated source may only use attributes of math")
            math_bases.add(id(node.value))
    # sympy prints nan and infinities as float('nan'), float('inf'), float('-inf'): the only strings allowed
    special = {id(node.args[0]) for node in nodes if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
               and node.func.id == "float" and len(node.args) == 1 and isinstance(node.args[0], ast.Constant)
               and node.args[0].value in ("nan", "inf", "-inf")}
    for node in nodes:
        if not isinstance(node, _NODES) or (isinstance(node, ast.FunctionDef) and node is not fn):
            raise ValueError(f"generated source contains {type(node).__name__}")
        if isinstance(node, ast.Constant) and type(node.value) not in (int, float, bool) and id(node) not in special:
            raise ValueError("generated source contains a non-numeric constant")
        if isinstance(node, ast.Name) and (node.id.startswith("_") or node.id == "math") \
                and id(node) not in math_bases:
            raise ValueError(f"generated source uses the name {node.id}")
        if isinstance(node, ast.Call) and (node.keywords or not (
                isinstance(node.func, ast.Attribute) or (isinstance(node.func, ast.Name) and node.func.id in _BUILTINS))):
            raise ValueError("generated source calls something other than math functions")


def function_from_source(source: str) -> Callable[..., list[float]]:
    """The function defined by generated source (printed by sympy from parsed expressions, or read back from
    mechsys's own signed cache), after `check_source` has confirmed it is arithmetic only."""
    check_source(source)
    namespace: dict = {"math": math, "__builtins__": {"abs": abs, "min": min, "max": max, "float": float}}
    exec(compile(source, "<mechsys-generated>", "exec"), namespace)  # noqa: S102
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
