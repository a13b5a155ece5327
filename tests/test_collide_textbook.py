"""Impacts against Krodkiewski, "Dynamics of Mechanical Systems", ch. 3 (digest: seed000_part1_digest.md §1.7 and
problems 40-56; the CORRECTED forms and the [computed] numbers are used, never a printed typo).

Part 1 (`mechsys collide`, `mechsys.analysis.impact.collide.resolve`): one impact at a given state.
Part 2 (`mechsys simulate` with gap contacts as events): sequential impacts, the rest rule, the impact table.

Tolerances: closed forms to 1e-9 relative; numbers the digest prints are compared to its printed digits.
"""
from __future__ import annotations

import csv
import math
import multiprocessing
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.impact.collide import resolve
from mechsys.cli import app
from mechsys.errors import AnalysisError

ROOT = Path(__file__).resolve().parents[1]
SYSTEMS = ROOT / "systems"
DATA = ROOT / "tests" / "data"
G = 9.81

_MODELS: dict = {}


def load(path: Path | str, **overrides):
    """The model with prescribed motions released (as `mechsys collide` loads it), cached per file + overrides."""
    key = (str(path), tuple(sorted(overrides.items())))
    if key not in _MODELS:
        _MODELS[key] = mechsys.load(path, overrides or None, release_prescribed=True)
    return _MODELS[key]


def rates(result) -> dict[str, float]:
    return dict(zip(result.coordinates, map(float, result.rates_after)))


def collide_json(*args: str) -> dict:
    import json

    r = CliRunner().invoke(app, ["collide", *map(str, args), "-f", "json"])
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)


def close(got, want, rtol=1e-9, atol=0.0, what=""):
    got, want = np.asarray(got, float), np.asarray(want, float)
    assert np.all(np.abs(got - want) <= rtol * np.maximum(np.abs(got), np.abs(want)) + atol), \
        f"{what}: got {got!r}, want {want!r}, diff {got - want!r}"


def printed(got: float, text: str, what=""):
    """``got`` rounds to the digest's printed number ``text`` (half a unit of its last digit)."""
    decimals = len(text.split(".")[1]) if "." in text else 0
    bound = 0.5 * 10.0 ** (-decimals) + 1e-9 * max(1.0, abs(got))  # exact ties (0.203125 -> 0.20313) allowed
    assert abs(got - float(text)) <= bound, f"{what}: {got!r} does not print as {text}"


# =============================================================================================== §1.7, (3.33-3.37)
BULLET = SYSTEMS / "bullet_pendulum.yaml"


def bullet_closed_form(m1, IO, rG, m2, v, rC, e):
    D = IO + m2 * rC**2
    return {"phi": m2 * v * rC * (1 + e) / D, "x2": v * (m2 * rC**2 - e * IO) / D,
            "UC": m2 * v * IO * (1 + e) / D, "UOx": m2 * v * (1 + e) * (m1 * rC * rG - IO) / D}


@pytest.mark.parametrize("e, rC, v", [(0.2, 0.6, 300), (0.0, 0.6, 300), (1.0, 0.3, 450), (0.5, 1.1, 120)])
def test_bullet_pendulum_formulas_3_33_to_3_37(e, rC, v):
    """§1.7 / C0: phi', x2', U_C, U_Ox (joint impulse on the pendulum along x), U_Oy = 0."""
    out = collide_json(BULLET, "--set", f"e={e}", "--set", f"rC={rC}", "--set", f"v={v}", "--set", f"der(x2)={v}",
                       "--set", f"y2=-{rC}")
    want = bullet_closed_form(5.0, 2.0, 0.5, 0.05, v, rC, e)
    close(out["rates_after"]["phi"], want["phi"], what="phi'")
    close(out["rates_after"]["x2"], want["x2"], what="x2'")
    close(out["rates_after"]["y2"], 0.0, atol=1e-12, what="y2'")
    close(out["impulse"], want["UC"], what="U_C")
    UO = out["joint_impulses"]["pendulum"]
    close(UO[0], want["UOx"], atol=1e-12 * want["UC"], what="U_Ox")
    close(UO[1:], [0.0, 0.0], atol=1e-12 * want["UC"], what="U_Oy, U_Oz")
    close(out["normal_velocity_after"][0], e * v, atol=1e-12 * v, what="Newton's hypothesis (3.13)")


def test_bullet_pendulum_file_values():
    """The bundled file as it stands (m1 = 5, IO = 2, rG = 0.5, m2 = 0.05, v = 300, rC = 0.6, e = 0.2)."""
    out = collide_json(BULLET)
    want = bullet_closed_form(5.0, 2.0, 0.5, 0.05, 300, 0.6, 0.2)
    close([out["rates_after"]["phi"], out["rates_after"]["x2"], out["impulse"]],
          [want["phi"], want["x2"], want["UC"]])
    close(out["joint_impulses"]["pendulum"][0], want["UOx"])
    T_after = 0.5 * 2.0 * want["phi"] ** 2 + 0.5 * 0.05 * want["x2"] ** 2
    close(out["energy_loss"], 0.5 * 0.05 * 300**2 - T_after, what="energy lost")


def test_percussion_of_an_unknown_link_names_it():
    """`--percussion --link nope` says the link is unknown (it said a hinged link was needed)."""
    from test_cli_hardening import one_line

    r = CliRunner().invoke(app, ["collide", str(BULLET), "--percussion", "--link", "pendulam"])
    line = one_line(r)
    assert "--link pendulam: unknown link (did you mean 'pendulum'?)" in line


