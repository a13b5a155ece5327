"""sympy's canonical order of the arguments of a sum or product (Basic.compare), with less overhead."""
from __future__ import annotations

from functools import cmp_to_key

import sympy as sp

#: sympy versions (major.minor) whose Basic.compare `compare` follows step for step, and whose Mul.flatten and
#: Add.flatten the differentiator's direct sums and products follow (tests/test_differentiate.py checks both)
VERIFIED = ("1.14",)
try:
    from sympy.core.basic import _cmp_name

    OWN = ".".join(sp.__version__.split(".")[:2]) in VERIFIED
except ImportError:  # pragma: no cover - another sympy layout: its own compare
    OWN = False

_BASIC_COMPARE = sp.Basic.compare
_NAME_ORDER: dict[tuple[type, type], int] = {}  # _cmp_name of two classes, remembered


def _stepwise(a: sp.Basic, b: sp.Basic) -> int:
    """Basic.compare(a, b), sympy's canonical order of the arguments of a sum or product, step for step, with the
    order of two class names remembered (sympy searches its list of class names at every node compared: a third
    of the sorting of a long chain's sums) and no call for an argument shared by a and b. Arguments of a class
    with its own compare are compared by it, as in sympy."""
    if a is b:
        return 0
    ka, kb = a.__class__, b.__class__
    if ka is not kb:
        c = _NAME_ORDER.get((ka, kb))
        if c is None:
            c = _NAME_ORDER[(ka, kb)] = _cmp_name(ka, kb)
        if c:
            return c
    st, ot = a._hashable_content(), b._hashable_content()
    if len(st) != len(ot):
        return 1 if len(st) > len(ot) else -1
    for l, r in zip(st, ot):
        if isinstance(l, sp.Basic):
            if l is r:
                continue  # (compare of an object with itself is 0, its own compare's too)
            c = _stepwise(l, r) if type(l).compare is _BASIC_COMPARE else l.compare(r)
        elif isinstance(l, frozenset):
            c = sp.Basic(*l).compare(sp.Basic(*r) if isinstance(r, frozenset) else r)
        else:
            c = (l > r) - (l < r)
        if c:
            return c
    return 0


#: Basic.compare: step for step with less overhead where verified, else sympy's own
compare = _stepwise if OWN else _BASIC_COMPARE
#: the sort key of Add's and Mul's arguments (sympy's _args_sortkey)
canonical_key = cmp_to_key(compare)
