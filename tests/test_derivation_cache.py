"""The derivation cache (issue 13): equations of motion and cyclic decisions stored once per model structure and
read back by every command. A cached result equals an uncached one, a change of the model's structure is a miss,
and the entries are data read through a whitelist (mechsys/mechanics/serialize.py)."""
import json
from pathlib import Path

import pytest
import sympy as sp

import mechsys
from mechsys.mechanics import serialize
from mechsys.mechanics.model import MechanicalModel

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = sorted(p.stem for p in (ROOT / "systems").glob("*.yaml") if p.stem != "bicycle")


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("MECHSYS_CACHE", str(folder))
    return folder


def parts(eq) -> list:
    return [eq.M.shape, eq.A.shape, *eq.M, *eq.f, *eq.Q, *eq.A, *eq.b, eq.T, eq.V]


def no_derivation(monkeypatch):
    def refuse(self):
        raise AssertionError("derived although the cache holds the equations")
    monkeypatch.setattr(MechanicalModel, "_kane", refuse)
    monkeypatch.setattr(MechanicalModel, "_lagrange", refuse)


@pytest.mark.parametrize("name", BUNDLED)
def test_cached_equations_equal_derived_ones(name, cache_dir, monkeypatch):
    """Both formulations of every bundled model: the entry written by the first load gives, in a new model
    object, expressions equal (==, exactly) to the derived ones, without deriving."""
    path = ROOT / "systems" / f"{name}.yaml"
    derived = {m: parts(mechsys.load(path).equations(m)) for m in ("kane", "lagrange")}
    no_derivation(monkeypatch)
    for method, want in derived.items():
        model = mechsys.load(path)
        assert parts(model.equations(method)) == want
        assert model.kinetic_energy == want[-2] and model.potential_energy == want[-1]


@pytest.mark.parametrize("first, then", [("kane", "lagrange"), ("lagrange", "kane")])
@pytest.mark.parametrize("name", ["four_bar", "rolling_disk", "slider_crank"])
def test_a_formulation_derived_after_the_other_equals_one_derived_alone(name, first, then, cache_dir,
                                                                       monkeypatch):
    """A model with constraints takes A, b, T, V and Q from the other formulation's stored entry (mechanics/model.py
    equations): the same expressions as a derivation on an empty cache, and A and b are not derived again."""
    path = ROOT / "systems" / f"{name}.yaml"
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    alone = parts(mechsys.load(path).equations(then))
    monkeypatch.setenv("MECHSYS_CACHE", str(cache_dir))
    mechsys.load(path).equations(first)
    model = mechsys.load(path)
    assert model.kin.constraints
    after = parts(model.equations(then))
    assert after == alone
    assert first in model._eqs  # the other entry was read ...
    # ... and the constraint rows came from it: the objects the loaded formulation holds
    assert model.constraint_jacobian is model._eqs[first].A and model.constraint_rhs is model._eqs[first].b


@pytest.mark.parametrize("name", ["rolling_disk", "slider_crank"])
def test_the_constraint_rows_are_read_from_a_stored_derivation(name, cache_dir, monkeypatch):
    """`info` and `simulate` ask for A and b before any formulation: a stored one is read instead of deriving
    them (the same expressions as with the cache off)."""
    path = ROOT / "systems" / f"{name}.yaml"
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    fresh = mechsys.load(path)
    want = (fresh.constraint_jacobian, fresh.constraint_rhs)
    monkeypatch.setenv("MECHSYS_CACHE", str(cache_dir))
    mechsys.load(path).equations("kane")
    model = mechsys.load(path)

    def refuse(*_a, **_k):
        raise AssertionError("derived although a stored derivation holds it")
    monkeypatch.setattr(MechanicalModel, "partials", refuse)
    monkeypatch.setattr(MechanicalModel, "dt", refuse)
    assert (model.constraint_jacobian, model.constraint_rhs) == want
    assert "kane" in model._eqs


def test_a_change_of_structure_is_a_miss_and_a_change_of_value_a_hit(tmp_path, cache_dir, monkeypatch):
    text = (ROOT / "systems" / "double_pendulum.yaml").read_text()
    first = tmp_path / "a.yaml"
    first.write_text(text)
    mechsys.load(first).equations("kane")
    calls = []
    original = MechanicalModel._kane
    monkeypatch.setattr(MechanicalModel, "_kane", lambda self: calls.append(1) or original(self))
    valued = tmp_path / "b.yaml"  # another value of a parameter: the same symbolic equations
    valued.write_text(text.replace("g: 9.81", "g: 9.80665"))
    assert "g: 9.80665" in valued.read_text()
    mechsys.load(valued).equations("kane")
    assert calls == []
    changed = tmp_path / "c.yaml"  # gravity along another axis: other equations
    changed.write_text(text.replace("acceleration: [0, -g, 0]", "acceleration: [-g, 0, 0]"))
    assert changed.read_text() != text
    eq = mechsys.load(changed).equations("kane")
    assert calls == [1]
    uncached = original(mechsys.load(changed))
    assert list(eq.f) == list(uncached[1])


def test_a_tampered_entry_is_ignored(cache_dir, monkeypatch):
    path = ROOT / "systems" / "centrifuge.yaml"
    want = parts(mechsys.load(path).equations("kane"))
    for entry in cache_dir.glob("*.json"):
        data = entry.read_bytes()
        entry.write_bytes(data.replace(b'"Add"', b'"Mul"'))  # the signature no longer matches
    assert parts(mechsys.load(path).equations("kane")) == want  # derived again, not read


def test_the_loader_accepts_only_the_whitelist():
    x, y = sp.symbols("x y", real=True)
    symbols = {"x": x, "y": y}
    exprs = [sp.sin(x) ** 2 * y + sp.Rational(3, 7) * sp.cos(x + y) - sp.pi, sp.Float("0.1", 30) * x, sp.atan2(y, x)]
    data = json.loads(json.dumps(serialize.dump(exprs, symbols)))
    assert serialize.load(data, symbols) == exprs
    for bad in (["eval", 0], ["S", "z"], ["Add", 99], ["__import__", 0]):
        assert serialize.load({"nodes": [["S", "x"], bad], "roots": [1]}, symbols) is None
    with pytest.raises(serialize.Unsupported):
        serialize.dump([sp.Function("g")(x)], symbols)
    with pytest.raises(serialize.Unsupported):
        serialize.dump([sp.Symbol("x")], symbols)  # the same name without the model's assumptions


@pytest.mark.parametrize("name", ["centrifuge", "rolling_disk", "slider_crank"])
def test_cached_cyclic_decisions_equal_fresh_ones(name, cache_dir, monkeypatch):
    path = ROOT / "systems" / f"{name}.yaml"
    fresh = mechsys.load(path).cyclic_decision
    import mechsys.mechanics.symmetry as symmetry
    monkeypatch.setattr(symmetry, "decide", lambda model: (_ for _ in ()).throw(AssertionError("decided again")))
    cached = mechsys.load(path).cyclic_decision
    assert (cached.names, cached.basis, cached.denied) == (fresh.names, fresh.basis, fresh.denied)
    name0, value0 = next(iter(mechsys.load(path).doc.parameter_values.items()))
    other = mechsys.load(path, {name0: repr(value0 * 1.01 if value0 else 0.5)})
    with pytest.raises(AssertionError, match="decided again"):
        other.cyclic_decision  # other parameter values: another key