@pytest.mark.parametrize("e, v", [(0.0, 300), (0.2, 300), (0.7, 90), (1.0, 500)])
def test_centre_of_percussion_no_hinge_impulse(e, v):
    """rC = IO/(m1 rG) = 0.8: U_Ox = 0 for any e and v; `--percussion` reports that distance."""
    cp = collide_json(BULLET, "--percussion")
    assert cp["link"] == "pendulum"
    close([cp["I_O"], cp["r_G"], cp["distance"]], [2.0, 0.5, 2.0 / (5.0 * 0.5)])
    close(cp["point_in_link_axes"], [0.0, -0.8, 0.0], atol=1e-15)
    out = collide_json(BULLET, "--set", "rC=0.8", "--set", "y2=-0.8", "--set", f"e={e}", "--set", f"v={v}",
                       "--set", f"der(x2)={v}")
    UC = bullet_closed_form(5.0, 2.0, 0.5, 0.05, v, 0.8, e)["UC"]
    close(out["impulse"], UC)
    close(out["joint_impulses"]["pendulum"], [0.0, 0.0, 0.0], atol=1e-12 * UC, what="U_O at the centre of percussion")


# =============================================================================================== Problem 40
P40 = DATA / "p40_loom_hammer.yaml"


def p40_closed_form(M, L, m, l, omega, e):
    I = M * L**2 / 3
    D = I + m * l**2
    return {"I": I, "ws": (I * omega - m * l**2 * e * omega) / D, "vs": I * l * omega * (1 + e) / D,
            "U": m * I * l * omega * (1 + e) / D, "UA": m * l * omega * (1 + e) * (I - M * L / 2 * l) / D}


def test_p40_loom_hammer():
    r = resolve(load(P40))
    want = p40_closed_form(2, 1, 0.5, 0.8, 10, 0.5)
    close([rates(r)["th"], rates(r)["s"], r.impulses[0]], [want["ws"], want["vs"], want["U"]])
    close(r.joint_impulses["hammer"][0], want["UA"], what="UA")
    close(r.joint_impulses["hammer"][1:], [0, 0], atol=1e-12)
    for got, text in [(want["I"], "0.66667"), (rates(r)["th"], "5.13514"), (rates(r)["s"], "8.10811"),
                      (r.impulses[0], "4.05405"), (r.joint_impulses["hammer"][0], "-0.81081")]:
        printed(got, text)


def test_p40_centre_of_percussion_at_two_thirds():
    """UA = 0 at l = 2L/3 (any omega, e); `--percussion --link hammer` gives 2L/3."""
    cp = collide_json(P40, "--percussion", "--link", "hammer")
    close(cp["distance"], 2 / 3)
    r = resolve(load(P40, l="2*L/3", e=0.3, omega=7))
    want = p40_closed_form(2, 1, 0.5, 2 / 3, 7, 0.3)
    close([rates(r)["th"], rates(r)["s"]], [want["ws"], want["vs"]])
    close(r.joint_impulses["hammer"], [0, 0, 0], atol=1e-12 * want["U"])


def test_p40_prescribed_hammer_is_released_during_the_impact(tmp_path):
    """A hammer driven at omega*t gives the same impact: prescribed motions are released (M = MO, eq. 3.14)."""
    path = tmp_path / "p40_driven.yaml"
    path.write_text(P40.read_text().replace("th: {initial: 0, rate: omega}", "th: {prescribed: omega*t}"))
    out = collide_json(path)
    want = p40_closed_form(2, 1, 0.5, 0.8, 10, 0.5)
    close(out["rates_before"]["th"], 10.0)
    close([out["rates_after"]["th"], out["rates_after"]["s"], out["impulse"]], [want["ws"], want["vs"], want["U"]])


# =============================================================================================== Problem 41
def test_p41_double_pendulum_corrected():
    """w3 = 12 mo v/(l(7m + 12mo)), w4 = -(3/2) w3 (ERRATA: the book prints -3 w3); e = 0: the particle moves on
    with the joint, l w3."""
    m, l, mo, v = 2, 1, 0.5, 10
    r = resolve(load(DATA / "p41_double_pendulum.yaml"))
    u = rates(r)
    w3 = 12 * mo * v / (l * (7 * m + 12 * mo))
    w4 = u["th3"] + u["th4"]  # absolute angular velocity of bar 4
    close(u["th3"], w3, what="w3")
    close(w4, -1.5 * w3, what="w4")
    assert abs(w4 - (-3 * w3)) > 0.1 * abs(w3), "the book's printed w4 = -3 w3 is an erratum"
    close(u["xo"], l * w3, what="particle after (e = 0)")
    close(r.normal_velocity_after[0], 0.0, atol=1e-12 * v)


# =============================================================================================== Problem 42
P42 = DATA / "p42_ballistic_pendulum.yaml"


def test_p42_ballistic_pendulum_impact():
    """e = 0: ws = m v rC/(IO + m rC^2), the bullet moves with the pendulum (ws rC). With v from the book's
    swing formula for alpha = 10 deg, ws = sqrt(2 M g rG (1 - cos alpha)/IO) = 0.704831 and v = 176.631."""
    m, M, IO, rG, rC = 0.01, 5, 1.5, 0.5, 0.6
    ws_swing = math.sqrt(2 * M * G * rG * (1 - math.cos(math.radians(10))) / IO)
    v = (IO + m * rC**2) / (m * rC) * ws_swing
    printed(ws_swing, "0.704831")
    printed(v, "176.631")
    r = resolve(load(P42))  # the file's v is the book's formula of alpha
    u = rates(r)
    close(r.rates_before[1], v, what="v")
    close(u["phi"], m * v * rC / (IO + m * rC**2), what="ws")
    close(u["phi"], ws_swing, what="ws from the swing formula")
    close(u["xb"], u["phi"] * rC, what="bullet embedded")
    close(r.impulses[0], IO * u["phi"] / rC, what="U = IO ws/rC")
    printed(u["phi"], "0.704831")


