"""The on-disk cache of compiled code: hits on re-runs and parameter changes, misses on structural changes."""
from pathlib import Path

import numpy as np

import mechsys
from mechsys.analysis.motion.simulate import compile_model, simulate

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "systems" / "double_pendulum.yaml"


def test_second_run_skips_derivation_and_gives_the_same_result(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path))
    first = mechsys.load(MODEL)
    r1 = simulate(first, 1.0, 0.1)
    assert compile_model(first).cache_hit is False and len(list(tmp_path.glob("*.json"))) == 1
    second = mechsys.load(MODEL, {"m1": "2"})  # parameters are inputs: same compiled code
    assert compile_model(second).cache_hit is True
    assert not second._eqs and "_body_kinematics" not in vars(second)  # nothing was derived
    r2 = simulate(mechsys.load(MODEL), 1.0, 0.1)
    assert np.array_equal(r1.q, r2.q)


def test_structural_change_misses_and_cache_can_be_disabled(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path))
    compile_model(mechsys.load(MODEL))
    changed = tmp_path / "changed.yaml"
    changed.write_text(MODEL.read_text().replace("acceleration: [0, -g, 0]", "acceleration: [0, -2*g, 0]"))
    assert compile_model(mechsys.load(changed)).cache_hit is False
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    assert compile_model(mechsys.load(MODEL)).cache_hit is False


def test_damaged_cache_entry_is_ignored(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path))
    compile_model(mechsys.load(MODEL))
    for f in tmp_path.glob("*.json"):
        f.write_text("{not json")
    model = mechsys.load(MODEL)
    assert compile_model(model).cache_hit is False
    assert simulate(model, 0.5, 0.1).q.shape == (6, 2)


def test_an_entry_too_large_to_read_back_is_not_written(tmp_path, monkeypatch):
    """read_private refuses files over MAX_ENTRY_BYTES, so store does not write them (the 40-link chain's Lagrange
    JSON, 985 MB, was signed and written and never read); an entry at the limit is written and read back."""
    from mechsys.numeric import cache

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path))
    monkeypatch.setattr(cache, "MAX_ENTRY_BYTES", 4096)
    fits = {"text": "x" * (4096 - len(cache._MAGIC) - 65 - len('{"text": ""}'))}
    cache.store("fits", fits)
    assert cache.load("fits") == fits and (tmp_path / "fits.json").stat().st_size == 4096
    cache.store("big", {"text": "x" * 5000})
    assert cache.load("big") is None and not (tmp_path / "big.json").exists()
