"""`modes` where the modal picture is not the whole story, on models written from the docs and checked against
derivations by hand here: a damper behind a massless node (the receptance and the transfer function of the
condensed system), a spinning disk swept for its Campbell diagram (the damped eigenvalues in the sweep table) and a
Jeffcott rotor above its stability threshold (growing motion with positive modal damping ratios)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from helpers import DATA_DIR
from mechsys.cli import app

runner = CliRunner()
MAXWELL = DATA_DIR / "beyond" / "maxwell_branch.yaml"
JEFFCOTT = DATA_DIR / "beyond" / "jeffcott.yaml"
SPUN_DISK = DATA_DIR / "beyond" / "spun_disk.yaml"


def cli_json(*args: str) -> dict:
    r = runner.invoke(app, [*map(str, args), "-f", "json"])
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)


def maxwell_receptance(w: float) -> np.ndarray:
    """[x, s] per unit force on [x, s]: the block (m, spring k1 to ground, spring k2 to the node) and the massless
    node (spring k2 to the block, damper c to ground), by hand."""
    m, k1, k2, c = 1.0, 100.0, 100.0, 5.0
    Z = np.array([[k1 + k2 - m * w**2, -k2], [-k2, k2 + 1j * w * c]])
    return np.linalg.inv(Z)


@pytest.mark.parametrize("inp, out", [("x", "x"), ("s", "s"), ("s", "x")])
def test_the_receptance_with_a_damper_behind_a_massless_node_is_exact(inp, out):
    """The FRF came from the statically condensed system: it dropped the damper (x/x 19 % off at 20 rad/s) and a
    force on the node's own flexibility (s/s 1e-3 where it tends to 1/(c i w))."""
    freqs = [0.0, 10.0, 20.0, 50.0, 1000.0]
    data = cli_json("modes", MAXWELL, "--frf", "0:1000:101", "--input", inp, "--response", out)["frf"]
    omega = np.array(data["omega"])
    H = np.array(data["magnitude"]) * np.exp(1j * np.array(data["phase"]))
    k = {"x": 0, "s": 1}
    for w in freqs:
        (i,) = np.flatnonzero(np.isclose(omega, w))
        assert H[i] == pytest.approx(maxwell_receptance(w)[k[out], k[inp]], rel=1e-9, abs=1e-15)


def test_a_damper_on_a_condensed_coordinate_is_named_as_an_approximation():
    text = runner.invoke(app, ["modes", str(MAXWELL)])
    assert text.exit_code == 0
    flat = " ".join(text.output.split())
    assert "damping acts on the condensed (massless) coordinate(s) s" in flat and "--frf is exact" in flat


def test_the_transfer_function_of_a_massless_coordinate_keeps_its_static_flexibility(tmp_path):
    """Without the damper the condensation is exact: the node's own static flexibility 1/k2 is the feedthrough D,
    so s/s(i w) from --transfer equals the receptance by hand (it tended to 0 at high frequency)."""
    path = tmp_path / "undamped.yaml"
    path.write_text(MAXWELL.read_text(encoding="utf-8").replace(
        "  - {type: damper, between: [ground.wall, node], coefficient: c}",
        "  - {type: spring, between: [ground.wall, node], stiffness: k2, free_length: L}"), encoding="utf-8")
    tf = cli_json("modes", path, "--transfer", "--input", "s", "--response", "s")["transfer_function"]
    m, k1, k2 = 1.0, 100.0, 100.0
    for w in (3.0, 30.0, 3000.0):
        Z = np.array([[k1 + k2 - m * w**2, -k2], [-k2, 2 * k2]])
        s = 1j * w
        H = np.polyval(tf["numerator"], s) / np.polyval(tf["denominator"], s)
        assert H == pytest.approx(np.linalg.inv(Z)[1, 1], rel=1e-9)


def test_a_sweep_of_the_spin_gives_the_whirl_frequencies_of_the_campbell_diagram(tmp_path):
    """mode1.frequency is of M and the symmetric K alone (63.2456 rad/s at every spin: a flat Campbell diagram);
    the table now carries the damped eigenvalues, the roots of (Id s^2 + c s + k)^2 + (Ip Omega s)^2 = 0 (from the
    disk's tilt equations by hand)."""
    out = tmp_path / "campbell.csv"
    r = runner.invoke(app, ["sweep", str(SPUN_DISK), "--param", "Omega=0:100:3", "--run", "modes", "-j", "1",
                            "-o", str(out)])
    assert r.exit_code == 0, r.output
    rows = np.genfromtxt(out, delimiter=",", names=True, dtype=None, encoding="utf-8")
    Id, Ip, k, c = 0.05, 0.08, 200.0, 0.5
    for row in rows:
        Om = float(row["Omega"])
        G = Ip * Om * np.array([[0.0, 1.0], [-1.0, 0.0]])  # Id a'' + (c I + G) a' + k a = 0, by hand
        A = np.block([[np.zeros((2, 2)), np.eye(2)], [-k / Id * np.eye(2), -(c * np.eye(2) + G) / Id]])
        roots = sorted((v for v in np.linalg.eigvals(A) if v.imag > 0), key=lambda v: v.imag)
        got = [(row[f"damped{j}frequency"], row[f"damped{j}decay_rate"]) for j in (1, 2)]
        for (w, decay), v in zip(got, roots):
            assert w == pytest.approx(v.imag, rel=1e-9) and decay == pytest.approx(-v.real, rel=1e-9)
        assert row["coupling"] == ("none" if Om == 0 else "gyroscopic")


