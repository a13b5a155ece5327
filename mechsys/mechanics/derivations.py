"""The derivation cache: a model's equations of motion (M, f, Q, T, V, A, b) stored on disk once per structure,
and the decision which coordinates are cyclic (per structure and parameter values).

Every command that derives equations (`derive`, `info`, `equilibria`, `modes`, `collide`, ...) reads them back
instead of deriving again. The entry is data (mechanics/serialize.py: a whitelisted expression table, never
code), signed like every cache entry (numeric/cache.py) and keyed by ``cache.model_key``: the file's structure
with names in file order, the decisions that depend on values, the released coordinates, the parameter and
coordinate order, the code fingerprint and the formulation. A damaged, foreign or unsupported entry is ignored.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable

import sympy as sp

from mechsys.mechanics import serialize

if TYPE_CHECKING:
    from mechsys.mechanics.model import Equations, MechanicalModel
    from mechsys.mechanics.symmetry import CyclicDecision

PARTS = ("M", "f", "Q", "A", "b")  # matrices; then T and V


def model_symbols(model: MechanicalModel) -> dict[str, sp.Symbol]:
    """The model's symbols by name (what stored expressions may name); empty on a name clash (then no cache)."""
    out = {s.name: s for s in (model.t, *model.q, *model.u, *model.a, *model.parameter_symbols)}
    return out if len(out) == 3 * len(model.q) + 1 + len(model.parameter_symbols) else {}


def store(model: MechanicalModel, eq: Equations) -> None:
    """Write ``eq`` (a no-op when the cache is off or the expressions leave the whitelist)."""
    from mechsys.numeric import cache

    symbols = model_symbols(model)
    mats = [sp.Matrix(getattr(eq, k)) for k in PARTS]
    try:
        data = serialize.dump([e for m in mats for e in m] + [eq.T, eq.V], symbols) if symbols else None
    except serialize.Unsupported:
        data = None
    if data is not None:
        cache.store(cache.model_key(model, f"equations:{eq.method}"),
                    {"shapes": [list(m.shape) for m in mats], "expressions": data})


def load(model: MechanicalModel, method: str) -> Equations | None:
    """The stored equations of ``model`` by ``method``, with the model's own symbols; None when absent or unusable.
    The model's energies and constraint rows are filled from them too (no second derivation)."""
    from mechsys.mechanics.model import Equations
    from mechsys.numeric import cache

    symbols = model_symbols(model)
    entry = cache.load(cache.model_key(model, f"equations:{method}")) if symbols else None
    if entry is None:
        return None
    exprs = serialize.load(entry.get("expressions"), symbols)
    try:
        shapes = [(int(r), int(c)) for r, c in entry["shapes"]]
    except (KeyError, TypeError, ValueError):
        return None
    if exprs is None or len(shapes) != len(PARTS) or len(exprs) != sum(r * c for r, c in shapes) + 2:
        return None
    mats, k = {}, 0
    for name, (r, c) in zip(PARTS, shapes):
        mats[name] = sp.Matrix(r, c, exprs[k:k + r * c]) if r * c else sp.zeros(r, c)
        k += r * c
    n, m = len(model.q), len(model.kin.constraints)
    if shapes[:3] != [(n, n), (n, 1), (n, 1)] or mats["A"].shape[0] != m or mats["b"].shape[0] != m:
        return None
    T, V = exprs[-2], exprs[-1]
    for attr, value in (("kinetic_energy", T), ("potential_energy", V), ("generalized_forces", mats["Q"]),
                        ("constraint_jacobian", mats["A"]), ("constraint_rhs", mats["b"])):
        model.__dict__.setdefault(attr, value)  # cached properties: read from the entry, not derived again
    return Equations(method, model.coordinates, model.q, model.u, model.a, mats["M"], mats["f"], mats["Q"], T, V,
                     mats["A"], mats["b"], [c.name for c in model.kin.constraints])


def cyclic_decision(model: MechanicalModel, decide: Callable[[MechanicalModel], CyclicDecision]) -> CyclicDecision:
    """``decide(model)`` (mechanics/symmetry.py), remembered on disk: it compiles M, f, A, b and Phi for its shift
    test, the larger part of `info` on a 3-D model. It depends on the structure and on the parameter values
    (generic values are drawn around them; a declared symmetry is checked at them), so both are in the key."""
    import json

    from mechsys.mechanics.symmetry import CyclicDecision
    from mechsys.numeric import cache

    values = [[name, float(v)] for name, v in model.doc.parameter_values.items()]
    key = cache.model_key(model, "cyclic:" + json.dumps(values))
    entry = cache.load(key)
    try:
        names = [str(n) for n in entry["names"]]
        basis = {str(k): str(v) for k, v in entry["basis"].items()}
        denied = [str(n) for n in entry["denied"]]
        if set(names) | set(basis) | set(denied) <= set(model.coordinates) and set(names) == set(basis):
            return CyclicDecision(names, basis, denied)
    except (TypeError, KeyError, AttributeError):
        pass  # absent (None) or malformed: decide again
    out = decide(model)
    cache.store(key, {"names": out.names, "basis": out.basis, "denied": out.denied})
    return out


def autonomous_decision(model: MechanicalModel, method: str, decide: Callable[[], bool]) -> bool:
    """``decide()`` (MechanicalModel.is_autonomous: whether t appears in M, f, A, b, a scan of the whole
    equations), remembered on disk. It reads the structure and, where t appears, the parameter values (d/dt = 0
    is checked numerically at them), so both are in the key."""
    import json

    from mechsys.numeric import cache

    values = [[name, float(v)] for name, v in model.doc.parameter_values.items()]
    key = cache.model_key(model, f"autonomous:{method}:" + json.dumps(values))
    entry = cache.load(key)
    if entry is not None and isinstance(entry.get("autonomous"), bool):
        return entry["autonomous"]
    out = bool(decide())
    cache.store(key, {"autonomous": out})
    return out
