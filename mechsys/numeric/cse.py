"""sympy's cse with its search for common sub-sums and sub-products on plain sets: the same result, faster.

sympy.cse's opt_cse calls ``match_common_args`` for the sums and for the products of the expressions. sympy keeps
its argument and function sets as ``OrderedSet`` (an OrderedDict underneath): every intersection and difference is
a loop in Python, quadratic over a long chain's sums (the 40-link chain's generated package: a third of
`codegen`'s time). Nothing in that search depends on the order in which a set is walked (the candidates are sorted
by (count, index), arguments by their value numbers, and the functions that share a match are each rewritten on
their own), so the same search over Python's sets gives the same substitutions; tests/test_cse.py compares the two
on every bundled model's equations and the chains'.
"""
from __future__ import annotations

from typing import Any, Iterable, Iterator, Sequence

import sympy as sp
from sympy.core.cache import clear_cache
from sympy.simplify import cse_main

from mechsys.mechanics.dag import Interner

__all__ = ["cse", "interned", "match_common_args"]


def cse(exprs: Sequence[sp.Expr], symbols: Iterator[sp.Symbol] | None = None,
        order: str = "none") -> tuple[list, list]:
    """sympy.cse(exprs, symbols, order) with match_common_args below, over the expressions interned (one object
    per value, dag.Interner): cse keys subexpressions by value, and equal ones built apart are compared through
    their whole trees (a 10-box chain of spherical joints: 70 million comparisons, 37 s of its first `simulate`)."""
    exprs = interned(exprs)
    original = getattr(cse_main, "match_common_args", None)
    if original is None:  # a sympy without it: its own cse
        return sp.cse(exprs, symbols=symbols, order=order)
    cse_main.match_common_args = match_common_args
    try:
        return cse_main.cse(exprs, symbols=symbols, order=order)
    finally:
        cse_main.match_common_args = original


def interned(exprs: Sequence) -> list:
    """The expressions with one object per value (dag.Interner), sympy's cache cleared first: its entries hold
    equal nodes over other argument objects, which a lookup would compare through their whole trees. What keys
    subexpressions by value (cse, tree_cse) then meets equal ones as one object."""
    clear_cache()
    one = Interner()
    return [one.of(e) if isinstance(e, sp.Basic) else e for e in exprs]


class _Tracker:
    """sympy's FuncArgTracker: value numbers of the arguments (in the order the functions are met), each function's
    argument numbers and each argument's function numbers, as sets."""

    def __init__(self, funcs: list) -> None:
        self.value_numbers: dict = {}
        self.values: list = []
        self.arg_to_funcs: list[set[int]] = []
        self.func_to_args: list[set[int]] = []
        for i, func in enumerate(funcs):
            args = set()
            for arg in func.args:
                number = self.number(arg)
                args.add(number)
                self.arg_to_funcs[number].add(i)
            self.func_to_args.append(args)

    def number(self, value) -> int:
        number = self.value_numbers.setdefault(value, len(self.values))
        if number == len(self.values):
            self.values.append(value)
            self.arg_to_funcs.append(set())
        return number

    def in_value_order(self, args: set[int]) -> list:
        return [self.values[k] for k in sorted(args)]

    def common_counts(self, args: set[int], first: int) -> dict[int, int]:
        """Function number (at least ``first``) -> how many of ``args`` it has, where that is 2 or more. As sympy
        does: the largest function set (a length or a mass in most products) is only looked up, not walked."""
        sets = [self.arg_to_funcs[arg] for arg in args]
        if not sets:
            return {}
        largest = max(sets, key=len)
        counts: dict[int, int] = {}
        for funcs in sets:
            if funcs is not largest:
                for f in funcs:
                    if f >= first:
                        counts[f] = counts.get(f, 0) + 1
        for f in counts:
            if f in largest:
                counts[f] += 1
        return {f: c for f, c in counts.items() if c >= 2}

    def holding(self, args: set[int], among: set[int]) -> set[int]:
        """The functions of ``among`` that have every one of ``args`` (each intersection walks the smaller set)."""
        return among.intersection(*(self.arg_to_funcs[arg] for arg in args))

    def update(self, f: int, args: set[int]) -> None:
        old = self.func_to_args[f]
        for arg in old - args:
            self.arg_to_funcs[arg].discard(f)
        for arg in args - old:
            self.arg_to_funcs[arg].add(f)
        self.func_to_args[f] = set(args)

    def stop(self, f: int) -> None:
        for arg in self.func_to_args[f]:
            self.arg_to_funcs[arg].discard(f)


def match_common_args(func_class: type[sp.Basic], funcs: Iterable[sp.Basic], opt_subs: dict[sp.Basic, Any]) -> None:
    """sympy.simplify.cse_main.match_common_args (sympy 1.12-1.14), step for step, on sets."""
    funcs = sorted(funcs, key=lambda f: len(f.args))
    tracker = _Tracker(funcs)
    changed: set[int] = set()
    for i in range(len(funcs)):
        counts = tracker.common_counts(tracker.func_to_args[i], i + 1)
        queue = sorted(counts, key=lambda k: (counts[k], k))  # smaller matches first
        waiting = set(queue)
        for j in queue:
            waiting.discard(j)
            common = tracker.func_to_args[i] & tracker.func_to_args[j]
            if len(common) <= 1:
                continue  # combined by an earlier match
            rest_i = tracker.func_to_args[i] - common
            if rest_i:
                number = tracker.number(cse_main.Unevaluated(func_class, tracker.in_value_order(common)))
                tracker.update(i, rest_i | {number})
                changed.add(i)
            else:
                number = tracker.number(funcs[i])  # the whole function is the common subexpression
            tracker.update(j, (tracker.func_to_args[j] - common) | {number})
            changed.add(j)
            for k in tracker.holding(common, waiting):
                tracker.update(k, (tracker.func_to_args[k] - common) | {number})
                changed.add(k)
        if i in changed:
            opt_subs[funcs[i]] = cse_main.Unevaluated(func_class, tracker.in_value_order(tracker.func_to_args[i]))
        tracker.stop(i)