# =============================================================================================== Problem 46
P46 = DATA / "p46_oblique_block.yaml"


def test_p46_oblique_impact_on_spring_block():
    m, M, k, v, e = 1, 4, 1000, 10, 0.5
    r = resolve(load(P46))
    u = rates(r)
    vs1 = v * math.sqrt(0.5 * (m - M * e) ** 2 / (M + m) ** 2 + 0.5)
    vs2 = math.sqrt(2) / 2 * v * m * (1 + e) / (M + m)
    U = math.sqrt(2) / 2 * v * m * M * (1 + e) / (M + m)
    close(math.hypot(u["x"], u["y"]), vs1, what="vs1")
    close(u["y"], -v / math.sqrt(2), what="tangential component unchanged")
    close(u["xb"], vs2, what="vs2")
    close(r.impulses[0], U, what="U")
    A = vs2 * math.sqrt(M / k)
    for got, text in [(vs1, "7.21110"), (u["xb"], "2.12132"), (r.impulses[0], "8.48528"), (A, "0.134164")]:
        printed(got, text)


def test_p46_amplitude_of_the_block_after_the_impact():
    """Post-impact motion from the separation velocities: the block oscillates with A = vs2 sqrt(M/k)."""
    from mechsys.analysis.motion.simulate import simulate

    r = resolve(load(P46))
    after = {f"der({c})": repr(float(x)) for c, x in zip(r.coordinates, r.rates_after)}
    model = mechsys.load(P46, after)
    period = 2 * math.pi * math.sqrt(4 / 1000)
    sim = simulate(model, period, period / 4000)
    xb = sim.q[:, sim.coordinates.index("xb")]
    printed(float(np.max(np.abs(xb))), "0.134164", what="amplitude")


# =============================================================================================== Problem 48
def test_p48_cylinder_hits_a_step():
    """Smooth contact through G: normal velocity reversed and scaled by e, tangential kept, spin unchanged."""
    m, R, omega, alpha, e = 3, 0.2, 15, 0.7, 0.4
    r = resolve(load(DATA / "p48_cylinder_step.yaml"))
    u = rates(r)
    vG = np.array([u["x"], u["y"]])
    n = np.array([-math.sin(alpha), math.cos(alpha)])
    t = np.array([math.cos(alpha), math.sin(alpha)])
    close(vG @ n, e * R * omega * math.sin(alpha), what="vsGx1 (normal)")
    close(vG @ t, R * omega * math.cos(alpha), what="vsGy1 (tangential)")
    close(u["th"], -omega, what="ws = omega (clockwise)")
    close(r.impulses[0], m * (1 + e) * R * omega * math.sin(alpha), what="U")


# =============================================================================================== Problem 51
P51 = DATA / "p51_racket.yaml"


def p51_closed_form(m, h, M, I, a, b, alpha, omega, e):
    Io = I + M * a**2
    w = math.sqrt(2 * G * h)
    k = m * b**2 / Io
    return {"vsx1": (w * math.cos(alpha) * (e - k) + omega * b * (1 + e)) / (1 + k),
            "vsx1_as_printed": (w * math.cos(alpha) * (k + e) + omega * b * (1 + e)) / (1 + k),
            "vsy1": w * math.sin(alpha),
            "U": (1 + e) * (w * math.cos(alpha) + omega * b) / (1 / m + b**2 / Io),
            "ws": omega - (1 + e) * (w * math.cos(alpha) + omega * b) / (1 / m + b**2 / Io) * b / Io}


def _p51_ground_normal(tmp_path) -> Path:
    """The same contact with the racket normal written in ground axes (valid at phi = alpha)."""
    path = tmp_path / "p51_ground.yaml"
    text = P51.read_text()
    assert "normal: [0, 1, 0], frame: racket" in text
    path.write_text(text.replace("normal: [0, 1, 0], frame: racket", "normal: [-sin(alpha), cos(alpha), 0]"))
    return path


def _check_p51(r, e):
    want = p51_closed_form(0.058, 1.2, 0.35, 0.012, 0.3, 0.5, 0.3, 4, e)
    u = rates(r)
    n = np.array([-math.sin(0.3), math.cos(0.3)])
    d = np.array([math.cos(0.3), math.sin(0.3)])
    vb = np.array([u["xb"], u["yb"]])
    close(vb @ n, want["vsx1"], what="vsx1 (corrected)")
    close(abs(vb @ d), want["vsy1"], what="vsy1")
    close(r.impulses[0], want["U"], what="U")
    close(u["phi"], want["ws"], what="racket after")
    assert abs(vb @ n - want["vsx1_as_printed"]) > 0.1, "the printed '+ m b^2/Io' is an erratum"
    if e == 0:  # sticking along the normal: the ball moves with the racket point
        close(vb @ n, u["phi"] * 0.5, what="e = 0")


@pytest.mark.parametrize("e", [0.7, 0.0])
def test_p51_racket_impact_ground_normal(tmp_path, e):
    r = resolve(mechsys.load(_p51_ground_normal(tmp_path), {"e": e}, release_prescribed=True))
    _check_p51(r, e)


@pytest.mark.parametrize("e", [0.7, 0.0])
def test_p51_racket_impact_normal_in_racket_axes(e):
    """Same impact with `normal: [0, 1, 0], frame: racket` (the racket-face normal in racket axes)."""
    _check_p51(resolve(load(P51, e=e)), e)


