"""Coulomb friction in the impulse law (`friction:` on a contact): stick inside the cone |U_t| <= mu U_n, slip on it.

Closed forms are derived here from the Newton-Euler impulse equations of each body (not from mechsys's generalized
formulation), so they check the generalized solve independently.

Ball (tests/data/friction_ball.yaml): a solid sphere, m, R, I = 2/5 m R^2, centre velocity (vx, -v), spin w about z
(counter-clockwise). Its lowest point P = G - R e_y slides at s = vx + w R. Impulse (F, U) at P (tangential along x,
normal along y):
    m (vx' - vx) = F,   m (vy' + v) = U,   I (w' - w) = (r x F)_z = R F        (r = -R e_y)
Newton: vy' = e v, so U = m (1 + e) v. The sliding velocity changes by Delta s = F/m + R^2 F/I = 7 F/(2 m).
  * stick (s' = 0): F = -(2/7) m s; valid when |F| <= mu U, i.e. (2/7)|s| <= mu (1 + e) v. Then
        vx' = (5/7) vx - (2/7) w R,   w' = -vx'/R      (rolling after the impact)
  * slip (otherwise): F = -mu U sgn(s), so Delta vx = -mu (1 + e) v sgn(s) and Delta w = -(5/2) mu (1 + e) v sgn(s)/R.
The normal and tangential problems are decoupled (the normal passes through G), so the kinetic energy can only
decrease: T+ - T- = (F/2)(s + s') + (U/2)(1 - e)(-v) <= 0.

3-D sphere (friction_sphere_3d.yaml): the same with vectors. At zero zyx angles omega = (c', b', a') in ground axes,
s = (vx + a' R, 0, vz - c' R); stick: Delta v_G = -(2/7) s, Delta omega = (5/(2 m R^2)) r x F; slip: Delta v_G =
-mu (1 + e) v s/|s|.

Rod (friction_rod.yaml): the end P = G + a, a = -(L/2)(cos th, sin th), I = m L^2/12. v_P = v_G + w e_z x a. With
the impulse F = (Ft, Un) at P, Delta v_P = K F with K = I2/m + (1/I) [[ay^2, -ax ay], [-ax ay, ax^2]] (coupled).
  * stick: F = K^-1 (-vPx, -(1 + e) vPy);
  * slip with sigma = sgn(vPx): Ft = -sigma mu Un, Un = -(1 + e) vPy / (1/m + ax^2/I + sigma mu ax ay/I).
Then vG' = vG + F/m, w' = w + (ax Un - ay Ft)/I.

Hinged rod (friction_pendulum.yaml): I_O = m L^2/3, tip P = L (sin phi, -cos phi). Newton gives phi'+ = -e phi'-.
Angular impulse about O: I_O Delta phi' = L (sin phi Un + cos phi Ft). Sticking is impossible for e > 0 (one
freedom), so the tip slips with Ft = -mu Un sgn(phi'-): Un = -I_O (1 + e) phi'- / (L (sin phi - mu sgn cos phi)).
Hinge impulse on the rod: U_O = m Delta v_G - (Ft, Un), v_G = phi' (L/2)(cos phi, sin phi).

Flat rod (friction_flat_rod.yaml): lands on both ends at once with centre velocity (vx, -v). By symmetry U_A = U_B =
m (1 + e) v/2 and the spin stays 0; stick (vx' = 0, F_A = F_B = -m vx/2) when |vx| <= mu (1 + e) v, else slip:
vx' = vx - mu (1 + e) v sgn(vx).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.impact.collide import resolve
from mechsys.cli import app

DATA = Path(__file__).resolve().parent / "data"
_MODELS: dict = {}


def load(name: str, **overrides):
    key = (name, tuple(sorted(overrides.items())))
    if key not in _MODELS:
        _MODELS[key] = mechsys.load(DATA / f"{name}.yaml", overrides or None, release_prescribed=True)
    return _MODELS[key]


def close(got, want, rtol=1e-9, atol=1e-12, what=""):
    got, want = np.asarray(got, float), np.asarray(want, float)
    assert np.all(np.abs(got - want) <= rtol * np.maximum(np.abs(got), np.abs(want)) + atol), \
        f"{what}: got {got!r}, want {want!r}"


def rates(r) -> dict[str, float]:
    return dict(zip(r.coordinates, map(float, r.rates_after)))


# ============================================================================================ ball on a rough floor
BALL = dict(m=0.5, R=0.1, v=3.0, e=0.6)


def ball_closed_form(vx, w, mu, m, R, v, e):
    s = vx + w * R
    U = m * (1 + e) * v
    if 2 / 7 * abs(s) <= mu * (1 + e) * v:
        vx2 = 5 / 7 * vx - 2 / 7 * w * R
        return "stick", vx2, -vx2 / R, -2 / 7 * m * s, U
    sg = math.copysign(1.0, s)
    return "slip", vx - mu * (1 + e) * v * sg, w - 2.5 * mu * (1 + e) * v * sg / R, -mu * U * sg, U


@pytest.mark.parametrize("vx, w", [(2.0, 5.0), (2.0, -40.0), (-1.0, 3.0), (0.0, 12.0)])
@pytest.mark.parametrize("mu", [0.02, 0.1, 0.4, 3.0])
def test_ball_stick_or_slip_closed_form(vx, w, mu):
    """Stick gives the rolling condition vx' + w' R = 0 with vx' = (5/7) vx - (2/7) w R; slip changes vx by
    mu (1 + e) v against the sliding velocity s = vx + w R."""
    r = resolve(load("friction_ball", vx=vx, w=w, mu=mu))
    mode, vx2, w2, F, U = ball_closed_form(vx, w, mu, **BALL)
    got = rates(r)
    assert r.modes == [mode]
    close(got["x"], vx2, what="vx'")
    close(got["th"], w2, what="w'")
    close(got["y"], BALL["e"] * BALL["v"], what="vy'")
    close(r.impulses[0], U, what="U_n")
    close(r.tangential_impulses[0], [F, 0, 0], what="U_t")
    assert r.restitution_factor == 1.0
    assert r.energy_loss >= -1e-12 * r.energy_before
    if mode == "stick":
        close(got["x"] + got["th"] * BALL["R"], 0.0, atol=1e-12, what="rolling after the impact")


@pytest.mark.parametrize("side", [1 - 1e-6, 1 + 1e-6])
def test_ball_threshold_between_stick_and_slip(side):
    """At mu* = (2/7)|s|/((1 + e) v) the two laws agree; just below it the ball slips, just above it sticks."""
    vx, w = 2.0, 5.0
    mu_star = 2 / 7 * abs(vx + w * BALL["R"]) / ((1 + BALL["e"]) * BALL["v"])
    r = resolve(load("friction_ball", vx=vx, w=w, mu=mu_star * side))
    assert r.modes == ["slip" if side < 1 else "stick"]
    mode, vx2, w2, F, U = ball_closed_form(vx, w, mu_star * side, **BALL)
    close(rates(r)["x"], vx2, what="vx'")
    close(r.tangential_impulses[0][0], F, what="U_t")


def test_ball_json_contract_keys():
    """`mechsys collide -f json` keeps the contract keys and adds tangential_impulse and mode per contact."""
    out = CliRunner().invoke(app, ["collide", str(DATA / "friction_ball.yaml"), "--set", "mu=0.05", "-f", "json"])
    assert out.exit_code == 0, out.output
    d = json.loads(out.stdout)
    for key in ("rates_after", "impulse", "joint_impulses", "energy_loss", "tangential_impulse", "mode"):
        assert key in d
    mode, vx2, w2, F, U = ball_closed_form(2.0, 5.0, 0.05, **BALL)
    assert d["mode"] == mode == "slip"
    close(d["tangential_impulse"], [F, 0, 0], what="tangential_impulse")
    close(d["impulse"], U, what="impulse")
    close(d["rates_after"]["x"], vx2, what="vx'")
    text = CliRunner().invoke(app, ["collide", str(DATA / "friction_ball.yaml")])
    assert text.exit_code == 0 and "stick" in text.stdout


def test_mu_zero_reproduces_frictionless_exactly(tmp_path):
    """friction: 0 (through a parameter) and no friction key give bit-identical results."""
    src = (DATA / "friction_ball.yaml").read_text()
    plain = tmp_path / "ball.yaml"
    plain.write_text(src.replace(", friction: mu}", "}"))
    assert "friction" not in plain.read_text().split("contacts:")[1]
    a = resolve(load("friction_ball", mu=0))
    b = resolve(mechsys.load(plain, None, release_prescribed=True))
    assert np.array_equal(a.rates_after, b.rates_after) and np.array_equal(a.impulses, b.impulses)
    assert a.energy_loss == b.energy_loss
    close(a.tangential_impulses, np.zeros((1, 3)), atol=0, what="no friction impulse")
    assert a.modes == b.modes == ["slip"]
    close(rates(a)["x"], 2.0, atol=0, what="tangential velocity kept")


# ============================================================================================ 3-D sphere
@pytest.mark.parametrize("mu", [0.05, 0.25])
def test_sphere_3d_friction_vector_closed_form(mu):
    m, R, vx, vz, v, e = 0.3, 0.05, 1.2, -0.7, 2.5, 0.7
    a1, b1, c1 = 9.0, -4.0, 14.0
    r = resolve(load("friction_sphere_3d", mu=mu))
    s = np.array([vx + a1 * R, 0.0, vz - c1 * R])
    U = m * (1 + e) * v
    stick = 2 / 7 * np.linalg.norm(s) <= mu * (1 + e) * v
    F = -2 / 7 * m * s if stick else -mu * U * s / np.linalg.norm(s)
    assert r.modes == ["stick" if stick else "slip"] and r.modes == [["slip", "stick"][mu == 0.25]]
    got = rates(r)
    close([got["x"], got["y"], got["z"]], [vx + F[0] / m, e * v, vz + F[2] / m], what="v_G'")
    dw = 5 / (2 * m * R**2) * np.cross([0, -R, 0], F)
    close([got["c"], got["b"], got["a"]], [c1 + dw[0], b1 + dw[1], a1 + dw[2]], what="omega'")
    close(r.tangential_impulses[0], F, what="U_t")
    close(np.linalg.norm(r.tangential_impulses[0]) <= mu * r.impulses[0] * (1 + 1e-12), True)
    if stick:  # the contact point rolls: v_G' + omega' x r = 0
        w2 = np.array([got["c"], got["b"], got["a"]])
        close(np.array([got["x"], 0, got["z"]]) + np.cross(w2, [0, -R, 0]), np.zeros(3), atol=1e-12)


# ============================================================================================ coupled rod
def rod_closed_form(th0, vx, vy, w, mu, e, m=2.0, L=1.0, mode=None):
    I = m * L**2 / 12
    ax, ay = -L / 2 * math.cos(th0), -L / 2 * math.sin(th0)
    vPx, vPy = vx - w * ay, vy + w * ax
    K = np.eye(2) / m + np.array([[ay**2, -ax * ay], [-ax * ay, ax**2]]) / I
    F = np.linalg.solve(K, [-vPx, -(1 + e) * vPy])
    if mode == "slip" or (mode is None and abs(F[0]) > mu * F[1]):
        sg = math.copysign(1.0, vPx)
        Un = -(1 + e) * vPy / (1 / m + ax**2 / I + sg * mu * ax * ay / I)
        F = np.array([-sg * mu * Un, Un])
        mode = "slip"
    mode = mode or "stick"
    return mode, vx + F[0] / m, vy + F[1] / m, w + (ax * F[1] - ay * F[0]) / I, F


@pytest.mark.parametrize("w, mu, mode", [(0.0, 0.3, "stick"), (-4.0, 0.3, "slip"), (-4.0, 3.0, "stick"),
                                         (3.0, 0.02, "slip")])
def test_rod_end_coupled_friction(w, mu, mode):
    r = resolve(load("friction_rod", w=w, mu=mu))
    want_mode, vx2, vy2, w2, F = rod_closed_form(0.6, 1.5, -2.0, w, mu, 0.5)
    assert want_mode == mode and r.modes == [mode]
    got = rates(r)
    close([got["x"], got["y"], got["th"]], [vx2, vy2, w2], what="rates after")
    close([r.tangential_impulses[0][0], r.impulses[0]], F, what="(U_t, U_n)")
    assert r.restitution_factor == 1.0 and r.energy_loss > 0


KANE = dict(th0=0.9097644762512118, mu=0.52, e=0.84, vx=0.05697528912905625, vy=-1.5184222350470542,
            w=4.048483323234846)


def test_energy_guard_lowers_restitution_kane_paradox():
    """Newton's law + sticking gains energy for this rod state (the closed-form stick solution has T+ > T-); the
    solver lowers e by a factor until T+ = T-, and the result is the stick closed form at that lowered e."""
    k = KANE
    m, L = 2.0, 1.0
    I = m * L**2 / 12
    T = lambda vx, vy, w: 0.5 * m * (vx**2 + vy**2) + 0.5 * I * w**2  # noqa: E731
    mode, vx2, vy2, w2, _ = rod_closed_form(k["th0"], k["vx"], k["vy"], k["w"], k["mu"], k["e"], mode="stick")
    assert T(vx2, vy2, w2) > 1.05 * T(k["vx"], k["vy"], k["w"])  # plain Newton + stick: 5 % energy gain
    model = load("friction_rod", mu=k["mu"], e=k["e"], th0=k["th0"], vx=k["vx"], vy=k["vy"], w=k["w"])
    r = resolve(model)
    assert 0 < r.restitution_factor < 1 and r.modes == ["stick"]
    close(r.energy_after, r.energy_before, rtol=1e-9, what="energy kept at the limit")
    assert r.energy_loss >= 0
    _, vx3, vy3, w3, _ = rod_closed_form(k["th0"], k["vx"], k["vy"], k["w"], k["mu"], k["e"] * r.restitution_factor,
                                         mode="stick")
    close(rates(r)["x"], vx3, what="vx' at the lowered e")
    close([rates(r)["y"], rates(r)["th"]], [vy3, w3], what="vy', w' at the lowered e")


@pytest.mark.parametrize("mu, e", [(0.1, 0.3), (0.5, 0.9), (1.5, 1.0), (0.3, 0.0)])
def test_energy_never_increases_random_rod_states(mu, e):
    """200 random approach states of the rod end (angle, velocity, spin) per (mu, e): T+ <= T-."""
    model = load("friction_rod", mu=mu, e=e)
    rng = np.random.default_rng(int(mu * 100 + e * 10))
    n = 0
    for _ in range(200):
        th0 = rng.uniform(0.05, 1.5)
        q = np.array([0.0, 0.5 * math.sin(th0), th0])
        u = np.array([rng.uniform(-3, 3), rng.uniform(-3, -0.1), rng.uniform(-8, 8)])
        if u[1] - u[2] * 0.5 * math.cos(th0) >= 0:
            continue  # the end does not approach the floor
        r = resolve(model, q=q, u=u)
        n += 1
        assert r.energy_after <= r.energy_before * (1 + 1e-12), (q, u, r.modes, r.energy_loss)
        assert np.linalg.norm(r.tangential_impulses[0]) <= mu * r.impulses[0] * (1 + 1e-9) + 1e-12
    assert n > 100


# ============================================================================================ joint impulses
@pytest.mark.parametrize("mu", [0.0, 0.3, 5.0])
def test_hinged_rod_tip_friction_and_hinge_impulse(mu):
    m, L, phi, w, e = 1.5, 0.8, 0.5, -3.0, 0.5
    r = resolve(load("friction_pendulum", mu=mu))
    IO = m * L**2 / 3
    sg = math.copysign(1.0, w)
    Un = -IO * (1 + e) * w / (L * (math.sin(phi) - mu * sg * math.cos(phi)))
    Ft = -mu * Un * sg
    close(rates(r)["phi"], -e * w, what="phi'")
    close(r.impulses[0], Un, what="U_n")
    close(r.tangential_impulses[0], [Ft, 0, 0], what="U_t")
    dvG = -(1 + e) * w * L / 2 * np.array([math.cos(phi), math.sin(phi)])
    close(r.joint_impulses["rod"], [m * dvG[0] - Ft, m * dvG[1] - Un, 0.0], what="hinge impulse")
    assert r.modes == ["slip"]


# ============================================================================================ simultaneous contacts
@pytest.mark.parametrize("mu", [0.2, 0.5])
def test_flat_rod_two_simultaneous_rough_contacts(mu):
    m, vx, v, e = 2.0, 1.0, 2.0, 0.4
    r = resolve(load("friction_flat_rod", mu=mu))
    close(r.impulses, [m * (1 + e) * v / 2] * 2, what="equal normal impulses")
    got = rates(r)
    close([got["y"], got["th"]], [e * v, 0.0], atol=1e-12, what="vy', w'")
    if abs(vx) <= mu * (1 + e) * v:
        assert r.modes == ["stick", "stick"]
        close(got["x"], 0.0, atol=1e-12, what="vx'")
        close(r.tangential_impulses[:, 0], [-m * vx / 2] * 2, what="F_A, F_B")
    else:
        assert r.modes == ["slip", "slip"]
        close(got["x"], vx - mu * (1 + e) * v, what="vx'")
        close(r.tangential_impulses[:, 0], [-mu * m * (1 + e) * v / 2] * 2, what="F_A, F_B")


# ============================================================================================ input errors
def _run(tmp_path, text: str):
    f = tmp_path / "bad.yaml"
    f.write_text(text)
    r = CliRunner().invoke(app, ["collide", str(f)])
    return f, r


def test_negative_friction_is_a_positioned_input_error(tmp_path):
    text = (DATA / "friction_ball.yaml").read_text().replace("mu: 0.4 ", "mu: -0.4 ")
    f, r = _run(tmp_path, text)
    assert r.exit_code == 2
    lines = [x for x in r.output.splitlines() if x.strip()]
    line, src = next((i, x) for i, x in enumerate(text.splitlines(), 1) if "friction: mu" in x)
    col = src.index("friction: mu") + len("friction: ") + 1  # the value of the key
    assert len(lines) == 1 and lines[0].startswith(f"{f}:{line}:{col}: contacts[0].friction: ")
    assert "must not be negative" in lines[0] and "Traceback" not in r.output


def test_friction_on_a_plain_gap_is_refused(tmp_path):
    text = (DATA / "friction_ball.yaml").read_text().replace(
        "between: [ball.P, ground.O], normal: y,", "gap: y - R,")
    f, r = _run(tmp_path, text)
    assert r.exit_code == 2
    assert "contacts[0].friction:" in r.output and "friction needs the contact points" in r.output
    assert len([x for x in r.output.splitlines() if x.strip()]) == 1
