"""Cheap, exact clean-up of printed equations: Pythagorean identities, angle sums, unit-vector norms, tidy signs."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cmp_to_key, reduce
from itertools import combinations, product
from typing import TYPE_CHECKING, Callable, Iterator, TypeVar

import sympy as sp
from sympy.core.mul import _keep_coeff

from mechsys.mechanics.construct import Constructors
from mechsys.mechanics.model import Equations
from mechsys.mechanics.order import canonical_key, compare

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel

#: Work one command may spend on the clean-up, in node visits; what is left is printed as derived (and reported).
#: A count, not a time: what is printed must not depend on the machine or its load. The bicycle's whole clean-up
#: (Lagrange) is 6,942 visits, about 0.6 s; the rolling disk's 894 (0.15 s).
BUDGET_VISITS = 20_000

# Expanding a product to find a unit-vector norm is tried only on small factors and sums (cheap and bounded).
_NORM_FACTOR_TERMS = 4     # terms of a sum factor that may be multiplied out
_NORM_FACTOR_NODES = 80    # tree nodes of such a factor
_NORM_PRODUCTS = 16        # terms one multiplied-out term may produce
_NORM_SUM_TERMS = 64       # terms of a sum whose products are tried
_NORM_CANDIDATES = 6       # products tried in one sum

Value = TypeVar("Value")
_TRIG = (sp.sin, sp.cos)
_OTHER = {sp.sin: sp.cos, sp.cos: sp.sin}
_UNDEFINED = (sp.zoo, sp.nan, sp.oo, -sp.oo)
_BY_REST = cmp_to_key(lambda a, b: compare(a[1], b[1]))  # (coefficient, rest) pairs by rest, canonical order


class OutOfTime(Exception):
    """The clean-up budget is spent."""


@dataclass(frozen=True)
class Cleanup:
    """The equations to print, and how many of their entries the budget left as derived or only partly cleaned
    (identities and signs, no unit-vector norms)."""

    equations: Equations
    entries: int
    left_as_derived: int
    partly_cleaned: int
    budget: int
    spent: int = 0  # node visits used

    def note(self) -> str | None:
        """One line for the reader when the budget ran out, else None."""
        if self.left_as_derived:
            what = f"{self.left_as_derived} of {self.entries} entries left as derived"
        elif self.partly_cleaned:
            what = f"unit-vector norms not tried in {self.partly_cleaned} of {self.entries} entries"
        else:
            return None
        return (f"readable form: clean-up stopped after {self.budget:,} node visits; {what}, use --simplify for a "
                "full (slow) simplification or --raw for none")


# ------------------------------------------------------------------------------------------------ traversal
_PENDING = object()  # an argument not folded yet


def _fold(expr: sp.Basic, combine: Callable[[sp.Basic, tuple], Value], memo: dict,
          tick: Callable[[], None]) -> Value:
    """Post-order fold without recursion (deep trees are fine): combine(node, values of its args), memoized."""
    stack = [expr]
    while stack:
        node = stack[-1]
        if node in memo:
            stack.pop()
            continue
        # one lookup per argument (an argument equal to a remembered one but another object is compared with it
        # through its whole tree: derived equations hold many such copies)
        values = [memo.get(a, _PENDING) for a in node.args]
        if any(v is _PENDING for v in values):
            stack.extend(a for a, v in zip(node.args, values) if v is _PENDING)
            continue
        stack.pop()
        tick()
        memo[node] = combine(node, tuple(values))
    return memo[expr]


def _no_tick() -> None:
    return None


# ----------------------------------------------------------------------------------------- Pythagoras
def _factors(term: sp.Expr) -> tuple[sp.Expr, tuple[sp.Expr, ...]]:
    """(numeric coefficient, other factors) of one term of a sum."""
    if term.is_Mul:  # term.as_coeff_Mul() without building the product of the other factors
        args = term.args
        return (args[0], args[1:]) if args[0].is_Number else (sp.S.One, args)
    return (term, ()) if term.is_Number else (sp.S.One, (term,))


def _trig_square(factor: sp.Expr) -> tuple[type, sp.Expr, sp.Expr] | None:
    """(sin or cos, argument, the factor divided by its square) for sin(x)**n or cos(x)**n with integer n >= 2."""
    if not (factor.is_Pow and isinstance(factor.base, _TRIG) and factor.exp.is_Integer and factor.exp >= 2):
        return None
    return factor.base.func, factor.base.args[0], factor.base ** (factor.exp - 2)


def _reductions(factors: tuple[sp.Expr, ...]) -> Iterator[tuple[type, sp.Expr, frozenset]]:
    """For each sin(x)**n / cos(x)**n factor: (function, x, the other factors once sin(x)**2 / cos(x)**2 is
    taken out), as a set (a product's factors have distinct bases)."""
    for k, f in enumerate(factors):
        trig = _trig_square(f)
        if trig is None:
            continue
        func, arg, rest = trig
        others = factors[:k] + factors[k + 1:] + ((rest,) if rest != 1 else ())
        yield func, arg, frozenset(others)


def _pair_squares(terms: list[sp.Expr]) -> list[sp.Expr] | None:
    """c*R*sin(x)**2 + c*R*cos(x)**2 -> c*R for every disjoint pair of terms; None when there is none."""
    slots: dict[tuple, dict[type, int]] = {}
    for i, term in enumerate(terms):
        coeff, factors = _factors(term)
        for func, arg, others in _reductions(factors):
            slots.setdefault((arg, coeff, others), {}).setdefault(func, i)
    used: set[int] = set()
    new = []
    for (_, coeff, others), slot in slots.items():
        i, j = slot.get(sp.sin), slot.get(sp.cos)
        if i is None or j is None or i in used or j in used:
            continue
        used |= {i, j}
        new.append(sp.Mul(coeff, *others))
    return [t for k, t in enumerate(terms) if k not in used] + new if new else None


def _pair_complements(terms: list[sp.Expr]) -> list[sp.Expr] | None:
    """c*R - c*R*sin(x)**2 -> c*R*cos(x)**2 (and sin for cos), once per term; None when there is none."""
    plain = {}
    for i, term in enumerate(terms):
        coeff, factors = _factors(term)
        plain.setdefault((coeff, frozenset(factors)), i)
    used: set[int] = set()
    new = []
    for i, term in enumerate(terms):
        coeff, factors = _factors(term)
        for func, arg, others in _reductions(factors):
            j = plain.get((-coeff, others))
            if j is None or i in used or j in used or i == j:
                continue
            used |= {i, j}
            new.append(sp.Mul(-coeff, *others, _OTHER[func](arg) ** 2))
    return [t for k, t in enumerate(terms) if k not in used] + new if new else None


def _trig_power(factor: sp.Expr) -> tuple[type, sp.Expr] | None:
    """(sin or cos, argument) for sin(x)**n or cos(x)**n, integer n >= 1."""
    if isinstance(factor, _TRIG):
        return factor.func, factor.args[0]
    if factor.is_Pow and isinstance(factor.base, _TRIG) and factor.exp.is_Integer and factor.exp >= 1:
        return factor.base.func, factor.base.args[0]
    return None


def _one_power_less(factor: sp.Expr) -> tuple[sp.Expr, ...]:
    """sin(x)**n / sin(x) (likewise cos) as the factors it leaves: none for n = 1."""
    return (factor.base ** (factor.exp - 1),) if factor.is_Pow else ()


def _trig_factors(factors: tuple[sp.Expr, ...]) -> list[tuple[int, tuple]]:
    """(index, _trig_power) of each sin/cos factor."""
    return [(k, t) for k, t in enumerate(map(_trig_power, factors)) if t is not None]


def _angle_pairs(factors: tuple[sp.Expr, ...], trig: list[tuple[int, tuple]]) -> Iterator[tuple]:
    """For each two of the sin/cos factors ``trig`` (_trig_factors of ``factors``) of different arguments:
    ((function of x, function of y), x, y, the other factors once one power of each is taken out, as a set), x and
    y in sympy's canonical order."""
    for (i, (fi, xi)), (j, (fj, xj)) in combinations(trig, 2):
        if xi == xj:
            continue
        others = (factors[:i] + factors[i + 1:j] + factors[j + 1:] + _one_power_less(factors[i])
                  + _one_power_less(factors[j]))
        if xi.compare(xj) > 0:
            fi, xi, fj, xj = fj, xj, fi, xi
        yield (fi, fj), xi, xj, frozenset(others)


#: c*R*f(x)*g(y) + s*c*R*f'(x)*g'(y) (s = +-1) -> c*R*h(x op y): the sum and difference formulas, keyed by the
#: two products' functions of (x, y) and the sign s
_ANGLE_RULES = {((sp.cos, sp.cos), (sp.sin, sp.sin), 1): (sp.cos, -1),
                ((sp.cos, sp.cos), (sp.sin, sp.sin), -1): (sp.cos, 1),
                ((sp.sin, sp.cos), (sp.cos, sp.sin), 1): (sp.sin, 1),
                ((sp.sin, sp.cos), (sp.cos, sp.sin), -1): (sp.sin, -1)}
_ANGLE_PARTNER = {(sp.cos, sp.cos): (sp.sin, sp.sin), (sp.sin, sp.cos): (sp.cos, sp.sin)}
_ANGLE_EITHER = {**_ANGLE_PARTNER, **{b: a for a, b in _ANGLE_PARTNER.items()}}  # each kind of pair's partner


def _angle(rule: tuple, x: sp.Expr, y: sp.Expr) -> sp.Expr | None:
    """sin or cos of x +- y, or None when sympy evaluates it to something other than a number times a sin or cos
    (the pair is then left as it is: a clean-up result of the same kind of factors as its input)."""
    func, sign = rule
    value = func(x + sign * y)
    return value if all(f.is_Number or isinstance(f, _TRIG) for f in sp.Mul.make_args(value)) else None


def _pair_angles(terms: list[sp.Expr]) -> list[sp.Expr] | None:
    """c*R*cos(x)*cos(y) + c*R*sin(x)*sin(y) -> c*R*cos(x - y), and likewise cos(x + y), sin(x + y) and sin(x - y),
    for every disjoint pair of terms in the sum's order; None when there is none."""
    candidates = []  # the terms with two sin/cos factors or more
    sins: set = set()
    coss: set = set()
    for i, term in enumerate(terms):
        coeff, factors = _factors(term)
        trig = _trig_factors(factors)
        if len(trig) >= 2:
            candidates.append((i, coeff, factors, trig))
            for _, (func, arg) in trig:
                (sins if func is sp.sin else coss).add(arg)
    if len(candidates) < 2 or sins.isdisjoint(coss):  # every rule needs sin(x) in one term and cos(x) in another
        return None
    slots: dict[tuple, list[tuple[tuple, sp.Expr, int]]] = {}
    for i, coeff, factors, trig in candidates:
        for funcs, x, y, others in _angle_pairs(factors, trig):
            slots.setdefault((x, y, others), []).append((funcs, coeff, i))
    used: set[int] = set()
    new = []
    for (x, y, others), entries in slots.items():
        for funcs, coeff, i in entries:
            partner = _ANGLE_PARTNER.get(funcs)
            if partner is None or i in used:
                continue
            for other, c2, j in entries:
                sign = 1 if c2 == coeff else -1 if c2 == -coeff else 0
                if other != partner or j in used or not sign:
                    continue
                value = _angle(_ANGLE_RULES[(funcs, partner, sign)], x, y)
                if value is not None:
                    used |= {i, j}
                    new.append(sp.Mul(coeff, *others, value))
                    break
    return [t for k, t in enumerate(terms) if k not in used] + new if new else None


def pythagoras(add: sp.Expr) -> sp.Expr:
    """The sum with sin(x)**2 + cos(x)**2 = 1 applied wherever two terms share every other factor, then the sum
    and difference formulas (cos(x)*cos(y) + sin(x)*sin(y) = cos(x - y), ...) likewise."""
    terms = list(sp.Add.make_args(add))
    changed = False
    while True:
        step = _pair_squares(terms) or _pair_complements(terms) or _pair_angles(terms)
        if step is None:
            break
        changed = True
        terms = list(sp.Add.make_args(sp.Add(*step)))
    return sp.Add(*terms) if changed else add


# ---------------------------------------------------------------------------------------------------- signs
def _content(coeffs: list[sp.Expr]) -> sp.Expr:
    """The positive rational content of rational coefficients (their gcd over the lcm of their denominators),
    or 1 when one of them is not rational."""
    if not all(c.is_Rational for c in coeffs):
        return sp.Integer(1)
    return sp.Rational(reduce(math.gcd, (abs(c.p) for c in coeffs)), reduce(math.lcm, (c.q for c in coeffs)))


def _tidy_factor(factor: sp.Expr) -> tuple[sp.Expr, sp.Expr] | None:
    """(number, factor') with number*factor' == factor, where a sum raised to an integer power loses its numeric
    content and its minus signs when most of its terms have one (on a tie: when the term first in sympy's
    canonical order of the non-numeric parts has one, the same term for the sum and its negative):
    (-2*a - 2*b)**2 -> (4, (a + b)**2). None when there is nothing to do."""
    base, exp = factor.as_base_exp()
    if not (base.is_Add and exp.is_Integer):
        return None
    split = [t.as_coeff_Mul() for t in base.args]
    coeffs = [c for c, _ in split]
    minus = 2 * sum(1 for c in coeffs if _negative_number(c)) - len(coeffs)
    negative = minus > 0 or minus == 0 and _negative_number(min(split, key=_BY_REST)[0])
    content = _content(coeffs)
    if content == 1 and not negative:
        return None
    if negative:
        content = -content
    divided = _divided(base, split, content)
    return (content, divided) if exp is sp.S.One else (content ** exp, divided ** exp)


def _negative_number(c: sp.Expr) -> bool:
    """c.is_negative for a number, read off a rational's numerator: asking a new Rational object through the
    assumptions system first deduces all its facts (a third of a 20-link Lagrange clean-up's time)."""
    return c.p < 0 if c.is_Rational else bool(c.is_negative)


def _divided(base: sp.Expr, split: list[tuple[sp.Expr, sp.Expr]], number: sp.Expr) -> sp.Expr:
    """The sum divided by a number that divides its rational coefficients: no term merges with another, so the
    terms are only re-sorted, as sympy's Add.primitive does (a full Add() costs far more on big sums)."""
    quotients: dict[sp.Expr, sp.Expr] = {}  # a sum's coefficients repeat (a chain's: 1, 1/2, their negatives)
    terms = []
    for c, rest in split:
        q = quotients.get(c)
        if q is None:
            q = quotients[c] = c / number
        if rest.is_Mul and q is not sp.S.One and q is not sp.S.NegativeOne:
            # what _keep_coeff builds (rest has no numeric factor), its commutativity known: rest's
            terms.append(sp.Mul._from_args((q, *rest.args), rest.is_commutative))
        else:
            terms.append(_keep_coeff(q, rest))
    first = terms.pop(0) if terms[0].is_Number else None
    terms.sort(key=canonical_key)  # Add's order (sympy's _addsort)
    return base._new_rawargs(*([first] if first is not None else []), *terms)


def tidy_signs(expr: sp.Expr, memo: dict | None = None) -> sp.Expr:
    """A product or power with the numbers and minus signs of its sum factors moved to its coefficient. ``memo``:
    the factors' results so far (a chain's mass-matrix entries share their sum factors)."""
    coeff = sp.Integer(1)
    factors = []
    changed = False
    for f in sp.Mul.make_args(expr):
        if memo is None:
            tidy = _tidy_factor(f)
        elif f in memo:
            tidy = memo[f]
        else:
            tidy = memo[f] = _tidy_factor(f)
        if tidy is None:
            factors.append(f)
            continue
        changed = True
        coeff *= tidy[0]
        factors.append(tidy[1])
    if not changed:
        return expr
    quick = _product(coeff, factors) if expr.is_Mul else None
    return quick if quick is not None else sp.Mul(coeff, *factors)


def _product(coeff: sp.Expr, factors: list[sp.Expr]) -> sp.Expr | None:
    """sp.Mul(coeff, *factors) built directly where Mul's flatten would only multiply the numbers and sort the
    factors (the factors of a product with some sum factors divided by their content): a rational coefficient and
    commutative factors that are no numbers, each on its own base; two or more of them, or one that is not a sum
    (a number times one sum is multiplied out). None otherwise (sympy's Mul then: merging powers, distributing a
    number over a sum, floats...)."""
    rest = []
    for f in factors:
        if f.is_Rational:
            coeff = coeff * f
        elif f.is_number or not f.is_commutative:
            return None
        else:
            rest.append(f)
    if not coeff.is_Rational or coeff == 0 or not rest or len({f.as_base_exp()[0] for f in rest}) < len(rest):
        return None
    if len(rest) == 1 and (coeff == 1 or rest[0].is_Add):
        return None
    rest.sort(key=canonical_key)  # Mul's order (sympy's _mulsort)
    return sp.Mul._from_args(rest if coeff == 1 else [coeff, *rest], True)


# ---------------------------------------------------------------------------------------- unit-vector norms
def _direct_trig(term: sp.Expr, sins: set, coss: set) -> None:
    """Add the arguments of the sin and cos factors (any power) of a product to sins and coss."""
    for f in sp.Mul.make_args(term):
        base = f.base if f.is_Pow else f
        if isinstance(base, sp.sin):
            sins.add(base.args[0])
        elif isinstance(base, sp.cos):
            coss.add(base.args[0])


def _may_pair(terms: tuple, expanded: set) -> bool:
    """Whether multiplying out can give sin(x)**2 and cos(x)**2 of one x: both must already be factors of a term
    or of a term of a sum factor (a cheap necessary condition that avoids building the products)."""
    sins: set = set()
    coss: set = set()
    for term in terms:
        for f in sp.Mul.make_args(term):
            base = f.base if f.is_Pow else f
            for part in (base.args if term in expanded and base.is_Add else (f,)):
                _direct_trig(part, sins, coss)
    return not sins.isdisjoint(coss)


Monomial = tuple[sp.Expr, dict]  # (numeric coefficient, {base: exponent})


def _monomial(term: sp.Expr) -> Monomial:
    coeff, factors = _factors(term)
    powers: dict = {}
    for f in factors:
        base, exp = f.as_base_exp()
        powers[base] = powers.get(base, 0) + exp
    return coeff, powers


def _times(a: Monomial, b: Monomial) -> Monomial:
    powers = dict(a[1])
    for base, exp in b[1].items():
        powers[base] = powers.get(base, 0) + exp
    return a[0] * b[0], powers


def _collected(monomials: list[Monomial]) -> dict[frozenset, sp.Expr]:
    """The monomials with like ones added: {the set of (base, exponent): coefficient}."""
    collected: dict[frozenset, sp.Expr] = {}
    for coeff, powers in monomials:
        key = frozenset((b, e) for b, e in powers.items() if e != 0)
        collected[key] = collected.get(key, 0) + coeff
    return collected


def _has_square_pair(monomials: list[Monomial]) -> bool:
    """Whether two of the (collected) monomials are c*R*sin(x)**2 and c*R*cos(x)**2."""
    collected = _collected(monomials)
    seen: dict[tuple, set] = {}
    for key, coeff in collected.items():
        if coeff == 0:
            continue
        for base, exp in key:
            if isinstance(base, _TRIG) and exp.is_Integer and exp >= 2:
                rest = key - {(base, exp)} | ({(base, exp - 2)} if exp > 2 else set())
                funcs = seen.setdefault((base.args[0], coeff, rest), set())
                funcs.add(base.func)
                if len(funcs) == 2:
                    return True
    return False


def _has_angle_pair(monomials: list[Monomial]) -> bool:
    """Whether two of the (collected) monomials are a pair of the sum and difference formulas: c*R*cos(x)*cos(y)
    and +-c*R*sin(x)*sin(y), or c*R*sin(x)*cos(y) and +-c*R*cos(x)*sin(y) (the pairs _pair_angles takes)."""
    slots: dict[tuple, set] = {}
    for key, coeff in _collected(monomials).items():
        if coeff == 0:
            continue
        factors = tuple(base ** exp for base, exp in key)
        for funcs, x, y, others in _angle_pairs(factors, _trig_factors(factors)):
            slot = slots.setdefault((x, y, others), set())
            if (_ANGLE_EITHER[funcs], coeff) in slot or (_ANGLE_EITHER[funcs], -coeff) in slot:
                return True
            slot.add((funcs, coeff))
    return False


@dataclass
class _Work:
    """The budget of one command's clean-up (node visits), shared by its passes."""

    budget: int
    spent: int = 0


class _Cleaner:
    """One clean-up pass over many expressions, sharing the work on common subexpressions, against a budget."""

    def __init__(self, work: "_Work", norms: bool = True, settled: bool = False, angles: bool = False) -> None:
        self.work = work
        self.norms = norms
        self.settled = settled  # the input already went through the identities and signs: redo them on change
        self.angles = angles  # also try the norms where only the sum and difference formulas would apply
        self.memo: dict[sp.Basic, sp.Basic] = {}
        self.sizes: dict[sp.Basic, int] = {}
        self.products: dict[sp.Expr, sp.Expr] = {}
        self.factors: dict[sp.Expr, tuple | None] = {}  # tidy_signs's memo
        self.build = Constructors()  # nodes rebuilt over cleaned args: directly where flatten would only sort

    def tick(self) -> None:
        self.work.spent += 1
        if self.work.spent > self.work.budget:
            raise OutOfTime

    def size(self, expr: sp.Basic) -> int:
        return _fold(expr, lambda node, args: 1 + sum(args), self.sizes, _no_tick)

    def clean(self, expr: sp.Expr) -> sp.Expr:
        return _fold(expr, self._node, self.memo, self.tick)

    def _node(self, node: sp.Basic, args: tuple) -> sp.Basic:
        """The node over its cleaned args, with the rules applied; the node as derived if that evaluated to an
        infinity or nan (a division by an expression that the identities make zero: keep what was derived)."""
        changed = args != node.args
        new = self._rebuilt(node, args) if changed else node
        redo = changed or not self.settled
        if new.is_Add:
            new = pythagoras(new) if redo else new
            new = self._norms(new) if self.norms else new
        elif (new.is_Mul or new.is_Pow) and redo:
            new = tidy_signs(new, self.factors)
        return node if new.is_Atom and new in _UNDEFINED and node not in _UNDEFINED else new

    def _rebuilt(self, node: sp.Basic, args: tuple) -> sp.Basic:
        """node.func(*args)."""
        kind = node.func
        if kind is sp.Add:
            return self.build.add(list(args))
        return self.build.mul(list(args)) if kind is sp.Mul else kind(*args)

    def _expandable(self, factor: sp.Expr) -> int:
        """How many terms the factor contributes when multiplied out (1: it stays as it is)."""
        if not (factor.is_Add or factor.is_Pow and factor.base.is_Add and factor.exp == 2):
            return 1
        base, exp = factor.as_base_exp()
        if len(base.args) <= _NORM_FACTOR_TERMS and self.size(base) <= _NORM_FACTOR_NODES and base.has(*_TRIG):
            return len(base.args) ** int(exp)
        return 1

    def _count(self, term: sp.Expr) -> int:
        """How many terms the term gives when multiplied out over its small trigonometric sum factors."""
        total = 1
        for f in _factors(term)[1]:
            total *= self._expandable(f)
        return total

    def _products(self, term: sp.Expr) -> sp.Expr:
        """The term multiplied out over its small trigonometric sum factors (memoized)."""
        if term not in self.products:
            coeff, factors = _factors(term)
            choices = []
            for f in factors:
                base, exp = f.as_base_exp()
                choices += [base.args] * int(exp) if self._expandable(f) > 1 else [(f,)]
            self.products[term] = sp.Add(*(sp.Mul(coeff, *pick) for pick in product(*choices)))
        return self.products[term]

    def _monomials(self, term: sp.Expr, expand: bool) -> list[Monomial]:
        """The term as monomials, multiplied out if asked (plain Python: cheaper than building the sympy sum)."""
        if not expand:
            return [_monomial(term)]
        out = [_monomial(_factors(term)[0])]
        for f in _factors(term)[1]:
            base, exp = f.as_base_exp()
            parts = [_monomial(t) for t in base.args] if self._expandable(f) > 1 else [(sp.Integer(1), {base: exp})]
            for _ in range(int(exp) if self._expandable(f) > 1 else 1):
                out = [_times(m, p) for m in out for p in parts]
        return out

    def _norms(self, add: sp.Expr) -> sp.Expr:
        """Multiply out the small trigonometric products of a sum when the identities then make it smaller:
        (c*cos(y) - s*sin(y))**2 + (c*sin(y) + s*cos(y))**2 -> c**2 + s**2. Greedy: each product stays
        multiplied out only if that does not make the result larger. The trials are worked out class by class of
        the terms' signatures where that holds (_Classes: a trial redoes only what its product touches), else
        whole (_Whole); either gives the same result."""
        if not add.is_Add or len(add.args) > _NORM_SUM_TERMS:
            return add
        candidates = [t for t in add.args if 1 < self._count(t) <= _NORM_PRODUCTS][:_NORM_CANDIDATES]
        wanted = set(candidates)  # looked up by hash: a list compares unequal terms through their trees
        if not candidates or not _may_pair(add.args, wanted):
            return add
        monomials = [m for t in add.args for m in self._monomials(t, t in wanted)]
        if not _has_square_pair(monomials) and not (self.angles and _has_angle_pair(monomials)):
            return add
        expanded = {t: self._products(t) for t in candidates}
        trials = _Classes.of(add, expanded, self) or _Whole(add, expanded, self)
        chosen = set(expanded)
        self.tick()
        best = trials.result(chosen)
        if best is None:
            return add
        for term in candidates:  # in the sum's order: a set's order follows the process's string hashing
            if chosen - {term}:
                self.tick()  # one visit per trial, as many whichever way it is computed
            trial = trials.result(chosen - {term})
            if trial is not None and trial.size <= best.size:
                chosen, best = chosen - {term}, trial
        return best.expr() if best.size < self.size(add) else add


# ------------------------------------------------------------------------------------- the norms' trials
@dataclass
class _Trial:
    """A sum with some products multiplied out and the identities applied: its size, and how to build it."""

    size: int
    expr: Callable[[], sp.Expr]


class _Whole:
    """Each trial built whole: the sum with the chosen products multiplied out, then pythagoras."""

    def __init__(self, add: sp.Expr, expanded: dict, cleaner: "_Cleaner") -> None:
        self.add, self.expanded, self.size = add, expanded, cleaner.size

    def result(self, chosen: set) -> _Trial | None:
        """The trial; None if no identity applies (or nothing is multiplied out)."""
        if not chosen:
            return None
        summed = sp.Add(*(self.expanded[t] if t in chosen else t for t in self.add.args))
        result = pythagoras(summed)
        return None if result is summed else _Trial(self.size(result), lambda: result)


def _signature(term: sp.Expr) -> frozenset:
    """What pythagoras keeps of a term: its factors other than integer powers of sin and cos, with their powers.
    Merging like terms, sin(x)**2 + cos(x)**2 = 1 and its complements, and the sum and difference formulas (whose
    results are a number times a sin or cos, _angle) only ever join terms of one signature and give terms of that
    signature."""
    return frozenset((base, exp) for base, exp in _monomial(term)[1].items()
                     if exp != 0 and not (isinstance(base, _TRIG) and exp.is_Integer))


def _lone_sum(signature: frozenset) -> bool:
    """Whether a term's only factor other than sin and cos powers is a sum: once an identity takes them away,
    number*(a + b) would multiply out into terms of other signatures."""
    rest = [(b, e) for b, e in signature if not isinstance(b, _TRIG)]
    return len(rest) == 1 and rest[0][0].is_Add and rest[0][1] == 1


class _Classes:
    """The trials computed signature by signature: pythagoras never joins terms of different signatures, so a
    trial's result is the union of its signature classes' results, and a trial that multiplies out one product
    other than the last one redoes only the classes that product's terms fall in. The same results as _Whole,
    term for term (tests/test_readable.py compares the two)."""

    def __init__(self, add: sp.Expr, expanded: dict, signatures: dict, cleaner: "_Cleaner") -> None:
        self.add, self.expanded, self.signatures, self.size = add, expanded, signatures, cleaner.size
        self.touched = {t: {signatures[t], *(signatures[e] for e in sp.Add.make_args(x))}
                        for t, x in expanded.items()}
        self.done: dict[tuple, tuple[bool, tuple, int]] = {}

    @classmethod
    def of(cls, add: sp.Expr, expanded: dict, cleaner: "_Cleaner") -> "_Classes | None":
        """The split of this sum, or None when it may not hold (a lone sum factor) or would not help (one class)."""
        terms = [*add.args, *(e for x in expanded.values() for e in sp.Add.make_args(x))]
        signatures = {t: _signature(t) for t in terms}
        if len(set(signatures.values())) < 2 or any(_lone_sum(s) for s in signatures.values()):
            return None
        return cls(add, expanded, signatures, cleaner)

    def _sequence(self, chosen: set) -> list[sp.Expr]:
        """The terms in the order Add.flatten meets them in the whole sum: a multiplied-out product that is a
        sum is met after the other terms (float coefficients add in the same order)."""
        now, later = [], []
        for t in self.add.args:
            x = self.expanded[t] if t in chosen else t
            (later.extend(x.args) if x.is_Add and t in chosen else now.append(x))
        return now + later

    def _class(self, signature: frozenset, chosen: set, sequence: list) -> tuple[bool, tuple, int]:
        """(whether an identity applied, the terms of the result, their total size) of one class."""
        key = (signature, frozenset(t for t in chosen if signature in self.touched[t]))
        if key not in self.done:
            summed = sp.Add(*(e for e in sequence if self.signatures[e] == signature))
            result = pythagoras(summed)
            terms = () if result == 0 else sp.Add.make_args(result)
            self.done[key] = (result is not summed, terms, sum(self.size(e) for e in terms))
        return self.done[key]

    def result(self, chosen: set) -> _Trial | None:
        if not chosen:
            return None
        sequence = self._sequence(chosen)
        classes = [self._class(s, chosen, sequence) for s in dict.fromkeys(self.signatures[e] for e in sequence)]
        if not any(changed for changed, _, _ in classes):
            return None
        count = sum(len(terms) for _, terms, _ in classes)
        size = sum(size for _, _, size in classes) + (count >= 2) + (count == 0)
        return _Trial(size, lambda: sp.Add(*(e for _, terms, _ in classes for e in terms)))


# ------------------------------------------------------------------------------------------------ equations
def _entries(eq: Equations) -> list[tuple[str, tuple]]:
    """(field, index) of every printed expression, in the order derive prints them."""
    n, k = eq.M.shape[0], eq.A.shape[0]
    out: list[tuple[str, tuple]] = [("T", ()), ("V", ())] + [("Q", (i, 0)) for i in range(n)]
    for i in range(n):
        out += [("M", (i, j)) for j in range(eq.M.shape[1])] + [("f", (i, 0))]
    for r in range(k):
        out += [("A", (r, j)) for j in range(eq.A.shape[1])] + [("b", (r, 0))]
    return out


def _get(eq: Equations, name: str, index: tuple) -> sp.Expr:
    value = getattr(eq, name)
    return value[index] if index else value


def _clean_entries(eq: Equations, entries: list[tuple[str, tuple]], cleaner: _Cleaner) -> tuple[Equations, int]:
    """The equations with the entries cleaned in order until the budget is spent, and how many were not reached."""
    values = {"M": eq.M.copy(), "f": eq.f.copy(), "Q": eq.Q.copy(), "A": eq.A.copy(), "b": eq.b.copy(),
              "T": eq.T, "V": eq.V}
    for done, (name, index) in enumerate(entries):
        try:
            cleaned = cleaner.clean(_get(eq, name, index))
        except OutOfTime:
            return replace(eq, **values), len(entries) - done
        if index:
            values[name][index] = cleaned
        else:
            values[name] = cleaned
    return replace(eq, **values), 0


def readable(eq: Equations, budget: int | None = None) -> Cleanup:
    """The equations with every printed entry cleaned up exactly (the same functions of the same symbols) within
    the budget (node visits, default BUDGET_VISITS): first the identities and signs on every entry in print
    order, then with what is left the unit-vector norms; what the budget interrupts stays as it was.
    Entries are the printed expressions that are not a single number or symbol."""
    work = _Work(BUDGET_VISITS if budget is None else budget)
    entries = [(name, index) for name, index in _entries(eq) if _get(eq, name, index).args]
    cheap, left = _clean_entries(eq, entries, _Cleaner(work, norms=False))
    if left:
        return Cleanup(cheap, len(entries), left, 0, work.budget, work.spent)
    full, partly = _clean_entries(cheap, entries, _Cleaner(work, settled=True, angles=_inline(cheap, entries)))
    return Cleanup(full, len(entries), 0, partly, work.budget, work.spent)


def _inline(eq: Equations, entries: list[tuple[str, tuple]]) -> bool:
    """Whether the equations are small enough to print inline (report/printing.AUTO_NODES, the size at which
    `derive` starts to name shared subexpressions). Only then are the norms tried where only the sum and difference
    formulas would apply: the trials' measure, the size of each sum's tree, is then the printed size; in named
    output, multiplying out a factor printed once by name makes the text longer (the bicycle's: 37 kB -> 43 kB)."""
    from mechsys.report.printing import AUTO_NODES

    sizer = _Cleaner(_Work(0), norms=False)
    total = 0
    for name, index in entries:
        total += sizer.size(_get(eq, name, index))
        if total > AUTO_NODES:
            return False
    return True


def clean_expression(expr: sp.Expr, budget: int | None = None) -> sp.Expr:
    """One expression cleaned up as `readable` does a small model's, in one pass (OutOfTime when the budget runs
    out)."""
    return _Cleaner(_Work(BUDGET_VISITS if budget is None else budget), angles=True).clean(sp.sympify(expr))


def stored_readable(model: MechanicalModel, eq: Equations, budget: int | None = None) -> Cleanup:
    """readable(eq) for ``model``'s own derived equations, kept in the derivation cache as data (the entries the
    clean-up changed, through mechanics/serialize.py's whitelist, and the budget's counts), so a second `derive`
    of the model prints without cleaning up again. Only the changed entries are stored: the rest are the derived
    ones (the 80-link chain's budget reaches 2 % of its entries; storing all of them again took 2.5 s). The key is
    the model's (cache.model_key: structure, names, decisions, code), the formulation, the budget and this
    module's source; a stored entry that does not fit the equations' shapes is ignored."""
    import hashlib
    from pathlib import Path

    from mechsys.mechanics import derivations, serialize
    from mechsys.numeric import cache

    budget = BUDGET_VISITS if budget is None else budget
    symbols = derivations.model_symbols(model)
    if cache.cache_dir() is None or not symbols:
        return readable(eq, budget)
    digest = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]
    key = cache.model_key(model, f"readable:{eq.method}:{budget}:{digest}")
    derived = _flat(eq)
    entry = cache.load(key)
    if entry is not None:
        stored = _stored(entry, symbols, len(derived))
        if stored is not None:
            changed, counts = stored
            flat = list(derived)
            for k, expr in changed.items():
                flat[k] = expr
            return Cleanup(_unflat(eq, flat), counts[0], counts[1], counts[2], budget, counts[3])
    cleanup = readable(eq, budget)
    changed = {k: e for k, (e, d) in enumerate(zip(_flat(cleanup.equations), derived)) if e is not d and e != d}
    try:
        data = serialize.dump(list(changed.values()), symbols)
    except serialize.Unsupported:
        return cleanup
    cache.store(key, {"changed": list(changed), "expressions": data,
                      "counts": [cleanup.entries, cleanup.left_as_derived, cleanup.partly_cleaned, cleanup.spent]})
    return cleanup