# =============================================================================================== Problem 54
def test_p54_car_crash_with_hinged_passenger():
    m1, m2, m3, I, a, v, e = 1000, 1200, 80, 5, 0.4, 10, 0.3
    r = resolve(load(DATA / "p54_car_passenger.yaml"))
    u = rates(r)
    D = I * (m1 + m2 + m3) + a**2 * m3 * (m1 + m2)
    ws3 = a * m1 * m3 * v * (1 + e) / D
    v2 = m1 * v * (1 + e) * (I + a**2 * m3) / D
    v1 = v2 - e * v
    close([u["th3"], u["x2"], u["x1"]], [ws3, v2, v1])
    UAx = -I * ws3 / a  # book: I ws3 = -a UAx, UAx acts on car 2, -UAx on the passenger
    close(r.joint_impulses["passenger"][0], -UAx, what="hinge impulse on the passenger")
    close(r.joint_impulses["passenger"][1:], [0, 0], atol=1e-9)
    close(m2 * v2, r.impulses[0] + UAx, what="m2 v2s = UC + UAx")
    dT = 0.5 * m1 * v**2 - (0.5 * m1 * v1**2 + 0.5 * m2 * v2**2 + 0.5 * m3 * (v2 - ws3 * a) ** 2 + 0.5 * I * ws3**2)
    close(r.energy_loss, dT, what="energy lost")
    for got, text in [(u["th3"], "10.51567"), (u["x2"], "5.84934"), (u["x1"], "2.84934"), (r.energy_loss, "25027.30")]:
        printed(got, text)


# =============================================================================================== Problem 55
CARRIAGES = SYSTEMS / "carriages.yaml"


def p55_book(e: float, v: float, m: float) -> list[tuple[str, tuple[float, float, float], float]]:
    """The book's three collisions: (contact, velocities after, impulse)."""
    c1 = ((1 - e) * v / 2, (1 + e) * v / 2, 0.0)
    c2 = (c1[0], (1 - e**2) * v / 4, (1 + e) ** 2 * v / 4)
    c3 = ((1 - e) * ((1 - e) / 4 + (1 + e) ** 2 / 8) * v, (1 + e) * ((1 - e) / 4 + (1 - e) ** 2 / 8) * v,
          (1 + e) ** 2 * v / 4)
    return [("c12", c1, m * (1 + e) * v / 2), ("c23", c2, m * (1 + e) ** 2 * v / 4), ("c12", c3, m * (c3[1] - c2[1]))]


def binary_sequence(e: float, v: float, m: float, limit: int = 50):
    """Independent reference: equal masses on a line, binary collisions of whichever neighbours approach."""
    vel = [v, 0.0, 0.0]
    out = []
    for _ in range(limit):
        k = next((k for k in (0, 1) if vel[k] - vel[k + 1] > 1e-12 * v), None)
        if k is None:
            break
        a, b = vel[k], vel[k + 1]
        vel[k], vel[k + 1] = ((1 - e) * a + (1 + e) * b) / 2, ((1 + e) * a + (1 - e) * b) / 2
        out.append((("c12", "c23")[k], tuple(vel), m * (vel[k + 1] - b)))
    return out


def collide_chain(model, limit=20, negligible=1e-9):
    """Resolve impacts one after another from the file's state until nothing approaches. Approach speeds below
    ``negligible`` times the first one are round-off of the previous solve (e.g. -8e-16 m/s in the cradle), not
    impacts: the chain stops there."""
    seq, u = [], None
    for _ in range(limit):
        try:
            r = resolve(model, u=u)
        except AnalysisError as exc:
            assert "no contact is approaching" in str(exc)
            return seq
        if seq and -np.min(r.normal_velocity_before) < negligible * -np.min(seq[0].normal_velocity_before):
            return seq
        seq.append(r)
        u = r.rates_after
    raise AssertionError("no end to the impacts")


def test_p55_first_impact_is_carriage_1_on_2():
    out = collide_json(CARRIAGES)
    m, v, e = 10000, 2.0, 0.5
    close([out["rates_after"][c] for c in ("x1", "x2", "x3")], [(1 - e) * v / 2, (1 + e) * v / 2, 0.0], atol=1e-12)
    close(out["impulse"], [m * (1 + e) * v / 2, 0.0], atol=1e-9)
    close(out["energy_loss"], 0.375 * 0.5 * m * v**2)


@pytest.mark.parametrize("e", [0.5, 0.25, 0.8])
def test_p55_three_sequential_collisions(e):
    """Three collisions (1-2, 2-3, 1-2) with the book's velocities and impulses, then none: v1 < v2 < v3."""
    m, v = 10000, 2.0
    seq = collide_chain(load(CARRIAGES, e=e))
    book = p55_book(e, v, m)
    assert len(seq) == 3
    ref = binary_sequence(e, v, m)  # the independent reference agrees with the book's formulas
    assert [c for c, _, _ in ref] == [c for c, _, _ in book]
    close([x for _, vel, U in ref for x in (*vel, U)], [x for _, vel, U in book for x in (*vel, U)], rtol=1e-12,
          atol=1e-15 * m * v)
    for r, (contact, vel, U) in zip(seq, book):
        k = r.contacts.index(contact)
        close(r.impulses[k], U, what=f"impulse {contact}")
        close(r.impulses[1 - k], 0.0, atol=1e-9 * m * v)
        close(r.rates_after, vel, atol=1e-12 * v, rtol=1e-9, what=f"velocities after {contact}")
    final = seq[-1].rates_after
    assert final[0] < final[1] < final[2]


