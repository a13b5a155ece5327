"""Rest equations that are undefined somewhere or vanish only at infinity, and slow modes in small units (models a
user writes: a block on a rail pushed by a generalized force).

- F = 1/x has no root: the search reported 48 'equilibria' at |x| ~ 1e20, where 1/x passed the residual test, and
  modes vibrated about one. Newton's step from such a point doubles x: the acceptance now asks for a small step.
- F = -log(x) and F = -k sqrt(x) are not defined for x < 0: the search crashed (internal error: math domain error).
  It now skips such points, says so, and finds x = 1 for -log(x) (stiffness 1/x = 1, w = 1 with m = 1).
- A mass of 1 on a spring of 1e-9 vibrates at 3.16e-5 rad/s: modes called it a rigid-body mode (a bound of 1e-9 on
  w^2 in absolute units).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from mechsys.cli import app

UNDEFINED = "the forces are not defined at some points the search met"


def _block(tmp_path: Path, force: str, initial: float = 1.0) -> Path:
    path = tmp_path / "block.yaml"
    path.write_text(f"name: block\nparameters: {{k: 8, m: 1}}\ncoordinates:\n  x: {{initial: {initial}, rate: 0}}\n"
                    "links:\n  b:\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n    mass: m\n"
                    f"forces:\n  - {{type: generalized_force, coordinate: x, value: \"{force}\"}}\n")
    return path


def _run(*args: str):
    return CliRunner().invoke(app, list(args))


def test_a_force_that_only_tends_to_zero_has_no_equilibrium(tmp_path):
    path = _block(tmp_path, "1/x", 0.5)
    result = _run("equilibria", str(path), "-f", "json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["equilibria"] == [] and data["message"].startswith("no equilibrium found")
    modes = _run("modes", str(path))
    assert modes.exit_code == 1 and "no equilibrium found to vibrate about" in modes.output


def test_a_force_undefined_for_negative_x_is_searched_where_it_is_defined(tmp_path):
    path = _block(tmp_path, "-log(x)")
    result = _run("equilibria", str(path), "-f", "json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert [e["coordinates"]["x"] for e in data["equilibria"]] == [pytest.approx(1.0, abs=1e-12)]
    assert data["equilibria"][0]["stability"] == "stable" and UNDEFINED in data["message"]
    modes = json.loads(_run("modes", str(path), "-f", "json").output)
    assert modes["modes"][0]["frequency_rad_s"] == pytest.approx(1.0, rel=1e-9)


def test_a_square_root_force_does_not_crash_the_search(tmp_path):
    result = _run("equilibria", str(_block(tmp_path, "-k*sqrt(x)")), "-f", "json")
    assert result.exit_code == 0, result.output
    assert UNDEFINED in json.loads(result.output)["message"]


@pytest.mark.parametrize("m, k", [(1.0, 1e-9), (1e6, 1e-6)])
def test_a_slow_mode_in_small_units_is_not_rigid(tmp_path, m, k):
    path = tmp_path / "soft.yaml"
    path.write_text(f"name: soft\nparameters: {{m: {m}, k: {k}}}\ncoordinates:\n  x: {{initial: 0.01}}\nlinks:\n"
                    "  b:\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n    mass: m\n"
                    "forces:\n  - {type: potential, value: k/2*x^2}\n")
    data = json.loads(_run("modes", str(path), "-f", "json").output)
    (mode,) = data["modes"]
    assert mode["rigid_body"] is False and mode["frequency_rad_s"] == pytest.approx(math.sqrt(k / m), rel=1e-9)


def test_the_note_survives_the_stored_search(tmp_path, monkeypatch):
    """A second search on the model reads the roots from the cache without meeting the undefined points: its note is
    the same as the first's (cached == uncached), and the same with the cache off."""
    import mechsys
    from mechsys.analysis.equilibrium.equilibria import find_equilibria

    path = _block(tmp_path, "-log(x)")
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    first, second = (find_equilibria(mechsys.load(path)).message for _ in range(2))
    assert list((tmp_path / "cache").rglob("*")), "the search was stored"
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    off = find_equilibria(mechsys.load(path)).message
    assert first == second == off and UNDEFINED in first


def test_a_stiff_chains_soft_mode_is_not_called_rigid():
    """Six masses tied to a wall by springs of 1 to 1e8: K is positive definite, so no mode is rigid. The bound of
    1e-9 of the largest omega^2 called the first mode (0.450316 rad/s, 31,600 times below the highest) rigid, with
    frequency 0 and damping 0, exit 0. Checked against eigh of the chain's own K and M, and the modal damping
    phi^T C phi / (2 omega) of its dampers."""
    import scipy.linalg as sla

    path = Path(__file__).resolve().parent / "data" / "beyond" / "stiff_chain.yaml"
    result = CliRunner().invoke(app, ["modes", str(path), "-f", "json"])
    assert result.exit_code == 0, result.output
    modes = json.loads(result.output)["modes"]
    m = np.array([1, 0.5, 2, 0.1, 1, 0.3])
    k = np.array([1, 1e2, 1e4, 1e6, 1e8, 1e3])
    c = np.array([0.05, 0.5, 5, 200, 2e4, 0.2])

    def chain(s):  # element i joins mass i-1 (the wall for i = 0) and mass i
        out = np.diag(s + np.append(s[1:], 0.0))
        out -= np.diag(s[1:], 1) + np.diag(s[1:], -1)
        return out

    w2, phi = sla.eigh(chain(k), np.diag(m))
    assert [mode["rigid_body"] for mode in modes] == [False] * 6
    assert [mode["frequency_rad_s"] for mode in modes] == pytest.approx(np.sqrt(w2).tolist(), rel=1e-8)
    zeta = [float(phi[:, i] @ chain(c) @ phi[:, i]) / (2 * math.sqrt(w2[i])) for i in range(6)]
    assert [mode["damping_ratio"] for mode in modes] == pytest.approx(zeta, rel=1e-6)