def _flat(eq: Equations) -> list[sp.Expr]:
    """The entries of M, f, Q, A, b (row by row), then T and V."""
    from mechsys.mechanics.derivations import PARTS

    return [e for name in PARTS for e in getattr(eq, name)] + [eq.T, eq.V]


def _unflat(eq: Equations, flat: list[sp.Expr]) -> Equations:
    """``eq`` with its entries replaced by ``flat`` (in _flat's order)."""
    from mechsys.mechanics.derivations import PARTS

    mats, k = {}, 0
    for name in PARTS:
        rows, cols = getattr(eq, name).shape
        mats[name] = sp.Matrix(rows, cols, flat[k:k + rows * cols])
        k += rows * cols
    return replace(eq, T=flat[-2], V=flat[-1], **mats)


def _stored(entry: dict, symbols: dict, size: int) -> tuple[dict[int, sp.Expr], list[int]] | None:
    """(the changed entries by position, the counts) of a stored clean-up, or None when it does not fit."""
    from mechsys.mechanics import serialize

    positions, counts = entry.get("changed"), entry.get("counts")
    exprs = serialize.load(entry.get("expressions"), symbols)
    if exprs is None or not isinstance(positions, list) or len(positions) != len(exprs) \
            or not all(type(k) is int and 0 <= k < size for k in positions) or len(set(positions)) != len(positions):
        return None
    if not (isinstance(counts, list) and len(counts) == 4 and all(type(c) is int for c in counts)):
        return None
    return dict(zip(positions, exprs)), counts