def test_p55_table_for_e_one_half():
    """Digest table (e = 0.5): velocities / v and cumulative energy lost / (m v^2/2) after each collision."""
    m, v = 10000, 2.0
    seq = collide_chain(load(CARRIAGES))
    table = [((0.25, 0.75, 0.0), 0.375), ((0.25, 0.1875, 0.5625), 0.5859375),
             ((0.203125, 0.234375, 0.5625), 0.58740234375)]
    lost = 0.0
    for r, (vel, ratio) in zip(seq, table):
        lost += r.energy_loss
        close(r.rates_after / v, vel, atol=1e-12)
        close(lost / (0.5 * m * v**2), ratio)
    printed(sum(r.energy_loss for r in seq[:2]) / (0.5 * m * v**2), "0.58594")
    printed(sum(r.energy_loss for r in seq) / (0.5 * m * v**2), "0.58740")
    printed(seq[2].rates_after[0] / v, "0.20313")
    printed(seq[2].rates_after[1] / v, "0.23438")


def test_p55_elastic_is_a_newton_cradle():
    """e = 1: final velocities (0, 0, v), no energy lost (the third collision has zero approach speed)."""
    v = 2.0
    seq = collide_chain(load(CARRIAGES, e=1))
    assert [r.contacts[int(np.argmax(r.impulses))] for r in seq] == ["c12", "c23"]
    close(seq[-1].rates_after, [0.0, 0.0, v], atol=1e-9 * v)
    for r in seq:
        assert abs(r.energy_loss) <= 1e-9 * r.energy_before


def test_p55_small_restitution_needs_more_than_three_collisions():
    """The book's 'no more collisions after the third' needs (1-e)^2 < 4e, i.e. e > 3 - 2 sqrt(2) = 0.1716
    (my derivation): with e = 0.1, carriage 2 is faster than 3 after collision 3 and the chain goes on."""
    m, v, e = 10000, 2.0, 0.1
    seq = collide_chain(load(CARRIAGES, e=e))
    ref = binary_sequence(e, v, m)
    assert len(seq) == len(ref) > 3
    for r, (contact, vel, U) in zip(seq, ref):
        close(r.impulses[r.contacts.index(contact)], U, rtol=1e-8, atol=1e-9 * m * v)
        close(r.rates_after, vel, rtol=1e-8, atol=1e-12 * v)
    close(sum(seq[-1].rates_after), v, what="momentum")


# =============================================================================================== Newton's cradle
CRADLE = SYSTEMS / "newton_cradle.yaml"


def cradle_speed(L=0.3, alpha=0.5):
    return math.sqrt(2 * G * L * (1 - math.cos(alpha)))


def test_newton_cradle_transfers_the_velocity_through_the_chain():
    """e = 1, at the moment ball 1 strikes: four binary impacts c12, c23, c34, c45, each of impulse m w, and only
    ball 5 moves afterwards, with w."""
    m, L = 0.1, 0.3
    w = cradle_speed()
    seq = collide_chain(load(CRADLE, th1=0, **{"der(th1)": repr(w / L)}))
    assert [r.contacts[int(np.argmax(r.impulses))] for r in seq] == ["c12", "c23", "c34", "c45"]
    for k, r in enumerate(seq):
        close(np.max(r.impulses), m * w, what=f"impulse {k}")
        want = np.zeros(5)
        want[k + 1] = w / L
        close(r.rates_after, want, atol=1e-12 * w / L, rtol=1e-9, what=f"after impact {k + 1}")
        assert abs(r.energy_loss) <= 1e-9 * r.energy_before


# =============================================================================================== bouncing ball
BALL = SYSTEMS / "bouncing_ball.yaml"


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_bouncing_ball_single_impact(e):
    r = resolve(load(BALL, y=0, e=e, **{"der(y)": -3}))
    close(rates(r)["y"], 3 * e, atol=1e-15)
    close(r.impulses[0], 0.1 * 3 * (1 + e))
    close(r.energy_loss, 0.5 * 0.1 * 9 * (1 - e**2), atol=1e-15)


def test_collide_without_approach_is_an_analysis_error():
    r = CliRunner().invoke(app, ["collide", str(BALL)])
    assert r.exit_code == 1 and "no contact is approaching" in r.output


# =============================================================================================== two free 3-D bodies
FREE = DATA / "two_free_bodies.yaml"
_BODY = {  # from tests/data/two_free_bodies.yaml, entered independently of the model
    "body1": {"mass": 2.0, "c": [0.05, -0.1, 0.02], "I": (0.30, 0.45, 0.52, 0.04, -0.03, 0.05),
              "q": slice(0, 6), "point": [0.42, 0.18, -0.25]},
    "body2": {"mass": 3.5, "c": [-0.08, 0.04, 0.1], "I": (0.62, 0.51, 0.40, -0.06, 0.02, 0.03),
              "q": slice(6, 12), "point": [-0.17501628424458465, -0.6101504356119276, 0.3107237813061886]},
}


def _R(axis, a):
    c, s = math.cos(a), math.sin(a)
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]), "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def _body_state(body, q, u):
    """Position and velocity of G, angular velocity, rotation (free joint: translate, then z-y-x body-fixed)."""
    x, a, b, c = q[:3], *q[3:]
    R1, R2, R3 = _R("z", a), _R("y", b), _R("x", c)
    R = R1 @ R2 @ R3
    w = u[3] * np.array([0, 0, 1.0]) + u[4] * (R1 @ [0, 1.0, 0]) + u[5] * (R1 @ R2 @ [1.0, 0, 0])
    rc = R @ body["c"]
    return x + rc, u[:3] + np.cross(w, rc), w, R


def _inertia(xx, yy, zz, xy, xz, yz):
    return np.array([[xx, -xy, -xz], [-xy, yy, -yz], [-xz, -yz, zz]])


