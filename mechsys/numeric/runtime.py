"""Runtime of generated code, without sympy: functions and matrix evaluators rebuilt from (cached) source."""
from __future__ import annotations

import dis
import inspect
import math
import operator
import sys
import types
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np


# What generated source may contain: one function `_f` of plain arguments that assigns and returns arithmetic,
# conditional expressions and calls of math functions. Anything else (imports, attributes other than math.*,
# other calls, loops, nested functions, strings) is refused. The check reads the compiled code object, not a
# syntax tree: Python's compiler parses in C (the linearization of a 20-link chain, 720 kB of source: 0.24 s to
# compile and 5 ms to check its code, against 1.8 s to build and walk its syntax tree). Nothing runs before the
# check: compiling only translates.
_BUILTINS = frozenset({"abs", "min", "max", "float"})
_MATH = frozenset(name for name in dir(math) if not name.startswith("_"))
#: the names code may read: the math module and its public functions and constants, four builtins
_NAMES = frozenset({"math"}) | _MATH | _BUILTINS
#: the operations straight-line arithmetic compiles to, by name (those this Python has): locals, constants, the
#: globals above, attributes, calls, operators, comparisons, lists and tuples, and the forward jumps of `a if c
#: else b` and `and`/`or`. No imports, stores other than to locals, subscripts, backward jumps (loops), functions
#: made inside, keyword calls or anything else.
_OPERATIONS = ("NOP", "CACHE", "RESUME", "EXTENDED_ARG", "LOAD_FAST", "LOAD_FAST_CHECK", "LOAD_FAST_LOAD_FAST",
               "STORE_FAST", "STORE_FAST_LOAD_FAST", "STORE_FAST_STORE_FAST", "LOAD_CONST", "RETURN_VALUE",
               "RETURN_CONST", "LOAD_GLOBAL", "LOAD_ATTR", "LOAD_METHOD", "PRECALL", "CALL", "PUSH_NULL",
               "BINARY_OP", "UNARY_NEGATIVE", "UNARY_POSITIVE", "UNARY_NOT", "TO_BOOL", "COMPARE_OP", "BUILD_LIST",
               "BUILD_TUPLE", "LIST_APPEND", "LIST_EXTEND", "POP_TOP", "COPY", "SWAP", "JUMP_FORWARD",
               "POP_JUMP_FORWARD_IF_FALSE", "POP_JUMP_FORWARD_IF_TRUE", "JUMP_IF_FALSE_OR_POP",
               "JUMP_IF_TRUE_OR_POP", "NOT_TAKEN")
#: POP_JUMP_IF_* jump forward only from Python 3.12 on (3.11 has backward forms of its own names)
_FORWARD_ONLY_FROM = (3, 12)
_ALLOWED_OPS = frozenset(dis.opmap[name] for name in _OPERATIONS + (
    ("POP_JUMP_IF_FALSE", "POP_JUMP_IF_TRUE") if sys.version_info >= _FORWARD_ONLY_FROM else ()) if name in dis.opmap)
_FLAGS = inspect.CO_VARARGS | inspect.CO_VARKEYWORDS | inspect.CO_GENERATOR | inspect.CO_COROUTINE \
    | inspect.CO_ASYNC_GENERATOR | inspect.CO_ITERABLE_COROUTINE
#: the module every accepted source compiles to: `def _f(...)` and nothing else (no defaults, annotations or
#: decorators, which compile to other instructions)
_MODULE = compile("def _f():\n    return []", "<mechsys-generated>", "exec")


def _plain_constant(value: object) -> bool:
    if type(value) is tuple:  # a list of constants compiles to a list extended by a tuple constant
        return all(_plain_constant(v) for v in value)
    return value is None or type(value) in (int, float, bool)


