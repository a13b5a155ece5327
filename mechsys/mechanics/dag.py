"""Walks of expression DAGs that visit each shared subexpression once: the free symbols of derived equations, a
substitution of symbols, and their value in floating point.

sympy's ``free_symbols`` unions the free symbols of every argument again at every use of a shared subtree (derived
equations are DAGs: a bicycle's M and f share most of theirs), so asking it for each entry of M, f, A and b, and
again per coordinate, walked the trees dozens of times (the cyclic-coordinate decision of a cold `info`)."""
from __future__ import annotations

import math
from typing import Any, Iterable, Mapping, Optional

import numpy as np
import sympy as sp

#: node types whose free symbols are exactly the union of their arguments' (no bound variables)
_PLAIN = (sp.Add, sp.Mul, sp.Pow, sp.Function, sp.Tuple)


class FreeSymbols:
    """``of(expr)``: the free symbols of expr, each subexpression object's computed once (kept with its object,
    so an id is never reused while remembered); equal to ``expr.free_symbols``. Held as bit masks over the
    symbols met so far (a union is an integer or: a long chain's nodes carry 160 symbols each, and unions of
    frozensets were most of its cyclic decision); ``mask`` and ``has`` ask without building a set."""

    def __init__(self) -> None:
        self._memo: dict[int, tuple[sp.Basic, int]] = {}
        self._bits: dict[sp.Basic, int] = {}
        self._symbols: list[sp.Basic] = []
        self._sets: dict[int, frozenset] = {0: frozenset()}

    def bits(self, symbols: Iterable[sp.Basic]) -> int:
        """The mask of ``symbols`` (each symbol gets its bit when first met)."""
        mask = 0
        for s in symbols:
            bit = self._bits.get(s)
            if bit is None:
                bit = self._bits[s] = 1 << len(self._symbols)
                self._symbols.append(s)
            mask |= bit
        return mask

    def mask(self, expr: sp.Basic) -> int:
        """The mask of expr's free symbols."""
        memo = self._memo
        hit = memo.get(id(expr))
        if hit is not None and hit[0] is expr:
            return hit[1]
        expr = sp.sympify(expr)
        stack = [(expr, False)]
        while stack:  # iterative post-order: deep sums and products never reach the recursion limit
            node, ready = stack.pop()
            hit = memo.get(id(node))
            if hit is not None and hit[0] is node:
                continue
            if not node.args or not isinstance(node, _PLAIN):
                memo[id(node)] = (node, self.bits(node.free_symbols))
            elif ready:
                mask = 0
                for a in node.args:
                    mask |= memo[id(a)][1]
                memo[id(node)] = (node, mask)
            else:
                stack.append((node, True))
                for a in node.args:
                    hit = memo.get(id(a))
                    if hit is None or hit[0] is not a:
                        stack.append((a, False))
        return memo[id(expr)][1]

    def has(self, expr: sp.Basic, symbol: sp.Basic) -> bool:
        """``symbol in expr.free_symbols``."""
        mask = self.mask(expr)  # (assigns the bits of expr's symbols first)
        bit = self._bits.get(symbol)
        return bit is not None and bool(mask & bit)

    def _set(self, mask: int) -> frozenset:
        out = self._sets.get(mask)
        if out is None:
            members, rest = [], mask
            while rest:  # the set bits only (a generated program has thousands of symbols, a term a few)
                low = rest & -rest
                members.append(self._symbols[low.bit_length() - 1])
                rest ^= low
            out = self._sets[mask] = frozenset(members)
        return out

    def of(self, expr: sp.Basic) -> frozenset:
        return self._set(self.mask(expr))

    def of_all(self, exprs: Iterable[sp.Basic]) -> frozenset:
        """The union over ``exprs`` (the entries of matrices, say)."""
        mask = 0
        for e in exprs:
            mask |= self.mask(e)
        return self._set(mask)


class _PerEntry:
    """A map of expressions (``of``) applied to a matrix entry by entry."""

    def of(self, expr: sp.Basic) -> sp.Basic:
        raise NotImplementedError

    def matrix(self, mat: sp.MatrixBase) -> sp.Matrix:
        return sp.Matrix(mat.shape[0], mat.shape[1], [self.of(e) for e in mat])