def momenta(q, u, about=np.zeros(3)):
    """Total linear momentum, angular momentum about a fixed point and kinetic energy."""
    p, h, T = np.zeros(3), np.zeros(3), 0.0
    for body in _BODY.values():
        rG, vG, w, R = _body_state(body, q[body["q"]], u[body["q"]])
        IG = R @ _inertia(*body["I"]) @ R.T
        p += body["mass"] * vG
        h += np.cross(rG - about, body["mass"] * vG) + IG @ w
        T += 0.5 * body["mass"] * vG @ vG + 0.5 * w @ IG @ w
    return p, h, T


@pytest.mark.parametrize("e", [0.6, 1.0, 0.0])
def test_two_free_bodies_conserve_momentum_through_an_eccentric_impact(e):
    model = load(FREE, e=e)
    q = np.array([model.doc.initial[c] for c in model.coordinates], float)
    r = resolve(model)
    n = -np.array([1.0, 2.0, 2.0]) / 3
    # the contact points coincide, and the normal misses both centres of mass
    P = [_body_state(b, q[b["q"]], np.zeros(6))[3] @ b["point"] + q[b["q"]][:3] for b in _BODY.values()]
    close(P[0], P[1], atol=1e-12, what="contact points")
    for b in _BODY.values():
        rG = _body_state(b, q[b["q"]], np.zeros(6))[0]
        assert np.linalg.norm(np.cross(rG - P[0], n)) > 0.1
    p0, h0, T0 = momenta(q, r.rates_before)
    p1, h1, T1 = momenta(q, r.rates_after)
    close([T0, T1], [r.energy_before, r.energy_after], what="kinetic energy (my kinematics against the model)")
    scale_p = np.linalg.norm(p0) + r.impulses[0]
    close(p1, p0, atol=1e-12 * scale_p, rtol=0, what="linear momentum")
    for O in (np.zeros(3), np.array([3.0, -2.0, 5.0])):
        _, hO0, _ = momenta(q, r.rates_before, O)
        _, hO1, _ = momenta(q, r.rates_after, O)
        close(hO1, hO0, atol=1e-12 * (np.linalg.norm(hO0) + r.impulses[0] * (1 + np.linalg.norm(P[0] - O))),
              rtol=0, what=f"angular momentum about {O}")
    # body 1 receives U n, body 2 receives -U n (eqs 3.2-3.9)
    m1 = _BODY["body1"]["mass"]
    vG1_0 = _body_state(_BODY["body1"], q[:6], r.rates_before[:6])[1]
    vG1_1 = _body_state(_BODY["body1"], q[:6], r.rates_after[:6])[1]
    close(m1 * (vG1_1 - vG1_0), r.impulses[0] * n, atol=1e-12 * r.impulses[0], rtol=0, what="impulse on body 1")
    close(r.normal_velocity_after[0], -e * r.normal_velocity_before[0], atol=1e-12 * abs(r.normal_velocity_before[0]))
    assert r.impulses[0] > 0
    if e == 1:
        assert abs(r.energy_loss) <= 1e-9 * r.energy_before
    else:
        assert r.energy_loss > 0
    close(r.joint_impulses["body1"] + r.joint_impulses["body2"], np.zeros(6), atol=1e-9, what="free joints")


# =============================================================================================== e = 1: no loss
ELASTIC_CASES = [
    (BULLET, {}), (P40, {}), (DATA / "p41_double_pendulum.yaml", {}), (P42, {}), (P46, {}),
    (DATA / "p48_cylinder_step.yaml", {}), (DATA / "p54_car_passenger.yaml", {}), (CARRIAGES, {}),
    (BALL, {"y": 0, "der(y)": -2.5}), (CRADLE, {"th1": 0, "der(th1)": 4.0}), (FREE, {}),
]


@pytest.mark.parametrize("path, overrides", ELASTIC_CASES, ids=[p.stem for p, _ in ELASTIC_CASES])
def test_perfectly_elastic_impacts_lose_no_energy(path, overrides):
    r = resolve(load(path, e=1, **overrides))
    assert r.energy_before > 0
    assert abs(r.energy_loss) <= 1e-9 * r.energy_before, r.energy_loss
    k = int(np.argmax(r.impulses))
    close(r.normal_velocity_after[k], -r.normal_velocity_before[k], what="vn reversed")


def test_perfectly_elastic_racket_loses_no_energy(tmp_path):
    r = resolve(mechsys.load(_p51_ground_normal(tmp_path), {"e": 1}, release_prescribed=True))
    assert abs(r.energy_loss) <= 1e-9 * r.energy_before


def test_restitution_may_depend_on_the_approach_speed(tmp_path):
    """e(vn) (Fig. 3 of ch. 3): restitution: 0.8/(1 + abs(vn)/5) with vn = -3 gives e = 0.5."""
    path = tmp_path / "ball.yaml"
    path.write_text(BALL.read_text().replace("restitution: e}", "restitution: 0.8/(1 + abs(vn)/5)}"))
    r = resolve(mechsys.load(path, {"y": 0, "der(y)": -3}))
    close(r.rates_after[0], 1.5)


# ================================================================================================================
# Part 2: impacts inside `mechsys simulate` (gap contacts as events, impulse law, sequential impacts at one
# instant, rest rule with a capture velocity, `--impacts FILE.csv`, SimulationResult.impacts). Written in parallel
# with that feature (they failed until it landed); each run is in a child process with a time limit, so an endless
# impact sequence fails the test instead of hanging the suite.
# ================================================================================================================
def _simulate_child(conn, path, overrides, t_end, dt, kwargs):
    try:
        from mechsys.analysis.motion.simulate import simulate

        r = simulate(mechsys.load(path, overrides or None, release_prescribed=True), t_end, dt, **kwargs)
        conn.send({"t": r.t, "q": r.q, "u": r.u, "T": r.T, "V": r.V, "coordinates": r.coordinates,
                   "impacts": list(getattr(r, "impacts", None) or []), "has_impacts": hasattr(r, "impacts")})
    except BaseException as exc:  # noqa: BLE001 - reported in the parent
        conn.send({"error": f"{type(exc).__name__}: {exc}"})