def check_source(source: str) -> types.CodeType:
    """Raise ValueError unless ``source`` is generated arithmetic of the form above (so source read back from
    the cache is data in a tiny language, whatever happened to the file). Returns the compiled module code (the
    source is compiled once)."""
    code = compile(source, "<mechsys-generated>", "exec", dont_inherit=True)
    functions = [c for c in code.co_consts if isinstance(c, types.CodeType)]
    if code.co_code != _MODULE.co_code or code.co_names != ("_f",) or len(functions) != 1 \
            or [c for c in code.co_consts if c is not functions[0]] != [c for c in _MODULE.co_consts
                                                                      if not isinstance(c, types.CodeType)]:
        raise ValueError("generated source must define exactly one function _f")
    fn = functions[0]
    if fn.co_name != "_f" or fn.co_flags & _FLAGS or fn.co_kwonlyargcount or fn.co_posonlyargcount \
            or fn.co_freevars or fn.co_cellvars:
        raise ValueError("generated _f must take plain positional arguments")
    for value in fn.co_consts:
        if not _plain_constant(value):
            raise ValueError(f"generated source contains the constant {type(value).__name__}")
    for name in fn.co_names:
        if name not in _NAMES:
            raise ValueError(f"generated source uses the name {name}")
    for op in set(fn.co_code[::2]) - _ALLOWED_OPS:
        raise ValueError(f"generated source contains {dis.opname[op]}")
    return code


def function_from_source(source: str) -> Callable[..., list[float]]:
    """The function defined by generated source (printed by sympy from parsed expressions, or read back from
    mechsys's own signed cache), after `check_source` has confirmed it is arithmetic only."""
    return function_from_code(check_source(source))


def function_from_code(code: types.CodeType, math_module: object = math) -> Callable[..., list[float]]:
    """The function ``_f`` of code that `check_source` accepted, its `math.` names read from ``math_module``."""
    namespace: dict = {"math": math_module, "__builtins__": {"abs": abs, "min": min, "max": max, "float": float}}
    exec(code, namespace)  # noqa: S102
    return namespace["_f"]


# ------------------------------------------------------------------------------- many points at once
class _Points(np.ndarray):
    """The values of one variable of generated code at many points. numpy's +, -, *, / and negation round as
    Python's float operations do (IEEE); powers, floored remainders and quotients and the math functions are
    Python's own, applied per element (numpy squares, takes square roots and evaluates sin its own way, which may
    differ in the last bit)."""

    def __array_wrap__(self, array, context=None, return_scalar=False):
        return array.view(_Points)


def _per_element(f: Callable, *args):
    """f applied to each element (Python floats in, Python floats out): a _Points array, or f's scalar."""
    out = np.frompyfunc(f, len(args), 1)(*args)
    return out.astype(float).view(_Points) if isinstance(out, np.ndarray) else out


for _name, _op in (("pow", operator.pow), ("mod", operator.mod), ("floordiv", operator.floordiv)):
    setattr(_Points, f"__{_name}__", lambda self, other, op=_op: _per_element(op, self, other))
    setattr(_Points, f"__r{_name}__", lambda self, other, op=_op: _per_element(op, other, self))
del _name, _op


class _MathPerElement:
    """The math module with each function applied per element of _Points arrays (constants as they are)."""

    def __init__(self) -> None:
        for name in _MATH:
            value = getattr(math, name)
            setattr(self, name, (lambda f: lambda *a: _per_element(f, *a))(value) if callable(value) else value)


_MATH_PER_ELEMENT = _MathPerElement()


def rows_function_from_code(code: types.CodeType) -> Callable[[np.ndarray], np.ndarray | None]:
    """``_f`` of checked generated code evaluated at many argument rows in one pass (each operation once on all
    rows, not the whole code once per row: the 20-link chain's linearization at 504 equilibria, 0.17 s
    instead of 2.0 s). Each row's outputs are bit for bit what ``_f(*row)`` gives for float64 arguments. None
    when the code cannot run that way exactly: a condition, min or max on the rows, or any floating-point
    exception (a division by zero, an overflow, an invalid operation, a math domain error), after which the
    rows are to be evaluated one by one, as before."""
    fn = function_from_code(code, _MATH_PER_ELEMENT)

    def rows(args: np.ndarray) -> np.ndarray | None:
        args = np.asarray(args, dtype=float)
        try:
            with np.errstate(divide="raise", over="raise", invalid="raise", under="ignore"):
                values = fn(*(args[:, j].view(_Points) for j in range(args.shape[1])))
                if any(np.iscomplexobj(v) for v in values):  # (storing would drop the imaginary part)
                    return None
                out = np.empty((args.shape[0], len(values)))
                for j, v in enumerate(values):
                    out[:, j] = v
        except (ArithmeticError, ValueError, TypeError):  # FloatingPointError is an ArithmeticError
            return None
        return out

    return rows


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