class Substitution(_PerEntry):
    """``of(expr)``: ``expr.xreplace(mapping)`` for a mapping of symbols, each subexpression object rebuilt once
    (sympy's xreplace walks every path of a DAG: 6 s of the 20-link chain's linearization blocks, for a t = 0 that
    does not occur). Nodes without a replaced symbol are returned as they are; the others are rebuilt with
    ``func(*args)`` as xreplace does, so the result equals xreplace's."""

    def __init__(self, mapping: Mapping[sp.Symbol, sp.Basic], free: FreeSymbols | None = None) -> None:
        self.mapping = {k: sp.sympify(v) for k, v in mapping.items()}
        self.free = free or FreeSymbols()
        self.keys = self.free.bits(self.mapping)
        self._memo: dict[int, tuple[sp.Basic, sp.Basic]] = {}

    def of(self, expr: sp.Basic) -> sp.Basic:
        expr = sp.sympify(expr)
        if not self.keys & self.free.mask(expr):
            return expr
        stack = [(expr, False)]
        while stack:  # iterative post-order, like FreeSymbols
            node, ready = stack.pop()
            if self._known(node) is not None:
                continue
            if node in self.mapping:
                self._memo[id(node)] = (node, self.mapping[node])
            elif not node.args or not self.keys & self.free.mask(node):
                self._memo[id(node)] = (node, node)
            elif ready:
                args = [self._known(a) for a in node.args]
                changed = any(a is not b for a, b in zip(args, node.args))
                self._memo[id(node)] = (node, node.func(*args) if changed else node)
            else:
                stack.append((node, True))
                stack.extend((a, False) for a in node.args if self._known(a) is None)
        return self._known(expr)

    def _known(self, node: sp.Basic) -> sp.Basic | None:
        hit = self._memo.get(id(node))
        return hit[1] if hit is not None and hit[0] is node else None


#: the functions value() evaluates, by sympy type
_MATH = {sp.sin: math.sin, sp.cos: math.cos, sp.tan: math.tan, sp.asin: math.asin, sp.acos: math.acos,
         sp.atan: math.atan, sp.sinh: math.sinh, sp.cosh: math.cosh, sp.tanh: math.tanh, sp.exp: math.exp,
         sp.log: math.log, sp.Abs: abs, sp.sign: lambda x: float((x > 0) - (x < 0))}


def value(expr: sp.Basic, values: Mapping[sp.Symbol, float]) -> Optional[float]:
    """``expr`` in machine floating point with ``values`` for its symbols, each shared node computed once (a
    rolling constraint's row, which xreplace with Floats walks path by path: a tenth of the time); None when a
    symbol has no value, a node is not a sum, product, power, number or elementary function, or a step leaves
    the reals (a domain error, an overflow): the caller then asks sympy."""
    out = Evaluation(values).of(expr)
    return out[0] if out is not None else None


class Evaluation:
    """``of(expr)``: (value, magnitude) of expressions at one point in machine floating point, each shared node
    computed once across all of them; the magnitude is the largest absolute value of any node on the way (a
    scale for the round-off of the value: a difference below ROUND_OFF times it may be cancellation). None when
    a symbol has no value, a node is not a sum, product, power, number or elementary function, or the value is
    not a finite real. ``base`` and ``changed``: the same point with the symbols ``changed`` moved; a node free
    of them takes base's value (a coordinate shifted: only the nodes that contain it are computed again)."""

    def __init__(self, values: Mapping[sp.Symbol, float], base: "Evaluation | None" = None,
                 changed: frozenset = frozenset(), free: FreeSymbols | None = None) -> None:
        self.values = values
        self.base = base
        self.free = free if free is not None else (base.free if base is not None else FreeSymbols())
        self._changed = self.free.bits(changed)
        self._memo: dict[int, tuple[sp.Basic, Optional[tuple[float, float]]]] = {}

    def of(self, expr: sp.Basic) -> Optional[tuple[float, float]]:
        root = sp.sympify(expr)
        return _post_order(root, self._memo, self._settle, _combine)

    def _settle(self, node: sp.Basic) -> tuple[bool, Optional[tuple[float, float]]]:
        """(True, value) of a node known without its arguments (a leaf, or one the shifted symbols leave alone)."""
        if self.base is not None and node.args and not self._changed & self.free.mask(node):
            return True, self.base.of(node)
        if node.is_Symbol:
            return True, _finite(self.values.get(node))
        if node.is_Number or node.is_NumberSymbol:
            return True, _finite(node)
        return False, None