def run_simulation(path, overrides=None, t_end=1.0, dt=None, timeout=15.0, **kwargs) -> dict:
    """simulate() in a child process, so that a Zeno loop fails the test instead of hanging the suite."""
    ctx = multiprocessing.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_simulate_child, args=(child, str(path), overrides, t_end, dt, kwargs))
    proc.start()
    try:
        if not parent.poll(timeout):
            raise AssertionError(f"simulate did not finish within {timeout} s (an endless impact sequence?)")
        out = parent.recv()
    finally:
        proc.kill()
        proc.join()
    assert "error" not in out, out.get("error")
    assert out["has_impacts"], "SimulationResult has no 'impacts'"
    return out


def _vec(value, coordinates):
    return np.array([value[c] for c in coordinates] if isinstance(value, dict) else value, float)


def ball_times(h, e, g, count):
    t1 = math.sqrt(2 * h / g)
    return [t1 * (1 + 2 * e * (1 - e ** (k - 1)) / (1 - e)) for k in range(1, count + 1)]


def test_simulate_bouncing_ball_impact_times_and_rest():
    """Impacts at t_k = t1 (1 + 2(e + ... + e^(k-1))) to 1e-9, impulses m (1+e) e^(k-1) sqrt(2 g h); finitely many
    (rest rule), the last one at t_inf = t1 (1+e)/(1-e) to 1e-9; afterwards the ball lies on the floor."""
    m, h, e, g = 0.1, 1.0, 0.5, 9.81
    t1 = math.sqrt(2 * h / g)
    t_inf = t1 * (1 + e) / (1 - e)
    out = run_simulation(BALL, t_end=1.5 * t_inf, dt=1e-3)
    imp = out["impacts"]
    assert 5 < len(imp) < 1000, f"{len(imp)} impacts"
    assert all(row["contact"] == "floor" for row in imp)
    want = ball_times(h, e, g, len(imp))
    w = math.sqrt(2 * g * h)
    for k, row in enumerate(imp[:20]):
        assert abs(row["t"] - want[k]) <= 1e-9, (k, row["t"], want[k])
        assert abs(row["impulse"] - m * (1 + e) * e**k * w) <= 1e-9 * m * w, (k, row["impulse"])
        rb, ra = _vec(row["rates_before"], out["coordinates"]), _vec(row["rates_after"], out["coordinates"])
        close(rb[0], -(e**k) * w, atol=1e-9 * w)
        close(ra[0], e ** (k + 1) * w, atol=1e-9 * w)
    times = [row["t"] for row in imp]
    assert times == sorted(times)
    assert abs(times[-1] - t_inf) <= 1e-9, (times[-1], t_inf)
    after = out["t"] > t_inf + 1e-6
    assert after.any()
    assert np.max(np.abs(out["q"][after, 0])) <= 1e-9 and np.max(np.abs(out["u"][after, 0])) <= 1e-9
    assert np.min(out["q"][:, 0]) >= -1e-9, "the ball went through the floor"


def test_simulate_rest_rule_is_a_plastic_capture():
    """capture_velocity = 0.5 m/s: approach speeds w e^k = 4.43, 2.21, 1.11, 0.55, 0.277, so the fifth impact is
    below it; that impact is plastic (impulse m * 0.277, normal velocity 0 after, the record says so) and the ball
    then rests on the floor."""
    m, h, e, g = 0.1, 1.0, 0.5, 9.81
    w = math.sqrt(2 * g * h)
    out = run_simulation(BALL, t_end=2.0, dt=1e-3, capture_velocity=0.5)
    imp = out["impacts"]
    assert len(imp) == 5, [(r["t"], r["impulse"]) for r in imp]
    close([r["t"] for r in imp], ball_times(h, e, g, 5), rtol=0, atol=1e-9)
    assert [bool(r.get("captured")) for r in imp] == [False] * 4 + [True]
    close(imp[-1]["impulse"], m * e**4 * w, rtol=1e-9, what="plastic impulse of the captured impact")
    close(_vec(imp[-1]["rates_after"], out["coordinates"]), [0.0], atol=1e-12, what="rates after the capture")
    after = out["t"] > imp[-1]["t"] + 1e-9
    close(out["q"][after, 0], 0.0, atol=1e-9, what="resting")
    close(out["u"][after, 0], 0.0, atol=1e-12, what="resting")


def test_simulate_elastic_ball_bounces_forever_without_loss():
    """e = 1: impacts at t1, 3 t1, 5 t1, ... and the energy does not change."""
    h, g = 1.0, 9.81
    t1 = math.sqrt(2 * h / g)
    out = run_simulation(BALL, {"e": 1}, t_end=7.5 * t1, dt=t1 / 50)
    times = [row["t"] for row in out["impacts"]]
    close(times, [t1, 3 * t1, 5 * t1, 7 * t1], rtol=0, atol=1e-9)
    E = out["T"] + out["V"]
    close(E, np.full_like(E, E[0]), rtol=1e-8, what="energy")


