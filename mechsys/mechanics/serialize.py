"""Sympy expressions as JSON data and back through a whitelist of node types: the derivation cache holds data.

An expression list becomes a table of nodes (a DAG: a subexpression shared by several entries is stored once) and
the indices of the roots. Each node is ``[kind, ...]``: ``["S", name]`` a symbol of the model (only names the
caller lists are accepted, and they come back as the caller's own symbol objects), ``["I", digits]`` an integer,
``["R", p, q]`` a rational, ``["F", sign, mantissa, exponent, bits, precision]`` a float (exact), ``["C", name]``
a constant (pi, E, I, oo, -oo, zoo, nan), ``[op, i, j, ...]`` an operation of the whitelist on earlier nodes.
Loading builds each node with ``evaluate=False`` from its stored arguments (already canonical), so the result is
the same expression, equal under ``==``; anything else in the data makes ``load`` return None. Nothing is
executed: no eval, no sympify, no pickle.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import sympy as sp

OPERATIONS = {"Add": sp.Add, "Mul": sp.Mul, "Pow": sp.Pow, "sin": sp.sin, "cos": sp.cos, "tan": sp.tan,
              "asin": sp.asin, "acos": sp.acos, "atan": sp.atan, "atan2": sp.atan2, "sinh": sp.sinh,
              "cosh": sp.cosh, "tanh": sp.tanh, "exp": sp.exp, "log": sp.log, "Abs": sp.Abs, "sign": sp.sign,
              "Min": sp.Min, "Max": sp.Max, "Heaviside": sp.Heaviside}
CONSTANTS = {"pi": sp.pi, "E": sp.E, "I": sp.I, "oo": sp.oo, "-oo": -sp.oo, "zoo": sp.zoo, "nan": sp.nan}
_NAMES = {v: k for k, v in OPERATIONS.items()}


class Unsupported(Exception):
    """A node the whitelist does not cover: the expressions are not cached (derived again next time)."""


def dump(exprs: Sequence[sp.Expr], symbols: Mapping[str, sp.Symbol]) -> dict:
    """{"nodes": [...], "roots": [...]} of ``exprs``, one node per distinct value; Unsupported if a node is not on the
    whitelist or a symbol is not one of ``symbols`` (by name and identity). Nodes are met by identity, then merged by
    their encoding (operation and argument indices): keying them by value compared each copy of a subexpression
    with the first through its whole tree (a 20-link chain's equations: a tenth of `derive`)."""
    nodes: list[list] = []
    by_encoding: dict[tuple, int] = {}
    by_id: dict[int, int] = {}
    alive: list[sp.Basic] = []  # the nodes whose ids are keys stay alive until the end

    def visit(e: sp.Basic) -> int:
        stack = [e]
        while stack:  # iterative post-order: deep sums of products must not exhaust Python's stack
            node = stack[-1]
            if id(node) in by_id:
                stack.pop()
                continue
            args = () if isinstance(node, (sp.Symbol, sp.Number)) else node.args
            waiting = [a for a in args if id(a) not in by_id]
            if waiting:
                stack.extend(reversed(waiting))
                continue
            stack.pop()
            encoded = _encode(node, by_id, symbols)
            k = by_encoding.setdefault(tuple(encoded), len(nodes))
            if k == len(nodes):
                nodes.append(encoded)
            by_id[id(node)] = k
            alive.append(node)
        return by_id[id(e)]

    roots = [visit(sp.sympify(e)) for e in exprs]
    return {"nodes": nodes, "roots": roots}


def _encode(e: sp.Basic, by_id: dict[int, int], symbols: Mapping[str, sp.Symbol]) -> list:
    if isinstance(e, sp.Symbol):
        if symbols.get(e.name) is not e and symbols.get(e.name) != e:
            raise Unsupported(f"symbol {e.name!r} is not one of the model's")
        return ["S", e.name]
    if not e.args:  # the constants are atoms
        for name, value in CONSTANTS.items():
            if e == value:
                return ["C", name]
    if isinstance(e, sp.Integer):
        return ["I", str(int(e))]
    if isinstance(e, sp.Rational):
        return ["R", str(e.p), str(e.q)]
    if isinstance(e, sp.Float):
        sign, man, exp, bits = e._mpf_
        return ["F", int(sign), str(man), int(exp), int(bits), int(e._prec)]
    name = _NAMES.get(e.func)
    if name is None or e.func is not OPERATIONS[name]:
        raise Unsupported(f"{type(e).__name__} is not on the whitelist")
    return [name, *(by_id[id(a)] for a in e.args)]


def load(data: object, symbols: Mapping[str, sp.Symbol]) -> list[sp.Expr] | None:
    """The expressions of ``dump``'s data, or None when the data is malformed or names anything outside the
    whitelist (an unknown operation, a symbol the model does not have, a forward reference)."""
    try:
        nodes, roots = data["nodes"], data["roots"]  # type: ignore[index]
        built: list[sp.Basic] = []
        for node in nodes:
            built.append(_decode(node, built, symbols))
        return [built[int(i)] for i in roots]
    except (KeyError, TypeError, ValueError, IndexError, AttributeError):
        return None


def _decode(node: list, built: list, symbols: Mapping[str, sp.Symbol]) -> sp.Basic:
    kind = node[0]
    if kind == "S":
        return symbols[str(node[1])]  # KeyError: a symbol the model does not have
    if kind == "C":
        return CONSTANTS[str(node[1])]
    if kind == "I":
        return sp.Integer(int(str(node[1]), 10))
    if kind == "R":
        return sp.Rational(int(str(node[1]), 10), int(str(node[2]), 10))
    if kind == "F":
        sign, man, exp, bits, prec = node[1:]
        return sp.Float._new((int(sign), int(str(man), 10), int(exp), int(bits)), int(prec))
    op = OPERATIONS[str(kind)]
    args = []
    for i in node[1:]:
        i = int(i)
        if not 0 <= i < len(built):
            raise ValueError("forward reference")
        args.append(built[i])
    return op(*args, evaluate=False)