def _combine(node: sp.Basic, args: list) -> Optional[tuple[float, float]]:
    return None if None in args else _apply(node, args)


def _post_order(root: sp.Basic, memo: dict, settle, combine):
    """memo[id(node)] = (node, value) for root and what it needs, without recursion (a deep product never reaches
    Python's recursion limit), each shared node once: ``settle(node)`` gives (True, value) where a node needs no
    arguments, else ``combine(node, values of its arguments)``."""
    stack = [root]
    while stack:
        node = stack[-1]
        if id(node) in memo:
            stack.pop()
            continue
        done, result = settle(node)
        if not done:
            waiting = [a for a in node.args if id(a) not in memo]
            if waiting:
                stack.extend(waiting)
                continue
            result = combine(node, [memo[id(a)][1] for a in node.args])
        memo[id(node)] = (node, result)
        stack.pop()
    return memo[id(root)][1]

#: the functions ``precise`` evaluates, by sympy type (mpmath's, at the working precision)
_MPMATH = {sp.sin: "sin", sp.cos: "cos", sp.tan: "tan", sp.asin: "asin", sp.acos: "acos", sp.atan: "atan",
           sp.sinh: "sinh", sp.cosh: "cosh", sp.tanh: "tanh", sp.exp: "exp", sp.log: "log", sp.Abs: "fabs",
           sp.sign: "sign"}


def precise(expr: sp.Basic, values: Mapping[sp.Symbol, float], digits: int) -> Optional[float]:
    """|``expr``| with ``values`` for its symbols, every step in mpmath at ``digits`` significant digits, each shared
    node once: the same expression at two precisions tells a value from round-off without a scale (an identically
    zero row of a micrometre linkage is 1e-30 of its terms at 30 digits and 1e-60 at 60; a nonzero one keeps its
    value). None when a symbol has no value or a node is outside sums, products, powers, numbers and elementary
    functions (the caller then asks sympy)."""
    import mpmath

    ctx = mpmath.mp.clone()
    ctx.dps = digits
    prec = ctx.prec

    def settle(node: sp.Basic) -> tuple[bool, Any]:
        if node.is_Symbol:
            v = values.get(node)
            return True, None if v is None else ctx.mpf(v)
        if node.is_Number or node.is_NumberSymbol:
            try:
                return True, ctx.mpmathify(node._to_mpmath(prec))
            except (TypeError, ValueError, AttributeError):
                return True, None
        return False, None

    def combine(node: sp.Basic, args: list) -> Any:
        if any(a is None for a in args):
            return None
        try:
            if node.is_Add:
                return ctx.fsum(args)
            if node.is_Mul:
                return ctx.fprod(args)
            if node.is_Pow:
                base, exp = args
                return base ** (int(exp) if node.exp.is_Integer else exp)
            if type(node) is sp.atan2:
                return ctx.atan2(*args)
            if type(node) in _MPMATH and len(args) == 1:
                return getattr(ctx, _MPMATH[type(node)])(args[0])
        except (ValueError, ZeroDivisionError, OverflowError, TypeError):
            return None
        return None

    out = _post_order(sp.sympify(expr), {}, settle, combine)
    if out is None:
        return None
    try:
        return float(abs(out)) if ctx.isfinite(out) else None
    except (TypeError, ValueError):
        return None


#: functions whose value (or whose derivative) jumps where their argument changes sign
SWITCHING = (sp.Abs, sp.sign, sp.Heaviside, sp.DiracDelta)


def switches(exprs: Iterable[sp.Basic], x: sp.Symbol) -> list[sp.Expr]:
    """Functions of ``x`` whose sign changes mark where the expressions may jump or kink: the arguments of their
    abs, sign, Heaviside and DiracDelta nodes, the differences of a Min's or Max's arguments, a Piecewise's conditions
    (lhs - rhs), each shared node visited once; only those that contain ``x``."""
    from itertools import combinations

    out: list[sp.Expr] = []
    seen: set[int] = set()
    stack = [sp.sympify(e) for e in exprs]
    while stack:
        node = stack.pop()
        if id(node) in seen or not node.args:
            continue
        seen.add(id(node))
        if isinstance(node, SWITCHING):
            out.append(node.args[0])
        elif isinstance(node, (sp.Min, sp.Max)):
            out += [a - b for a, b in combinations(node.args, 2)]
        elif isinstance(node, sp.Piecewise):
            relations = (r for _, cond in node.args for r in sp.sympify(cond).atoms(sp.core.relational.Relational))
            out += [r.lhs - r.rhs for r in relations]
        stack.extend(node.args)
    return [s for s in out if s.has(x)]