@pytest.mark.parametrize("layout", ["touching", "separated"])
@pytest.mark.parametrize("e", [0.5, 1.0])
def test_simulate_carriages_sequential_collisions(layout, e):
    """Problem 55 by simulation: exactly three impacts for e = 0.5 (1-2, 2-3, 1-2) with the book's impulses and the
    final velocities of the table; e = 1 ends with (0, 0, v) and no energy lost. Carriages 2 and 3 either touch
    at the start (the file) or stand d apart (--set x3=d); the book's "negligible gap" gives the same answer."""
    m, v, d = 10000, 2.0, 0.01
    overrides = {"e": e} if layout == "touching" else {"e": e, "x3": d}
    out = run_simulation(CARRIAGES, overrides, t_end=40 * d / v, dt=d / v / 20)
    imp = out["impacts"]
    book = p55_book(e, v, m) if e < 1 else p55_book(e, v, m)[:2]
    assert [row["contact"] for row in imp] == [c for c, _, _ in book], [(r["t"], r["contact"]) for r in imp]
    for row, (_, vel, U) in zip(imp, book):
        close(row["impulse"], U, what=f"impulse at t = {row['t']}")
        close(_vec(row["rates_after"], out["coordinates"]), vel, atol=1e-9 * v, rtol=1e-9)
    close(imp[0]["t"], d / v)
    if layout == "touching":
        close([row["t"] for row in imp], [d / v] * len(imp), what="all at the first contact")
    final = out["u"][-1]
    close(final, book[-1][1], atol=1e-9 * v, rtol=1e-9, what="final velocities")
    x = out["q"][-1]
    assert x[0] <= x[1] + 1e-9 and x[1] <= x[2] + 1e-9, "carriages passed through each other"
    if e == 1:
        close(out["T"][-1], out["T"][0], what="no energy lost")


def test_simulate_cli_writes_the_impact_table(tmp_path):
    out = tmp_path / "impacts.csv"
    r = CliRunner().invoke(app, ["simulate", str(CARRIAGES), "--set", "x3=0.01", "--t-end", "0.2",
                                 "--impacts", str(out)])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader(out.open()))
    assert {"t", "contact", "impulse"} <= set(rows[0])
    assert [row["contact"] for row in rows] == ["c12", "c23", "c12"]
    close([float(row["impulse"]) for row in rows], [U for _, _, U in p55_book(0.5, 2.0, 10000)], rtol=1e-6)
    close(float(rows[0]["t"]), 0.005, rtol=1e-6)


def significant(impacts, scale):
    """Impacts with an impulse above 1e-9 * scale. Resting neighbours whose velocities are round-off (1e-15) may
    close at ~1e-16 m/s and be captured by the rest rule: those records carry no impulse and are left out."""
    rest = [row for row in impacts if abs(row["impulse"]) <= 1e-9 * scale]
    assert all(row.get("captured", True) for row in rest), rest
    return [row for row in impacts if abs(row["impulse"]) > 1e-9 * scale]


def test_simulate_newton_cradle_elastic():
    """Ball 1 released from alpha hits ball 2 at the quarter period t_a = sqrt(L/g) K(sin^2(alpha/2)); four impacts
    at that instant (c12 ... c45), each m w; ball 5 leaves with w and balls 1-4 stay at rest; energy is kept."""
    from scipy.special import ellipk

    m, L, alpha = 0.1, 0.3, 0.5
    w = cradle_speed(L, alpha)
    t_a = math.sqrt(L / G) * ellipk(math.sin(alpha / 2) ** 2)
    out = run_simulation(CRADLE, t_end=2.5 * t_a, dt=t_a / 200)
    imp = significant(out["impacts"], m * w)
    assert [row["contact"] for row in imp] == ["c12", "c23", "c34", "c45"], [(r["t"], r["contact"]) for r in imp]
    for row in imp:
        assert abs(row["t"] - t_a) <= 1e-9, row["t"] - t_a
        close(row["impulse"], m * w, rtol=1e-8)
    close(_vec(imp[-1]["rates_after"], out["coordinates"]), [0, 0, 0, 0, w / L], atol=1e-8 * w / L, rtol=1e-8)
    after = out["t"] > t_a + 1e-9
    close(out["q"][after, :4], 0.0, atol=1e-9, what="balls 1-4 at rest")
    close(np.max(out["q"][after, 4]), alpha, rtol=1e-4, what="ball 5 swings out to alpha")
    E = out["T"] + out["V"]
    close(E, np.full_like(E, E[0]), rtol=1e-8, atol=1e-8 * abs(E[0]) + 1e-12, what="energy")


def test_simulate_newton_cradle_swings_back():
    """Ball 5 returns at 3 t_a and the velocity runs back through the chain (c45, c34, c23, c12): ball 1 leaves
    with -w and balls 2-5 stay at rest. (Resting balls 1-4 touch between 1 and 3 t_a; a contact captured there by
    the rest rule must not glue them together.)"""
    from scipy.special import ellipk

    m, L, alpha = 0.1, 0.3, 0.5
    w = cradle_speed(L, alpha)
    t_a = math.sqrt(L / G) * ellipk(math.sin(alpha / 2) ** 2)
    out = run_simulation(CRADLE, t_end=3.5 * t_a, dt=t_a / 200)
    imp = significant(out["impacts"], m * w)
    assert [row["contact"] for row in imp] == ["c12", "c23", "c34", "c45", "c45", "c34", "c23", "c12"], \
        [(r["t"] / t_a, r["contact"]) for r in imp]
    for row in imp[4:]:
        assert abs(row["t"] - 3 * t_a) <= 1e-8, row["t"] - 3 * t_a
        close(row["impulse"], m * w, rtol=1e-7)
    close(_vec(imp[-1]["rates_after"], out["coordinates"]), [-w / L, 0, 0, 0, 0], atol=1e-7 * w / L, rtol=1e-7)
    after = out["t"] > 3 * t_a + 1e-8
    close(out["q"][after, 1:], 0.0, atol=1e-8, what="balls 2-5 at rest")