def test_a_rotor_above_its_threshold_counts_its_growing_modes():
    """Internal damping ci makes the Jeffcott rotor unstable above sqrt(k/m) (1 + ce/ci) = 94.87 rad/s. At Omega =
    300 the modal damping ratios stay positive (0.047) and unstable_modes was 0; the eigenvalues of the rotor's own
    M s^2 + (ce + ci) s + [[k, ci Omega], [-ci Omega, k]] have a positive real part."""
    m, k, ce, ci, Om = 10.0, 40000.0, 20.0, 40.0, 300.0
    K = np.array([[k, ci * Om], [-ci * Om, k]])
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [-K / m, -np.eye(2) * (ce + ci) / m]])
    growth = float(np.max(np.linalg.eigvals(A).real))
    assert growth > 0
    data = cli_json("modes", JEFFCOTT, "--set", f"Omega={Om}")
    assert data["unstable_modes"] == 1
    assert f"up to {growth:.6g} 1/s" in data["note"]
    assert cli_json("modes", JEFFCOTT, "--set", "Omega=50")["unstable_modes"] == 0


DAMPED_BLOCK = """\
name: damped_block
parameters: {m: 1, k: 100, c: 2}
coordinates:
  x: {initial: 0.5, rate: 0}
ground:
  points: {A: ANCHOR}
links:
  b:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}
    mass: m
forces:
  - {type: spring, between: [b, ground.A], stiffness: k, free_length: FREE}
  - {type: damper, between: [b, ground.A], coefficient: c}
"""


def test_a_damper_of_zero_length_at_the_rest_is_refused_not_dropped(tmp_path):
    """A block on a spring and a damper, both to the anchor A. With A 1 m away (the spring's free length 1) the rest
    is x = 0 and the damping ratio c / (2 sqrt(k m)) = 0.1. With A at the block's rest (free length 0) the damper has
    no direction there; its linearization (sign(0) = 0) dropped it: ratio 0 and 'stable (critical)'."""
    apart, together = tmp_path / "apart.yaml", tmp_path / "together.yaml"
    apart.write_text(DAMPED_BLOCK.replace("ANCHOR", "[-1, 0, 0]").replace("FREE", "1"))
    together.write_text(DAMPED_BLOCK.replace("ANCHOR", "[0, 0, 0]").replace("FREE", "0"))
    assert cli_json("modes", str(apart))["modes"][0]["damping_ratio"] == pytest.approx(0.1, rel=1e-12)
    result = CliRunner().invoke(app, ["modes", str(together)])
    assert result.exit_code == 1 and "the damper between b and ground.A has zero length" in result.output
    (e,) = cli_json("equilibria", str(together))["equilibria"]
    assert e["coordinates"]["x"] == pytest.approx(0.0, abs=1e-12) and e["stability"] == "undecided"
    assert "zero length" in e["reason"]


def test_the_split_zero_eigenvalues_of_a_tops_cyclic_angles_are_no_damped_frequency():
    """A heavy symmetric top (A = 2e-3 about the pivot, C = 1e-3, m g l = 0.24525) precessing steadily at psi' = 4.2
    with phi' = 60. Its two cyclic angles give two double zero eigenvalues; rounding split one into +-6.9e-8 i, which
    `modes` named as a frequency of the motion and `sweep --run modes` (or `check`) reported as damped1.frequency
    instead of the nutation. Own derivation: with p_psi, p_phi conserved, the nutation is theta'' = -U'(theta)/A with
    U = (p_psi - p_phi cos(theta))^2 / (2 A sin^2(theta)) + m g l cos(theta); its frequency is sqrt(U''(theta0)/A)."""
    import sympy as sp

    import mechsys
    from mechsys.analysis.batch.tasks import ANALYSES

    path = DATA_DIR / "beyond" / "top_pivot_moments.yaml"
    result = runner.invoke(app, ["modes", str(path), "--set", "der(psi)=4.2", "-f", "json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    theta0 = data["equilibrium"]["coordinates"]["theta"]
    A, C, mgl, psi_rate, phi_rate = 2e-3, 1e-3, 0.5 * 9.81 * 0.05, 4.2, 60.0
    th = sp.Symbol("theta")
    w3 = psi_rate * math.cos(theta0) + phi_rate
    p_phi = C * w3
    p_psi = A * psi_rate * math.sin(theta0) ** 2 + p_phi * math.cos(theta0)
    U = (p_psi - p_phi * sp.cos(th)) ** 2 / (2 * A * sp.sin(th) ** 2) + mgl * sp.cos(th)
    assert float(U.diff(th).subs(th, theta0)) == pytest.approx(0, abs=1e-9)  # a steady precession
    nutation = math.sqrt(float(U.diff(th, 2).subs(th, theta0)) / A)
    assert nutation == pytest.approx(27.860829, abs=1e-6)
    assert f"|Im λ| = {nutation:.7g} rad/s" in data["coupling"]
    model = mechsys.load(path, overrides={"der(psi)": 4.2})
    row = ANALYSES["modes"](model, {})
    assert row["damped1.frequency"] == pytest.approx(nutation, rel=1e-9)
    assert "damped2.frequency" not in row