def identically_zero(expr: sp.Expr, values: dict) -> bool:
    """True when ``expr`` vanishes structurally, or at several random states (then it is identically 0). Scale-free:
    a value beyond the round-off of its largest term settles "not zero"; a smaller one is computed at 30 and at 60
    digits, and only round-off (which shrinks with the precision) counts as zero, whatever the units (a linkage of
    1e-12 m has rows of 1e-12 that are not zero; a model in grams and millimetres has zero rows of 1e-9)."""
    expr = sp.sympify(expr)
    if expr == 0:
        return True
    import random

    rng = random.Random(1234)
    symbols = sorted(expr.free_symbols, key=str)
    for _ in range(4):
        subs = {s: values.get(s, rng.uniform(-1.3, 1.7)) for s in symbols}
        rough = Evaluation(subs).of(expr)  # machine precision, each shared node once
        if rough is not None and abs(rough[0]) > 1e-8 * rough[1]:
            return False
        low, high = (_at_digits(expr, subs, digits) for digits in (30, 60))
        if low is None or high is None:
            return False
        if high != 0 and abs(low - high) <= 1e-6 * high:
            return False  # the same value at both precisions: not round-off
    return True


def _at_digits(expr: sp.Expr, subs: dict, digits: int) -> float | None:
    """|expr| at ``digits`` significant digits (dag.precise, else sympy's evalf); None outside the complex numbers."""
    out = precise(expr, subs, digits)
    if out is not None:
        return out
    try:
        return abs(complex(expr.evalf(digits, subs={s: sp.Float(v, digits) for s, v in subs.items()})))
    except (TypeError, ValueError):
        return None


#: the functions Points evaluates, by sympy type (numpy's, elementwise)
_NUMPY = {sp.sin: np.sin, sp.cos: np.cos, sp.tan: np.tan, sp.asin: np.arcsin, sp.acos: np.arccos,
          sp.atan: np.arctan, sp.sinh: np.sinh, sp.cosh: np.cosh, sp.tanh: np.tanh, sp.exp: np.exp,
          sp.log: np.log, sp.Abs: np.abs, sp.sign: np.sign}


class Points:
    """``of(expr)``: the values of expressions at several points at once, as numpy arrays (one element per point),
    each shared node computed once across all of them: what a compiled function called at each point gives, to
    round-off, without generating or compiling code (a bicycle's M, f, A, b at the cyclic test's eight states: one
    walk instead of a CSE and an exec). A value outside the reals is nan, an overflow inf. None when a symbol has
    no value or a node is not a sum, product, power, number or elementary function."""

    def __init__(self, values: Mapping[sp.Symbol, np.ndarray]) -> None:
        self.values = {k: np.asarray(v, dtype=float) for k, v in values.items()}
        self._memo: dict[int, tuple[sp.Basic, Optional[np.ndarray]]] = {}

    def of(self, expr: sp.Basic) -> Optional[np.ndarray]:
        with np.errstate(all="ignore"):
            return _post_order(sp.sympify(expr), self._memo, self._settle, _combine_arrays)

    def _settle(self, node: sp.Basic) -> tuple[bool, Optional[np.ndarray]]:
        if node.is_Symbol:
            return True, self.values.get(node)
        if node.is_Number or node.is_NumberSymbol:
            return True, _number(node)
        return False, None


def _combine_arrays(node: sp.Basic, args: list) -> Optional[np.ndarray]:
    return None if any(a is None for a in args) else _apply_arrays(node, args)

def _number(node: sp.Basic) -> Optional[float]:
    try:
        return float(node)
    except (TypeError, ValueError):
        return None  # a complex number: outside the walk


def _apply_arrays(node: sp.Basic, args: list) -> Optional[np.ndarray]:
    """The node's values from its arguments' (numpy, elementwise); None outside the supported nodes."""
    if node.is_Add:
        out = args[0]
        for a in args[1:]:
            out = out + a
        return out
    if node.is_Mul:
        out = args[0]
        for a in args[1:]:
            out = out * a
        return out
    if node.is_Pow:
        base, exp = args
        if isinstance(exp, float) and exp.is_integer():
            return np.asarray(base, dtype=float) ** int(exp)  # a negative base to a whole power is real
        return np.power(np.asarray(base, dtype=float), exp)
    if type(node) is sp.atan2:
        return np.arctan2(*args)
    if type(node) in _NUMPY and len(args) == 1:
        return _NUMPY[type(node)](args[0])
    return None


def _finite(x: object) -> Optional[tuple[float, float]]:
    try:
        v = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return (v, abs(v)) if math.isfinite(v) else None


def _apply(node: sp.Basic, args: list[tuple[float, float]]) -> Optional[tuple[float, float]]:
    """The node's (value, magnitude) from its arguments'; None outside the supported nodes or the reals."""
    xs = [a[0] for a in args]
    try:
        if node.is_Add:
            result = math.fsum(xs)
        elif node.is_Mul:
            result = math.prod(xs)
        elif node.is_Pow:
            result = math.pow(xs[0], xs[1])
        elif type(node) is sp.atan2:
            result = math.atan2(xs[0], xs[1])
        elif type(node) in _MATH and len(xs) == 1:
            result = _MATH[type(node)](xs[0])
        else:
            return None
    except (ValueError, OverflowError, ZeroDivisionError, TypeError):
        return None
    if not math.isfinite(result):
        return None
    return result, max(abs(result), *(a[1] for a in args))


#: nodes rebuilt over interned arguments: sums and products as they are (no evaluation), powers and these
#: functions unevaluated; a node of another kind is kept as it is (one object per value still, its arguments
#: those it was built with)
_RAW = (sp.Add, sp.Mul)
_FUNCTIONS = frozenset(_MATH) | {sp.atan2}


class Interner(_PerEntry):
    """One object per value across the expressions it is given: derived equations hold many equal subexpressions
    built apart (the 80-link chain's printed equations: 548,521 objects, 222,329 distinct values). Whatever keys
    them by value (the printers' census and names) compares two such objects through their whole trees, and
    whatever keys them by object (the printers' memo) works once per copy; over interned expressions an equal
    pair is one object, and equality stops at the first shared argument. Each node is rebuilt over its interned
    arguments, to the same value (sums and products from their arguments as they are, powers and elementary
    functions as their constructors build them unevaluated; a node of another kind is kept with the arguments it
    was built with), never through sympy's constructor cache, which may hold an equal node over other argument
    objects (an earlier Interner's: a CI run's test order left two copies). The expressions given must stay alive
    while the Interner is used (it remembers nodes by identity)."""

    def __init__(self) -> None:
        self._canon: dict[sp.Basic, sp.Basic] = {}
        self._memo: dict[int, sp.Basic] = {}  # id(node) -> its interned object

    def of(self, expr: sp.Basic) -> sp.Basic:
        """The interned object equal to ``expr``."""
        memo, canon = self._memo, self._canon
        stack = [expr]  # iterative: the trees of long chains are deeper than Python's stack
        pop, push = stack.pop, stack.append
        while stack:
            node = stack[-1]
            if id(node) in memo:
                pop()
                continue
            args = node.args
            if not args:
                memo[id(node)] = canon.setdefault(node, node)
                pop()
                continue
            waiting = False  # its arguments first
            for a in args:
                if id(a) not in memo:
                    push(a)
                    waiting = True
            if waiting:
                continue
            pop()
            new = [memo[id(a)] for a in args]
            key = node
            for n, a in zip(new, args):
                if n is not a:
                    key = self._rebuilt(node, new)
                    break
            memo[id(node)] = canon.setdefault(key, key)
        return memo[id(expr)]

    def _rebuilt(self, node: sp.Basic, args: list[sp.Basic]) -> sp.Basic:
        """``node`` over the interned ``args`` (equal to its own), built as its constructor builds it unevaluated
        but not through sympy's cache, which would give back an equal node over other argument objects."""
        if isinstance(node, _RAW):
            return node._new_rawargs(*args)
        if type(node) is sp.Pow:  # Pow.__new__ unevaluated: Expr.__new__, then its commutativity
            out = sp.Expr.__new__(sp.Pow, *args)
            out.is_commutative = args[0].is_commutative and args[1].is_commutative
            return out
        if type(node) in _FUNCTIONS and "nargs" in getattr(node, "__dict__", ()):
            # Application.__new__ unevaluated: Basic.__new__, then the instance's nargs (the same class and
            # number of arguments: the same nargs)
            out = sp.Basic.__new__(type(node), *args)
            out.nargs = node.nargs
            return out
        return node
